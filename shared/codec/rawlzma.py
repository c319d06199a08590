"""Raw LZMA2 streams tuned for the varint and msgpack bytes of our codecs, decoded bounded.

The interior start bundle's first view (:mod:`~walkstream.shared.codec.contentspack`)
and the compact topology (:mod:`~walkstream.shared.roomcompact`, version 3) are small
bodies (2 to 20 kB) that the first frame of a walk waits for on a 56 kbit/s link.  A
raw LZMA2 stream (no ``xz`` container: no header, index or check, 60 bytes less) with
one literal context bit and no position bits (:data:`FILTERS`) codes them 10 to 20 %
smaller than zlib level 9: duplex.ifc's compact topology 2,737 -> 2,374 bytes, its
first view's ten cells 15.9 kB where one gzip stream takes 19.4 kB.  The dictionary is
1 MiB, so that a decoder never allocates more for a body that small.
"""

from __future__ import annotations

import lzma

from walkstream.shared.errors import CodecError

__all__ = ["FILTERS", "compress_raw", "decompress_raw"]

FILTERS: list[dict[str, int]] = [
    {"id": lzma.FILTER_LZMA2, "preset": 9 | lzma.PRESET_EXTREME, "dict_size": 1 << 20, "lc": 1, "lp": 0, "pb": 0}
]
"""The filter chain (on duplex.ifc's first view: 15,885 bytes; the ``xz`` defaults,
``lc`` 3 and ``pb`` 2: 16,068)."""


def compress_raw(data: bytes) -> bytes:
    """``data`` as one raw LZMA2 stream with :data:`FILTERS`."""
    return lzma.compress(data, format=lzma.FORMAT_RAW, filters=FILTERS)


def decompress_raw(data: bytes, what: str, max_bytes: int) -> bytes:
    """A raw LZMA2 stream written by :func:`compress_raw`, decompressed to at most ``max_bytes``.

    Raises
    ------
    CodecError
        Damaged, truncated, decompressing past ``max_bytes`` (a bomb), or bytes after its end.
    """
    dec = lzma.LZMADecompressor(lzma.FORMAT_RAW, filters=FILTERS)
    try:
        raw = dec.decompress(bytes(data), max_bytes)
    except lzma.LZMAError as exc:
        raise CodecError(f"{what}: damaged LZMA stream ({exc})") from exc
    if not dec.eof:
        raise CodecError(f"{what}: LZMA stream truncated, or it decompresses to more than {max_bytes} bytes")
    if dec.unused_data:
        raise CodecError(f"{what}: {len(dec.unused_data)} bytes after the LZMA stream's end")
    return raw
