"""Integer sequences in the smallest of four encodings: ``[format, payload]``.

Coordinates of parameters (:mod:`.params`), cell records and cell indexes
(:mod:`walkstream.shared.wire`) are sequences of int64 values, mostly small deltas.
Each is sent as the pair ``[format, payload]``:

format 0
    ``payload`` is a msgpack array of integers (what a JSON reader sees, too);
format 1
    ``payload`` is ``bin``: little-endian int16 values;
format 2
    ``payload`` is ``bin``: little-endian int32 values;
format 3
    ``payload`` is ``bin``: zigzag LEB128 varints.

:func:`pack_ints` picks the smallest by a size model (no candidate is packed
twice); :func:`unpack_ints` reads any of them, bounded.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from typing import Any

import numpy as np

from walkstream.shared.codec.bounded import checked_int, is_int
from walkstream.shared.codec.varint import (
    decode_varints,
    py_decode_varints,
    py_varints,
    unzigzag_int,
    varint_size,
    zigzag_int,
)
from walkstream.shared.errors import CodecError

__all__ = [
    "INT_FORMATS",
    "pack_ints",
    "unpack_ints",
    "FMT_LIST",
    "FMT_I16",
    "FMT_I32",
    "FMT_VARINT",
    "mp_list_size",
    "smallest_payload",
    "unpack_payload",
]

FMT_LIST = 0
"""Payload format: a msgpack list of the ints."""
FMT_I16 = 1
"""Payload format: little-endian int16 bytes."""
FMT_I32 = 2
"""Payload format: little-endian int32 bytes."""
FMT_VARINT = 3
"""Payload format: zigzag varint bytes."""
INT_FORMATS = (FMT_LIST, FMT_I16, FMT_I32, FMT_VARINT)
"""The payload formats: msgpack list, int16, int32, zigzag varints."""


# ---------------------------------------------------------------------------
# size models (to choose the smallest payload without packing every candidate)
# ---------------------------------------------------------------------------


def _mp_int_size(d: int) -> int:
    if -32 <= d < 128:
        return 1
    if -128 <= d < 256:
        return 2
    if -(2**15) <= d < 2**16:
        return 3
    if -(2**31) <= d < 2**32:
        return 5
    return 9


def mp_list_size(values: list[int]) -> int:
    """Bytes msgpack takes for ``values`` as a plain list."""
    n = len(values)
    return (1 if n < 16 else 3 if n < 65536 else 5) + sum(map(_mp_int_size, values))


def _mp_bin_header(n: int) -> int:
    return 2 if n < 256 else 3 if n < 65536 else 5


def smallest_payload(d: list[int]) -> tuple[int, list[int] | bytes]:
    """The smallest of four encodings of int64 values: ``(format, payload)``."""
    n = len(d)
    if n == 0:
        return FMT_LIST, []
    best_fmt, best = FMT_LIST, mp_list_size(d)
    lo, hi = min(d), max(d)
    if -(2**15) <= lo and hi < 2**15:
        fixed_fmt, width = FMT_I16, 2
    elif -(2**31) <= lo and hi < 2**31:
        fixed_fmt, width = FMT_I32, 4
    else:
        fixed_fmt, width = FMT_LIST, 0
    if width and _mp_bin_header(width * n) + width * n < best:
        best_fmt, best = fixed_fmt, _mp_bin_header(width * n) + width * n
    z = [zigzag_int(v) for v in d]
    vb = sum(map(varint_size, z))
    if _mp_bin_header(vb) + vb < best:
        return FMT_VARINT, py_varints(z)
    if best_fmt == FMT_I16:
        return best_fmt, struct.pack(f"<{n}h", *d)
    if best_fmt == FMT_I32:
        return best_fmt, struct.pack(f"<{n}i", *d)
    return FMT_LIST, d


def unpack_payload(fmt: int, payload: object, what: str, field: str) -> list[int]:
    """The integers of payload ``payload`` in format ``fmt``, checked (``what`` and ``field`` name it in errors)."""
    if fmt == FMT_LIST:
        if not isinstance(payload, list):
            raise CodecError(f"{what}: {field}: expected a list, got {type(payload).__name__}")
        if not all(is_int(v) and -(2**63) <= v < 2**63 for v in payload):
            raise CodecError(f"{what}: {field}: expected int64 values only")
        return payload
    if not isinstance(payload, bytes):
        raise CodecError(f"{what}: {field}: expected bin, got {type(payload).__name__}")
    if fmt == FMT_I16:
        if len(payload) % 2:
            raise CodecError(f"{what}: {field}: int16 blob of odd length {len(payload)}")
        return list(struct.unpack(f"<{len(payload) // 2}h", payload))
    if fmt == FMT_I32:
        if len(payload) % 4:
            raise CodecError(f"{what}: {field}: int32 blob of length {len(payload)}")
        return list(struct.unpack(f"<{len(payload) // 4}i", payload))
    if fmt != FMT_VARINT:
        raise CodecError(f"{what}: {field}: unknown format {fmt}")
    if len(payload) > 256:
        z = decode_varints(payload, f"{what}: {field}")
        return (
            (z >> np.uint64(1)).astype(np.int64) ^ -(z & np.uint64(1)).astype(np.int64)
        ).tolist()
    return [unzigzag_int(v) for v in py_decode_varints(payload, f"{what}: {field}")]


# ---------------------------------------------------------------------------
# public pair form
# ---------------------------------------------------------------------------


def pack_ints(values: Sequence[int], *, compact: bool = True) -> list[Any]:
    """``[format, payload]`` of int64 ``values``: the smallest encoding, or a plain list.

    Parameters
    ----------
    values : (k,) int
        The integers (numpy integers are converted).
    compact : bool
        False gives format 0 (a plain list) whatever its size, for JSON readers.

    >>> pack_ints([1, 2, 3])
    [0, [1, 2, 3]]
    >>> fmt, payload = pack_ints([1000] * 40)  # int16 (varints tie at 2 bytes each)
    >>> fmt, len(payload)
    (1, 80)
    """
    d = [int(v) for v in values]
    if not compact:
        return [FMT_LIST, d]
    fmt, payload = smallest_payload(d)
    return [fmt, payload]


def unpack_ints(obj: object, what: str, field: str, max_len: int | None = None) -> list[int]:
    """The integers of a ``[format, payload]`` pair (see the module docs), checked.

    Raises
    ------
    CodecError
        Not a pair, an unknown format, a payload that does not match it, or more
        than ``max_len`` values.
    """
    if not isinstance(obj, list | tuple) or len(obj) != 2:
        raise CodecError(f"{what}: {field}: expected [format, payload]")
    fmt = checked_int(obj[0], what, f"{field} format", 0, FMT_VARINT)
    out = unpack_payload(fmt, obj[1], what, field)
    if max_len is not None and len(out) > max_len:
        raise CodecError(f"{what}: {field}: {len(out)} values, more than {max_len}")
    return [int(v) for v in out]
