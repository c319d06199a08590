"""Geometry of room cells: convex parts, shared edges, plane sets, and batched convex clipping.

Mulloni et al. keep cells convex (a point is in a cell when it is behind all of its
planes), so a room that is not convex is cut into convex parts (:func:`convex_parts`);
neighbouring cells meet along shared edges (:func:`shared_segments`), where portals
are; and the contents of a cell are the triangles clipped to its volume
(:func:`clip_polygons`, vectorised over many polygons against one plane at a time).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import shapely
import shapely.ops
from numpy.typing import ArrayLike, NDArray

from walkstream.shared.arrays import F64
from walkstream.shared.geometry import triangulate_rings
from walkstream.shared.roomcompact import prism_planes

__all__ = [
    "orient_ccw",
    "is_convex",
    "convex_parts",
    "shared_segments",
    "without_holes",
    "cell_planes",
    "clip_polygons",
    "fan_triangles",
    "ray_distance",
    "polygon_rings",
]

_EPS = 1e-9


def orient_ccw(ring: ArrayLike) -> F64:
    """A ring ``(n, 2)`` counter-clockwise, without a repeated closing vertex."""
    r = np.asarray(ring, dtype=np.float64).reshape(-1, 2)
    if len(r) > 1 and np.allclose(r[0], r[-1]):
        r = r[:-1]
    x, y = (r - r[0]).T
    area2 = float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))
    return r[::-1].copy() if area2 < 0 else r


def _turns(r: F64) -> F64:
    """Cross product at each vertex of a ring (positive: a left, convex turn for CCW)."""
    e0 = r - np.roll(r, 1, axis=0)
    e1 = np.roll(r, -1, axis=0) - r
    return e0[:, 0] * e1[:, 1] - e0[:, 1] * e1[:, 0]


def is_convex(ring: ArrayLike, tol: float = 1e-3) -> bool:
    """Whether a CCW ring is convex, allowing vertices ``tol`` metres off a straight line.

    >>> is_convex([[0, 0], [2, 0], [2, 2], [0, 2]]), is_convex([[0, 0], [2, 0], [2, 1], [1, 1], [1, 2], [0, 2]])
    (True, False)
    """
    r = orient_ccw(ring)
    e1 = np.hypot(*(np.roll(r, -1, axis=0) - r).T)
    return bool(np.all(_turns(r) >= -tol * np.maximum(e1, _EPS)))


def _cut(poly: shapely.Polygon, ring: F64, i: int, direction: F64) -> list[shapely.Polygon] | None:
    """Cut ``poly`` from its vertex ``i`` along ``direction`` to the boundary it meets first."""
    v = ring[i]
    span = 4.0 * float(np.ptp(ring, axis=0).max()) + 1.0
    ray = shapely.LineString([v + direction * 1e-7, v + direction * span])
    hit = ray.intersection(poly.exterior)
    pts = [q for g in getattr(hit, "geoms", [hit]) if not g.is_empty for q in np.asarray(g.coords)]
    if not pts:
        return None
    d = np.array([float(np.dot(q - v, direction)) for q in pts])
    ok = d > 1e-6
    if not ok.any():
        return None
    end = v + direction * (float(d[ok].min()) + 1e-7)
    pieces = shapely.ops.split(poly, shapely.LineString([v, end]))
    parts = [g for g in pieces.geoms if isinstance(g, shapely.Polygon) and g.area > 1e-6]
    return parts if len(parts) >= 2 else None


def _hertel_mehlhorn(ring: F64) -> list[F64]:
    """Fallback: triangulate, then merge neighbouring pieces while the union stays convex."""
    tris = triangulate_rings([ring])
    polys = [shapely.Polygon(ring[t]) for t in tris]
    merged = True
    while merged:
        merged = False
        for i in range(len(polys)):
            for j in range(i + 1, len(polys)):
                if polys[i].touches(polys[j]) and polys[i].intersection(polys[j]).length > 1e-6:
                    u = shapely.union(polys[i], polys[j])
                    if isinstance(u, shapely.Polygon) and is_convex(np.asarray(u.exterior.coords)[:-1]):
                        polys[i] = u
                        del polys[j]
                        merged = True
                        break
            if merged:
                break
    return [orient_ccw(np.asarray(p.exterior.coords)[:-1]) for p in polys]


def convex_parts(ring: ArrayLike, tol: float = 1e-3, _depth: int = 0) -> list[F64]:
    """Cut a simple polygon into convex parts, each ``(n, 2)`` counter-clockwise.

    A reflex vertex is resolved by extending one of its two edges into the polygon
    until it meets the boundary (for the rectangular rooms of buildings this gives
    the natural cuts: an L is two rectangles); the cut that leaves fewer reflex
    vertices is taken, the shorter one on a tie.  Parts are made exactly convex (their
    hull; the notches filled are below ``tol``).

    >>> [len(p) for p in convex_parts([[0, 0], [4, 0], [4, 2], [2, 2], [2, 4], [0, 4]])]
    [4, 4]
    """
    r = orient_ccw(ring)
    poly = shapely.Polygon(r)
    if is_convex(r, tol) or _depth > 64:
        hull = poly.convex_hull
        return [orient_ccw(np.asarray(hull.exterior.coords)[:-1])]
    turns = _turns(r)
    e1 = np.hypot(*(np.roll(r, -1, axis=0) - r).T)
    reflex = np.flatnonzero(turns < -tol * np.maximum(e1, _EPS))
    best: tuple[int, float, list[shapely.Polygon]] | None = None
    for i in reflex.tolist():
        e_in = r[i] - r[i - 1]
        e_out = r[(i + 1) % len(r)] - r[i]
        for d in (e_in, -e_out):
            n = float(np.hypot(*d))
            if n < _EPS:
                continue
            parts = _cut(poly, r, i, d / n)
            if parts is None:
                continue
            left = 0
            for pc in parts:
                pr = orient_ccw(np.asarray(pc.exterior.coords)[:-1])
                pe = np.hypot(*(np.roll(pr, -1, axis=0) - pr).T)
                left += int(np.sum(_turns(pr) < -tol * np.maximum(pe, _EPS)))
            length = float(sum(pc.length for pc in parts) - poly.length)
            if best is None or (left, length) < (best[0], best[1]):
                best = (left, length, parts)
    if best is None:
        return _hertel_mehlhorn(r)
    out: list[F64] = []
    for pc in best[2]:
        pc = pc.simplify(tol * 0.5)
        if isinstance(pc, shapely.Polygon) and pc.area > 1e-6:
            out += convex_parts(np.asarray(pc.exterior.coords)[:-1], tol, _depth + 1)
    return out


def shared_segments(a: ArrayLike, b: ArrayLike, tol: float = 0.02, min_length: float = 0.05) -> list[F64]:
    """Straight pieces of outline ``a`` that lie within ``tol`` of outline ``b``.

    A straight stretch of ``a`` that its outline splits into several edges (a vertex
    on a straight side: a doorway cut from a wall's hole where a room's corner meets
    the hole's face) is one segment, its length counted whole: taken edge by edge, a
    piece of it shorter than ``min_length`` was dropped and the portal stopped short
    of the opening, leaving a strip of it through which rays leave the cell where no
    portal walk follows them.

    Returns
    -------
    list of (2, 2) float64
        Each a segment (start, end) along ``a``'s boundary, at least ``min_length`` long.
    """
    ra = orient_ccw(a)
    pb = shapely.Polygon(orient_ccw(b))
    zone = pb.buffer(tol, join_style="mitre")
    pieces: list[F64] = []
    for k in range(len(ra)):
        seg = shapely.LineString([ra[k], ra[(k + 1) % len(ra)]])
        part = seg.intersection(zone)
        for g in getattr(part, "geoms", [part]):
            if isinstance(g, shapely.LineString) and g.length > 0.0:
                c = np.asarray(g.coords)
                piece = np.array([c[0], c[-1]], dtype=np.float64)
                if pieces and _continues(pieces[-1], piece):
                    pieces[-1] = np.array([pieces[-1][0], piece[1]])
                else:
                    pieces.append(piece)
    if len(pieces) > 1 and _continues(pieces[-1], pieces[0]):  # the stretch through the ring's first vertex
        pieces[0] = np.array([pieces.pop()[0], pieces[0][1]])
    return [p for p in pieces if float(np.hypot(*(p[1] - p[0]))) >= min_length]


#: How far (metres) a piece's end may lie off the line of the piece before it and
#: still continue it: a vertex on a straight side comes from shapely's overlays, on the
#: line to rounding; a tenth of the millimetre to which portals are rounded outward.
_STRAIGHT_M = 1e-4


def _continues(a: F64, b: F64) -> bool:
    """Whether segment ``b`` ``(2, 2)`` starts where ``a`` ends and runs on along its line."""
    d = a[1] - a[0]
    n = float(np.hypot(*d))
    if n == 0.0 or float(np.hypot(*(b[0] - a[1]))) > _STRAIGHT_M:
        return False
    e = b[1] - a[0]
    return abs(float(d[0] * e[1] - d[1] * e[0])) / n <= _STRAIGHT_M and float(d @ (b[1] - b[0])) > 0.0


def cell_planes(outline: ArrayLike, zmin: float, zmax: float) -> F64:
    """The planes of a convex prism: ``(k + 2, 4)`` rows ``nx, ny, nz, d`` with unit
    outward normals; a point ``p`` is inside when ``n . p + d <= 0`` for every row.

    >>> cell_planes([[0, 0], [1, 0], [1, 1], [0, 1]], 0.0, 3.0)[[0, -2, -1]].tolist()
    [[0.0, -1.0, 0.0, 0.0], [0.0, 0.0, -1.0, 0.0], [0.0, 0.0, 1.0, -3.0]]
    """
    return prism_planes(orient_ccw(outline), zmin, zmax)


def clip_polygons(
    poly: NDArray[np.float64], count: NDArray[np.int64], plane: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Clip many convex polygons by one plane, keeping the side ``n . p + d <= 0``.

    Parameters
    ----------
    poly : (n, k, 3) float64
        Vertices in order; rows past ``count`` are padding.
    count : (n,) int
        Vertices of each polygon.
    plane : (4,) float
        ``nx, ny, nz, d``.

    Returns
    -------
    poly : (n, k', 3) float64
    count : (n,) int64
        A polygon clipped away has count 0; winding is kept.
    """
    n, k = poly.shape[:2]
    if n == 0:
        return poly, count
    pl = np.asarray(plane, dtype=np.float64)
    d = poly @ pl[:3] + pl[3]
    idx = np.arange(k)
    cnt = np.maximum(count, 1)
    valid = idx[None, :] < count[:, None]
    nxt = (idx[None, :] + 1) % cnt[:, None]
    rows = np.arange(n)[:, None]
    pn = poly[rows, nxt]
    dn = d[rows, nxt]
    inside = d <= 0.0
    inside_n = dn <= 0.0
    denom = d - dn
    t = np.where(np.abs(denom) > 1e-300, d / np.where(np.abs(denom) > 1e-300, denom, 1.0), 0.0)
    cross = poly + t[..., None] * (pn - poly)
    cand = np.stack([poly, cross], axis=2).reshape(n, 2 * k, 3)
    mask = np.stack([inside & valid, (inside != inside_n) & valid], axis=2).reshape(n, 2 * k)
    new_count = mask.sum(axis=1).astype(np.int64)
    width = max(3, int(new_count.max()))
    order = np.argsort(~mask, axis=1, kind="stable")[:, :width]
    out = np.take_along_axis(cand, order[..., None], axis=1)
    new_count[new_count < 3] = 0
    return out, new_count


def fan_triangles(poly: NDArray[np.float64], count: NDArray[np.int64]) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Triangles ``(t, 3, 3)`` of convex polygons as fans from their first vertex, and
    the polygon each came from ``(t,)``."""
    n, k = poly.shape[:2]
    if n == 0:
        return np.zeros((0, 3, 3)), np.zeros(0, np.int64)
    j = np.arange(1, max(k - 1, 1))
    use = (j[None, :] + 1) < count[:, None]  # (n, k-2)
    src, jj = np.nonzero(use)
    a = poly[src, 0]
    b = poly[src, j[jj]]
    c = poly[src, j[jj] + 1]
    tri = np.stack([a, b, c], axis=1)
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    keep = area > 1e-10
    return tri[keep], src[keep]


def ray_distance(start: ArrayLike, direction: ArrayLike, outline: ArrayLike, reach: float = 1.0) -> float | None:
    """Distance from ``start`` along ``direction`` to the first point of ``outline``'s
    boundary within ``reach`` metres (0 when ``start`` is inside), or None."""
    s = np.asarray(start, dtype=np.float64)
    d = np.asarray(direction, dtype=np.float64)
    d = d / max(float(np.hypot(*d)), _EPS)
    poly = shapely.Polygon(orient_ccw(outline))
    if poly.covers(shapely.Point(s)):
        return 0.0
    hit = shapely.LineString([s, s + d * reach]).intersection(poly)
    if hit.is_empty:
        return None
    pts = [q for g in getattr(hit, "geoms", [hit]) for q in np.asarray(g.coords)]
    return float(min(np.dot(np.asarray(q) - s, d) for q in pts))


def without_holes(geom: shapely.Geometry) -> shapely.Geometry:
    """The polygons of ``geom`` cut into pieces without holes: each polygon with a hole
    is split by a line across its first hole's middle (along the polygon's longer
    side) until none is left.  A room holding a smaller room (a meeting box in an open
    office) keeps the ring around it rather than covering it.

    >>> g = shapely.box(0, 0, 4, 4).difference(shapely.box(1, 1, 2, 2))
    >>> sorted(round(p.area, 1) for p in without_holes(g).geoms)
    [6.0, 9.0]
    """
    out: list[shapely.Polygon] = []
    todo = [g for g in getattr(geom, "geoms", [geom]) if isinstance(g, shapely.Polygon)]
    while todo:
        g = todo.pop()
        if not g.interiors:
            out.append(g)
            continue
        x0, y0, x1, y1 = g.bounds
        c = shapely.Polygon(g.interiors[0]).centroid
        if x1 - x0 >= y1 - y0:
            blade = shapely.box(x0 - 1, y0 - 1, c.x, y1 + 1)
        else:
            blade = shapely.box(x0 - 1, y0 - 1, x1 + 1, c.y)
        for half in (g.intersection(blade), g.difference(blade)):
            todo += [h for h in getattr(half, "geoms", [half]) if isinstance(h, shapely.Polygon) and h.area > 0]
    return shapely.MultiPolygon(out) if out else shapely.Polygon()


def polygon_rings(geom: shapely.Geometry, min_area: float = 1e-3) -> Sequence[F64]:
    """The exterior rings (CCW, ``(n, 2)``) of the polygons in a shapely geometry
    (their holes are dropped; :func:`without_holes` first where they matter)."""
    out = []
    for g in getattr(geom, "geoms", [geom]):
        if isinstance(g, shapely.Polygon) and g.area >= min_area:
            out.append(orient_ccw(np.asarray(g.exterior.coords)[:-1]))
        elif hasattr(g, "geoms"):
            out += list(polygon_rings(g, min_area))
    return out
