"""Potentially visible sets with their ACH, id sets and cell polygons.

pvs
    ``b"\x01"`` then unsigned LEB128 varints ``k, id_0, id_1 - id_0, ...,
    units_0, ..., units_{k-1}`` with ids ascending and the units summing to
    exactly 65535 (``k > 0``).
ids
    unsigned LEB128 varints of the ascending ids, delta coded (empty set: ``b""``).
polygon
    msgpack array of ``[x, y]`` float64 pairs.
"""

from __future__ import annotations

import msgpack
import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.shared.arrays import F64, I64, U64
from walkstream.shared.codec.bounded import INT64_MAX, byte_length, unpack_bounded
from walkstream.shared.codec.varint import decode_varints, encode_varints
from walkstream.shared.errors import CodecError

__all__ = [
    "ACH_UNITS",
    "quantise_ach",
    "encode_pvs",
    "decode_pvs",
    "pvs_size",
    "encode_ids",
    "decode_ids",
    "encode_polygon",
    "decode_polygon",
]

ACH_UNITS = 65535
"""ACH is stored as integer units of ``1 / ACH_UNITS``; one cell's units sum to this."""
_MAX_PVS_BYTES = 1 << 27
_MAX_IDS_BYTES = 1 << 24
_MAX_POLYGON_VERTICES = 1 << 16


# ---------------------------------------------------------------------------
# PVS + ACH
# ---------------------------------------------------------------------------


def quantise_ach(ach: ArrayLike) -> NDArray[np.int64]:
    """Quantise coverage values to integer units that sum to exactly ``ACH_UNITS``.

    Largest-remainder rounding of ``ach / sum(ach) * 65535``, except that every
    object with ``ach > 0`` gets at least one unit (it was seen; 0 would read as
    "not visible").  Those extra units are taken back from the objects whose
    rounding was most generous.  Ties are broken by position, so the result is
    deterministic.

    Parameters
    ----------
    ach:
        ``(k,)`` non-negative finite values (pixel counts or fractions: they are
        normalised here).

    Returns
    -------
    ndarray
        ``(k,) int64`` units summing to ``ACH_UNITS`` (empty for ``k == 0``).

    Raises
    ------
    CodecError
        A value is negative or not finite, all values are 0 while ``k > 0``, or more
        than 65535 objects have ``ach > 0``.
    """
    a = np.asarray(ach, dtype=np.float64).reshape(-1)
    if len(a) == 0:
        return np.zeros(0, np.int64)
    if not np.isfinite(a).all() or (a < 0).any():
        raise CodecError("ACH: values must be finite and non-negative")
    pos = a > 0
    if not pos.any():
        raise CodecError(f"ACH: all {len(a)} values are 0, so coverage is undefined")
    # scale by the maximum first so that a sum of huge pixel counts cannot overflow
    a = a / a.max()
    total = a.sum()
    if pos.sum() > ACH_UNITS:
        raise CodecError(f"ACH: {int(pos.sum())} visible objects, more than {ACH_UNITS} units")
    target = a / total * ACH_UNITS
    units = np.floor(target).astype(np.int64)
    units[pos & (units == 0)] = 1
    rem = target - units
    short = ACH_UNITS - int(units.sum())
    if short > 0:
        # hand out the missing units by largest remainder, among seen objects only
        cand = np.flatnonzero(pos)
        order = cand[np.argsort(-rem[cand], kind="stable")]
        # floors lose < 1 unit each, so short <= len(cand) (float rounding aside)
        while short > 0:
            take = order[:short]
            units[take] += 1
            short -= len(take)
    while short < 0:
        # minimum-one bumps overshot: take units back, most over-served first
        cand = np.flatnonzero(units > 1)
        order = cand[np.argsort(rem[cand], kind="stable")][:-short]
        units[order] -= 1
        rem[order] += 1
        short += len(order)
    return units


def encode_pvs(ids: ArrayLike, ach: ArrayLike) -> bytes:
    """Encode a cell's potentially visible set and its ACH.

    Parameters
    ----------
    ids:
        ``(k,)`` distinct non-negative object ids, any order.
    ach:
        ``(k,)`` non-negative coverage of each object (normalised here).

    Returns
    -------
    bytes
        ``b"\\x01"`` and varints: ``k``, the ascending ids delta coded, then the ACH
        units (see :func:`quantise_ach`).  A 200-object PVS is ~350-550 bytes; an
        empty one is 2 bytes.

    Raises
    ------
    CodecError
        Shapes differ, ids repeat or are negative, or the ACH cannot be quantised.
    """
    i = np.asarray(ids)
    a = np.asarray(ach, dtype=np.float64).reshape(-1)
    if i.size == 0 and a.size == 0:
        return b"\x01\x00"
    if i.ndim != 1 or i.dtype.kind not in "iu":
        raise CodecError(f"PVS: ids: expected a 1-d integer array, got {i.dtype} shape {i.shape}")
    if len(i) != len(a):
        raise CodecError(f"PVS: {len(i)} ids but {len(a)} ACH values")
    if i.dtype.kind == "i" and (i < 0).any():
        raise CodecError("PVS: ids must be non-negative")
    if i.dtype == np.uint64 and (i > np.uint64(INT64_MAX)).any():
        raise CodecError("PVS: ids must fit in int64")
    order = np.argsort(i, kind="stable")
    si = i[order].astype(np.uint64)
    deltas = np.diff(si, prepend=np.uint64(0))
    if len(si) > 1 and (deltas[1:] == 0).any():
        raise CodecError("PVS: ids repeat")
    units = quantise_ach(a[order])
    values = np.concatenate([np.array([len(si)], np.uint64), deltas, units.astype(np.uint64)])
    return b"\x01" + encode_varints(values)


def _pvs_varints(data: bytes | bytearray | memoryview, what: str) -> U64:
    n = byte_length(data, what)
    if n > _MAX_PVS_BYTES:
        raise CodecError(f"{what}: {n} bytes, more than the limit of {_MAX_PVS_BYTES}")
    if n < 2:
        raise CodecError(f"{what}: {n} bytes, too short for a PVS")
    mv = memoryview(data).cast("B")
    if mv[0] != 1:
        raise CodecError(f"{what}: format {mv[0]}, this walkstream reads format 1")
    return decode_varints(mv[1:], what)


def decode_pvs(data: bytes | bytearray | memoryview, what: str = "PVS") -> tuple[I64, F64]:
    """Decode bytes made by :func:`encode_pvs`.

    Returns
    -------
    ids:
        ``(k,) int64`` strictly ascending.
    ach:
        ``(k,) float64`` = units / 65535; sums to 1 (up to float rounding) for
        ``k > 0``.

    Raises
    ------
    CodecError
        Truncated or trailing data, a count that does not match, ids that overflow
        or repeat, or units that do not sum to 65535.
    """
    v = _pvs_varints(data, what)
    k = int(v[0])
    if len(v) != 1 + 2 * k:
        raise CodecError(
            f"{what}: declares {k} objects but holds {len(v) - 1} values, expected {2 * k}"
        )
    if k == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.float64)
    deltas, units = v[1 : 1 + k], v[1 + k :]
    if len(deltas) > 1 and (deltas[1:] == 0).any():
        raise CodecError(f"{what}: ids repeat")
    if (deltas > np.uint64(INT64_MAX)).any():
        raise CodecError(f"{what}: id out of the int64 range")
    ids = np.cumsum(deltas, dtype=np.uint64)
    # each delta < 2**63, so a wrap past 2**64 shows up as a decrease
    if (ids[1:] < ids[:-1]).any() or ids[-1] > np.uint64(INT64_MAX):
        raise CodecError(f"{what}: id out of the int64 range")
    if (units > np.uint64(ACH_UNITS)).any() or int(units.sum()) != ACH_UNITS:
        raise CodecError(f"{what}: ACH units must sum to {ACH_UNITS}")
    return ids.astype(np.int64), units.astype(np.float64) / ACH_UNITS


def pvs_size(data: bytes | bytearray | memoryview, what: str = "PVS") -> int:
    """Number of objects in an encoded PVS, reading only its first varint."""
    n = byte_length(data, what)
    if n < 2:
        raise CodecError(f"{what}: {n} bytes, too short for a PVS")
    mv = memoryview(data).cast("B")
    if mv[0] != 1:
        raise CodecError(f"{what}: format {mv[0]}, this walkstream reads format 1")
    head = bytes(mv[1:11])
    end = next((j for j, b in enumerate(head) if b < 0x80), None)
    if end is None:
        raise CodecError(f"{what}: truncated object count")
    return int(decode_varints(head[: end + 1], what)[0])


# ---------------------------------------------------------------------------
# id sets and polygons
# ---------------------------------------------------------------------------


def encode_ids(ids: ArrayLike) -> bytes:
    """Encode a set of non-negative ids as ascending delta varints.

    Parameters
    ----------
    ids:
        ``(k,)`` distinct non-negative integers, any order.

    Returns
    -------
    bytes
        ``b""`` for an empty set.
    """
    i = np.asarray(ids)
    if i.size == 0:
        return b""
    if i.ndim != 1 or i.dtype.kind not in "iu":
        raise CodecError(f"ids: expected a 1-d integer array, got {i.dtype} shape {i.shape}")
    if i.dtype.kind == "i" and (i < 0).any():
        raise CodecError("ids: must be non-negative")
    si = np.sort(i).astype(np.uint64)
    d = np.diff(si, prepend=np.uint64(0))
    if (d[1:] == 0).any():
        raise CodecError("ids: repeat")
    return encode_varints(d)


def decode_ids(data: bytes | bytearray | memoryview, what: str = "ids") -> I64:
    """Decode :func:`encode_ids` bytes to ``(k,) int64`` strictly ascending ids."""
    n = byte_length(data, what)
    if n > _MAX_IDS_BYTES:
        raise CodecError(f"{what}: {n} bytes, more than the limit of {_MAX_IDS_BYTES}")
    d = decode_varints(data, what)
    if len(d) == 0:
        return np.zeros(0, np.int64)
    if (d[1:] == 0).any():
        raise CodecError(f"{what}: ids repeat")
    if (d > np.uint64(INT64_MAX)).any():
        raise CodecError(f"{what}: id out of the int64 range")
    ids = np.cumsum(d, dtype=np.uint64)
    if (ids[1:] < ids[:-1]).any() or ids[-1] > np.uint64(INT64_MAX):
        raise CodecError(f"{what}: id out of the int64 range")
    return ids.astype(np.int64)


def encode_polygon(poly: ArrayLike) -> bytes:
    """Encode a polygon as a msgpack array of ``[x, y]`` float64 pairs.

    Parameters
    ----------
    poly:
        ``(n, 2)`` finite coordinates, ``n >= 3``, no repeated closing vertex.
    """
    p = np.asarray(poly, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2 or len(p) < 3:
        raise CodecError(f"polygon: expected shape (n >= 3, 2), got {p.shape}")
    if not np.isfinite(p).all():
        raise CodecError("polygon: coordinates must be finite")
    return msgpack.packb(p.tolist(), use_bin_type=True, use_single_float=False)


def decode_polygon(data: bytes | bytearray | memoryview, what: str = "polygon") -> F64:
    """Decode :func:`encode_polygon` bytes to a read-only ``(n, 2) float64`` array."""
    obj = unpack_bounded(
        data, what, max_array_len=_MAX_POLYGON_VERTICES, max_str_len=0, max_bin_len=0
    )
    if not isinstance(obj, list) or len(obj) < 3:
        raise CodecError(f"{what}: expected an array of >= 3 [x, y] pairs")
    for p in obj:
        if not (
            isinstance(p, list)
            and len(p) == 2
            and all(type(c) is float or type(c) is int for c in p)
        ):
            raise CodecError(f"{what}: expected [x, y] number pairs, got {p!r:.40}")
    try:
        a = np.array(obj, dtype=np.float64)
    except OverflowError as exc:
        raise CodecError(f"{what}: coordinate out of the float64 range") from exc
    if not np.isfinite(a).all():
        raise CodecError(f"{what}: coordinates must be finite")
    a.flags.writeable = False
    return a
