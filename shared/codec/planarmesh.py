"""Cell contents as planar polygons, boxes and rectangles on an absolute millimetre grid (``walkstream-cellmesh/3``, /2).

The bake clips every element to the cells it occupies (``server/bake/roomcontents.py``),
so a door frame, a piece of wall or the outside cell arrive as many small coplanar
triangles.  Version 2 of the cell-contents blob sends each part's planar regions as
polygons (with holes) and lets the decoder triangulate them again (earcut), which
takes fewer bytes and gives fewer triangles; what cannot be merged safely stays as
triangles.  This module encodes (and states the layout and the error bound);
:mod:`~walkstream.shared.codec.planardecode` decodes, bounded.

Error bound
-----------
Every position is rounded to an absolute grid of :data:`GRID` = 1 mm in scene-local
metres, ``q = round(p / 0.001)``; the decoder gives ``q * 0.001`` as float32.  Every
decoded vertex is therefore one of the encoded vertices, each coordinate within
**0.5 mm** plus the float32 rounding of the scene-local value (``2**-24 * |p|``, 6 um
at 100 m), and every point of the decoded surface lies within the same bound (per
coordinate) of the encoded surface: a polygon's triangulation covers exactly the
union of its triangles in the plane of the rounded vertices.  Generated scenes are on
a millimetre grid already; the bake's clipping planes (``REACH`` = 6 cm) keep them there
for axis-aligned walls.

Merging (encoder)
-----------------
Per part, triangles are grouped by plane (unit normal to 1e-3, offset to 1 mm).  A
group of two or more triangles becomes polygons when all of these hold, else its
triangles are kept as they are:

* the union (shapely, in the plane's 2D frame, on the already rounded vertices) is a
  polygon or a multipolygon whose every vertex is one of the group's vertices (no new
  intersection points) and whose area is the sum of the triangles' areas (they do not
  overlap);
* the triangulation the decoder will make has that area too (earcut can fail on
  rings that touch themselves) and uses every ring vertex in a triangle with area
  (a vertex left only in flat triangles would be a T-junction);
* it takes no more vertices than the triangles did.

Two triangles sharing an edge become a quadrilateral without a union (most box
faces).  A ring vertex between two collinear edges is dropped only when no other plane group
or kept triangle of the part uses the same point: a vertex another region shares stays,
so no T-junction (and no hairline crack) appears between a part's regions that was not
there before.

Layout
------
One tag byte (``Z`` zlib level 9, ``X`` lzma preset 6, ``N`` none, as version 1),
then the msgpack map::

    {"format": "walkstream-cellmesh/2", "parts": p, "elements": bin, "materials": bin,
     "vertices": bin, "triangles": bin, "regions": bin, "rings": bin, "ring_sizes": bin,
     "positions": bin, "indices": bin}

``elements``, ``materials``, ``vertices``, ``triangles`` and ``indices`` are as in
version 1 (the kept triangles: per-part counts, per-part local indices as zigzag
varint deltas).  ``regions`` is each part's polygon count, ``rings`` each polygon's
ring count (exterior first, then holes), ``ring_sizes`` each ring's vertex count, all
varints.  ``positions`` are the millimetre integers of every part's kept-triangle
vertices followed by its ring vertices, part after part, axis by axis (all x, then all
y, then all z), each as a zigzag varint of the difference to the previous vertex (the
grid is absolute, so the differences run on across parts).  Exteriors wind
counter-clockwise seen from the front of the face; the decoder orients the triangles
it makes by the ring's Newell normal and recomputes flat normals.

Version 3: boxes and axis rectangles
------------------------------------
Generated furniture, window frames and glass are axis-aligned boxes (a window frame is
five overlapping ones), walls and window reveals are boxes with some faces left out
(the bake clips them to cells), and most other regions are rectangles in an axis
plane; as rings they cost 24 and 4 vertices.  Version 3 (:data:`BOXED_FORMAT`) first
takes each part's whole boxes out of its triangles
(:func:`~walkstream.shared.codec.boxmesh.find_boxes`: twelve triangles, two halves of
each face's rectangle, facing out), merges the rest as version 2, and then sends every
single-ring region that is an axis rectangle with axis-parallel edges on its own; two
opposite such rectangles of one part, and those of the same box's other faces, go as
that box with a face mask (:func:`~walkstream.shared.codec.boxmesh.group_rects`).
What is left is version 2.  The map adds, each key only when the blob has any::

    "box_counts": bin, "boxes": bin, "box_faces": bin,
    "rect_counts": bin, "rect_kinds": bin, "rects": bin

``box_counts`` and ``rect_counts`` are per-part varints; ``boxes`` six zigzag varints a
box, box after box: the step from the previous box's low corner (running across
parts), then its size (> 0); ``box_faces`` a byte a box, bits 0 to 5 its faces (-x, +x,
-y, +y, -z, +z; at least one), bit 6 that they face into the box; ``rect_kinds`` a
byte a rectangle, ``2 * axis + (1 if it faces +axis)``; ``rects`` five zigzag varints a
rectangle, field by field (all x steps of the low corners, then y, z, then the extents
along the two other axes in increasing order; extents > 0).  Within a part boxes and
rectangles are sorted by low corner (small, alike steps).  The decoder appends to each
part its rectangles and then its boxes' faces, four vertices and two triangles each
(no vertex shared between faces, so the normals stay flat).  Same error bound: every
corner is an encoded grid point; every rectangle is one the triangles covered, so the
surface is the same.  A box's corners count as used by another plane when merging
the part's other regions, so no ring drops a vertex a box has (no T-junction).  On the
generated office (``--preset paper``) this takes the 21 cells the tour starts with
from 13.2 kB to 8.2 kB as one gzip stream (as ``POST .../rooms/contents`` sends them),
and the whole building from 53.9 to 26.1 kB.

Version 4: welded triangles
---------------------------
The triangles that stay triangles are mostly curved surfaces (a stair's nosing and
handrail, a round window's frame), which exporters write with every corner repeated on
every face: on FZK-Haus the stair's 2,146 triangles come with 5,816 corners on 1,136 grid
points.  Version 4 (:data:`WELDED_FORMAT`) gives each part's kept triangles one vertex
per grid point, and sends their indices as **high-water codes** (``keptindices``) over all parts at once
(every part's vertices follow the previous part's, in the order its triangles first use
them): 0 for the next vertex not used before, else ``h + 1 - i`` with ``h`` the highest
index used so far; a part's kept triangles go breadth first across shared edges when
that takes fewer varint bytes than their own order (the duplex's kitchen, its wall cabinets: 9.5 to
5.2 kB).  The decoder gives each kept triangle its own three corners again, so
the normals it recomputes stay flat, as before.  Nothing moves on the grid, so the error
bound is the same.  FZK-Haus's living room (its stair) goes from 14.9 to 8.4 kB, the
contents its tour downloads from 52.6 to 38.2 kB, the duplex's from 80.9 to 67.3 kB.
The map has the keys of version 3.
"""

from __future__ import annotations

from typing import Any

import mapbox_earcut
import numpy as np
import shapely
from numpy.typing import ArrayLike, NDArray
from shapely.geometry.polygon import orient

from walkstream.shared.codec.boxmesh import (
    Rect,
    box_corners,
    find_boxes,
    group_rects,
    rect_of,
    rect_pairs,
    rect_ring,
)
from walkstream.shared.codec.keptindices import (
    by_neighbours,
    coded_size,
    high_water_codes,
)
from walkstream.shared.codec.varint import (
    encode_varints,
    zigzag,
)
from walkstream.shared.errors import CodecError

__all__ = [
    "PLANAR_FORMAT",
    "BOXED_FORMAT",
    "WELDED_FORMAT",
    "GRID",
    "MAX_Q",
    "grid_error",
    "mesh_area",
    "area_tolerance",
    "encode_planar_body",
    "triangulate_region",
]

PLANAR_FORMAT = "walkstream-cellmesh/2"
"""The format tag of version 2 blobs."""
BOXED_FORMAT = "walkstream-cellmesh/3"
"""The format tag of version 3 blobs (version 2 plus boxes and axis rectangles)."""
WELDED_FORMAT = "walkstream-cellmesh/4"
"""The format tag of version 4 blobs (version 3 with each part's kept triangles sharing
their grid points; the decoder splits them again, so the normals stay flat)."""
GRID = 0.001
"""Metres per grid step (positions are ``q * GRID``, ``q`` integer)."""

MAX_Q = 1 << 40  # 1.1e9 m: far beyond any scene, small enough for exact float64 products
"""The grid's range: every millimetre integer (and every step between two) is below it in size."""

Rings = list[NDArray[np.int64]]
"""A polygon: its rings of ``(k, 3)`` millimetre integers, exterior first."""


def grid_error(positions: ArrayLike) -> float:
    """Largest coordinate error (metres) of ``positions (n, 3)`` after the 1 mm grid and float32."""
    p = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    if len(p) == 0:
        return 0.0
    back = (np.rint(p / GRID) * GRID).astype(np.float32).astype(np.float64)
    return float(np.abs(back - p).max())


def mesh_area(positions: ArrayLike, indices: ArrayLike) -> float:
    """Summed area (m^2) of triangles ``indices (m, 3)`` over ``positions (n, 3)``."""
    p = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    t = np.asarray(indices, dtype=np.int64).reshape(-1, 3)
    if len(t) == 0:
        return 0.0
    a, b, c = p[t[:, 0]], p[t[:, 1]], p[t[:, 2]]
    return float(0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1).sum())


def area_tolerance(positions: ArrayLike, indices: ArrayLike) -> float:
    """How much the grid may change the area of a mesh (m^2): every edge moves by at most
    half a grid step diagonal (``sqrt(3) / 2`` mm) across itself, so the summed edge
    length times one grid step bounds it (plus float32 rounding)."""
    p = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    t = np.asarray(indices, dtype=np.int64).reshape(-1, 3)
    if len(t) == 0:
        return 1e-9
    c = p[t]
    edges = np.linalg.norm(c - np.roll(c, -1, axis=1), axis=2).sum()
    return float(edges * GRID + 1e-6 * mesh_area(p, t) + 1e-9)


def _newell(ring: NDArray[Any]) -> NDArray[np.float64]:
    """``(3,)`` area vector (Newell) of a ring ``(k, 3)``: twice the area along its normal."""
    r = np.asarray(ring, dtype=np.float64)
    r = r - r[0]
    x, y, z = r[:, 0], r[:, 1], r[:, 2]
    x1, y1, z1 = np.append(x[1:], x[0]), np.append(y[1:], y[0]), np.append(z[1:], z[0])
    # written out: np.cross costs more than the ring on the small rings most regions have
    return np.array([(y * z1 - z * y1).sum(), (z * x1 - x * z1).sum(), (x * y1 - y * x1).sum()])


_CYCLIC = ((1, 2), (2, 0), (0, 1))  # the kept axes when axis k is dropped, so that (a x b)_k > 0


def triangulate_region(rings: Rings) -> NDArray[np.int64]:
    """Triangulate one polygon given as 3D rings (exterior first).

    The rings are projected onto the axis plane their normal is closest to; earcut
    triangulates them there, and every triangle is wound like the exterior.

    Parameters
    ----------
    rings : list of (k, 3) int
        Millimetre integers; the exterior counter-clockwise seen from the front.

    Returns
    -------
    (t, 3) int64
        Indices into the rings' concatenated vertices; triangles of zero area dropped.
    """
    n = _newell(rings[0])
    k = int(np.argmax(np.abs(n)))
    a, b = _CYCLIC[k]
    verts = np.concatenate(rings)
    local = (verts[:, (a, b)] - verts[0, (a, b)]).astype(np.int64)
    if len(rings) == 1 and len(local) == 3:
        idx = np.array([[0, 1, 2]], np.int64)
    else:
        ends = np.cumsum([len(r) for r in rings]).astype(np.uint32)
        idx = np.asarray(mapbox_earcut.triangulate_int64(local, ends), dtype=np.int64).reshape(-1, 3)
    if len(idx) == 0:
        return idx
    p, q, r = local[idx[:, 0]], local[idx[:, 1]], local[idx[:, 2]]
    cross = (q[:, 0] - p[:, 0]) * (r[:, 1] - p[:, 1]) - (q[:, 1] - p[:, 1]) * (r[:, 0] - p[:, 0])
    idx = idx[cross != 0]
    flip = (cross[cross != 0] > 0) != (n[k] > 0)
    idx[flip] = idx[flip][:, ::-1]
    return idx


def _area3(q: NDArray[np.int64], t: NDArray[np.int64]) -> float:
    """Summed area of triangles ``t`` over integer points ``q`` (square grid steps)."""
    if len(t) == 0:
        return 0.0
    p = q.astype(np.float64)
    return 0.5 * float(np.sqrt((_cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]]) ** 2).sum(axis=1)).sum())


def _cross(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """Row-wise cross product of ``(n, 3)`` arrays (np.cross's overhead dominates on small ones)."""
    return np.column_stack(
        [a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1], a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2], a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]]
    )


def _frame(n: NDArray[np.float64]) -> NDArray[np.float64]:
    """``(3, 2)`` an orthonormal ``u, v`` of the plane with normal ``n``, ``u x v = n``."""
    axis = np.eye(3)[int(np.argmin(np.abs(n)))]
    u = _cross(axis[None], n[None])[0]
    u /= np.linalg.norm(u)
    v = _cross(n[None], u[None])[0]
    return np.column_stack([u, v])


def _drop_collinear(ring: NDArray[np.int64], keep: set[tuple[int, int, int]]) -> NDArray[np.int64]:
    """``ring`` without the vertices between two collinear edges that no one else uses
    (exact: integer cross products)."""
    pts = [tuple(p) for p in ring.tolist()]
    n = len(pts)
    out: list[tuple[int, ...]] = []
    for i in range(n):
        cur = pts[i]
        if cur in keep:
            out.append(cur)
            continue
        prev = out[-1] if out else pts[i - 1]
        nxt = pts[(i + 1) % n]
        d0 = (cur[0] - prev[0], cur[1] - prev[1], cur[2] - prev[2])
        d1 = (nxt[0] - cur[0], nxt[1] - cur[1], nxt[2] - cur[2])
        straight = (
            d0[1] * d1[2] == d0[2] * d1[1]
            and d0[2] * d1[0] == d0[0] * d1[2]
            and d0[0] * d1[1] == d0[1] * d1[0]
            and d0[0] * d1[0] + d0[1] * d1[1] + d0[2] * d1[2] > 0
        )
        if not straight:
            out.append(cur)
    if len(out) < 3:
        return ring
    return np.array(out, dtype=np.int64)


def _merge_group(
    q: NDArray[np.int64], tri: NDArray[np.int64], normal: NDArray[np.float64], shared: set[tuple[int, int, int]]
) -> list[Rings] | None:
    """The polygons of one plane group's triangles, or ``None`` where merging is unsafe or no smaller."""
    frame = _frame(normal)
    corners = q[tri]  # (m, 3, 3)
    xy = corners.astype(np.float64) @ frame  # (m, 3, 2)
    lookup: dict[tuple[float, float], list[int]] = {}
    for p2, p3 in zip(xy.reshape(-1, 2).tolist(), corners.reshape(-1, 3).tolist(), strict=True):
        lookup.setdefault((p2[0], p2[1]), p3)
    area2 = 0.5 * np.abs(
        (xy[:, 1, 0] - xy[:, 0, 0]) * (xy[:, 2, 1] - xy[:, 0, 1]) - (xy[:, 1, 1] - xy[:, 0, 1]) * (xy[:, 2, 0] - xy[:, 0, 0])
    ).sum()
    union = shapely.union_all(shapely.polygons(xy))
    polys = list(getattr(union, "geoms", [union]))
    if not union.is_valid or any(p.geom_type != "Polygon" for p in polys):
        return None
    if abs(union.area - area2) > 1e-6 * max(area2, 1.0):
        return None
    out: list[Rings] = []
    for poly in polys:
        poly = orient(poly, 1.0)
        rings: Rings = []
        for ring in [poly.exterior, *poly.interiors]:
            pts: list[list[int]] = []
            for x, y in list(ring.coords)[:-1]:
                hit = lookup.get((x, y))
                if hit is None:
                    return None  # a new intersection point: not a clean union of the triangles
                pts.append(hit)
            rings.append(_drop_collinear(np.array(pts, dtype=np.int64), shared))
        if len(rings) > 1 or len(rings[0]) > 4:  # the decoder splits triangles and quads itself
            tris = triangulate_region(rings)
            if abs(_area3(np.concatenate(rings), tris) - poly.area) > 1e-6 * max(poly.area, 1.0):
                return None
            # a vertex earcut leaves in flat triangles only would be a T-junction with the
            # region that shares it: keep the triangles instead
            if len(np.unique(tris)) < sum(len(r) for r in rings):
                return None
        out.append(rings)
    if sum(len(r) for rings in out for r in rings) > len(np.unique(tri)):
        return None
    return out


def _quad(a: list[list[int]], b: list[list[int]]) -> NDArray[np.int64] | None:
    """The ring of two coplanar triangles (corner lists, same winding) that share an edge
    ``u -> v`` in ``a`` and ``v -> u`` in ``b``: ``v, w, u, x`` (``w``, ``x`` their third
    corners), or ``None`` when they share no such edge."""
    for k in range(3):
        u, v, w = a[k], a[(k + 1) % 3], a[(k + 2) % 3]
        for m in range(3):
            if b[m] == v and b[(m + 1) % 3] == u:
                return np.array([v, w, u, b[(m + 2) % 3]], dtype=np.int64)
    return None


def _encode_part(
    positions: NDArray[np.float64], indices: NDArray[np.int64], boxes: bool = False, weld: bool = False
) -> tuple[NDArray[np.int64], NDArray[np.int64], list[Rings], NDArray[np.int64]]:
    """One part: ``(kept vertices (n, 3) mm ints, kept triangles (m, 3), polygons, boxes (k, 6))``;
    boxes (``lo, hi`` mm ints, :func:`_find_boxes`) only when ``boxes``; with ``weld`` the
    kept triangles share every grid point they have in common (version 4)."""
    q = np.rint(positions / GRID).astype(np.int64)
    t = indices
    found = np.zeros((0, 6), np.int64)
    if boxes:
        found, in_box = find_boxes(q, t)
        t = t[~in_box]
    cq = q[t].astype(np.float64)
    cross = np.cross(cq[:, 1] - cq[:, 0], cq[:, 2] - cq[:, 0])
    norm = np.linalg.norm(cross, axis=1)
    live = norm > 0  # triangles that collapse on the grid have no area to draw
    t, cross, norm = t[live], cross[live], norm[live]
    if len(t) == 0:
        return np.zeros((0, 3), np.int64), np.zeros((0, 3), np.int64), [], found
    # group by the plane of the original (unrounded) triangle
    c = positions[t]
    n = np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    d = np.einsum("ij,ij->i", n, c.mean(axis=1))
    key = np.column_stack([np.rint(n * 1000), np.rint(d / GRID)]).astype(np.int64)
    _, group, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    group = group.reshape(-1)
    # how many plane groups use each grid point: a point of two groups is shared
    gp = np.unique(np.column_stack([np.repeat(group, 3), q[t].reshape(-1, 3)]), axis=0)
    pts, uses = np.unique(gp[:, 1:], axis=0, return_counts=True)
    shared: set[tuple[int, int, int]] = {(int(a), int(b), int(c)) for a, b, c in pts[uses > 1].tolist()}
    # a box's corners are on other planes too: a ring must keep them (no T-junction at a box)
    shared.update((int(a), int(b), int(c)) for a, b, c in box_corners(found).tolist())
    kept = np.ones(len(t), bool)
    polys: list[Rings] = []
    # two triangles of one plane sharing an edge (a box's face): a quadrilateral, no union needed
    pairs = np.flatnonzero(counts == 2)
    if len(pairs):
        order = np.argsort(group, kind="stable")
        first = np.searchsorted(group[order], pairs)
        for i, j in zip(order[first].tolist(), order[first + 1].tolist(), strict=True):
            ring = _quad(q[t[i]].tolist(), q[t[j]].tolist())
            if ring is not None:
                polys.append([ring])
                kept[i] = kept[j] = False
        counts = counts.copy()
        counts[pairs] = 0
    for g in np.flatnonzero(counts >= 2):
        members = np.flatnonzero(group == g)
        nn = n[members].mean(axis=0)
        merged = _merge_group(q, t[members], nn / np.linalg.norm(nn), shared)
        if merged is not None:
            polys.extend(merged)
            kept[members] = False
    if boxes and kept.sum() >= 2:
        # what could not merge (overlapping rectangles: a clipped window frame) may still
        # pair into rectangles, which version 3 sends as five numbers or box faces
        rest = np.flatnonzero(kept)
        for rect_key, (i, j) in rect_pairs(q, t[rest]).items():
            polys.append([rect_ring(rect_key)])
            kept[rest[[i, j]]] = False
    kt = t[kept]
    if weld and len(kt):
        # one vertex per grid point: a curved surface (a stair's nosing, a round window's
        # frame) keeps its triangles, whose corners the bake duplicated plane by plane
        _, point = np.unique(q[kt.reshape(-1)], axis=0, return_inverse=True)
        point = point.reshape(-1)
        rep = np.zeros(int(point.max()) + 1, np.int64)
        rep[point] = kt.reshape(-1)  # any original vertex at that grid point stands for it
        kt = rep[point].reshape(-1, 3)
        bfs = by_neighbours(kt)
        if coded_size(q, bfs) < coded_size(q, kt):
            kt = bfs
    used, first = np.unique(kt.reshape(-1), return_index=True)
    order = used[np.argsort(first)]  # vertices in the order they first appear
    remap = np.full(len(q), -1, np.int64)
    remap[order] = np.arange(len(order))
    return q[order], remap[kt], polys, found


def encode_planar_body(
    parts: list[tuple[int, int, NDArray[np.float64], NDArray[np.int64]]], version: int = 3
) -> dict[str, Any]:
    """The msgpack map of a version 3 blob (or version 2; see the module docstring).

    Parameters
    ----------
    parts:
        ``(element, material, positions (n, 3) float64, indices (m, 3) int64)``, checked
        by the caller (finite, in range, non-empty).
    version:
        3 (:data:`BOXED_FORMAT`: boxes and axis rectangles in their own fields) or 2
        (:data:`PLANAR_FORMAT`).

    Raises
    ------
    CodecError
        A position beyond the grid's range.
    """
    vcount, tcount, rcount = [], [], []
    ring_counts: list[int] = []
    ring_sizes: list[int] = []
    qs: list[NDArray[np.int64]] = []
    idx: list[NDArray[np.int64]] = []
    box_counts, rect_counts, rect_kinds = [], [], []
    boxes: list[tuple[int, ...]] = []
    rects: list[tuple[int, ...]] = []
    for k, (element, _m, p, t) in enumerate(parts):
        if np.abs(p).max(initial=0.0) / GRID >= MAX_Q:
            raise CodecError(f"cell mesh part {k} (element {element}): positions beyond {MAX_Q * GRID:.0f} m")
        kq, kt, polys, found = _encode_part(p, t, boxes=version >= 3, weld=version == 4)
        if version >= 3:
            kept = []
            mine: list[Rect] = []
            for rings in polys:
                rect = rect_of(rings[0]) if len(rings) == 1 else None
                if rect is None:
                    kept.append(rings)
                else:
                    mine.append((rect[0], *rect[1].tolist(), rect[2], rect[3]))
            # by low corner (then kind), so that the steps between them get small and alike
            mine.sort(key=lambda r: (r[1], r[2], r[3], r[0]))
            grouped, mine = group_rects(mine)
            part_boxes = sorted([(*b, 63) for b in found.tolist()] + grouped)
            box_counts.append(len(part_boxes))
            boxes.extend(part_boxes)
            for rect_row in mine:
                rect_kinds.append(rect_row[0])
                rects.append(rect_row[1:])
            rect_counts.append(len(mine))
            polys = kept
        vcount.append(len(kq))
        tcount.append(len(kt))
        rcount.append(len(polys))
        qs.append(kq)
        idx.append(kt.reshape(-1))
        for rings in polys:
            ring_counts.append(len(rings))
            for r in rings:
                ring_sizes.append(len(r))
                qs.append(r)
    allq = np.concatenate(qs) if qs else np.zeros((0, 3), np.int64)
    dq = np.diff(allq, axis=0, prepend=np.zeros((1, 3), np.int64))
    istarts = np.concatenate([[0], np.cumsum(np.asarray(tcount, np.int64) * 3)[:-1]]).astype(np.int64)
    alli = np.concatenate(idx) if idx else np.zeros(0, np.int64)
    di = np.diff(alli, prepend=0)
    live = istarts[istarts < len(alli)]
    di[live] = alli[live]
    eid = np.asarray([p[0] for p in parts], dtype=np.int64)
    body = {
        "format": PLANAR_FORMAT,
        "parts": len(parts),
        "elements": encode_varints(zigzag(np.diff(eid, prepend=0))),
        "materials": bytes(np.asarray([p[1] for p in parts], dtype=np.uint8)),
        "vertices": encode_varints(np.asarray(vcount, np.uint64)),
        "triangles": encode_varints(np.asarray(tcount, np.uint64)),
        "regions": encode_varints(np.asarray(rcount, np.uint64)),
        "rings": encode_varints(np.asarray(ring_counts, np.uint64)),
        "ring_sizes": encode_varints(np.asarray(ring_sizes, np.uint64)),
        "positions": encode_varints(zigzag(dq.T.reshape(-1))),
        "indices": encode_varints(zigzag(di)),
    }
    if version == 4:
        body["indices"] = encode_varints(high_water_codes(idx, vcount, tcount))
    if version >= 3:
        bx = np.asarray(boxes, np.int64).reshape(-1, 7)
        blo = np.diff(bx[:, :3], axis=0, prepend=np.zeros((1, 3), np.int64))
        rc = np.asarray(rects, np.int64).reshape(-1, 5)
        rlo = np.diff(rc[:, :3], axis=0, prepend=np.zeros((1, 3), np.int64))
        body["format"] = WELDED_FORMAT if version == 4 else BOXED_FORMAT
        # absent when empty: a small cell pays no bytes for what it lacks
        if len(bx):
            body["box_counts"] = encode_varints(np.asarray(box_counts, np.uint64))
            # box after box (its corner's step, then its size): a box repeated is one long match
            body["boxes"] = encode_varints(zigzag(np.column_stack([blo, bx[:, 3:6] - bx[:, :3]]).reshape(-1)))
            body["box_faces"] = bytes(bx[:, 6].astype(np.uint8))
        if len(rc):
            body["rect_counts"] = encode_varints(np.asarray(rect_counts, np.uint64))
            body["rect_kinds"] = bytes(np.asarray(rect_kinds, np.uint8))
            # field by field, as the positions
            body["rects"] = encode_varints(zigzag(np.column_stack([rlo, rc[:, 3:]]).T.reshape(-1)))
    return body
