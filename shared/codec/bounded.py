"""Bounded msgpack unpacking of untrusted bytes, and the checks every decoder shares.

The client decodes bytes it received over the network, so every decoder is
*bounded*: the input size is checked first, msgpack is unpacked with explicit
``max_*_len`` limits, every field is type- and range-checked, and any failure is
raised as :class:`~walkstream.shared.errors.CodecError` naming what was being decoded.
"""

from __future__ import annotations

import zlib
from typing import Any

import msgpack

from walkstream.shared.errors import CodecError

__all__ = [
    "unpack_bounded",
    "inflate_tagged",
    "inflate_bounded",
    "INT64_MAX",
    "DECODE_ERRORS",
    "byte_length",
    "is_int",
    "checked_int",
]

# Bounds for untrusted input.  A building with a million vertices is already absurd;
# the limits only have to stop a forged length from allocating gigabytes.
_MAX_RECORD_BYTES = 1 << 22
_MAX_STR = 1 << 12
INT64_MAX = 2**63 - 1
"""The largest int64."""


DECODE_ERRORS = (ValueError, TypeError, KeyError, IndexError, OverflowError, ZeroDivisionError)
"""What a decoder may raise on malformed input (each is turned into a :class:`CodecError`)."""


# ---------------------------------------------------------------------------
# bounded msgpack
# ---------------------------------------------------------------------------


def byte_length(data: object, what: str) -> int:
    """The length of ``data`` in bytes, or a :class:`CodecError` when it is not bytes-like."""
    if isinstance(data, bytes | bytearray):
        return len(data)
    if isinstance(data, memoryview):
        return data.nbytes
    raise CodecError(f"{what}: expected bytes, got {type(data).__name__}")


def unpack_bounded(
    data: bytes | bytearray | memoryview,
    what: str,
    *,
    max_bytes: int = _MAX_RECORD_BYTES,
    max_array_len: int = 1 << 16,
    max_map_len: int = 0,
    max_str_len: int = _MAX_STR,
    max_bin_len: int = _MAX_RECORD_BYTES,
) -> Any:
    """Unpack one msgpack object from untrusted bytes with hard limits.

    ``msgpack.unpackb`` has no ``max_buffer_size`` (only the streaming ``Unpacker``
    has), so the buffer bound is checked here before unpacking; the per-container
    limits go to msgpack.  Ext types (and timestamps) are always refused.

    Parameters
    ----------
    data:
        The bytes.
    what:
        What is being decoded, for error messages (``"building params"``).
    max_bytes, max_array_len, max_map_len, max_str_len, max_bin_len:
        Limits; exceeding any raises :class:`CodecError`.

    Raises
    ------
    CodecError
        The bytes are too long, truncated, not msgpack, exceed a limit, or have
        trailing bytes.
    """
    n = byte_length(data, what)
    if n == 0:
        raise CodecError(f"{what}: no bytes")
    if n > max_bytes:
        raise CodecError(f"{what}: {n} bytes, more than the limit of {max_bytes}")
    try:
        return msgpack.unpackb(
            data,
            raw=False,
            use_list=True,
            strict_map_key=True,
            max_array_len=max_array_len,
            max_map_len=max_map_len,
            max_str_len=max_str_len,
            max_bin_len=max_bin_len,
            max_ext_len=0,
        )
    except msgpack.ExtraData as exc:
        raise CodecError(f"{what}: trailing bytes after the msgpack object") from exc
    except (ValueError, TypeError, OverflowError, RecursionError, msgpack.UnpackException) as exc:
        detail = str(exc) or type(exc).__name__
        raise CodecError(f"{what}: not valid msgpack ({detail})") from exc


def is_int(x: object) -> bool:
    """Whether ``x`` is a plain int (a msgpack bool must not pass as 1 or 0)."""
    return type(x) is int


def checked_int(x: object, what: str, field: str, lo: int | None = None, hi: int | None = None) -> int:
    """``x`` when it is an int within ``[lo, hi]``, else a :class:`CodecError` naming ``what`` and ``field``."""
    if not is_int(x):
        raise CodecError(f"{what}: {field}: expected an integer, got {type(x).__name__}")
    assert isinstance(x, int)
    if lo is not None and x < lo:
        raise CodecError(f"{what}: {field}: expected >= {lo}, got {x}")
    if hi is not None and x > hi:
        raise CodecError(f"{what}: {field}: expected <= {hi}, got {x}")
    return x


def inflate_tagged(body: bytes, what: str, magic: bytes, version: int, max_bytes: int, name: str) -> bytes:
    """The zlib payload of a ``magic version:u8 zlib(...)`` body, inflated bounded.

    Raises
    ------
    CodecError
        One line naming ``name``: no ``magic``, another version, corrupt, truncated,
        inflating past ``max_bytes`` (a bomb), or stray bytes after the stream.
    """
    byte_length(body, what)
    b = bytes(body)
    k = len(magic)
    if len(b) <= k or b[:k] != magic:
        raise CodecError(f"{what}: not a {name} (no {magic.decode()} header)")
    if b[k] != version:
        raise CodecError(f"{what}: {name} version {b[k]} is not supported (this reader knows {version})")
    return inflate_bounded(b[k + 1 :], what, max_bytes, name)


def inflate_bounded(data: bytes, what: str, max_bytes: int, name: str, wbits: int = 15) -> bytes:
    """One zlib stream (``wbits`` 15) or gzip member (``wbits`` 31), inflated to at most
    ``max_bytes``.

    Raises
    ------
    CodecError
        One line naming ``name``: corrupt, inflating past ``max_bytes`` (a bomb),
        truncated, or stray bytes after the stream.
    """
    inflater = zlib.decompressobj(wbits)
    try:
        raw = inflater.decompress(data, max_bytes + 1)
    except zlib.error as exc:
        raise CodecError(f"{what}: corrupt {name} ({exc})") from exc
    if len(raw) > max_bytes or inflater.unconsumed_tail:
        raise CodecError(f"{what}: {name} inflates to more than {max_bytes} bytes")
    if not inflater.eof:
        raise CodecError(f"{what}: truncated {name}")
    if inflater.unused_data:
        raise CodecError(f"{what}: {len(inflater.unused_data)} stray bytes after the {name}")
    return raw
