"""LEB128 varints (vectorised, with scalar twins for short inputs) and zigzag signs.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.shared.arrays import U64
from walkstream.shared.codec.bounded import byte_length
from walkstream.shared.errors import CodecError

__all__ = [
    "encode_varints",
    "decode_varints",
    "zigzag",
    "unzigzag",
    "varint_field",
    "py_varints",
    "py_decode_varints",
    "varint_size",
    "zigzag_int",
    "unzigzag_int",
]


# ---------------------------------------------------------------------------
# varints (vectorised)
# ---------------------------------------------------------------------------


def _varint_lengths(v: U64) -> NDArray[np.int64]:
    """Bytes per value of the LEB128 encoding of ``v``, ``(k,) int64``."""
    nb = np.ones(len(v), np.int64)
    t = v >> np.uint64(7)
    while t.any():  # at most 9 rounds: loops over byte positions, not values
        nb += t > 0
        t >>= np.uint64(7)
    return nb


def encode_varints(values: ArrayLike) -> bytes:
    """Encode non-negative integers as unsigned LEB128 varints.

    Parameters
    ----------
    values:
        ``(k,)`` integers in ``[0, 2**64)``.

    Returns
    -------
    bytes
        The concatenated varints (``b""`` for ``k == 0``).
    """
    a = np.asarray(values)
    if a.size == 0:
        return b""
    if a.dtype.kind not in "iu":
        raise CodecError(f"varints: expected integers, got dtype {a.dtype}")
    if a.dtype.kind == "i" and (a < 0).any():
        raise CodecError("varints: expected non-negative integers")
    v = a.reshape(-1).astype(np.uint64)
    nb = _varint_lengths(v)
    starts = np.cumsum(nb) - nb
    out = np.empty(int(nb.sum()), np.uint8)
    for j in range(int(nb.max())):
        sel = nb > j
        byte = (v[sel] >> np.uint64(7 * j)) & np.uint64(0x7F)
        more = (nb[sel] > j + 1).astype(np.uint64) << np.uint64(7)
        out[starts[sel] + j] = (byte | more).astype(np.uint8)
    return out.tobytes()


def decode_varints(data: bytes | bytearray | memoryview, what: str = "varints") -> U64:
    """Decode concatenated unsigned LEB128 varints.

    Only canonical (shortest) encodings of values below ``2**64`` are accepted.

    Parameters
    ----------
    data:
        The bytes (``b""`` decodes to an empty array).
    what:
        What is being decoded, for error messages.

    Returns
    -------
    ndarray
        ``(k,) uint64`` values.

    Raises
    ------
    CodecError
        The last varint is truncated, a varint is longer than 10 bytes, overflows 64
        bits, or is not in shortest form.
    """
    n = byte_length(data, what)
    if n == 0:
        return np.zeros(0, np.uint64)
    buf = np.frombuffer(data, dtype=np.uint8)
    ends = np.flatnonzero(buf < 0x80)
    if len(ends) == 0 or ends[-1] != n - 1:
        raise CodecError(f"{what}: truncated varint at the end of {n} bytes")
    starts = np.empty_like(ends)
    starts[0] = 0
    starts[1:] = ends[:-1] + 1
    lengths = ends - starts + 1
    if lengths.max() > 10:
        raise CodecError(f"{what}: varint longer than 10 bytes")
    # shortest form: a multi-byte varint never ends in a zero byte
    if ((lengths > 1) & (buf[ends] == 0)).any():
        raise CodecError(f"{what}: varint not in shortest form")
    if ((lengths == 10) & (buf[ends] > 1)).any():
        raise CodecError(f"{what}: varint overflows 64 bits")
    vals = np.zeros(len(ends), np.uint64)
    for j in range(int(lengths.max())):
        sel = lengths > j
        part = (buf[starts[sel] + j] & 0x7F).astype(np.uint64)
        vals[sel] |= part << np.uint64(7 * j)
    return vals


# Per-record helpers below work on Python ints: a building has tens of values, and
# at that size a plain loop beats the fixed cost of a dozen numpy calls.


def py_varints(values: Iterable[int]) -> bytes:
    """Scalar twin of :func:`encode_varints` for non-negative ints."""
    out = bytearray()
    for v in values:
        while v >= 0x80:
            out.append((v & 0x7F) | 0x80)
            v >>= 7
        out.append(v)
    return bytes(out)


def py_decode_varints(data: bytes, what: str) -> list[int]:
    """Scalar twin of :func:`decode_varints` (same checks, same messages)."""
    vals: list[int] = []
    v = shift = nb = 0
    for b in data:
        v |= (b & 0x7F) << shift
        shift += 7
        nb += 1
        if b < 0x80:
            if nb > 1 and b == 0:
                raise CodecError(f"{what}: varint not in shortest form")
            if v >= 1 << 64:
                raise CodecError(f"{what}: varint overflows 64 bits")
            vals.append(v)
            v = shift = nb = 0
        elif nb >= 10:
            raise CodecError(f"{what}: varint longer than 10 bytes")
    if nb:
        raise CodecError(f"{what}: truncated varint at the end of {len(data)} bytes")
    return vals


def varint_size(z: int) -> int:
    """Bytes the varint of non-negative ``z`` takes."""
    return max(1, (z.bit_length() + 6) // 7)


def zigzag_int(d: int) -> int:
    """Scalar twin of :func:`zigzag`."""
    return (d << 1) ^ (d >> 63)


def unzigzag_int(z: int) -> int:
    """Scalar twin of :func:`unzigzag`."""
    return (z >> 1) ^ -(z & 1)


def zigzag(d: NDArray[np.int64]) -> NDArray[np.uint64]:
    """Signed ``(k,)`` integers as unsigned (0, -1, 1, -2, ... -> 0, 1, 2, 3, ...)."""
    return ((d << 1) ^ (d >> 63)).astype(np.uint64)


def unzigzag(u: NDArray[np.uint64]) -> NDArray[np.int64]:
    """Inverse of :func:`zigzag`."""
    v = u.astype(np.int64)
    return (v >> 1) ^ -(v & 1)


def varint_field(body: dict[str, Any], key: str, count: int, what: str) -> U64:
    """The ``count`` varints stored as bytes under ``body[key]`` (a decoded msgpack map).

    Raises
    ------
    CodecError
        ``key`` missing or not bytes, damaged varints, or another count.
    """
    raw = body.get(key)
    if not isinstance(raw, bytes):
        raise CodecError(f"{what}: {key} is not bytes")
    v = decode_varints(raw, f"{what}: {key}")
    if len(v) != count:
        raise CodecError(f"{what}: {key}: expected {count} values, got {len(v)}")
    return np.asarray(v, dtype=np.uint64)
