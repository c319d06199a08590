"""Several contents parts as one LZMA-compressed frame: an interior's first view in one dictionary.

The start bundle of an interior brings the contents of every cell the first pose sees,
and its first perfect frame waits for all of them (on the duplex, ten cells down five
doorways).  Sent one part at a time in the answer's gzip stream, each cell goes in the
cheaper of two forms (:mod:`~walkstream.server.service.contentsform`): inflated, so that
it shares gzip's 32 kB window with the cells before it, or as stored, compressed on its
own (lzma on the larger cells).  Neither form gets both LZMA's better coding and a
dictionary over the whole view.  One LZMA2 stream over the inflated parts does: the
duplex's first view (two heads and eight whole cells) costs 19.7 kB in the gzip stream
part by part and 17.3 kB as one pack.

A pack is the msgpack map::

    {"pack": "walkstream-contentspack/1", "parts": n, "body": bin}

``body`` is a raw LZMA2 stream (:mod:`~walkstream.shared.codec.rawlzma`) of ``n`` contents
parts (:mod:`~walkstream.shared.codec.cellbatch`: ``{cell, etag, body}`` or a head's
``{cell, etag, body, missing}``) packed one after the other, each exactly as it would
go alone.  A reader unpacks the ``n`` parts and reads each as if it had come alone; a
pack's parts are all in when the pack is, so a client that needs every one of them
(a first perfect frame) waits no longer for it, and one that could use the first
early waits for the last.

Decoding is bounded: at most :data:`MAX_PACK_BYTES` inflated, exactly ``n`` parts,
nothing after the last; any failure is a :class:`~walkstream.shared.errors.CodecError`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import msgpack

from walkstream.shared.codec.rawlzma import compress_raw, decompress_raw
from walkstream.shared.errors import CodecError

__all__ = ["PACK_FORMAT", "MAX_PACK_BYTES", "MAX_PACK_PARTS", "pack_parts", "is_pack",
           "unpack_parts"]

PACK_FORMAT = "walkstream-contentspack/1"
"""The ``pack`` field of a pack."""

MAX_PACK_BYTES = 64 << 20
"""Most bytes a pack's body inflates to."""

MAX_PACK_PARTS = 1 << 10
"""Most parts in one pack."""

_KEYS = frozenset({"pack", "parts", "body"})


def pack_parts(parts: Sequence[bytes]) -> bytes:
    """The packed msgpack map of a pack of ``parts`` (each a packed contents part).

    Raises
    ------
    ValueError
        No part, or more than :data:`MAX_PACK_PARTS`.
    """
    if not 0 < len(parts) <= MAX_PACK_PARTS:
        raise ValueError(f"a pack holds 1 to {MAX_PACK_PARTS} parts, got {len(parts)}")
    body = compress_raw(b"".join(parts))
    data: bytes = msgpack.packb({"pack": PACK_FORMAT, "parts": len(parts), "body": body}, use_bin_type=True)
    return data


def is_pack(obj: Any) -> bool:
    """Whether an unpacked stream object is a pack (a map with a ``pack`` field)."""
    return isinstance(obj, dict) and "pack" in obj


def unpack_parts(obj: Any, what: str = "contents pack") -> list[tuple[Any, int]]:
    """The parts of an unpacked pack, in order, each with its packed size in bytes.

    Raises
    ------
    CodecError
        Not a pack of this format, a damaged body, more than :data:`MAX_PACK_BYTES`
        inflated, or not exactly the parts it says (each a map).
    """
    if not isinstance(obj, dict) or set(obj) != _KEYS or obj["pack"] != PACK_FORMAT:
        raise CodecError(f"{what}: not a {PACK_FORMAT} map")
    n, body = obj["parts"], obj["body"]
    if type(n) is not int or not 0 < n <= MAX_PACK_PARTS or not isinstance(body, bytes):
        raise CodecError(f"{what}: parts must be 1 to {MAX_PACK_PARTS} and body bytes")
    raw = decompress_raw(body, what, MAX_PACK_BYTES)
    u = msgpack.Unpacker(raw=False, max_buffer_size=max(len(raw), 1), max_map_len=8, max_array_len=0,
                         max_str_len=1 << 12, max_bin_len=len(raw), max_ext_len=0, strict_map_key=True)
    u.feed(raw)
    out: list[tuple[Any, int]] = []
    pos = 0
    try:
        for o in u:
            out.append((o, u.tell() - pos))
            pos = u.tell()
            if len(out) > n:
                break
    except (msgpack.UnpackException, ValueError) as exc:
        raise CodecError(f"{what}: damaged part {len(out)} ({exc})") from exc
    if len(out) != n or pos != len(raw):
        raise CodecError(f"{what}: {len(out)} whole parts where {n} were said")
    if not all(isinstance(o, dict) for o, _ in out):
        raise CodecError(f"{what}: a part that is not a map")
    return out
