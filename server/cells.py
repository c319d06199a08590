"""View cells: the regions of the navigation space that each get one baked PVS.

Two kinds of cell partition are supported (DESIGN.md, "View cells"):

Street cells (Marvie et al. 2003, section 2)
    The navigation space of a city with street data, i.e. the union of its street
    pieces, crossroads and squares, is cut into convex cells.  Every crossroad is one
    cell; every street piece is cut across its length into pieces no longer than
    ``max_length`` (measured along the piece's long axis) so that the potentially
    visible set of a cell stays small; every square is decomposed into convex parts,
    and each part is cut along both of its axes into pieces of about ``max_length``.
    Overlapping source polygons (e.g. street lines buffered by the GeoJSON loader
    that cross each other) are made disjoint first: crossroads win over squares,
    squares over street pieces, lower ids over higher ones.

Grid cells (m-LOMA)
    Without street data the free space is covered by a regular grid of squares; a
    square is kept when at least ``min_free`` of it is not covered by building
    footprints.  Neighbours are the 4-connected kept squares.

Every cell is a convex, counter-clockwise polygon in scene-local metres with a height
range (eye heights above the flat ground).  Cell ids are the cells' positions in the
returned list; they are deterministic: cells are ordered by kind (crossroad, street,
square, grid) and then by centroid (y, then x, rounded to a millimetre).

:func:`cell_locator` maps viewer positions to cell ids; :func:`viewpoints` picks a
few start positions spread over the scene.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import shapely
from numpy.typing import NDArray

from walkstream.server.sources.scene import SourceScene
from walkstream.shared.cells import CELL_KINDS, CellLocator, outline_polygons
from walkstream.shared.errors import InputError
from walkstream.shared.records import Viewpoint, readonly

__all__ = [
    "MIN_SHARED_EDGE",
    "ViewCell",
    "Viewpoint",
    "cell_locator",
    "cell_polygons",
    "grid_cells",
    "make_cells",
    "street_cells",
    "viewpoints",
]

F64 = NDArray[np.float64]

#: Cell kinds in id order.
#: Two cells are neighbours when their boundaries share more than this many metres.
MIN_SHARED_EDGE = 0.5
#: Points this close (metres) to a cell count as inside it.

# Source polygons overlapping by less than this (m^2) are rounding noise, not overlap.
_OVERLAP_EPS = 1e-6
# Parts smaller than this (m^2) left over by cutting or overlap removal are dropped.
_SLIVER_AREA = 1e-3
# Vertices closer than this (metres) are merged; a vertex this close to the line
# through its neighbours is collinear and dropped.
_VERTEX_EPS = 1e-9
# Rays for the viewpoint directions stop after this many metres.
_VIEW_RAY = 400.0
_PRIORITY = {"crossroad": 0, "square": 1, "street": 2}


# --------------------------------------------------------------------------- records


@dataclass(frozen=True, slots=True)
class ViewCell:
    """One view cell.

    Attributes
    ----------
    id:
        Cell id, its index in the list the cell came in (non-negative).
    kind:
        ``"street"``, ``"crossroad"``, ``"square"`` or ``"grid"``.
    polygon:
        ``(n, 2) float64`` convex outline, counter-clockwise, scene-local metres, no
        repeated closing vertex; read-only.
    zmin, zmax:
        Range of eye heights (metres above the ground) the cell's PVS is valid for.
    neighbours:
        Ids of the adjacent cells, ascending.
    """

    id: int
    kind: str
    polygon: F64
    zmin: float
    zmax: float
    neighbours: tuple[int, ...]

    def __post_init__(self) -> None:
        if self.kind not in CELL_KINDS:
            raise InputError(f"ViewCell.kind: expected one of {CELL_KINDS}, got {self.kind!r}")
        poly = np.asarray(self.polygon, dtype=np.float64).reshape(-1, 2)
        if len(poly) < 3:
            raise InputError(f"ViewCell.polygon: expected >= 3 vertices, got {len(poly)}")
        if not float(self.zmin) <= float(self.zmax):
            raise InputError(f"ViewCell: zmin {self.zmin} > zmax {self.zmax}")
        object.__setattr__(self, "id", int(self.id))
        object.__setattr__(self, "polygon", readonly(poly))
        object.__setattr__(self, "zmin", float(self.zmin))
        object.__setattr__(self, "zmax", float(self.zmax))
        object.__setattr__(self, "neighbours", tuple(sorted(int(n) for n in self.neighbours)))

    @property
    def centroid(self) -> tuple[float, float]:
        """Area centroid ``(x, y)`` of the polygon (inside it: the cell is convex)."""
        return _centroid(self.polygon)

    @property
    def area(self) -> float:
        """Area in square metres."""
        return _signed_area(self.polygon)




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
    max_length = _positive("max_length", max_length)
    zmin, zmax = _height_range(height_range)
    if not zmin <= float(eye_height) <= zmax:
        raise InputError(f"eye_height {eye_height} m is outside height_range ({zmin}, {zmax})")
    if not scene.streets:
        raise InputError(
            f"scene {scene.name!r} has no street pieces, crossroads or squares: street cells "
            "need street data (use grid cells instead)"
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
    parts = [(k, p) for k, p in parts if _signed_area(p) >= _SLIVER_AREA]
    return _finish(parts, zmin, zmax)


def grid_cells(
    scene: SourceScene,
    *,
    cell_size: float = 40.0,
    height_range: tuple[float, float] = (1.5, 2.0),
    min_free: float = 0.15,
    bbox: tuple[float, float, float, float] | None = None,
) -> list[ViewCell]:
    """Cover the free space with a regular grid of square cells (m-LOMA).

    The grid starts at the bbox's lower-left corner and has ``ceil(width / cell_size)``
    by ``ceil(height / cell_size)`` squares (the last row and column may reach past
    the bbox).  A square is kept when the part of it not covered by building
    footprints is at least ``min_free`` of its area (footprint overlaps, which real
    data has a few of, are counted twice: negligible, and it keeps this vectorised).

    Parameters
    ----------
    scene:
        The scene; its buildings are the obstacles.
    cell_size:
        Side of a grid square in metres.
    height_range:
        ``(zmin, zmax)`` eye heights the cells' PVSs are baked for.
    min_free:
        Smallest free share of a kept square, in ``[0, 1]``.
    bbox:
        ``(xmin, ymin, xmax, ymax)`` in scene-local metres; default the bounding box
        of the building footprints (of the streets when there are no buildings).

    Returns
    -------
    list[ViewCell]
        Kind ``"grid"`` cells ordered by row (south to north) then column (west to
        east); neighbours are the kept squares sharing an edge.

    Raises
    ------
    InputError
        If a parameter is out of range, or the scene is empty and no bbox is given.
    """
    cell_size = _positive("cell_size", cell_size)
    zmin, zmax = _height_range(height_range)
    if not 0.0 <= float(min_free) <= 1.0:
        raise InputError(f"min_free must lie in [0, 1], got {min_free}")
    x0, y0, x1, y1 = _grid_bbox(scene, bbox)
    nx = max(1, math.ceil((x1 - x0) / cell_size - 1e-9))
    ny = max(1, math.ceil((y1 - y0) / cell_size - 1e-9))
    if nx * ny > 4_000_000:
        raise InputError(
            f"grid of {nx} x {ny} cells is too large; use a larger cell_size or a smaller bbox"
        )
    col_grid, row_grid = np.meshgrid(np.arange(nx), np.arange(ny))  # row-major: y then x
    cols, rows = col_grid.ravel(), row_grid.ravel()
    bx0 = x0 + cols * cell_size
    by0 = y0 + rows * cell_size
    boxes = shapely.box(bx0, by0, bx0 + cell_size, by0 + cell_size)
    free = _free_share(boxes, _footprints(scene))
    keep = free >= float(min_free) - 1e-12

    # id of each kept square by (row, col); -1 where dropped
    ids = np.full((ny + 2, nx + 2), -1, np.int64)  # padded so neighbours never wrap
    ids[rows[keep] + 1, cols[keep] + 1] = np.arange(int(keep.sum()))
    cells = []
    for cid, (r, c, xa, ya) in enumerate(
        zip(rows[keep], cols[keep], bx0[keep], by0[keep], strict=True)
    ):
        nb = ids[[r, r + 1, r + 1, r + 2], [c + 1, c, c + 2, c + 1]]
        xb, yb = xa + cell_size, ya + cell_size
        cells.append(
            ViewCell(
                id=cid,
                kind="grid",
                polygon=np.array([[xa, ya], [xb, ya], [xb, yb], [xa, yb]]),
                zmin=zmin,
                zmax=zmax,
                neighbours=tuple(int(n) for n in nb[nb >= 0]),
            )
        )
    return cells


def make_cells(
    scene: SourceScene,
    mode: str = "auto",
    *,
    max_length: float = 40.0,
    cell_size: float = 40.0,
    eye_height: float = 1.7,
    height_range: tuple[float, float] = (1.5, 2.0),
    min_free: float = 0.15,
    bbox: tuple[float, float, float, float] | None = None,
) -> list[ViewCell]:
    """View cells of a scene: street cells or grid cells.

    Parameters
    ----------
    scene:
        The scene.
    mode:
        ``"street"`` (:func:`street_cells`), ``"grid"`` (:func:`grid_cells`) or
        ``"auto"``: street cells when the scene has street pieces, else grid cells.
    max_length, eye_height:
        Passed to :func:`street_cells`.
    cell_size, min_free, bbox:
        Passed to :func:`grid_cells`.
    height_range:
        Passed to both.

    Raises
    ------
    InputError
        For an unknown mode, ``"street"`` on a scene without street data, or a
        parameter out of range.
    """
    if mode not in ("auto", "street", "grid"):
        raise InputError(f"cell mode must be 'auto', 'street' or 'grid', got {mode!r}")
    if mode == "street" or (mode == "auto" and scene.streets):
        return street_cells(
            scene, max_length=max_length, eye_height=eye_height, height_range=height_range
        )
    return grid_cells(
        scene, cell_size=cell_size, height_range=height_range, min_free=min_free, bbox=bbox
    )


def cell_polygons(cells: Sequence[ViewCell]) -> NDArray[np.object_]:
    """The cells' outlines as a ``(n,)`` array of shapely Polygons (index = position)."""
    return outline_polygons([c.polygon for c in cells])


def cell_locator(cells: Sequence[ViewCell]) -> CellLocator:
    """A :class:`~walkstream.shared.cells.CellLocator` over the cells (ids as given)."""
    return CellLocator([c.id for c in cells], [c.polygon for c in cells])




def viewpoints(
    cells: Sequence[ViewCell],
    scene: SourceScene,
    count: int = 4,
    *,
    eye_height: float = 1.7,
) -> list[Viewpoint]:
    """A few start viewpoints spread over the scene.

    Street cells: the centres of crossroad cells (those with four or more
    neighbours when there are enough; all cells when there are no crossroads), picked by farthest-point sampling from the one nearest the middle; each looks
    towards the adjacent street or square cell with the longest free sight line,
    i.e. along a street.  Grid cells: free space in cells that are almost unbuilt and
    have four neighbours (all cells if too few), looking in the one of 16 directions
    with the longest free sight line.

    Parameters
    ----------
    cells:
        The scene's cells (street or grid).
    scene:
        The scene (its buildings block sight lines).
    count:
        Number of viewpoints wanted; fewer are returned when there are fewer
        candidate cells.
    eye_height:
        Eye height; clamped into each cell's height range.

    Returns
    -------
    list[Viewpoint]
        Named ``"start<k>-<kind><cell id>"``; ``cell`` is the id of the cell containing
        the position.

    Raises
    ------
    InputError
        If ``cells`` is empty or ``count < 1``.
    """
    if not cells:
        raise InputError("viewpoints need at least one cell")
    if int(count) < 1:
        raise InputError(f"viewpoint count must be >= 1, got {count}")
    by_id = {c.id: c for c in cells}
    footprints = _footprints(scene)
    tree = shapely.STRtree(footprints)
    grid = all(c.kind == "grid" for c in cells)

    if grid:
        boxes = cell_polygons(cells)
        free = _free_share(boxes, footprints)
        cand = [c for c, f in zip(cells, free, strict=True) if f >= 0.95 and len(c.neighbours) == 4]
        if len(cand) < count:
            cand = list(cells)
    else:
        cand = [c for c in cells if c.kind == "crossroad"] or list(cells)
        # crossroads met by four or more cells lie inside the city: better views than
        # corners and T-junctions on the border, which look out at empty land
        inner = [c for c in cand if len(c.neighbours) >= 4]
        if len(inner) >= count:
            cand = inner
    cand.sort(key=lambda c: c.id)
    centres = np.array([c.centroid for c in cand])
    chosen = _spread(centres, int(count))

    out = []
    for k, i in enumerate(chosen):
        cell = cand[i]
        if grid:
            x, y = _free_point(cell, footprints, tree)
            angles = np.arange(16) * (2 * math.pi / 16)
            dirs = np.stack([np.cos(angles), np.sin(angles)], axis=1)
        else:
            x, y = cell.centroid
            targets = [
                by_id[n] for n in cell.neighbours if n in by_id and by_id[n].kind != "crossroad"
            ]
            if not targets:
                targets = [by_id[n] for n in cell.neighbours if n in by_id]
            if targets:
                dirs = np.array([t.centroid for t in targets]) - (x, y)
                dirs /= np.maximum(np.linalg.norm(dirs, axis=1, keepdims=True), 1e-12)
            else:
                angles = np.arange(8) * (2 * math.pi / 8)
                dirs = np.stack([np.cos(angles), np.sin(angles)], axis=1)
        free_len = _ray_lengths((x, y), dirs, footprints, tree)
        d = dirs[int(np.argmax(free_len))]  # first of the longest: deterministic
        z = min(max(float(eye_height), cell.zmin), cell.zmax)
        yaw = math.atan2(float(d[1]), float(d[0]))
        out.append(Viewpoint(f"start{k}-{cell.kind}{cell.id}", float(x), float(y), z, yaw, cell.id))
    return out


# --------------------------------------------------------------------------- helpers


def _positive(name: str, value: float) -> float:
    v = float(value)
    if not (math.isfinite(v) and v > 0):
        raise InputError(f"{name} must be a positive number of metres, got {value}")
    return v


def _height_range(height_range: tuple[float, float]) -> tuple[float, float]:
    try:
        zmin, zmax = (float(z) for z in height_range)
    except (TypeError, ValueError) as exc:
        raise InputError(f"height_range must be (zmin, zmax), got {height_range!r}") from exc
    if not (math.isfinite(zmin) and math.isfinite(zmax) and 0 <= zmin <= zmax):
        raise InputError(f"height_range must satisfy 0 <= zmin <= zmax, got {height_range!r}")
    return zmin, zmax


def _signed_area(ring: F64) -> float:
    x, y = (ring - ring[0]).T
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def _centroid(ring: F64) -> tuple[float, float]:
    # relative to the first vertex: keeps precision far from the origin
    o = ring[0]
    p = ring - o
    q = np.roll(p, -1, axis=0)
    cr = p[:, 0] * q[:, 1] - q[:, 0] * p[:, 1]
    a = cr.sum()
    if abs(a) < 1e-15:
        c = p.mean(axis=0)
    else:
        c = ((p + q) * cr[:, None]).sum(axis=0) / (3.0 * a)
    return float(c[0] + o[0]), float(c[1] + o[1])


def _clean_ring(ring: F64) -> F64:
    """CCW ring without closing, repeated or collinear vertices (may return < 3)."""
    r = np.asarray(ring, dtype=np.float64).reshape(-1, 2)
    if len(r) > 1 and np.all(np.abs(r[0] - r[-1]) <= _VERTEX_EPS):
        r = r[:-1]
    if len(r) >= 3 and _signed_area(r) < 0:
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


def _polygon_parts(geom: shapely.Geometry) -> list[shapely.Polygon]:
    return [
        p
        for p in shapely.get_parts(geom)
        if isinstance(p, shapely.Polygon) and not p.is_empty and p.area >= _SLIVER_AREA
    ]


def _disjoint_sources(scene: SourceScene) -> list[tuple[str, shapely.Polygon]]:
    """Valid street polygons in priority order, with overlaps given to the earlier one."""
    order = sorted(scene.streets, key=lambda s: (_PRIORITY[s.kind], s.id))
    kinds: list[str] = []
    geoms: list[shapely.Polygon] = []
    for s in order:
        poly = shapely.Polygon(s.ring)
        if not poly.is_valid:
            poly = shapely.make_valid(poly)
        for p in _polygon_parts(poly):
            kinds.append(s.kind)
            geoms.append(p)
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
    out: list[tuple[str, shapely.Polygon]] = []
    for kind, g in zip(kinds, out_geoms, strict=True):
        out.extend((kind, p) for p in _polygon_parts(g))
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
        if abs(_signed_area(pts)) < 1e-12:
            continue
        if _signed_area(pts) < 0:
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
    return out


def _finish(parts: list[tuple[str, F64]], zmin: float, zmax: float) -> list[ViewCell]:
    """Order parts deterministically, find neighbours and build the cells."""
    order = sorted(
        range(len(parts)),
        key=lambda k: (
            CELL_KINDS.index(parts[k][0]),
            *(round(v, 3) for v in reversed(_centroid(parts[k][1]))),
            round(_signed_area(parts[k][1]), 3),
        ),
    )
    parts = [parts[k] for k in order]
    polys = shapely.polygons([p for _, p in parts]) if parts else np.empty(0, object)
    nbrs = _neighbours(polys)
    return [
        ViewCell(id=k, kind=kind, polygon=ring, zmin=zmin, zmax=zmax, neighbours=tuple(nbrs[k]))
        for k, (kind, ring) in enumerate(parts)
    ]


def _neighbours(polys: NDArray[np.object_]) -> list[list[int]]:
    """Pairs of polygons whose boundaries share more than MIN_SHARED_EDGE metres.

    Exact boundary intersection misses collinear edges whose vertices differ by
    rounding (a cut point lies on its square's edge only up to an ulp), so the shared
    length is measured as the length of one boundary inside the other polygon grown
    by a micrometre.
    """
    out: list[list[int]] = [[] for _ in range(len(polys))]
    if len(polys) < 2:
        return out
    grown = shapely.buffer(polys, 1e-6, quad_segs=1, join_style="mitre")
    i, j = shapely.STRtree(polys).query(grown, predicate="intersects")
    keep = i < j
    i, j = i[keep], j[keep]
    shared = shapely.length(shapely.intersection(shapely.boundary(polys[i]), grown[j]))
    for a, b in zip(i[shared > MIN_SHARED_EDGE], j[shared > MIN_SHARED_EDGE], strict=True):
        out[int(a)].append(int(b))
        out[int(b)].append(int(a))
    return [sorted(n) for n in out]


def _footprints(scene: SourceScene) -> NDArray[np.object_]:
    """Building footprints as a ``(b,)`` array of shapely Polygons (holes kept)."""
    polys = [shapely.Polygon(b.rings[0], b.rings[1:]) for b in scene.buildings]
    return np.array(polys, dtype=object) if polys else np.empty(0, object)


def _grid_bbox(
    scene: SourceScene, bbox: tuple[float, float, float, float] | None
) -> tuple[float, float, float, float]:
    if bbox is not None:
        try:
            x0, y0, x1, y1 = (float(v) for v in bbox)
        except (TypeError, ValueError) as exc:
            raise InputError(f"bbox must be (xmin, ymin, xmax, ymax), got {bbox!r}") from exc
        if not all(map(math.isfinite, (x0, y0, x1, y1))) or not (x0 < x1 and y0 < y1):
            raise InputError(f"bbox must be finite with xmin < xmax and ymin < ymax, got {bbox!r}")
        return x0, y0, x1, y1
    rings = [b.rings[0] for b in scene.buildings] or [s.ring for s in scene.streets]
    if not rings:
        raise InputError(f"scene {scene.name!r} has no buildings or streets: give a bbox")
    pts = np.concatenate(rings)
    (x0, y0), (x1, y1) = pts.min(axis=0), pts.max(axis=0)
    if not (x0 < x1 and y0 < y1):
        raise InputError(f"scene {scene.name!r} has a degenerate bounding box: give a bbox")
    return float(x0), float(y0), float(x1), float(y1)


def _free_share(boxes: NDArray[np.object_], footprints: NDArray[np.object_]) -> F64:
    """``(n,)`` share of each polygon's area not covered by footprints."""
    area = shapely.area(boxes)
    built = np.zeros(len(boxes))
    if len(footprints) and len(boxes):
        b, f = shapely.STRtree(footprints).query(boxes, predicate="intersects")
        inter = shapely.area(shapely.intersection(boxes[b], footprints[f]))
        built = np.bincount(b, weights=inter, minlength=len(boxes)).astype(np.float64)
    return np.clip(1.0 - built / np.maximum(area, 1e-300), 0.0, 1.0)


def _spread(points: F64, count: int) -> list[int]:
    """Farthest-point sampling of ``count`` of ``(n, 2)`` points, from the middlemost."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    d = np.linalg.norm(points - (lo + hi) / 2, axis=1)
    chosen = [int(np.argmin(d))]
    dist = np.linalg.norm(points - points[chosen[0]], axis=1)
    while len(chosen) < min(count, len(points)):
        k = int(np.argmax(dist))
        if dist[k] <= 0:
            break
        chosen.append(k)
        dist = np.minimum(dist, np.linalg.norm(points - points[k], axis=1))
    return chosen


def _free_point(
    cell: ViewCell, footprints: NDArray[np.object_], tree: shapely.STRtree
) -> tuple[float, float]:
    """A point of ``cell`` outside every footprint: its centre when free, else inside
    the largest free part (kept a little away from the walls when there is room)."""
    x, y = cell.centroid
    centre = shapely.Point(x, y)
    near = footprints[tree.query(centre, predicate="dwithin", distance=0.5)]
    if len(near) == 0:
        return x, y
    box = shapely.Polygon(cell.polygon)
    hits = footprints[tree.query(box, predicate="intersects")]
    free = shapely.difference(box, shapely.union_all(hits))
    inner = shapely.buffer(free, -0.5)
    region = inner if not inner.is_empty else free
    parts = _polygon_parts(region) or _polygon_parts(free)
    if not parts:
        return x, y
    best = max(parts, key=lambda p: p.area)
    p = best.centroid if best.contains(best.centroid) else best.point_on_surface()
    return float(p.x), float(p.y)


def _ray_lengths(
    origin: tuple[float, float], dirs: F64, footprints: NDArray[np.object_], tree: shapely.STRtree
) -> F64:
    """``(d,)`` distance along each unit direction to the first footprint (capped)."""
    o = np.asarray(origin, dtype=np.float64)
    ends = o + dirs * _VIEW_RAY
    rays = shapely.linestrings(np.stack([np.broadcast_to(o, ends.shape), ends], axis=1))
    out = np.full(len(dirs), _VIEW_RAY)
    if len(footprints) == 0:
        return out
    r, f = tree.query(rays, predicate="intersects")
    if len(r):
        hit = shapely.intersection(rays[r], footprints[f])
        dist = shapely.distance(shapely.Point(o), hit)
        np.minimum.at(out, r, np.nan_to_num(dist, nan=_VIEW_RAY))
    return out
