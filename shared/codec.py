"""Compact wire and storage codecs for scene records.

Everything that leaves the bake goes through this module: building and street
parameters (msgpack arrays with centimetre-quantised, delta-coded coordinates),
potentially visible sets with their ACH (LEB128 varints, ACH in units of 1/65535),
id sets (cell neighbours) and cell boundaries.

The client decodes bytes it received over the network, so every decoder is
*bounded*: the input size is checked first, msgpack is unpacked with explicit
``max_*_len`` limits, every field is type- and range-checked, and any failure is
raised as :class:`shared.errors.CodecError` naming what was being decoded.  No
decoder lets a raw ``msgpack``/``KeyError``/``TypeError`` escape, and none allocates
more than a small multiple of its input size.

Formats (version 1)
-------------------
building
    msgpack array ``[header, id, ax, ay, counts, coords, heights, floors, fh_cm,
    style, source_id]``.  ``header = 1 << 5 | nb_format << 2 | coord_format``.
    ``ax, ay`` is the first exterior vertex in integer centimetres (the anchor);
    ``counts`` the vertex count (an int for one ring, a list for several);
    ``coords`` the ``2 (N - 1)`` per-vertex x/y deltas in centimetres chained over
    all rings (see :func:`encode_building` for the four coordinate formats);
    ``heights`` the neighbour heights in centimetres over all ``N`` vertices, sparse
    ``[i, h, i, h, ...]`` (format 0) or run-length ``[h, run, h, run, ...]``
    (format 1).
street
    msgpack array ``[header, id, n, ax, ay, coords, width_cm, source_id]`` with
    ``header = 2 << 5 | kind << 2 | coord_format``.
pvs
    ``b"\\x01"`` then unsigned LEB128 varints ``k, id_0, id_1 - id_0, ...,
    units_0, ..., units_{k-1}`` with ids ascending and the units summing to
    exactly 65535 (``k > 0``).
ids
    unsigned LEB128 varints of the ascending ids, delta coded (empty set: ``b""``).
polygon
    msgpack array of ``[x, y]`` float64 pairs.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable, Sequence
from typing import Any

import msgpack
import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.shared.errors import CodecError
from walkstream.shared.records import BuildingParams, StreetParams

__all__ = [
    "ACH_UNITS",
    "encode_building",
    "decode_building",
    "encode_street",
    "decode_street",
    "decode_object",
    "encode_pvs",
    "decode_pvs",
    "pvs_size",
    "quantise_ach",
    "encode_ids",
    "decode_ids",
    "encode_polygon",
    "decode_polygon",
    "encode_varints",
    "decode_varints",
    "unpack_bounded",
]

ACH_UNITS = 65535
"""ACH is stored as integer units of ``1 / ACH_UNITS``; one cell's units sum to this."""

_REC_BUILDING = 1
_REC_STREET = 2
_STREET_KINDS = ("street", "crossroad", "square")

# Coordinate payload formats, chosen per record by encoded size.
_FMT_LIST, _FMT_I16, _FMT_I32, _FMT_VARINT = 0, 1, 2, 3
_NB_SPARSE, _NB_RLE = 0, 1

# Bounds for untrusted input.  A building with a million vertices is already absurd;
# the limits only have to stop a forged length from allocating gigabytes.
_MAX_RECORD_BYTES = 1 << 22
_MAX_VERTICES = 1 << 20
_MAX_STR = 1 << 12
_MAX_PVS_BYTES = 1 << 27
_MAX_IDS_BYTES = 1 << 24
_MAX_POLYGON_VERTICES = 1 << 16
# |centimetres| below 2**53 keep float64 -> int64 conversion exact.
_MAX_CM = float(2**53)
_INT64_MAX = 2**63 - 1

U64 = NDArray[np.uint64]
I64 = NDArray[np.int64]
F64 = NDArray[np.float64]

_DECODE_ERRORS = (ValueError, TypeError, KeyError, IndexError, OverflowError, ZeroDivisionError)


# ---------------------------------------------------------------------------
# bounded msgpack
# ---------------------------------------------------------------------------


def _nbytes(data: object, what: str) -> int:
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
    n = _nbytes(data, what)
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


def _is_int(x: object) -> bool:
    # bool is an int subclass; msgpack true/false must not pass as 1/0
    return type(x) is int


def _int(x: object, what: str, field: str, lo: int | None = None, hi: int | None = None) -> int:
    if not _is_int(x):
        raise CodecError(f"{what}: {field}: expected an integer, got {type(x).__name__}")
    assert isinstance(x, int)
    if lo is not None and x < lo:
        raise CodecError(f"{what}: {field}: expected >= {lo}, got {x}")
    if hi is not None and x > hi:
        raise CodecError(f"{what}: {field}: expected <= {hi}, got {x}")
    return x


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
    n = _nbytes(data, what)
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


def _py_varints(values: Iterable[int]) -> bytes:
    out = bytearray()
    for v in values:
        while v >= 0x80:
            out.append((v & 0x7F) | 0x80)
            v >>= 7
        out.append(v)
    return bytes(out)


def _py_decode_varints(data: bytes, what: str) -> list[int]:
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


def _varint_size(z: int) -> int:
    return max(1, (z.bit_length() + 6) // 7)


def _zigzag(d: int) -> int:
    return (d << 1) ^ (d >> 63)


def _unzigzag(z: int) -> int:
    return (z >> 1) ^ -(z & 1)


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


def _mp_list_size(values: list[int]) -> int:
    n = len(values)
    return (1 if n < 16 else 3 if n < 65536 else 5) + sum(map(_mp_int_size, values))


def _mp_bin_header(n: int) -> int:
    return 2 if n < 256 else 3 if n < 65536 else 5


def _pack_ints(d: list[int]) -> tuple[int, list[int] | bytes]:
    """The smallest of four encodings of int64 values: ``(format, payload)``."""
    n = len(d)
    if n == 0:
        return _FMT_LIST, []
    best_fmt, best = _FMT_LIST, _mp_list_size(d)
    lo, hi = min(d), max(d)
    if -(2**15) <= lo and hi < 2**15:
        fixed_fmt, width = _FMT_I16, 2
    elif -(2**31) <= lo and hi < 2**31:
        fixed_fmt, width = _FMT_I32, 4
    else:
        fixed_fmt, width = _FMT_LIST, 0
    if width and _mp_bin_header(width * n) + width * n < best:
        best_fmt, best = fixed_fmt, _mp_bin_header(width * n) + width * n
    z = [_zigzag(v) for v in d]
    vb = sum(map(_varint_size, z))
    if _mp_bin_header(vb) + vb < best:
        return _FMT_VARINT, _py_varints(z)
    if best_fmt == _FMT_I16:
        return best_fmt, struct.pack(f"<{n}h", *d)
    if best_fmt == _FMT_I32:
        return best_fmt, struct.pack(f"<{n}i", *d)
    return _FMT_LIST, d


def _unpack_ints(fmt: int, payload: object, what: str, field: str) -> list[int]:
    if fmt == _FMT_LIST:
        if not isinstance(payload, list):
            raise CodecError(f"{what}: {field}: expected a list, got {type(payload).__name__}")
        if not all(_is_int(v) and -(2**63) <= v < 2**63 for v in payload):
            raise CodecError(f"{what}: {field}: expected int64 values only")
        return payload
    if not isinstance(payload, bytes):
        raise CodecError(f"{what}: {field}: expected bin, got {type(payload).__name__}")
    if fmt == _FMT_I16:
        if len(payload) % 2:
            raise CodecError(f"{what}: {field}: int16 blob of odd length {len(payload)}")
        return list(struct.unpack(f"<{len(payload) // 2}h", payload))
    if fmt == _FMT_I32:
        if len(payload) % 4:
            raise CodecError(f"{what}: {field}: int32 blob of length {len(payload)}")
        return list(struct.unpack(f"<{len(payload) // 4}i", payload))
    if len(payload) > 256:
        z = decode_varints(payload, f"{what}: {field}")
        return (
            (z >> np.uint64(1)).astype(np.int64) ^ -(z & np.uint64(1)).astype(np.int64)
        ).tolist()
    return [_unzigzag(v) for v in _py_decode_varints(payload, f"{what}: {field}")]


# ---------------------------------------------------------------------------
# rings
# ---------------------------------------------------------------------------


def _quantise_cm(a: ArrayLike, what: str) -> I64:
    with np.errstate(invalid="ignore", over="ignore"):
        q = np.rint(np.asarray(a, dtype=np.float64) * 100.0)
    if not np.isfinite(q).all() or (np.abs(q) >= _MAX_CM).any():
        raise CodecError(f"{what}: values must be finite and below 9e13 m in magnitude")
    return q.astype(np.int64)


def _pack_rings(
    rings: Sequence[F64], what: str
) -> tuple[int, int, int, list[int], list[int] | bytes]:
    counts = [len(r) for r in rings]
    if sum(counts) == 0:
        return _FMT_LIST, 0, 0, counts, []
    q = _quantise_cm(np.concatenate(rings).reshape(-1), what).tolist()
    # the anchor is vertex 0 itself, so its delta is always zero and is left out;
    # ring boundaries need no marker because the counts say where they fall
    d = [b - a for a, b in zip(q, q[2:], strict=False)]
    fmt, payload = _pack_ints(d)
    return fmt, q[0], q[1], counts, payload


def _unpack_rings(
    fmt: int, ax: object, ay: object, counts: list[int], payload: object, what: str
) -> list[F64]:
    total = sum(counts)
    d = _unpack_ints(fmt, payload, what, "coords")
    expected = 2 * (total - 1) if total else 0
    if len(d) != expected:
        raise CodecError(
            f"{what}: coords: expected {expected} deltas for {total} vertices, got {len(d)}"
        )
    if total == 0:
        return [np.zeros((0, 2)) for _ in counts]
    q = np.empty(2 * total, np.int64)
    q[0] = _int(ax, what, "anchor x", -(2**62), 2**62)
    q[1] = _int(ay, what, "anchor y", -(2**62), 2**62)
    q[2:] = d
    # x and y chains are independent cumulative sums over every other value
    xy = np.cumsum(q.reshape(-1, 2), axis=0).astype(np.float64) / 100.0
    if len(counts) == 1:
        return [xy]
    return np.split(xy, np.cumsum(counts)[:-1])


def _counts(x: object, what: str, min_count: int) -> list[int]:
    counts = [x] if _is_int(x) else x
    if not isinstance(counts, list) or not counts:
        raise CodecError(f"{what}: counts: expected an int or a non-empty list of ints")
    out = [_int(c, what, "counts", min_count, _MAX_VERTICES) for c in counts]
    if sum(out) > _MAX_VERTICES:
        raise CodecError(f"{what}: {sum(out)} vertices, more than the limit of {_MAX_VERTICES}")
    return out


# ---------------------------------------------------------------------------
# neighbour heights
# ---------------------------------------------------------------------------


def _pack_heights(h: list[int]) -> tuple[int, list[int]]:
    sparse = [x for i, v in enumerate(h) if v for x in (i, v)]
    if not sparse:
        return _NB_SPARSE, []
    rle: list[int] = []
    for v in h:
        if rle and rle[-2] == v:
            rle[-1] += 1
        else:
            rle += (v, 1)
    if _mp_list_size(rle) < _mp_list_size(sparse):
        return _NB_RLE, rle
    return _NB_SPARSE, sparse


def _unpack_heights(fmt: int, payload: object, n: int, what: str) -> F64:
    v = _unpack_ints(_FMT_LIST, payload, what, "neighbour heights")
    if len(v) % 2:
        raise CodecError(f"{what}: neighbour heights: expected pairs, got {len(v)} values")
    if fmt == _NB_SPARSE:
        idx, val = v[0::2], v[1::2]
        if idx and (
            idx[0] < 0 or idx[-1] >= n or any(b <= a for a, b in zip(idx, idx[1:], strict=False))
        ):
            raise CodecError(
                f"{what}: neighbour heights: indices must ascend within [0, {n}), got {idx[:8]}"
            )
        h = np.zeros(n, np.float64)
        h[idx] = val
        return h / 100.0
    val, runs = v[0::2], v[1::2]
    if any(r < 1 for r in runs) or sum(runs) != n:
        raise CodecError(f"{what}: neighbour heights: runs must be >= 1 and sum to {n}")
    return np.repeat(np.array(val, np.float64), runs) / 100.0


# ---------------------------------------------------------------------------
# buildings and streets
# ---------------------------------------------------------------------------


def encode_building(b: BuildingParams, *, with_source_id: bool = True) -> bytes:
    """Encode building parameters compactly (a typical 8-vertex building: 45-60 bytes).

    Coordinates are quantised to centimetres.  The anchor is the first exterior
    vertex in integer centimetres, so a building far from the origin stays exact to
    the centimetre; the other vertices (all rings, in order) follow as x/y deltas
    from the previous vertex, stored as whichever of a msgpack int list, an int16
    blob, an int32 blob or a zigzag-varint blob is smallest.  Neighbour heights are
    quantised to centimetres and stored sparse or run-length, whichever is smaller
    (most are zero).

    Parameters
    ----------
    b:
        The building; ``rings[i]`` is ``(n_i, 2) float64``.
    with_source_id:
        Keep ``b.source_id`` (drop it to save its bytes on the wire).

    Returns
    -------
    bytes
        The record; :func:`decode_building` gives back the building with every
        coordinate, neighbour height and the floor height within 5 mm.  (A sliver
        whose signed area changes sign under rounding comes back with its ring
        reversed by ``BuildingParams``, edges and their heights intact.)

    Raises
    ------
    CodecError
        A coordinate or height is not finite or absurdly large.
    """
    what = f"building {b.id}"
    fmt, ax, ay, counts, coords = _pack_rings(b.rings, what)
    h = _quantise_cm(np.concatenate(b.neighbour_heights), f"{what}: neighbour heights")
    nb_fmt, heights = _pack_heights(h.tolist())
    # a floor height below 5 mm would round to 0, which no building can have
    fh_cm = max(1, int(_quantise_cm(b.floor_height, f"{what}: floor_height")))
    header = _REC_BUILDING << 5 | nb_fmt << 2 | fmt
    rec = [
        header,
        b.id,
        ax,
        ay,
        counts[0] if len(counts) == 1 else counts,
        coords,
        heights,
        b.floors,
        fh_cm,
        b.style,
        b.source_id if with_source_id else "",
    ]
    try:
        return msgpack.packb(rec, use_bin_type=True)
    except (OverflowError, ValueError, TypeError) as exc:
        raise CodecError(f"{what}: cannot encode ({exc})") from exc


def _header(rec: object, what: str, kind: int, n_fields: int) -> tuple[list[Any], int]:
    if not isinstance(rec, list) or len(rec) != n_fields:
        got = f"{len(rec)} fields" if isinstance(rec, list) else type(rec).__name__
        raise CodecError(f"{what}: expected an array of {n_fields} fields, got {got}")
    h = _int(rec[0], what, "header", 0, 127)
    if h >> 5 != kind:
        raise CodecError(f"{what}: record type {h >> 5}, expected {kind}")
    return rec, h & 0x1F


def decode_building(
    data: bytes | bytearray | memoryview, what: str = "building params"
) -> BuildingParams:
    """Decode bytes made by :func:`encode_building`.

    Parameters
    ----------
    data:
        The record (untrusted).
    what:
        What is being decoded, for error messages.

    Returns
    -------
    BuildingParams
        Rings ``(n, 2) float64`` in metres (multiples of 1 cm).

    Raises
    ------
    CodecError
        The bytes are not a valid building record.
    """
    obj = unpack_bounded(data, what, max_array_len=2 * _MAX_VERTICES)
    try:
        return _decode_building(obj, what)
    except CodecError:
        raise
    except _DECODE_ERRORS as exc:
        raise CodecError(f"{what}: {exc}") from exc


def _decode_building(obj: object, what: str) -> BuildingParams:
    rec, flags = _header(obj, what, _REC_BUILDING, 11)
    _, oid, ax, ay, counts_f, coords, heights, floors, fh_cm, style, source_id = rec
    oid = _int(oid, what, "id", 0, _INT64_MAX)
    what = f"{what} (id {oid})"
    if flags >> 3:
        raise CodecError(f"{what}: unknown header flags {flags:#x}")
    counts = _counts(counts_f, what, 3)
    rings = _unpack_rings(flags & 3, ax, ay, counts, coords, what)
    h = _unpack_heights((flags >> 2) & 1, heights, sum(counts), what)
    if not isinstance(source_id, str):
        raise CodecError(f"{what}: source_id: expected a string, got {type(source_id).__name__}")
    return BuildingParams(
        id=oid,
        rings=tuple(rings),
        neighbour_heights=tuple(np.split(h, np.cumsum(counts)[:-1])),
        floors=_int(floors, what, "floors", 1, 2**31),
        floor_height=_int(fh_cm, what, "floor_height", 1, 2**31) / 100.0,
        style=_int(style, what, "style", -(2**63), 2**64 - 1),
        source_id=source_id,
    )


def encode_street(s: StreetParams, *, with_source_id: bool = True) -> bytes:
    """Encode a street piece, crossroad or square compactly.

    The outline is coded like a building ring (centimetre anchor plus deltas), the
    kind goes into the header byte and the width is stored in centimetres.

    Parameters
    ----------
    s:
        The street piece; ``ring`` is ``(n, 2) float64``.
    with_source_id:
        Keep ``s.source_id``.

    Returns
    -------
    bytes
        The record; :func:`decode_street` reproduces ring and width within 5 mm.
    """
    what = f"street {s.id}"
    fmt, ax, ay, counts, coords = _pack_rings([s.ring], what)
    width_cm = int(_quantise_cm(s.width, f"{what}: width"))
    header = _REC_STREET << 5 | _STREET_KINDS.index(s.kind) << 2 | fmt
    rec = [header, s.id, counts[0], ax, ay, coords, width_cm, s.source_id if with_source_id else ""]
    try:
        return msgpack.packb(rec, use_bin_type=True)
    except (OverflowError, ValueError, TypeError) as exc:
        raise CodecError(f"{what}: cannot encode ({exc})") from exc


def decode_street(
    data: bytes | bytearray | memoryview, what: str = "street params"
) -> StreetParams:
    """Decode bytes made by :func:`encode_street`.

    Raises
    ------
    CodecError
        The bytes are not a valid street record.
    """
    obj = unpack_bounded(data, what, max_array_len=2 * _MAX_VERTICES)
    try:
        return _decode_street(obj, what)
    except CodecError:
        raise
    except _DECODE_ERRORS as exc:
        raise CodecError(f"{what}: {exc}") from exc


def _decode_street(obj: object, what: str) -> StreetParams:
    rec, flags = _header(obj, what, _REC_STREET, 8)
    _, oid, n, ax, ay, coords, width_cm, source_id = rec
    oid = _int(oid, what, "id", 0, _INT64_MAX)
    what = f"{what} (id {oid})"
    kind = (flags >> 2) & 3
    if kind >= len(_STREET_KINDS) or flags >> 4:
        raise CodecError(f"{what}: unknown header flags {flags:#x}")
    counts = [_int(n, what, "vertex count", 0, _MAX_VERTICES)]
    (ring,) = _unpack_rings(flags & 3, ax, ay, counts, coords, what)
    if not isinstance(source_id, str):
        raise CodecError(f"{what}: source_id: expected a string, got {type(source_id).__name__}")
    return StreetParams(
        id=oid,
        kind=_STREET_KINDS[kind],
        ring=ring,
        width=_int(width_cm, what, "width", -(2**53), 2**53) / 100.0,
        source_id=source_id,
    )


def decode_object(
    data: bytes | bytearray | memoryview, what: str = "object params"
) -> BuildingParams | StreetParams:
    """Decode a building or street record, whichever the header says it is."""
    obj = unpack_bounded(data, what, max_array_len=2 * _MAX_VERTICES)
    try:
        if isinstance(obj, list) and obj and _is_int(obj[0]) and obj[0] >> 5 == _REC_STREET:
            return _decode_street(obj, what)
        return _decode_building(obj, what)
    except CodecError:
        raise
    except _DECODE_ERRORS as exc:
        raise CodecError(f"{what}: {exc}") from exc


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
    if i.dtype == np.uint64 and (i > np.uint64(_INT64_MAX)).any():
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
    n = _nbytes(data, what)
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
    if (deltas > np.uint64(_INT64_MAX)).any():
        raise CodecError(f"{what}: id out of the int64 range")
    ids = np.cumsum(deltas, dtype=np.uint64)
    # each delta < 2**63, so a wrap past 2**64 shows up as a decrease
    if (ids[1:] < ids[:-1]).any() or ids[-1] > np.uint64(_INT64_MAX):
        raise CodecError(f"{what}: id out of the int64 range")
    if (units > np.uint64(ACH_UNITS)).any() or int(units.sum()) != ACH_UNITS:
        raise CodecError(f"{what}: ACH units must sum to {ACH_UNITS}")
    return ids.astype(np.int64), units.astype(np.float64) / ACH_UNITS


def pvs_size(data: bytes | bytearray | memoryview, what: str = "PVS") -> int:
    """Number of objects in an encoded PVS, reading only its first varint."""
    n = _nbytes(data, what)
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
    n = _nbytes(data, what)
    if n > _MAX_IDS_BYTES:
        raise CodecError(f"{what}: {n} bytes, more than the limit of {_MAX_IDS_BYTES}")
    d = decode_varints(data, what)
    if len(d) == 0:
        return np.zeros(0, np.int64)
    if (d[1:] == 0).any():
        raise CodecError(f"{what}: ids repeat")
    if (d > np.uint64(_INT64_MAX)).any():
        raise CodecError(f"{what}: id out of the int64 range")
    ids = np.cumsum(d, dtype=np.uint64)
    if (ids[1:] < ids[:-1]).any() or ids[-1] > np.uint64(_INT64_MAX):
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


# ---------------------------------------------------------------------------
# meshes
# ---------------------------------------------------------------------------
#
# Rebuilt LOD2 meshes travel only in the ``--stream meshes`` comparison, which
# measures what the paper's central claim (send parameters, rebuild on the client)
# saves.  So the format is compact but honest, what a sensible mesh streamer would
# send: no quantisation of positions beyond float32, no entropy coding, but nothing
# the client can recompute exactly either (normals).
#
# mesh (format "walkstream-mesh/1")
#     msgpack map ``{"format": "walkstream-mesh/1", "vertices": n, "positions": bin,
#     "index_bytes": w, "indices": bin, "materials": bin}``: ``positions`` the
#     ``(n, 3)`` float32 little-endian vertex positions; ``indices`` the ``(m, 3)``
#     triangles as little-endian unsigned integers of ``w`` bytes, the smallest of 1,
#     2, 4 that holds ``n - 1``; ``materials`` one uint8 per triangle.  Normals are
#     not sent: :func:`decode_mesh` recomputes flat per-vertex normals from the
#     triangles (the meshes of :func:`shared.lsystem.interpret.interpret` and
#     :func:`shared.streets.build_street` never share a vertex between faces that
#     are not coplanar).  For a mesh that breaks those assumptions the encoder adds
#     what cannot be recomputed instead of silently changing the picture:
#     ``"vertex_materials"`` (uint8 per vertex, replacing ``materials``) when a
#     triangle's vertices have different materials, and ``"normals"`` ((n, 3)
#     float32) when the recomputed normals would differ from the mesh's.

from walkstream.shared.records import Mesh  # noqa: E402  (this section was appended to the module)

__all__ += ["MESH_FORMAT", "encode_mesh", "decode_mesh"]

MESH_FORMAT = "walkstream-mesh/1"
"""The format tag of :func:`encode_mesh` maps."""

_MAX_MESH_BYTES = 1 << 27
_MAX_MESH_VERTICES = 1 << 24
# a recomputed normal within ~2.6 degrees of the mesh's shades the same to the eye
# (float32 positions alone cost up to ~0.01 degrees on metre-sized faces)
_NORMAL_COS_TOLERANCE = 0.999
_MESH_KEYS = frozenset(
    {
        "format",
        "vertices",
        "positions",
        "index_bytes",
        "indices",
        "materials",
        "vertex_materials",
        "normals",
    }
)


def _index_bytes(n_vertices: int) -> int:
    """Width of the smallest unsigned type that holds every index of ``n_vertices``."""
    if n_vertices <= 1 << 8:
        return 1
    if n_vertices <= 1 << 16:
        return 2
    return 4


def _flat_normals(positions: NDArray[np.float32], indices: NDArray[Any]) -> NDArray[np.float32]:
    """Unit per-vertex normals: the area-weighted sum of the incident triangles' normals.

    Every vertex of a flat-shaded mesh lies on one planar face, so the sum points
    along that face's normal.  A vertex no triangle uses (or only degenerate ones)
    gets ``(0, 0, 1)``; it draws nothing.
    """
    n = len(positions)
    out = np.zeros((n, 3), np.float64)
    if n == 0:
        return out.astype(np.float32)
    t = indices.astype(np.int64)
    p = positions.astype(np.float64)
    if len(t):
        a = p[t[:, 0]]
        cross = np.cross(p[t[:, 1]] - a, p[t[:, 2]] - a)  # length = 2 * area
        for corner in range(3):
            for axis in range(3):
                out[:, axis] += np.bincount(t[:, corner], weights=cross[:, axis], minlength=n)
    length = np.sqrt((out * out).sum(axis=1))
    ok = length > 0
    out[ok] /= length[ok, None]
    out[~ok] = (0.0, 0.0, 1.0)
    return out.astype(np.float32)


def encode_mesh(mesh: Mesh) -> bytes:
    """Encode a triangle mesh for streaming (see the "mesh" format above).

    Parameters
    ----------
    mesh:
        The mesh, e.g. ``shared.buildings.build_lod(b, 2, grammar)``.

    Returns
    -------
    bytes
        About ``12 n + 3 w m + m`` bytes for ``n`` vertices and ``m`` triangles
        (``w`` = 1, 2 or 4), plus ~100 bytes of keys.

    Raises
    ------
    CodecError
        Positions are not finite, an index is out of range, or the mesh is larger
        than :func:`decode_mesh` accepts.
    """
    pos = np.ascontiguousarray(mesh.positions, dtype="<f4")
    idx = np.asarray(mesh.indices)
    n, m = len(pos), len(idx)
    if n > _MAX_MESH_VERTICES:
        raise CodecError(f"mesh: {n} vertices, more than the limit of {_MAX_MESH_VERTICES}")
    if not np.isfinite(pos).all():
        raise CodecError("mesh: positions must be finite")
    if m and int(idx.max()) >= n:
        raise CodecError(f"mesh: index {int(idx.max())} out of range for {n} vertices")
    width = _index_bytes(n)
    rec: dict[str, Any] = {
        "format": MESH_FORMAT,
        "vertices": n,
        "positions": pos.tobytes(),
        "index_bytes": width,
        "indices": idx.astype(f"<u{width}").tobytes(),
    }
    vm = np.asarray(mesh.materials, np.uint8)
    tm = vm[idx[:, 0]] if m else np.zeros(0, np.uint8)
    if m and ((vm[idx[:, 1]] != tm) | (vm[idx[:, 2]] != tm)).any():
        rec["vertex_materials"] = vm.tobytes()
    else:
        rec["materials"] = tm.tobytes()
    if m:
        used = np.zeros(n, bool)
        used[idx.reshape(-1)] = True
        given = np.asarray(mesh.normals, np.float64)[used]
        dots = (given * _flat_normals(pos, idx)[used]).sum(axis=1)
        if not (dots >= _NORMAL_COS_TOLERANCE).all():
            rec["normals"] = np.ascontiguousarray(mesh.normals, dtype="<f4").tobytes()
    data: bytes = msgpack.packb(rec, use_bin_type=True)
    if len(data) > _MAX_MESH_BYTES:
        raise CodecError(f"mesh: {len(data)} bytes, more than the limit of {_MAX_MESH_BYTES}")
    return data


def _mesh_bin(rec: dict[str, Any], key: str, size: int, unit: str, what: str) -> bytes:
    v = rec.get(key)
    if not isinstance(v, bytes):
        got = "nothing" if v is None else type(v).__name__
        raise CodecError(f"{what}: {key}: expected bin, got {got}")
    if len(v) != size:
        raise CodecError(f"{what}: {key}: expected {size} bytes ({unit}), got {len(v)}")
    return v


def decode_mesh(data: bytes | bytearray | memoryview, what: str = "mesh") -> Mesh:
    """Decode bytes made by :func:`encode_mesh`.

    Normals are recomputed from the triangles (flat, per vertex) unless the bytes
    carry them; materials are given per vertex, as :class:`~shared.records.Mesh`
    holds them (a vertex no triangle uses gets material 0).

    Parameters
    ----------
    data:
        The bytes (untrusted: everything is bounded and checked).
    what:
        What is being decoded, for error messages (``"mesh of object 12"``).

    Raises
    ------
    CodecError
        Not a mesh map, another format, an unknown or missing field, lengths that
        do not match the vertex and triangle counts, an index out of range, or
        positions or normals that are not finite.  The message names the field.
    """
    obj = unpack_bounded(
        data,
        what,
        max_bytes=_MAX_MESH_BYTES,
        # no field is an array; a few elements are let through so that a wrong type
        # is reported by its field name rather than as a msgpack limit
        max_array_len=16,
        max_map_len=len(_MESH_KEYS),
        max_str_len=64,
        max_bin_len=_MAX_MESH_BYTES,
    )
    if not isinstance(obj, dict):
        raise CodecError(f"{what}: expected a map, got {type(obj).__name__}")
    fmt = obj.get("format")
    if fmt != MESH_FORMAT:
        raise CodecError(f"{what}: format: expected {MESH_FORMAT!r}, got {fmt!r:.80}")
    unknown = sorted(str(k) for k in obj if k not in _MESH_KEYS)
    if unknown:
        raise CodecError(f"{what}: unknown field {unknown[0]!r:.80}")
    n = _int(obj.get("vertices"), what, "vertices", 0, _MAX_MESH_VERTICES)
    pos_b = _mesh_bin(obj, "positions", 12 * n, f"3 float32 per vertex, {n} vertices", what)
    pos = np.frombuffer(pos_b, "<f4").reshape(n, 3)
    if not np.isfinite(pos).all():
        raise CodecError(f"{what}: positions: not finite")
    width = _int(obj.get("index_bytes"), what, "index_bytes", 1, 4)
    if width not in (1, 2, 4):
        raise CodecError(f"{what}: index_bytes: expected 1, 2 or 4, got {width}")
    ib = obj.get("indices")
    if not isinstance(ib, bytes):
        got = "nothing" if ib is None else type(ib).__name__
        raise CodecError(f"{what}: indices: expected bin, got {got}")
    if len(ib) % (3 * width):
        raise CodecError(
            f"{what}: indices: {len(ib)} bytes is not a whole number of triangles "
            f"of {width}-byte indices"
        )
    idx = np.frombuffer(ib, f"<u{width}").reshape(-1, 3)
    m = len(idx)
    if m and int(idx.max()) >= n:
        raise CodecError(f"{what}: indices: index {int(idx.max())} out of range for {n} vertices")
    if ("materials" in obj) == ("vertex_materials" in obj):
        raise CodecError(f"{what}: materials: expected exactly one of materials, vertex_materials")
    if "materials" in obj:
        tm = np.frombuffer(_mesh_bin(obj, "materials", m, f"1 per triangle, {m}", what), np.uint8)
        vm = np.zeros(n, np.uint8)
        for corner in range(3):
            vm[idx[:, corner]] = tm
    else:
        vb = _mesh_bin(obj, "vertex_materials", n, f"1 per vertex, {n}", what)
        vm = np.frombuffer(vb, np.uint8)
    if "normals" in obj:
        nb = _mesh_bin(obj, "normals", 12 * n, f"3 float32 per vertex, {n} vertices", what)
        normals = np.frombuffer(nb, "<f4").reshape(n, 3)
        if not np.isfinite(normals).all():
            raise CodecError(f"{what}: normals: not finite")
    else:
        normals = _flat_normals(pos, idx)
    return Mesh(pos, normals, idx, vm)
