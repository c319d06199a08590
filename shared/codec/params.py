"""Building and street parameters: msgpack arrays of centimetre-quantised, delta-coded rings.

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
area
    msgpack array ``[header, id, kind, ax, ay, counts, coords, source_id]`` with
    ``header = 3 << 5 | coord_format``; ``kind`` indexes
    :data:`~walkstream.shared.areakinds.AREA_KINDS`; rings as a building's.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, overload

import msgpack
import numpy as np
from numpy.typing import ArrayLike

from walkstream.shared.areakinds import AREA_KINDS
from walkstream.shared.arrays import F64, I64
from walkstream.shared.codec.bounded import (
    DECODE_ERRORS,
    INT64_MAX,
    checked_int,
    is_int,
    unpack_bounded,
)
from walkstream.shared.codec.ints import FMT_LIST, mp_list_size, smallest_payload, unpack_payload
from walkstream.shared.errors import CodecError
from walkstream.shared.records import (
    AreaParams,
    BuildingParams,
    StreetParams,
)

__all__ = [
    "encode_building",
    "decode_building",
    "encode_street",
    "decode_street",
    "encode_area",
    "decode_area",
    "decode_object",
    "stored_form",
]

_REC_BUILDING = 1
_REC_STREET = 2
_REC_AREA = 3
_STREET_KINDS = ("street", "crossroad", "square")

_NB_SPARSE, _NB_RLE = 0, 1
_MAX_VERTICES = 1 << 20
# |centimetres| below 2**53 keep float64 -> int64 conversion exact.
_MAX_CM = float(2**53)


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
        return FMT_LIST, 0, 0, counts, []
    q = _quantise_cm(np.concatenate(rings).reshape(-1), what).tolist()
    # the anchor is vertex 0 itself, so its delta is always zero and is left out;
    # ring boundaries need no marker because the counts say where they fall
    d = [b - a for a, b in zip(q, q[2:], strict=False)]
    fmt, payload = smallest_payload(d)
    return fmt, q[0], q[1], counts, payload


def _unpack_rings(
    fmt: int, ax: object, ay: object, counts: list[int], payload: object, what: str
) -> list[F64]:
    total = sum(counts)
    d = unpack_payload(fmt, payload, what, "coords")
    expected = 2 * (total - 1) if total else 0
    if len(d) != expected:
        raise CodecError(
            f"{what}: coords: expected {expected} deltas for {total} vertices, got {len(d)}"
        )
    if total == 0:
        return [np.zeros((0, 2)) for _ in counts]
    q = np.empty(2 * total, np.int64)
    q[0] = checked_int(ax, what, "anchor x", -(2**62), 2**62)
    q[1] = checked_int(ay, what, "anchor y", -(2**62), 2**62)
    q[2:] = d
    # x and y chains are independent cumulative sums over every other value
    xy = np.cumsum(q.reshape(-1, 2), axis=0).astype(np.float64) / 100.0
    if len(counts) == 1:
        return [xy]
    return np.split(xy, np.cumsum(counts)[:-1])


def _counts(x: object, what: str, min_count: int) -> list[int]:
    counts = [x] if is_int(x) else x
    if not isinstance(counts, list) or not counts:
        raise CodecError(f"{what}: counts: expected an int or a non-empty list of ints")
    out = [checked_int(c, what, "counts", min_count, _MAX_VERTICES) for c in counts]
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
    if mp_list_size(rle) < mp_list_size(sparse):
        return _NB_RLE, rle
    return _NB_SPARSE, sparse


def _unpack_heights(fmt: int, payload: object, n: int, what: str) -> F64:
    v = unpack_payload(FMT_LIST, payload, what, "neighbour heights")
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
    if b.kind:
        # a landmark's kind is a twelfth field; ordinary buildings keep their exact old bytes
        rec.append(b.kind)
    try:
        return msgpack.packb(rec, use_bin_type=True)
    except (OverflowError, ValueError, TypeError) as exc:
        raise CodecError(f"{what}: cannot encode ({exc})") from exc


def _header(rec: object, what: str, kind: int, n_fields: int) -> tuple[list[Any], int]:
    if not isinstance(rec, list) or len(rec) != n_fields:
        got = f"{len(rec)} fields" if isinstance(rec, list) else type(rec).__name__
        raise CodecError(f"{what}: expected an array of {n_fields} fields, got {got}")
    h = checked_int(rec[0], what, "header", 0, 127)
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
    except DECODE_ERRORS as exc:
        raise CodecError(f"{what}: {exc}") from exc


def _decode_building(obj: object, what: str) -> BuildingParams:
    n = 12 if isinstance(obj, list) and len(obj) == 12 else 11
    rec, flags = _header(obj, what, _REC_BUILDING, n)
    _, oid, ax, ay, counts_f, coords, heights, floors, fh_cm, style, source_id = rec[:11]
    kind = checked_int(rec[11], what, "kind", 1, 2) if n == 12 else 0
    oid = checked_int(oid, what, "id", 0, INT64_MAX)
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
        floors=checked_int(floors, what, "floors", 1, 2**31),
        floor_height=checked_int(fh_cm, what, "floor_height", 1, 2**31) / 100.0,
        style=checked_int(style, what, "style", -(2**63), 2**64 - 1),
        source_id=source_id,
        kind=kind,
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
    except DECODE_ERRORS as exc:
        raise CodecError(f"{what}: {exc}") from exc


def _decode_street(obj: object, what: str) -> StreetParams:
    rec, flags = _header(obj, what, _REC_STREET, 8)
    _, oid, n, ax, ay, coords, width_cm, source_id = rec
    oid = checked_int(oid, what, "id", 0, INT64_MAX)
    what = f"{what} (id {oid})"
    kind = (flags >> 2) & 3
    if kind >= len(_STREET_KINDS) or flags >> 4:
        raise CodecError(f"{what}: unknown header flags {flags:#x}")
    counts = [checked_int(n, what, "vertex count", 0, _MAX_VERTICES)]
    (ring,) = _unpack_rings(flags & 3, ax, ay, counts, coords, what)
    if not isinstance(source_id, str):
        raise CodecError(f"{what}: source_id: expected a string, got {type(source_id).__name__}")
    return StreetParams(
        id=oid,
        kind=_STREET_KINDS[kind],
        ring=ring,
        width=checked_int(width_cm, what, "width", -(2**53), 2**53) / 100.0,
        source_id=source_id,
    )


def encode_area(a: AreaParams, *, with_source_id: bool = True) -> bytes:
    """Encode a typed area compactly: its kind's index and its rings coded as a building's.

    Returns
    -------
    bytes
        The record; :func:`decode_area` reproduces every vertex within 5 mm.
    """
    what = f"area {a.id}"
    fmt, ax, ay, counts, coords = _pack_rings(a.rings, what)
    header = _REC_AREA << 5 | fmt
    rec = [
        header,
        a.id,
        AREA_KINDS.index(a.kind),
        ax,
        ay,
        counts[0] if len(counts) == 1 else counts,
        coords,
        a.source_id if with_source_id else "",
    ]
    try:
        return msgpack.packb(rec, use_bin_type=True)
    except (OverflowError, ValueError, TypeError) as exc:
        raise CodecError(f"{what}: cannot encode ({exc})") from exc


def decode_area(data: bytes | bytearray | memoryview, what: str = "area params") -> AreaParams:
    """Decode bytes made by :func:`encode_area`.

    Raises
    ------
    CodecError
        The bytes are not a valid area record.
    """
    obj = unpack_bounded(data, what, max_array_len=2 * _MAX_VERTICES)
    try:
        return _decode_area(obj, what)
    except CodecError:
        raise
    except DECODE_ERRORS as exc:
        raise CodecError(f"{what}: {exc}") from exc


def _decode_area(obj: object, what: str) -> AreaParams:
    rec, flags = _header(obj, what, _REC_AREA, 8)
    _, oid, kind, ax, ay, counts_f, coords, source_id = rec
    oid = checked_int(oid, what, "id", 0, INT64_MAX)
    what = f"{what} (id {oid})"
    if flags >> 2:
        raise CodecError(f"{what}: unknown header flags {flags:#x}")
    k = checked_int(kind, what, "kind", 0, len(AREA_KINDS) - 1)
    counts = _counts(counts_f, what, 3)
    rings = _unpack_rings(flags & 3, ax, ay, counts, coords, what)
    if not isinstance(source_id, str):
        raise CodecError(f"{what}: source_id: expected a string, got {type(source_id).__name__}")
    return AreaParams(id=oid, kind=AREA_KINDS[k], rings=tuple(rings), source_id=source_id)


def decode_object(
    data: bytes | bytearray | memoryview, what: str = "object params"
) -> BuildingParams | StreetParams | AreaParams:
    """Decode a building, street or area record, whichever the header says it is."""
    obj = unpack_bounded(data, what, max_array_len=2 * _MAX_VERTICES)
    try:
        rec = obj[0] >> 5 if isinstance(obj, list) and obj and is_int(obj[0]) else None
        if rec == _REC_STREET:
            return _decode_street(obj, what)
        if rec == _REC_AREA:
            return _decode_area(obj, what)
        return _decode_building(obj, what)
    except CodecError:
        raise
    except DECODE_ERRORS as exc:
        raise CodecError(f"{what}: {exc}") from exc


@overload
def stored_form(p: BuildingParams) -> BuildingParams: ...
@overload
def stored_form(p: StreetParams) -> StreetParams: ...
@overload
def stored_form(p: AreaParams) -> AreaParams: ...
def stored_form(p: BuildingParams | StreetParams | AreaParams) -> BuildingParams | StreetParams | AreaParams:
    """``p`` as every reader of a database rebuilds it: encoded and decoded again
    (coordinates, heights and the floor height on the centimetre).

    Whatever a bake renders for a client to show (wall textures, impostor images) must be
    built from this form, not from the source's float coordinates: the grammar's choices
    are thresholds on lengths (the door goes on the longest free frontage, ``L >= LMAX``),
    so a rectangle's two equally long sides, a millimetre apart in the source, can swap
    their door under the rounding."""
    if isinstance(p, BuildingParams):
        return decode_building(encode_building(p))
    if isinstance(p, StreetParams):
        return decode_street(encode_street(p))
    return decode_area(encode_area(p))
