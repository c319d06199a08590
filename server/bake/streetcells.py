"""Street cells (Marvie et al. 2003, section 2): the street space cut into convex cells.

The navigation space of a city with street data, i.e. the union of its street
pieces, crossroads and squares, is cut into convex cells.  Every crossroad is one
cell; every street piece is cut across its length into pieces no longer than
``max_length`` (measured along the piece's long axis) so that the potentially
visible set of a cell stays small; every square is decomposed into convex parts,
and each part is cut along both of its axes into pieces of about ``max_length``.
Overlapping source polygons (e.g. a street area over a street) are made disjoint
first: crossroads win over squares, squares over street pieces, lower ids over
higher ones.  Real streets overlap buildings (a footprint drawn over the edge of a
road, a way along a wall): building footprints are subtracted from every piece
except the building passages of the scene (``SourceScene.passages``,
``tunnel=building_passage``), and parts smaller than :data:`MIN_CELL_AREA` m² left
by that clipping are dropped.  So every cell is convex, outside every footprint
(but a passage's), and disjoint from the others; adjacency comes from shared
boundaries.
"""

from __future__ import annotations

import math

import numpy as np
import shapely

from walkstream.server.bake.viewcell import (
    F64,
    ViewCell,
    check_height_range,
    finish_cells,
    footprint_polygons,
    positive_metres,
)
from walkstream.server.sources.scene import SourceScene
from walkstream.shared.errors import InputError
from walkstream.shared.geometry import signed_area

__all__ = ["MIN_CELL_AREA", "street_cells", "polygon_parts"]
#: Parts of street pieces smaller than this (m²) after clipping by footprints are dropped.
MIN_CELL_AREA = 0.5

# Source polygons overlapping by less than this (m^2) are rounding noise, not overlap.
_OVERLAP_EPS = 1e-6
# Parts narrower than this on average (metres, twice area over perimeter) are dropped.
_MIN_WIDTH = 0.2
# Parts smaller than this (m^2) left over by cutting or overlap removal are dropped.
_SLIVER_AREA = 1e-3
# Vertices closer than this (metres) are merged; a vertex this close to the line
# through its neighbours is collinear and dropped.
_VERTEX_EPS = 1e-9
_PRIORITY = {"crossroad": 0, "square": 1, "street": 2}


# --------------------------------------------------------------------------- public


def street_cells(
    scene: SourceScene,
    *,
    max_length: float = 40.0,
    eye_height: float = 1.7,
    height_range: tuple[float, float] = (1.5, 2.0),
) -> list[ViewCell]:
    """Cut the navigation space (street pieces, crossroads, squares) into convex cells.

    Parameters
    ----------
    scene:
        The scene; its ``streets`` are the navigation space.
    max_length:
        Longest extent (metres) of a street cell along its street, and of a square cell
        along either axis of its square part.  Crossroads are never cut.
    eye_height:
        The viewer's eye height; must lie in ``height_range`` (checked so that a PVS
        baked for the range is valid for the viewer).
    height_range:
        ``(zmin, zmax)`` eye heights the cells' PVSs are baked for.

    Returns
    -------
    list[ViewCell]
        Cells with ids ``0..n-1`` ordered by kind (crossroad, street, square) then by
        centroid; neighbours share a boundary segment longer than
        :data:`MIN_SHARED_EDGE`.

    Raises
    ------
    InputError
        If the scene has no street pieces, or a parameter is out of range.
    """
    max_length = positive_metres("max_length", max_length)
    zmin, zmax = check_height_range(height_range)
    if not zmin <= float(eye_height) <= zmax:
        raise InputError(f"eye_height {eye_height} m is outside height_range ({zmin}, {zmax})")
    if not scene.streets:
        raise InputError(
            f"scene {scene.name!r} has no street pieces, crossroads or squares (an empty "
            "street network after filtering?): street cells need street data; use --cells grid"
        )

    parts: list[tuple[str, F64]] = []
    for kind, poly in _disjoint_sources(scene):
        for convex in _convex_parts(poly):
            if kind == "crossroad":
                parts.append((kind, convex))
                continue
            u = _long_axis(convex)
            for piece in _cut(convex, u, max_length):
                if kind == "street":
                    parts.append((kind, piece))
                else:
                    # squares are open areas: cut across as well as along
                    v = np.array([-u[1], u[0]])
                    parts.extend((kind, p) for p in _cut(piece, v, max_length))
    parts = [(k, p) for k, p in parts if signed_area(p) >= _SLIVER_AREA]
    return finish_cells(parts, zmin, zmax)


def _clean_ring(ring: F64) -> F64:
    """CCW ring without closing, repeated or collinear vertices (may return < 3)."""
    r = np.asarray(ring, dtype=np.float64).reshape(-1, 2)
    if len(r) > 1 and np.all(np.abs(r[0] - r[-1]) <= _VERTEX_EPS):
        r = r[:-1]
    if len(r) >= 3 and signed_area(r) < 0:
        r = r[::-1]
    changed = True
    while changed and len(r) >= 3:
        changed = False
        prev, nxt = np.roll(r, 1, axis=0), np.roll(r, -1, axis=0)
        a, b = r - prev, nxt - prev
        base = np.linalg.norm(b, axis=1)
        dist = np.abs(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]) / np.maximum(base, 1e-300)
        dup = np.linalg.norm(a, axis=1) <= _VERTEX_EPS
        # a vertex on the segment between its neighbours adds nothing; one step at a
        # time so that removing a vertex never makes its neighbour's test stale
        bad = np.flatnonzero(dup | (dist <= _VERTEX_EPS))
        if len(bad):
            r = np.delete(r, bad[0], axis=0)
            changed = True
    return np.ascontiguousarray(r)


def polygon_parts(geom: shapely.Geometry) -> list[shapely.Polygon]:
    """The non-sliver polygons of ``geom``, however a repair nested them."""
    # a repair may nest a MultiPolygon in a GeometryCollection: flatten both levels
    return [
        p
        for g in shapely.get_parts(geom)
        for p in shapely.get_parts(g)
        if isinstance(p, shapely.Polygon) and not p.is_empty and p.area >= _SLIVER_AREA
    ]


def _disjoint_sources(scene: SourceScene) -> list[tuple[str, shapely.Polygon]]:
    """Valid street polygons in priority order, with overlaps given to the earlier one."""
    order = sorted(scene.streets, key=lambda s: (_PRIORITY[s.kind], s.id))
    kinds: list[str] = []
    geoms: list[shapely.Polygon] = []
    passage: list[bool] = []
    for s in order:
        poly = shapely.Polygon(s.ring)
        if not poly.is_valid:
            poly = shapely.make_valid(poly)
        for p in polygon_parts(poly):
            kinds.append(s.kind)
            geoms.append(p)
            passage.append(s.id in scene.passages)
    if not geoms:
        return []
    arr = np.array(geoms, dtype=object)
    i, j = shapely.STRtree(arr).query(arr, predicate="intersects")
    keep = i < j  # j loses the overlap to the earlier i
    i, j = i[keep], j[keep]
    overlap = shapely.area(shapely.intersection(arr[i], arr[j]))
    real = overlap > _OVERLAP_EPS
    out_geoms = list(geoms)
    for jj in np.unique(j[real]):
        winners = arr[i[real & (j == jj)]]
        out_geoms[jj] = shapely.difference(out_geoms[jj], shapely.union_all(winners))
    out_geoms = _clip_footprints(scene, out_geoms, passage)
    out: list[tuple[str, shapely.Polygon]] = []
    for kind, g in zip(kinds, out_geoms, strict=True):
        # clipping leaves slivers along walls: too small, or too thin to stand in
        out.extend(
            (kind, p)
            for p in polygon_parts(g)
            if p.area >= MIN_CELL_AREA and p.area >= _MIN_WIDTH * 0.5 * p.length
        )
    return out


def _clip_footprints(
    scene: SourceScene, geoms: list[shapely.Geometry], passage: list[bool]
) -> list[shapely.Geometry]:
    """Street geometries minus the building footprints (passages are left whole)."""
    fps = footprint_polygons(scene)
    if not len(fps) or not geoms:
        return geoms
    fps = np.array([f if f.is_valid else shapely.make_valid(f) for f in fps], dtype=object)
    arr = np.array(geoms, dtype=object)
    gi, fi = shapely.STRtree(fps).query(arr, predicate="intersects")
    out = list(geoms)
    for g in np.unique(gi).tolist():
        if passage[g]:
            continue
        cut = shapely.union_all(fps[fi[gi == g]])
        out[g] = shapely.make_valid(shapely.difference(out[g], cut))
    return out


def _is_convex_ring(ring: F64) -> bool:
    e = np.roll(ring, -1, axis=0) - ring
    f = np.roll(e, -1, axis=0)
    cr = e[:, 0] * f[:, 1] - e[:, 1] * f[:, 0]
    scale = np.linalg.norm(e, axis=1) * np.linalg.norm(f, axis=1)
    return bool(np.all(cr >= -1e-9 * scale))


def _convex_parts(poly: shapely.Polygon) -> list[F64]:
    """Convex CCW rings covering ``poly`` exactly (Hertel-Mehlhorn on a CDT)."""
    shell = _clean_ring(np.asarray(poly.exterior.coords))
    if len(shell) < 3:
        return []
    if not poly.interiors and _is_convex_ring(shell):
        return [shell]

    tris = shapely.get_parts(shapely.constrained_delaunay_triangles(poly))
    index: dict[tuple[float, float], int] = {}
    coords: list[tuple[float, float]] = []
    loops: list[list[int] | None] = []
    for t in tris:
        pts = np.asarray(t.exterior.coords)[:3]
        if abs(signed_area(pts)) < 1e-12:
            continue
        if signed_area(pts) < 0:
            pts = pts[::-1]
        loop = []
        for x, y in pts:
            key = (float(x), float(y))
            if key not in index:
                index[key] = len(coords)
                coords.append(key)
            loop.append(index[key])
        loops.append(loop)
    xy = np.array(coords)
    owner: dict[tuple[int, int], int] = {}
    for k, tri in enumerate(loops):
        assert tri is not None
        for a, b in zip(tri, tri[1:] + tri[:1], strict=True):
            owner[(a, b)] = k
    diagonals = [(a, b) for (a, b) in owner if (b, a) in owner and a < b]
    # removing long diagonals first tends to leave fewer, rounder parts
    diagonals.sort(key=lambda e: (-float(np.hypot(*(xy[e[0]] - xy[e[1]]))), e))
    for a, b in diagonals:
        p, q = owner.get((a, b)), owner.get((b, a))
        if p is None or q is None or p == q:
            continue
        lp, lq = loops[p], loops[q]
        assert lp is not None and lq is not None
        ip, iq = lp.index(b), lq.index(a)
        rp = lp[ip:] + lp[:ip]  # starts at b, ends at a
        rq = lq[iq:] + lq[:iq]  # starts at a, ends at b
        merged = rp + rq[1:-1]
        if not _is_convex_ring(xy[merged]):
            continue
        loops[p], loops[q] = merged, None
        del owner[(a, b)], owner[(b, a)]
        for u, v in zip(merged, merged[1:] + merged[:1], strict=True):
            owner[(u, v)] = p
    out = []
    for part in loops:
        if part is None:
            continue
        ring = _clean_ring(xy[part])
        if len(ring) >= 3:
            out.append(ring)
    return out


def _long_axis(ring: F64) -> F64:
    """Unit direction of the long side of the minimum rotated rectangle of ``ring``."""
    o = ring.mean(axis=0)
    rect = shapely.minimum_rotated_rectangle(shapely.Polygon(ring - o))
    c = np.asarray(rect.exterior.coords)
    if len(c) < 4:  # degenerate: fall back to the longest edge
        e = np.roll(ring, -1, axis=0) - ring
        d = e[int(np.argmax(np.linalg.norm(e, axis=1)))]
    else:
        e1, e2 = c[1] - c[0], c[2] - c[1]
        d = e1 if np.hypot(*e1) >= np.hypot(*e2) else e2
    d = d / max(float(np.hypot(*d)), 1e-300)
    # a canonical sign keeps the cut order independent of the rectangle's start vertex
    if d[0] < -1e-12 or (abs(d[0]) <= 1e-12 and d[1] < 0):
        d = -d
    return np.asarray(d, dtype=np.float64)


def _cut(ring: F64, u: F64, max_length: float) -> list[F64]:
    """Cut a convex ring by lines across ``u`` into slabs no longer than ``max_length``.

    The cut lines are equally spaced over the ring's extent along ``u``.  Each cut
    point is computed once, on the original edge, and shared by the two slabs on
    either side, so neighbouring slabs meet exactly (no sliver gaps or overlaps).
    """
    t = ring @ u
    tmin, tmax = float(t.min()), float(t.max())
    n = max(1, math.ceil((tmax - tmin) / max_length - 1e-9))
    if n == 1:
        return [ring]
    cuts = tmin + (tmax - tmin) * np.arange(1, n) / n
    # snap vertices lying on a cut line onto it so no near-duplicate cut point appears
    near = np.abs(t[:, None] - cuts[None, :]) <= 1e-9
    label = np.where(near.any(axis=1), cuts[np.argmax(near, axis=1)], t)

    pts: list[F64] = []
    lab: list[float] = []
    m = len(ring)
    for i in range(m):
        j = (i + 1) % m
        pts.append(ring[i])
        lab.append(float(label[i]))
        ta, tb = label[i], label[j]
        lo, hi = min(ta, tb), max(ta, tb)
        crossing = cuts[(cuts > lo) & (cuts < hi)]
        if len(crossing) == 0:
            continue
        # cut points are inserted in the order the edge is walked
        if ta <= tb:
            p0, p1, t0, t1, seq = ring[i], ring[j], t[i], t[j], crossing
        else:
            p0, p1, t0, t1, seq = ring[j], ring[i], t[j], t[i], crossing[::-1]
        s = (seq - t0) / (t1 - t0)
        pts.extend(p0 + s[:, None] * (p1 - p0))  # in traversal order: seq follows it
        lab.extend(float(c) for c in seq)
    refined = np.array(pts)
    labels = np.array(lab)
    bounds = np.concatenate([[tmin], cuts, [tmax]])
    bounds[0], bounds[-1] = -np.inf, np.inf
    out = []
    for k in range(n):
        # a convex ring's vertices inside a slab, in ring order, outline its part
        inside = (labels >= bounds[k]) & (labels <= bounds[k + 1])
        ring_k = _clean_ring(refined[inside])
        if len(ring_k) >= 3:
            out.append(ring_k)
    whole = shapely.Polygon(ring)
    total = sum(signed_area(r) for r in out)
    if abs(total - whole.area) > 1e-6 * max(whole.area, 1.0) or any(
        shapely.difference(shapely.Polygon(r), whole).area > 1e-6 for r in out
    ):
        # a nearly degenerate (needle-thin) ring: clip it by each slab instead
        return _cut_by_strips(whole, u, cuts, tmin, tmax)
    return out


def _cut_by_strips(whole: shapely.Polygon, u: F64, cuts: F64, tmin: float, tmax: float) -> list[F64]:
    """The slabs of :func:`_cut` by polygon clipping (for rings too thin to walk)."""
    v = np.array([-u[1], u[0]])
    c = np.asarray(whole.exterior.coords)[:-1]
    s = c @ v
    lo_v, hi_v = float(s.min()) - 1.0, float(s.max()) + 1.0
    edges = np.concatenate([[tmin - 1.0], cuts, [tmax + 1.0]])
    out = []
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        strip = shapely.Polygon([a * u + lo_v * v, b * u + lo_v * v, b * u + hi_v * v, a * u + hi_v * v])
        for part in polygon_parts(shapely.intersection(whole, strip)):
            ring = _clean_ring(np.asarray(part.exterior.coords))
            if len(ring) >= 3:
                out.append(ring)
    return out
