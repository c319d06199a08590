"""Decoding a cell-contents blob's planar body (``walkstream-cellmesh/2``, /3, /4), bounded.

The layout and the error bound are :mod:`~walkstream.shared.codec.planarmesh`'s (the
encoder's); this module reads that map back from untrusted bytes: every count, key,
step and index is checked against the limits below before anything is allocated, and
any failure is a :class:`~walkstream.shared.errors.CodecError` naming the field.  The
polygons are triangulated again (triangles and convex quadrilaterals with array
operations, the rest by earcut), version 3's rectangles and boxes become four-corner
faces, and version 4's welded triangles get a corner each again.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from walkstream.shared.codec.boxmesh import box_rects, rect_mesh
from walkstream.shared.codec.keptindices import from_high_water_codes
from walkstream.shared.codec.planarmesh import (
    BOXED_FORMAT,
    GRID,
    MAX_Q,
    WELDED_FORMAT,
    triangulate_region,
)
from walkstream.shared.codec.varint import decode_varints, unzigzag, varint_field
from walkstream.shared.errors import CodecError

__all__ = ["decode_planar_body"]

_MAX_VERTICES = 1 << 22
_MAX_PARTS = 1 << 16
_MAX_RING = 1 << 16
_KEYS = frozenset(
    {"format", "parts", "elements", "materials", "vertices", "triangles", "regions", "rings", "ring_sizes",
     "positions", "indices"}
)
_KEYS3 = frozenset({"box_counts", "boxes", "box_faces", "rect_counts", "rect_kinds", "rects"})


def _counts(body: dict[str, Any], key: str, count: int, what: str, hi: int) -> NDArray[np.int64]:
    v = varint_field(body, key, count, what)
    if len(v) and int(v.max()) > hi:
        raise CodecError(f"{what}: {key}: a value above {hi}")
    return np.asarray(v, dtype=np.int64)


def decode_planar_body(
    body: dict[str, Any], what: str
) -> list[tuple[int, int, NDArray[np.float32], NDArray[np.int64]]]:
    """Check and decode a version 2 or 3 map: ``(element, material, positions, indices)`` per part.

    Raises
    ------
    CodecError
        Unknown keys, counts that disagree or exceed the limits, indices out of range.
    """
    v4 = body.get("format") == WELDED_FORMAT
    v3 = v4 or body.get("format") == BOXED_FORMAT
    keys = _KEYS | _KEYS3 if v3 else _KEYS
    if set(body) - keys:
        raise CodecError(f"{what}: unknown keys {sorted(set(body) - keys)}")
    n_parts = body.get("parts")
    if type(n_parts) is not int or not 0 <= n_parts <= _MAX_PARTS:
        raise CodecError(f"{what}: parts must be 0..{_MAX_PARTS}")
    mats = body.get("materials")
    if not isinstance(mats, bytes) or len(mats) != n_parts:
        raise CodecError(f"{what}: materials: expected {n_parts} bytes")
    eid = np.cumsum(unzigzag(_counts(body, "elements", n_parts, what, 2**64 - 1).astype(np.uint64)))
    vcount = _counts(body, "vertices", n_parts, what, _MAX_VERTICES)
    tcount = _counts(body, "triangles", n_parts, what, 4 * _MAX_VERTICES)
    rcount = _counts(body, "regions", n_parts, what, _MAX_VERTICES)
    n_regions = int(rcount.sum())
    if n_regions > _MAX_VERTICES:
        raise CodecError(f"{what}: {n_regions} regions is too many")
    rings = _counts(body, "rings", n_regions, what, _MAX_RING)
    if len(rings) and int(rings.min()) < 1:
        raise CodecError(f"{what}: a region without rings")
    n_rings = int(rings.sum())
    if n_rings > _MAX_VERTICES:
        raise CodecError(f"{what}: {n_rings} rings is too many")
    sizes = _counts(body, "ring_sizes", n_rings, what, _MAX_RING)
    if len(sizes) and int(sizes.min()) < 3:
        raise CodecError(f"{what}: a ring of fewer than 3 vertices")
    nv, nt = int(vcount.sum()) + int(sizes.sum()), int(tcount.sum())
    if nv > _MAX_VERTICES or nt > 4 * _MAX_VERTICES:
        raise CodecError(f"{what}: {nv} vertices / {nt} triangles is too many")
    raw = body.get("positions")
    if not isinstance(raw, bytes):
        raise CodecError(f"{what}: positions is not bytes")
    dq = unzigzag(decode_varints(raw, f"{what}: positions"))
    if len(dq) != 3 * nv:
        raise CodecError(f"{what}: positions: expected {3 * nv} values, got {len(dq)}")
    if len(dq) and int(np.abs(dq).max()) >= MAX_Q:
        raise CodecError(f"{what}: a position step beyond the grid's range")
    q = np.cumsum(dq.reshape(3, nv).T, axis=0)
    if len(q) and int(np.abs(q).max()) >= MAX_Q:
        raise CodecError(f"{what}: a position beyond the grid's range")
    pos = (q.astype(np.float64) * GRID).astype(np.float32)
    if v4:
        idx = from_high_water_codes(_counts(body, "indices", 3 * nt, what, _MAX_VERTICES), vcount, tcount, what)
    else:
        di = unzigzag(_counts(body, "indices", 3 * nt, what, 2**64 - 1).astype(np.uint64))
        # a running sum restarting at every part start (where the stored value is absolute)
        run = np.cumsum(di)
        starts = (np.cumsum(tcount * 3) - tcount * 3).astype(np.int64)  # each part's first index (none: no part)
        offset = np.where(starts > 0, run[np.maximum(starts - 1, 0)] if len(run) else 0, 0)
        idx = run - np.repeat(offset, tcount * 3)
    # every region's first vertex (global), then its triangles (global indices)
    part_v0 = np.concatenate([[0], np.cumsum(vcount + _per_part(rings, sizes, rcount))])
    rtris, rpart = _region_triangles(q, rings, sizes, vcount, rcount, part_v0)
    out: list[tuple[int, int, NDArray[np.float32], NDArray[np.int64]]] = []
    t0 = 0
    rbounds = np.searchsorted(rpart, np.arange(n_parts + 1))
    # version 3: each part's rectangles and then its boxes' faces, four corners each
    faces, fbounds = _decode_rects(body, what, n_parts, nv) if v3 else (np.zeros((0, 4, 3)), None)
    fpos = (faces.reshape(-1, 3).astype(np.float64) * GRID).astype(np.float32)
    for k in range(n_parts):
        nvk, ntk = int(vcount[k]), int(tcount[k])
        t = idx[3 * t0 : 3 * (t0 + ntk)].reshape(-1, 3)
        if len(t) and (t.min() < 0 or t.max() >= nvk):
            raise CodecError(f"{what}: part {k}: index out of range")
        v0, v1 = int(part_v0[k]), int(part_v0[k + 1])
        region = rtris[rbounds[k] : rbounds[k + 1]] - v0
        if fbounds is None:
            out.append((int(eid[k]), mats[k], pos[v0:v1], np.concatenate([t, region])))
        else:
            f0, f1 = int(fbounds[k]), int(fbounds[k + 1])
            quads = (v1 - v0 + 4 * np.arange(f1 - f0)[:, None, None] + _QUAD).reshape(-1, 3)
            out.append(
                (int(eid[k]), mats[k], np.concatenate([pos[v0:v1], fpos[4 * f0 : 4 * f1]]), np.concatenate([t, region, quads]))
            )
        if v4 and ntk:
            # welded kept triangles get a corner each again: the normals stay flat
            e, m, pp, tt = out[-1]
            pp = np.concatenate([pp[t.reshape(-1)], pp[nvk:]])
            tt = np.concatenate([np.arange(3 * ntk).reshape(-1, 3), tt[ntk:] + (3 * ntk - nvk)])
            out[-1] = (e, m, pp, tt)
        t0 += ntk
    return out


_QUAD = np.array([[0, 1, 2], [0, 2, 3]], np.int64)


def _steps(body: dict[str, Any], key: str, rows: int, cols: int, what: str) -> NDArray[np.int64]:
    """``rows * cols`` zigzag varints under ``key`` as signed integers, each below the grid's range."""
    v = unzigzag(varint_field(body, key, rows * cols, what))
    if len(v) and int(np.abs(v).max()) >= MAX_Q:
        raise CodecError(f"{what}: {key}: a value beyond the grid's range")
    return v


def _decode_rects(
    body: dict[str, Any], what: str, n_parts: int, nv: int
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Version 3's rectangles and boxes: ``(faces (f, 4, 3) corners, (parts + 1,) each part's first face)``."""
    # a blob without rectangles (boxes) has none of their keys
    none = np.zeros(n_parts, np.int64)
    rcount = _counts(body, "rect_counts", n_parts, what, _MAX_VERTICES) if "rect_counts" in body else none
    bcount = _counts(body, "box_counts", n_parts, what, _MAX_VERTICES) if "box_counts" in body else none
    body = {"rect_kinds": b"", "rects": b"", "boxes": b"", "box_faces": b"", **body}
    nr, nb = int(rcount.sum()), int(bcount.sum())
    if nv + 4 * nr + 24 * nb > _MAX_VERTICES:
        raise CodecError(f"{what}: {nr} rectangles and {nb} boxes are too many")
    kinds = body.get("rect_kinds")
    if not isinstance(kinds, bytes) or len(kinds) != nr:
        raise CodecError(f"{what}: rect_kinds: expected {nr} bytes")
    rk = np.frombuffer(kinds, np.uint8).astype(np.int64)
    if len(rk) and int(rk.max()) > 5:
        raise CodecError(f"{what}: rect_kinds: a kind above 5")
    masks = body.get("box_faces")
    if not isinstance(masks, bytes) or len(masks) != nb:
        raise CodecError(f"{what}: box_faces: expected {nb} bytes")
    bm = np.frombuffer(masks, np.uint8).astype(np.int64)
    if len(bm) and (int(bm.max()) > 127 or int((bm & 63).min()) == 0):
        raise CodecError(f"{what}: box_faces: a box of no faces or an unknown bit")
    r = _steps(body, "rects", nr, 5, what).reshape(5, nr).T
    b = _steps(body, "boxes", nb, 6, what).reshape(nb, 6)
    rlo, blo = np.cumsum(r[:, :3], axis=0), np.cumsum(b[:, :3], axis=0)
    if (len(r) and int(r[:, 3:].min()) <= 0) or (len(b) and int(b[:, 3:].min()) <= 0):
        raise CodecError(f"{what}: a rectangle or box without area")
    if max(int(np.abs(rlo).max(initial=0)), int(np.abs(blo).max(initial=0))) >= MAX_Q:
        raise CodecError(f"{what}: a rectangle or box beyond the grid's range")
    bk, bflo, bext = box_rects(np.column_stack([blo, b[:, 3:]]))
    has = ((bm[:, None] >> np.arange(6)) & 1) == 1  # (nb, 6) the faces each box has
    bk = (bk.reshape(nb, 6) ^ (bm[:, None] >> 6)).reshape(-1)  # bit 6: facing into the box
    kinds_all = np.concatenate([rk, bk.reshape(nb, 6)[has]])
    lo_all = np.concatenate([rlo, bflo.reshape(nb, 6, 3)[has]])
    ext_all = np.concatenate([r[:, 3:], bext.reshape(nb, 6, 2)[has]])
    # part by part: its rectangles, then its boxes' faces (a stable sort keeps that order)
    parts = np.arange(n_parts)
    owner = np.concatenate([np.repeat(parts, rcount), np.repeat(np.repeat(parts, bcount), 6)[has.reshape(-1)]])
    order = np.argsort(owner, kind="stable")
    faces = rect_mesh(kinds_all[order], lo_all[order], ext_all[order])
    return faces, np.concatenate([[0], np.cumsum(np.bincount(owner, minlength=n_parts))])


def _per_part(rings: NDArray[np.int64], sizes: NDArray[np.int64], rcount: NDArray[np.int64]) -> NDArray[np.int64]:
    """``(parts,)`` ring vertices per part."""
    ring_part = np.repeat(np.repeat(np.arange(len(rcount)), rcount), rings)
    return np.bincount(ring_part, weights=sizes, minlength=len(rcount)).astype(np.int64)


def _region_triangles(
    q: NDArray[np.int64],
    rings: NDArray[np.int64],
    sizes: NDArray[np.int64],
    vcount: NDArray[np.int64],
    rcount: NDArray[np.int64],
    part_v0: NDArray[np.int64],
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """All regions' triangles (global vertex indices, region order) and each one's part.

    Triangles and convex quadrilaterals without holes (most regions) are split with
    array operations; the rest go through earcut one by one.
    """
    n_regions = len(rings)
    if n_regions == 0:
        return np.zeros((0, 3), np.int64), np.zeros(0, np.int64)
    region_part = np.repeat(np.arange(len(rcount)), rcount)
    ring_first = np.concatenate([[0], np.cumsum(rings)[:-1]])
    ring_vstart = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    # a part's ring vertices come after its kept-triangle vertices
    part_ring0 = part_v0[:-1] + vcount - np.concatenate([[0], np.cumsum(_per_part(rings, sizes, rcount))[:-1]])
    start = ring_vstart[ring_first] + part_ring0[region_part]
    total = np.add.reduceat(sizes, ring_first) if len(sizes) else np.zeros(0, np.int64)
    tris: list[NDArray[np.int64]] = []
    owner: list[NDArray[np.int64]] = []
    tri3 = np.flatnonzero((rings == 1) & (total == 3))
    tris.append(start[tri3, None] + np.arange(3))
    owner.append(tri3)
    quad = np.flatnonzero((rings == 1) & (total == 4))
    if len(quad):
        v = q[start[quad, None] + np.arange(4)].astype(np.float64)  # (k, 4, 3)
        rel = v - v[:, :1]
        n = np.cross(rel[:, 1], rel[:, 2]) + np.cross(rel[:, 2], rel[:, 3])
        d1 = np.einsum("ij,ij->i", np.cross(rel[:, 1], rel[:, 2]), n)
        d2 = np.einsum("ij,ij->i", np.cross(rel[:, 2], rel[:, 3]), n)
        split = np.where(((d1 > 0) & (d2 > 0))[:, None, None], [[0, 1, 2], [0, 2, 3]], [[1, 2, 3], [1, 3, 0]])
        ok = (d1 > 0) & (d2 > 0)
        other = ~ok
        if other.any():  # the 1-3 diagonal must be inside too, else earcut decides
            r2 = rel[other] - rel[other][:, 1:2]
            e1 = np.einsum("ij,ij->i", np.cross(r2[:, 2], r2[:, 3]), n[other])
            e2 = np.einsum("ij,ij->i", np.cross(r2[:, 3], r2[:, 0]), n[other])
            ok[np.flatnonzero(other)] = (e1 > 0) & (e2 > 0)
        tris.append((start[quad, None, None] + split)[ok].reshape(-1, 3))
        owner.append(np.repeat(quad[ok], 2))
        rest_quads = quad[~ok]
    else:
        rest_quads = quad
    fast = np.zeros(n_regions, bool)
    fast[tri3] = True
    fast[quad] = True
    fast[rest_quads] = False
    for r in np.flatnonzero(~fast).tolist():
        bounds = start[r] + np.concatenate([[0], np.cumsum(sizes[ring_first[r] : ring_first[r] + rings[r]])])
        region = [q[a:b] for a, b in zip(bounds[:-1], bounds[1:], strict=True)]
        t = triangulate_region(region) + start[r]
        tris.append(t)
        owner.append(np.full(len(t), r, np.int64))
    allt = np.concatenate(tris)
    own = np.concatenate(owner)
    order = np.argsort(own, kind="stable")
    return allt[order], region_part[own[order]]
