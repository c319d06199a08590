"""Each cell's form in a gzip-compressed contents stream (``server/service/contentsform.py``):
inflated to share the stream's dictionary, or as stored (lzma), whichever is cheaper there."""

from __future__ import annotations

import lzma
import random
import zlib

import pytest

from walkstream.server.service.contentsform import STREAM_LEVEL, ContentsStream


def _gzip(parts: list[bytes]) -> int:
    """Bytes of ``parts`` gzipped as the answers do: level 9, flushed after each part."""
    co = zlib.compressobj(STREAM_LEVEL, zlib.DEFLATED, 31)
    return sum(len(co.compress(p) + co.flush(zlib.Z_SYNC_FLUSH)) for p in parts)


def _noise(n: int, seed: int) -> bytes:
    return random.Random(seed).randbytes(n)


def test_a_repeat_beyond_gzips_window_goes_as_stored_lzma() -> None:
    # 40 kB of noise twice: the repeat lies beyond deflate's 32 kB window, within lzma's
    body = _noise(40_000, 1) * 2
    inflated, stored = b"N" + body, b"X" + lzma.compress(body)
    s = ContentsStream()
    assert s.cheaper(inflated, stored) == stored
    assert s.nbytes == _gzip([stored]) < 0.6 * _gzip([inflated])


def test_a_cell_like_one_already_sent_goes_inflated() -> None:
    # the second home of a mirrored pair: inflated, it is nearly free after the first
    body = _noise(3_000, 2)
    first, inflated, stored = b"N" + body, b"N" + body, b"X" + lzma.compress(body)
    s = ContentsStream()
    s.feed(first)
    assert s.cheaper(inflated, stored) == inflated
    assert s.nbytes == _gzip([first, inflated]) < _gzip([first, stored])


def test_the_mirror_counts_the_stream_as_sent() -> None:
    parts = [_noise(500, k) * (k + 1) for k in range(5)]
    s = ContentsStream()
    chosen = [s.cheaper(p, b"Z" + zlib.compress(p, 9)) for p in parts]
    # what the mirror says the stream holds is what a gzip of the chosen parts holds,
    # and no choice made it dearer than sending every part in its first form
    assert s.nbytes == _gzip(chosen) <= _gzip(parts)
    with pytest.raises(ValueError, match="no part"):
        s.cheaper()
