"""The compact topology (``walkstream-topology/2``): an interior's topological file in millimetres.

The packed topology (``walkstream-topology/1+gzip``) is gzip of msgpack float64
lists; most of its bytes are the float64s and every cell's planes, which are the
prism of its outline between its floor and ceiling.  This encoding stores
coordinates as integer millimetres, outlines and paths as differences of
consecutive vertices, a cell's planes only when they are not its outline's prism
(the decoder rebuilds those with :func:`prism_planes`; planes within a millimetre of
that prism everywhere in the cell count as the prism: on duplex.ifc, 21 of 50 cells
whose space walls lie off the millimetre grid, 3.7 -> 2.7 kB), and compresses the msgpack
body: 7.9 kB -> about 3.9 kB on the generated office with zlib.

Layout (media type :data:`TOPOLOGY_COMPACT_MEDIA`)::

    b"WSTC" version:u8 lzma(msgpack {storeys, kinds, cells, portals, stairs})

    version 4: portals = {id: differences, kind, a, b, polygon: [vertex differences],
                          mask: [nil | 0..7]}  (a mask: polygon holds two corners)
    versions 2, 3: portals = [[id, kind, a, b, vertex differences], ...], cells.name

Version 4 (written) leaves out what the walk's first frame does not need and what two
numbers say: the cells' names (the packed topology, ``GET .../topology``, still has
them; a version 4 cell decodes with the name ``""``: no client part reads them), and a
portal that is a rectangle spanned by two of its corners (each other corner taking
every coordinate from one of the two: a door in an axis-aligned wall, a stair's
horizontal opening) as those two corners and which coordinates its second corner takes
from the first (a 3-bit mask), not as four vertices; and it stores the portals column
by column (ids, kinds, cells, polygons, masks).  duplex.ifc 2,379 -> 1,884 bytes (the
names 277 of them), 0.07 s sooner at 56 kbit/s.  It compresses the msgpack body as a raw
LZMA2 stream, as version 3 did (:mod:`~walkstream.shared.codec.rawlzma`: duplex.ifc
2,737 -> 2,374 bytes); versions 3 and 2 (zlib level 9), with names and portals as rows
of vertices, are still read.

Exactness: outlines, heights and stair paths are rounded to the nearest
millimetre (half a millimetre at most; the generators and the IFC importer put
them on a millimetre grid already, so they come back as they were, to float32
noise), so cell location by the planes is unchanged away from a wall by more than
that.  Portal polygons are rounded *outward* (each coordinate away from the
polygon's centroid, or to the nearest millimetre where it equals the centroid's,
as on a wall's plane), so a decoded portal never shrinks and the conservative
portal culling stays conservative.

Decoding is bounded (inflated size, counts) and a malformed body raises a one-line
:class:`~walkstream.shared.errors.CodecError`.
"""

from __future__ import annotations

from typing import Any

import msgpack
import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.shared.arrays import F64
from walkstream.shared.codec import inflate_tagged, unpack_bounded
from walkstream.shared.codec.rawlzma import compress_raw, decompress_raw
from walkstream.shared.errors import CodecError
from walkstream.shared.roomwire import ContentsRef, PortalRef, RoomRecord, Topology

__all__ = [
    "TOPOLOGY_COMPACT_MEDIA",
    "TOPOLOGY_COMPACT_MAGIC",
    "prism_planes",
    "encode_topology_compact",
    "decode_topology_compact",
]

TOPOLOGY_COMPACT_MEDIA = "application/vnd.walkstream.topology-c2"
"""Media type of the compact topology (``walkstream-topology/2``)."""
TOPOLOGY_COMPACT_MAGIC = b"WSTC"
"""The first bytes of a compact topology."""
_VERSION = 4
_LZMA_VERSIONS = (3, 4)
_ZLIB_VERSION = 2
_MM = 1000.0
_MAX_INFLATED = 64 << 20
_MAX_COUNT = 1 << 20
_NEAR_M = 1e-3
"""A cell's planes within this of its rounded outline's prism (the outline's own
millimetre rounding: IFC spaces' sub-millimetre walls) are not stored; the decoder
rebuilds them from the outline."""


def prism_planes(outline: ArrayLike, zmin: float, zmax: float) -> F64:
    """The planes of the prism over a counter-clockwise ``outline`` ``(k, 2)``.

    Returns
    -------
    numpy.ndarray
        ``(k + 2, 4)`` rows ``nx, ny, nz, d`` with unit outward normals (the sides,
        then floor and ceiling); a point ``p`` is inside when ``n . p + d <= 0``.
    """
    r = np.asarray(outline, dtype=np.float64).reshape(-1, 2)
    e = np.roll(r, -1, axis=0) - r
    n = np.column_stack([e[:, 1], -e[:, 0]])
    n /= np.maximum(np.hypot(n[:, 0], n[:, 1]), 1e-9)[:, None]
    d = -np.einsum("ij,ij->i", n, r)
    sides = np.column_stack([n, np.zeros(len(r)), d])
    caps = np.array([[0.0, 0.0, -1.0, zmin], [0.0, 0.0, 1.0, -zmax]])
    out = np.concatenate([sides, caps])
    out[out == 0.0] = 0.0  # no negative zeros in stored planes
    return out


def _mm(a: ArrayLike) -> NDArray[np.int64]:
    return np.rint(np.asarray(a, np.float64) * _MM).astype(np.int64)


def _outward_mm(poly: F64) -> NDArray[np.int64]:
    """A polygon ``(k, 3)`` in millimetres, each coordinate rounded away from the centroid."""
    x = np.asarray(poly, np.float64) * _MM
    c = x.mean(axis=0)
    out = np.where(x > c, np.ceil(x), np.where(x < c, np.floor(x), np.rint(x)))
    # a coordinate that is the centroid's in exact arithmetic may differ from it by
    # float noise: within a thousandth of a millimetre it is rounded to nearest
    near = np.abs(x - c) < 1e-3
    out = np.where(near, np.rint(x), out)
    return out.astype(np.int64)


def _deltas(rows: NDArray[np.int64]) -> list[int]:
    """Flattened differences of consecutive rows (the first row as it is)."""
    d = np.diff(rows, axis=0, prepend=np.zeros((1, rows.shape[1]), np.int64))
    out: list[int] = d.reshape(-1).tolist()
    return out


def _corner_mask(q: NDArray[np.int64]) -> int | None:
    """Which coordinates of polygon ``q`` ``(4, 3)``'s second vertex are its first's (bit
    ``i`` for coordinate ``i``; the others are its third's) when the four vertices are a
    rectangle spanned by the first and third (the fourth taking the coordinates the
    second does not), else None."""
    if q.shape != (4, 3):
        return None
    a, c = q[0], q[2]
    for mask in range(8):
        first = np.array([(mask >> i) & 1 for i in range(3)], bool)
        if np.array_equal(q[1], np.where(first, a, c)) and np.array_equal(q[3], np.where(first, c, a)):
            return mask
    return None


def _corners(a: NDArray[np.int64], c: NDArray[np.int64], mask: int) -> NDArray[np.int64]:
    """The rectangle ``(4, 3)`` spanned by corners ``a`` and ``c`` (:func:`_corner_mask`)."""
    first = np.array([(mask >> i) & 1 for i in range(3)], bool)
    return np.stack([a, np.where(first, a, c), c, np.where(first, c, a)])


def _portal_columns(t: Topology, kind_of: dict[str, int]) -> dict[str, list[Any]]:
    """The portals column by column (what LZMA finds more of alike side by side): ids
    as differences, kinds, the two cells, each polygon's vertex differences (a
    rectangle spanned by two corners: those two, :func:`_corner_mask`) and its mask
    (nil: every vertex stored)."""
    polys = [_outward_mm(pg) for _pid, _k, _a, _b, pg in t.portals]
    masks = [_corner_mask(q) for q in polys]
    return {
        "id": _deltas(np.array([p[0] for p in t.portals], np.int64).reshape(-1, 1)),
        "kind": [kind_of[p[1]] for p in t.portals],
        "a": [p[2] for p in t.portals],
        "b": [p[3] for p in t.portals],
        "polygon": [_deltas(q if m is None else q[[0, 2]]) for q, m in zip(polys, masks, strict=True)],
        "mask": masks,
    }


def _near_prism(planes: NDArray[np.float64], prism: NDArray[np.float64], outline: NDArray[np.float64],
                zmin: float, zmax: float) -> bool:
    """Whether a cell's ``planes`` ``(k, 4)`` are its rounded outline's ``prism`` ``(k, 4)``,
    row by row, to :data:`_NEAR_M` wherever the cell is (each row's offset between the
    two planes, at the corners of the outline ``(m, 2)`` at ``zmin`` and ``zmax``: a
    plane's offset is linear, so no point of the cell differs more)."""
    if len(planes) == 0 or planes.shape != prism.shape:
        return False
    corners = np.concatenate([np.column_stack([outline, np.full(len(outline), z)]) for z in (zmin, zmax)])
    gap = (planes[:, :3] - prism[:, :3]) @ corners.T + (planes[:, 3] - prism[:, 3])[:, None]
    return bool(np.all(np.abs(gap) <= _NEAR_M) and np.all(np.einsum("ij,ij->i", planes[:, :3], prism[:, :3]) > 0.99))


def _payload(body: bytes, what: str) -> bytes:
    """The msgpack payload of a compact topology: versions 3 and 4 LZMA, version 2 zlib."""
    b = bytes(body)
    k = len(TOPOLOGY_COMPACT_MAGIC)
    if len(b) > k and b[:k] == TOPOLOGY_COMPACT_MAGIC and b[k] not in (_ZLIB_VERSION, *_LZMA_VERSIONS):
        raise CodecError(f"{what}: compact topology version {b[k]} is not supported (this reader knows "
                         f"{_ZLIB_VERSION} to {_VERSION})")
    if len(b) > k and b[:k] == TOPOLOGY_COMPACT_MAGIC and b[k] in _LZMA_VERSIONS:
        return decompress_raw(b[k + 1 :], f"{what}: compact topology", _MAX_INFLATED)
    return inflate_tagged(b, what, TOPOLOGY_COMPACT_MAGIC, _ZLIB_VERSION, _MAX_INFLATED, "compact topology")


def encode_topology_compact(t: Topology) -> bytes:
    """Encode ``t`` as ``walkstream-topology/2`` (see the module docstring)."""
    kinds = sorted({c.kind for c in t.cells} | {p[1] for p in t.portals})
    kind_of = {k: i for i, k in enumerate(kinds)}
    planes: list[list[Any]] = []
    for i, c in enumerate(t.cells):
        ol = _mm(c.outline) / _MM
        rebuilt = prism_planes(ol, round(c.zmin * _MM) / _MM, round(c.zmax * _MM) / _MM)
        if not _near_prism(c.planes, rebuilt, ol, c.zmin, c.zmax):
            planes.append([i, c.planes.reshape(-1).tolist()])
    body = {
        "storeys": [[i, n, int(_mm(a)), int(_mm(b))] for i, n, a, b in t.storeys],
        "kinds": kinds,
        "cells": {
            "id": _deltas(np.array([[c.id] for c in t.cells], np.int64).reshape(-1, 1)),
            "kind": [kind_of[c.kind] for c in t.cells],
            "storey": [c.storey for c in t.cells],
            "z": _deltas(_mm([[c.zmin, c.zmax] for c in t.cells]).reshape(-1, 2)),
            "n": [len(c.outline) for c in t.cells],
            "outline": [_deltas(_mm(c.outline)) for c in t.cells],
            "planes": planes,
            "triangles": [c.contents.triangles for c in t.cells],
            "bytes": [c.contents.nbytes for c in t.cells],
        },
        "portals": _portal_columns(t, kind_of),
        "stairs": [[p, lo, up, _deltas(_mm(pa).reshape(-1, 3))] for p, lo, up, pa in t.stairs],
    }
    return TOPOLOGY_COMPACT_MAGIC + bytes([_VERSION]) + compress_raw(msgpack.packb(body))


def _ints(x: Any, what: str) -> list[int]:
    if not isinstance(x, list) or not all(type(v) is int for v in x):
        raise CodecError(f"{what}: expected a list of integers")
    return x


def _rows(flat: Any, cols: int, what: str, min_rows: int) -> F64:
    """Rows of millimetre differences back to metres ``(k, cols)``."""
    v = _ints(flat, what)
    if len(v) % cols or len(v) < cols * min_rows:
        raise CodecError(f"{what}: expected at least {min_rows} rows of {cols} integers, got {len(v)} values")
    a = np.asarray(v, np.int64).reshape(-1, cols)
    return np.cumsum(a, axis=0).astype(np.float64) / _MM


def decode_topology_compact(body: bytes, what: str) -> Topology:
    """Decode a ``walkstream-topology/2`` body from untrusted bytes; its ``nbytes`` is
    the body's size (what crossed the link).

    Raises
    ------
    CodecError
        Not a compact topology, truncated, inflating past the bound, or a field
        missing, malformed or with counts that disagree.
    """
    raw = _payload(body, what)
    obj = unpack_bounded(raw, what, max_bytes=_MAX_INFLATED, max_array_len=_MAX_COUNT, max_map_len=16,
                         max_bin_len=0)
    if not isinstance(obj, dict):
        raise CodecError(f"{what}: expected a map")
    try:
        return _topology(obj, what, len(body))
    except KeyError as exc:
        raise CodecError(f"{what}: missing field {exc}") from exc
    except (TypeError, ValueError, IndexError) as exc:
        raise CodecError(f"{what}: {exc}") from exc


def _topology(obj: dict[str, Any], what: str, nbytes: int) -> Topology:
    kinds = [str(k) for k in obj["kinds"]]
    storeys = tuple((int(i), str(n), a / _MM, b / _MM) for i, n, a, b in obj["storeys"])
    c = obj["cells"]
    ids = np.cumsum(_ints(c["id"], f"{what}: cells.id")).tolist()
    ncell = len(ids)
    names = c.get("name", [""] * ncell)  # version 4 leaves the names out
    columns = {"name": names, **{k: c[k] for k in ("kind", "storey", "n", "outline", "triangles", "bytes")}}
    for key, v in columns.items():
        if not isinstance(v, list) or len(v) != ncell:
            raise CodecError(f"{what}: cells.{key}: expected {ncell} values, got {len(v) if isinstance(v, list) else v!r:.40}")
    z = _rows(c["z"], 2, f"{what}: cells.z", ncell)
    if len(z) != ncell:
        raise CodecError(f"{what}: cells.z: expected {ncell} rows, got {len(z)}")
    explicit: dict[int, F64] = {}
    for row, flat in c["planes"]:
        explicit[int(row)] = np.asarray(flat, np.float64).reshape(-1, 4)
    portals = []
    ends: dict[int, list[PortalRef]] = {}
    for pid, kind, a, b, poly in _portal_rows(obj["portals"], what):
        kname = kinds[kind]
        portals.append((int(pid), kname, int(a), int(b), poly))
        ends.setdefault(int(a), []).append(PortalRef(int(pid), kname, poly, int(b)))
        ends.setdefault(int(b), []).append(PortalRef(int(pid), kname, poly, int(a)))
    cells = []
    for i, cid in enumerate(ids):
        outline = _rows(c["outline"][i], 2, f"{what}: cells[{i}].outline", 3)
        if len(outline) != c["n"][i]:
            raise CodecError(f"{what}: cells[{i}].outline: {len(outline)} vertices, n says {c['n'][i]}")
        zmin, zmax = float(z[i, 0]), float(z[i, 1])
        planes = explicit.get(i)
        if planes is None:
            planes = prism_planes(outline, zmin, zmax)
        refs = tuple(ends.get(cid, ()))
        cells.append(RoomRecord(
            id=int(cid), kind=kinds[c["kind"][i]], name=str(names[i]), room=None, storey=int(c["storey"][i]),
            outline=outline, zmin=zmin, zmax=zmax, planes=planes, portals=refs,
            neighbours=tuple(sorted({r.cell for r in refs})),
            contents=ContentsRef(int(c["triangles"][i]), 0, 0, int(c["bytes"][i]), 0, 0.0),
        ))
    stairs = tuple(
        (int(p), int(lo), int(up), _rows(flat, 3, f"{what}: stairs[{k}].path", 2))
        for k, (p, lo, up, flat) in enumerate(obj["stairs"])
    )
    return Topology(storeys, tuple(cells), tuple(portals), stairs, nbytes=nbytes)



def _portal_rows(stored: Any, what: str) -> list[tuple[int, int, int, int, F64]]:
    """``(id, kind index, a, b, polygon (k, 3) in metres)`` of each stored portal: rows
    ``[id, kind, a, b, vertex differences]`` (versions 2 and 3) or the columns of
    :func:`_portal_columns` (version 4)."""
    if isinstance(stored, list):
        rows = []
        for k, row in enumerate(stored):
            if not isinstance(row, list) or len(row) != 5:
                raise CodecError(f"{what}: portals[{k}]: expected [id, kind, a, b, polygon]")
            rows.append((row[0], row[1], row[2], row[3], _rows(row[4], 3, f"{what}: portals[{k}].polygon", 3)))
        return rows
    if not isinstance(stored, dict):
        raise CodecError(f"{what}: portals: expected a list of rows or a map of columns")
    ids = np.cumsum(_ints(stored["id"], f"{what}: portals.id")).tolist()
    cols = {key: stored[key] for key in ("kind", "a", "b", "polygon", "mask")}
    for key, v in cols.items():
        if not isinstance(v, list) or len(v) != len(ids):
            raise CodecError(f"{what}: portals.{key}: expected {len(ids)} values")
    out = []
    for k, pid in enumerate(ids):
        where = f"{what}: portals[{k}]"
        mask, flat = cols["mask"][k], cols["polygon"][k]
        if mask is None:
            poly = _rows(flat, 3, f"{where}.polygon", 3)
        else:
            if type(mask) is not int or not 0 <= mask < 8:
                raise CodecError(f"{where}.mask: expected nil or an integer 0 to 7, got {mask!r:.40}")
            corners = _ints(flat, f"{where}.polygon")
            if len(corners) != 6:
                raise CodecError(f"{where}.polygon: expected 6 integers (two corners) with a mask, got {len(corners)}")
            a, c = np.cumsum(np.asarray(corners, np.int64).reshape(2, 3), axis=0)
            poly = _corners(a, c, mask).astype(np.float64) / _MM
        out.append((pid, cols["kind"][k], cols["a"][k], cols["b"][k], poly))
    return out
