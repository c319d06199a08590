"""Where a cell's visibility is sampled: points on the cell's outline and inside it, moved out of buildings.

:func:`region_points` gives the bake's points (the default ``sampling="region"``): the
outline points of :func:`boundary_points` -- every vertex of the cell's outline and
points along each edge at most ``spacing`` metres apart, each moved just inside the
cell and out of any building -- then a ``spacing`` grid inside the cell, the points
alternating between the top and the bottom of the cell's eye-height range (every
point at more heights when the range is taller than ``height_step``).
:func:`boundary_points` alone (``sampling="boundary"``) is the outline at the top
height; :func:`sample_points` gives the first bake's points (``sampling="corners"``:
the 8 corners of a box fitted to the cell, at the bottom and top of its height range,
optionally the centre too).  :func:`bake_points` picks one by name.
:func:`split_points` adds points between two whose views differ (adaptive
sampling, ``BakeSettings.split``).  :func:`dense_points` and :func:`reference_points`
give many more, spread through the cell, for references that measure what the
sampling misses.

Why the boundary: a walker anywhere in a convex cell sees nothing that is hidden from
every point of its outline at the same height, except through gaps that open only
from the inside; the views that matter most -- down a side street, through a gap
between two buildings -- open widest from the part of the outline in front of the
gap, which the four corners of a 40 m street segment do not reach (they see such a
gap at a grazing angle).  Measured against a dense reference
(``walkstream bench visibility``), points along the outline at 20 m cut the largest
missed building tenfold where the corners and the centre did not.  The eye-height
range of street cells (0.5 m) changes little of what is seen, but it moves a street
seen edge-on 60 m away by most of a 128 px pixel: that sliver, a third of a pixel
high, is caught or not by the pixel rows depending on the eye height, and it was the
largest miss of every outline setting at 128 px (0.037 % of a cell's reference
pixels) until the points alternated between the two ends of the range (``"region"``:
0.005 %, with the same points in the plane on a short street cell).  Inside points
catch what opens only from the middle of a wide cell (a building seen through a slot
between two others from a few metres of the cell).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
import shapely
from numpy.typing import ArrayLike, NDArray

from walkstream.shared.errors import InputError

if TYPE_CHECKING:
    from shapely import STRtree


from walkstream.shared.arrays import F64

__all__ = [
    "SAMPLINGS",
    "sample_points",
    "boundary_points",
    "region_points",
    "axis_points",
    "split_points",
    "height_levels",
    "bake_points",
    "dense_points",
    "reference_points",
]

#: the bake's sampling schemes (``BakeSettings.sampling``)
SAMPLINGS = ("boundary", "corners", "region")


# ------------------------------------------------------------------ sample points


def _cell_polygon(polygon: ArrayLike) -> shapely.Polygon:
    ring = np.asarray(polygon, dtype=np.float64)
    if ring.ndim != 2 or ring.shape[1] != 2 or len(ring) < 3 or not np.all(np.isfinite(ring)):
        raise InputError(
            f"polygon: expected (n >= 3, 2) finite coordinates, got shape {ring.shape}"
        )
    poly = shapely.Polygon(ring)
    if not poly.is_valid:
        poly = shapely.make_valid(poly)
    if poly.is_empty or poly.area <= 0:
        raise InputError("polygon: the cell polygon has no area")
    return poly


def _free_space(
    poly: shapely.Geometry, margin: float, footprints: STRtree | None
) -> shapely.Geometry | None:
    """Where a viewer may stand: inside the cell (inset by ``margin``) and out of buildings.

    Tries the full margin first (from the cell border and from footprints), then
    smaller ones, so that a cell narrower than two margins still gets points; returns
    ``None`` when the cell has no free space at all.
    """
    blocked = None
    if footprints is not None:
        hits = footprints.query(poly, predicate="intersects")
        if len(hits):
            blocked = shapely.union_all(footprints.geometries.take(hits))
    for m in (margin, margin / 4.0, 0.0):
        free = poly.buffer(-m) if m > 0 else poly
        if blocked is not None and not free.is_empty:
            free = free.difference(blocked.buffer(m) if m > 0 else blocked)
        if not free.is_empty and free.area > 0:
            return free
    return None


def _move_into(free: shapely.Geometry, xy: F64) -> F64:
    """Nearest points of ``free`` to each point ``(p, 2)`` (points inside stay put)."""
    pts = shapely.points(xy)
    inside = shapely.contains(free, pts)
    out = xy.copy()
    if not inside.all():
        lines = shapely.shortest_line(pts[~inside], free)
        out[~inside] = shapely.get_coordinates(lines).reshape(-1, 2, 2)[:, 1]
    return out


def _check_z(zmin: float, zmax: float) -> tuple[float, float]:
    lo, hi = float(zmin), float(zmax)
    if not (math.isfinite(lo) and math.isfinite(hi)) or hi < lo:
        raise InputError(f"expected finite zmin <= zmax, got zmin={zmin}, zmax={zmax}")
    return lo, hi


def sample_points(
    polygon: ArrayLike,
    zmin: float,
    zmax: float,
    *,
    margin: float = 0.3,
    centre: bool = False,
    footprints: STRtree | None = None,
) -> F64:
    """The cell's sample points: box corners moved just inside the cell and out of buildings.

    The four corners of the polygon's bounding box go to the nearest point of the
    polygon shrunk by ``margin`` (so that facades on the cell border act as occluders
    instead of being straddled), then out of any building footprint (within ``margin``
    of one) to the nearest free point of the cell.  If the cell has no free space at
    all, no points are returned.

    Parameters
    ----------
    polygon : (n, 2) float
        The cell outline, scene-local metres.
    zmin, zmax : float
        Bottom and top of the cell's eye-height range, metres.
    margin : float
        How far inside the cell and away from footprints the points go, metres.
        A cell narrower than ``2 * margin`` uses a smaller margin.
    centre : bool
        Also sample the centre of the cell (its centroid, moved into free space).
    footprints : shapely.STRtree, optional
        Building footprint polygons; points are kept out of them.

    Returns
    -------
    (p, 3) float64
        ``p = 8`` (10 with ``centre``), or 0 when the cell has no free space: the
        corners at ``zmin`` (order ``(xmin, ymin)``, ``(xmax, ymin)``, ``(xmax, ymax)``,
        ``(xmin, ymax)``), the same at ``zmax``, then the centre at ``zmin`` and ``zmax``.
    """
    lo_z, hi_z = _check_z(zmin, zmax)
    if not float(margin) >= 0:
        raise InputError(f"sample_points.margin: expected >= 0, got {margin}")
    poly = _cell_polygon(polygon)
    free = _free_space(poly, float(margin), footprints)
    if free is None:
        return np.zeros((0, 3), np.float64)
    x0, y0, x1, y1 = poly.bounds
    xy = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], np.float64)
    if centre:
        xy = np.vstack([xy, shapely.get_coordinates(poly.centroid)])
    xy = _move_into(free, xy)
    corners, mid = xy[:4], xy[4:]
    out = [np.column_stack([corners, np.full(4, z)]) for z in (lo_z, hi_z)]
    out += [np.column_stack([mid, np.full(len(mid), z)]) for z in (lo_z, hi_z)]
    return np.vstack(out)


def height_levels(zmin: float, zmax: float, step: float) -> F64:
    """Eye heights sampled in a cell's height range: the top, and more when it is tall.

    ``1 + floor((zmax - zmin) / step)`` heights evenly from ``zmax`` down to ``zmin``
    (one height, ``zmax``, when the range is shorter than ``step``): a walker's eye
    in a street cell moves by half a metre, which changes next to nothing of what it
    sees, and the top of the range sees the most over low obstacles.

    >>> height_levels(1.5, 2.0, 1.0).tolist()
    [2.0]
    >>> height_levels(0.0, 3.0, 1.5).tolist()
    [3.0, 1.5, 0.0]
    """
    lo, hi = _check_z(zmin, zmax)
    st = float(step)
    if not (math.isfinite(st) and st > 0):
        raise InputError(f"height_step: expected a positive number of metres, got {step}")
    n = 1 + int(math.floor((hi - lo) / st + 1e-9))
    return np.linspace(hi, lo, n) if n > 1 else np.array([hi])


def boundary_points(
    polygon: ArrayLike,
    zmin: float,
    zmax: float,
    *,
    spacing: float = 20.0,
    height_step: float = 1.0,
    margin: float = 0.3,
    centre: bool = False,
    footprints: STRtree | None = None,
) -> F64:
    """The cell's sample points along its outline, moved just inside it and out of buildings.

    Every vertex of the outline, and each edge cut into pieces of at most ``spacing``
    metres whose ends are sampled too; each point goes to the nearest point of the
    cell's free space (the cell shrunk by ``margin``, minus building footprints grown
    by ``margin``), and a point closer than ``min(spacing / 4, 2 m)`` to one kept
    before it is dropped (short edges of crossroads, corners pulled into one place).

    Parameters
    ----------
    polygon : (n, 2) float
        The cell outline, scene-local metres.
    zmin, zmax : float
        Bottom and top of the cell's eye-height range, metres.
    spacing : float
        Largest distance between neighbouring points along an edge, metres.
    height_step : float
        Heights per point: :func:`height_levels` (one height, ``zmax``, for a range
        shorter than this).
    margin : float
        How far inside the cell and away from footprints the points go, metres.
    centre : bool
        Also sample the centre of the cell (its centroid, moved into free space).
    footprints : shapely.STRtree, optional
        Building footprint polygons; points are kept out of them.

    Returns
    -------
    (p, 3) float64
        The points, height-major (all points at the top height first, in the order
        of the outline from its first vertex, then the centre), or none when the
        cell has no free space.
    """
    zs = height_levels(zmin, zmax, height_step)
    sp = float(spacing)
    if not (math.isfinite(sp) and sp > 0):
        raise InputError(f"spacing: expected a positive number of metres, got {spacing}")
    if not float(margin) >= 0:
        raise InputError(f"boundary_points.margin: expected >= 0, got {margin}")
    poly = _cell_polygon(polygon)
    free = _free_space(poly, float(margin), footprints)
    if free is None:
        return np.zeros((0, 3), np.float64)
    ring = np.asarray(poly.exterior.coords, np.float64)[:-1]
    a, b = ring, np.roll(ring, -1, axis=0)
    pieces = np.maximum(1, np.ceil(np.hypot(*(b - a).T) / sp)).astype(np.int64)
    edge = np.repeat(np.arange(len(ring)), pieces)
    k = np.arange(int(pieces.sum())) - np.repeat(np.cumsum(pieces) - pieces, pieces)
    xy = a[edge] + (b - a)[edge] * (k / pieces[edge])[:, None]
    if centre:
        xy = np.vstack([xy, shapely.get_coordinates(poly.centroid)])
    xy = _move_into(free, xy)
    near = min(sp / 4.0, 2.0)
    keep: list[int] = []
    for i in range(len(xy)):  # a few dozen points: a plain loop is clearer than a tree
        if not keep or np.min(np.hypot(*(xy[keep] - xy[i]).T)) >= near:
            keep.append(i)
    xy = xy[keep]
    return np.vstack([np.column_stack([xy, np.full(len(xy), z)]) for z in zs])


def region_points(
    polygon: ArrayLike,
    zmin: float,
    zmax: float,
    *,
    spacing: float = 20.0,
    height_step: float = 1.0,
    margin: float = 0.3,
    centre: bool = False,
    footprints: STRtree | None = None,
) -> F64:
    """The cell's sample points over its outline, its inside and its height range.

    The outline points of :func:`boundary_points`, then a square grid of ``spacing``
    metres over the cell's free space, centred on it (its nodes closer than
    ``spacing / 2`` to an outline point dropped: a 30 x 10 m street cell gets none, a
    60 x 10 m one a row down its middle, a square grid cell about one per
    ``spacing**2``); the heights alternate along the points
    between the top and the bottom of the eye-height range (every point at every
    :func:`height_levels` height when the range is taller than ``height_step``, as
    the outline does).  The dense reference spreads its eyes over the whole cell and
    height range; an eye half a metre lower moves a grazing street 60 m away by
    most of a 128 px pixel, so the two heights are two chances to catch it.

    Returns
    -------
    (p, 3) float64
        The outline points first (in the order of :func:`boundary_points`), then the
        grid nodes row by row; none when the cell has no free space.
    """
    lo, hi = _check_z(zmin, zmax)
    edge = boundary_points(
        polygon, lo, hi, spacing=spacing, height_step=height_step, margin=margin, centre=centre, footprints=footprints
    )
    if len(edge) == 0:
        return edge
    levels = height_levels(lo, hi, height_step)
    ring = edge[edge[:, 2] == levels[0], :2]
    poly = _cell_polygon(polygon)
    free = _free_space(poly, float(margin), footprints)
    assert free is not None  # boundary_points found free space
    sp = float(spacing)
    x0, y0, x1, y1 = free.bounds
    # the grid centred on the free space, so that a cell's inside is covered evenly
    nx, ny = int((x1 - x0) // sp), int((y1 - y0) // sp)
    gx = (x0 + x1) / 2.0 + (np.arange(nx + 1) - nx / 2.0) * sp
    gy = (y0 + y1) / 2.0 + (np.arange(ny + 1) - ny / 2.0) * sp
    xx, yy = np.meshgrid(gx, gy, indexing="xy")
    grid = np.column_stack([xx.reshape(-1), yy.reshape(-1)])
    grid = grid[shapely.contains_xy(free, grid[:, 0], grid[:, 1])]
    if len(grid):
        d = np.hypot(grid[:, None, 0] - ring[None, :, 0], grid[:, None, 1] - ring[None, :, 1]).min(axis=1)
        grid = grid[d >= sp / 2.0]
    return _at_heights(np.vstack([ring, grid]), levels, lo, hi)


def _at_heights(xy: F64, levels: F64, lo: float, hi: float) -> F64:
    """``xy`` at every height of ``levels`` when there are several, else alternating
    between the top ``hi`` and the bottom ``lo`` of the eye range along the points."""
    if len(levels) > 1:
        return np.vstack([np.column_stack([xy, np.full(len(xy), z)]) for z in levels])
    return np.column_stack([xy, np.where(np.arange(len(xy)) % 2 == 0, hi, lo)])


def axis_points(
    polygon: ArrayLike,
    zmin: float,
    zmax: float,
    *,
    spacing: float = 10.0,
    height_step: float = 1.0,
    margin: float = 0.3,
    footprints: STRtree | None = None,
) -> F64:
    """Points along the middle of a cell: its long axis, every ``spacing`` metres.

    The long axis is the middle line of the cell's smallest enclosing (rotated)
    rectangle, joining the middles of its two short sides: a street cell's
    centre line.  ``ceil(length / spacing)`` points evenly along it (half a step in
    from each end), each moved into the cell's free space when it falls outside
    (:func:`region_points`' margin, out of buildings); heights as
    :func:`region_points` gives them (alternating top and bottom of the eye range, or
    every :func:`height_levels` height when the range is taller than ``height_step``).

    The outline points of :func:`region_points` stand ``margin`` inside the cell's
    edge, so on a street cell they hug the facades on either side: a position in the
    middle of the street (where a walker walks) is up to half the street's width and
    half the outline spacing from every one of them, and from there a far building seen
    down the street past the near facades (a slit a few pixels wide) is hidden from
    every outline point by the facades nearer it.  These points close that gap for
    the far field's band (:mod:`~walkstream.server.bake.farband`).

    Returns
    -------
    (p, 3) float64
        The points, from one end of the axis to the other; none when the cell has no
        free space.
    """
    lo, hi = _check_z(zmin, zmax)
    if not (np.isfinite(spacing) and spacing > 0):
        raise InputError(f"axis_points.spacing: expected a positive number of metres, got {spacing}")
    poly = _cell_polygon(polygon)
    free = _free_space(poly, float(margin), footprints)
    if free is None:
        return np.zeros((0, 3))
    rect = np.asarray(shapely.minimum_rotated_rectangle(poly).exterior.coords, np.float64)[:4]
    if len(rect) < 4:  # a degenerate rectangle (a line): the cell has no width
        return np.zeros((0, 3))
    e1, e2 = rect[1] - rect[0], rect[2] - rect[1]
    if np.hypot(*e1) < np.hypot(*e2):  # e1 is a short side: the axis joins its middle to the opposite one's
        a, b = (rect[0] + rect[1]) / 2.0, (rect[2] + rect[3]) / 2.0
    else:
        a, b = (rect[1] + rect[2]) / 2.0, (rect[3] + rect[0]) / 2.0
    n = max(1, int(np.ceil(float(np.hypot(*(b - a))) / float(spacing))))
    t = (np.arange(n) + 0.5) / n
    xy = _move_into(free, a + t[:, None] * (b - a))
    return _at_heights(xy, height_levels(lo, hi, height_step), lo, hi)


def split_points(
    points: ArrayLike,
    seen: list[NDArray[np.int64]],
    polygon: ArrayLike,
    *,
    differ: float,
    max_gap: float,
    min_gap: float = 2.0,
    margin: float = 0.3,
    footprints: STRtree | None = None,
) -> F64:
    """New points between sampled points whose views differ: adaptive sampling.

    For every pair of points at most ``max_gap`` metres apart (in the plane) whose
    visible sets differ by more than ``differ`` (Jaccard distance: the objects seen
    from only one of them over the objects seen from either), the midpoint, moved
    into the cell's free space, at the pair's mean height.  A midpoint closer than
    ``min_gap`` to a point already sampled or chosen is left out, so that repeated
    rounds stop by themselves.  Where the views of two neighbours differ a lot, a
    gap between buildings opens or closes between them, and a walker between the
    two may see through it what neither sees (a building seen only through a slot a
    few metres wide in the middle of a street cell).

    Parameters
    ----------
    points : (p, 3) float
        The points sampled so far.
    seen : list of p (k_i,) int arrays
        The object ids each point sees (:meth:`VisibilityRenderer.point_counts
        <walkstream.server.bake.visibility.VisibilityRenderer.point_counts>`).
    polygon : (n, 2) float
        The cell outline.
    differ : float
        Jaccard distance above which a pair is split, in ``[0, 1)``.
    max_gap, min_gap : float
        Pairs farther apart than ``max_gap`` are not neighbours; no new point comes
        closer than ``min_gap`` to another, metres.
    margin, footprints :
        As for :func:`boundary_points`.

    Returns
    -------
    (q, 3) float64
        The new points (none when no pair differs enough).
    """
    pts = np.asarray(points, np.float64).reshape(-1, 3)
    if len(seen) != len(pts):
        raise InputError(f"split_points: expected one visible set per point ({len(pts)}), got {len(seen)}")
    if not 0.0 <= float(differ) < 1.0:
        raise InputError(f"split_points.differ: expected 0 <= differ < 1, got {differ}")
    if len(pts) < 2:
        return np.zeros((0, 3), np.float64)
    i, j = np.triu_indices(len(pts), 1)
    d = np.hypot(*(pts[i, :2] - pts[j, :2]).T)
    near = (d <= float(max_gap)) & (d >= 2.0 * float(min_gap))
    i, j = i[near], j[near]
    keep = []
    for a, b in zip(i.tolist(), j.tolist(), strict=True):  # a few dozen pairs
        union = len(np.union1d(seen[a], seen[b]))
        if union and 1.0 - len(np.intersect1d(seen[a], seen[b], assume_unique=True)) / union > float(differ):
            keep.append((a, b))
    if not keep:
        return np.zeros((0, 3), np.float64)
    ab = np.array(keep, np.int64)
    mid = (pts[ab[:, 0]] + pts[ab[:, 1]]) / 2.0
    free = _free_space(_cell_polygon(polygon), float(margin), footprints)
    if free is None:
        return np.zeros((0, 3), np.float64)
    mid[:, :2] = _move_into(free, mid[:, :2])
    out: list[F64] = []
    taken = pts[:, :2]
    for m in mid:
        if np.min(np.hypot(*(taken - m[:2]).T)) >= float(min_gap):
            out.append(m)
            taken = np.vstack([taken, m[:2]])
    return np.array(out, np.float64).reshape(-1, 3)


def bake_points(
    polygon: ArrayLike,
    zmin: float,
    zmax: float,
    *,
    sampling: str = "region",
    spacing: float = 20.0,
    height_step: float = 1.0,
    margin: float = 0.3,
    centre: bool = False,
    footprints: STRtree | None = None,
) -> F64:
    """The sample points of one cell as the bake places them (``sampling`` names the scheme).

    ``"boundary"``: :func:`boundary_points`; ``"region"``: :func:`region_points`
    (outline, inside and both ends of the height range); ``"corners"``:
    :func:`sample_points`, the first bake's 8 box corners (``spacing`` and
    ``height_step`` unused).
    """
    if sampling == "boundary":
        return boundary_points(
            polygon,
            zmin,
            zmax,
            spacing=spacing,
            height_step=height_step,
            margin=margin,
            centre=centre,
            footprints=footprints,
        )
    if sampling == "region":
        return region_points(
            polygon,
            zmin,
            zmax,
            spacing=spacing,
            height_step=height_step,
            margin=margin,
            centre=centre,
            footprints=footprints,
        )
    if sampling == "corners":
        return sample_points(polygon, zmin, zmax, margin=margin, centre=centre, footprints=footprints)
    raise InputError(f"sampling: expected one of {', '.join(SAMPLINGS)}, got {sampling!r}")


def dense_points(
    polygon: ArrayLike,
    zmin: float,
    zmax: float,
    n: int,
    *,
    levels: int = 3,
    margin: float = 0.3,
    footprints: STRtree | None = None,
    seed: int = 0,
) -> F64:
    """Many viewpoints spread through a cell, for a reference PVS.

    A jittered grid over the cell's free space (the polygon shrunk by ``margin``, minus
    building footprints grown by ``margin``, as for :func:`sample_points`): the grid
    spacing is chosen so that about ``n`` cells of it fall in the free space, each
    grid cell gets one uniformly random point (random generator seeded with ``seed``,
    so the result is deterministic), points outside the free space are dropped and
    ``n`` of the rest are kept, evenly spread over the grid order.

    Parameters
    ----------
    polygon : (m, 2) float
        The cell outline, scene-local metres.
    zmin, zmax : float
        Height range, metres.
    n : int
        Number of positions in the plane (>= 1).
    levels : int
        Heights per position, evenly from ``zmin`` to ``zmax`` (1: ``zmin`` only).
    margin : float
        Distance kept from the cell border and from footprints, metres.
    footprints : shapely.STRtree, optional
        Building footprints to keep out of.
    seed : int
        Seed of the jitter.

    Returns
    -------
    (q, 3) float64
        ``q = n * levels`` points (height-major: all positions at the first height,
        then the next), or fewer when the free space is too small, or none when the
        cell has no free space.
    """
    lo_z, hi_z = _check_z(zmin, zmax)
    if int(n) < 1 or int(levels) < 1:
        raise InputError(
            f"dense_points: expected n >= 1 and levels >= 1, got n={n}, levels={levels}"
        )
    poly = _cell_polygon(polygon)
    free = _free_space(poly, float(margin), footprints)
    if free is None:
        return np.zeros((0, 3), np.float64)
    x0, y0, x1, y1 = free.bounds
    rng = np.random.default_rng(seed)
    spacing = math.sqrt(free.area / int(n))
    xy = np.zeros((0, 2))
    for _ in range(12):
        nx = max(1, math.ceil((x1 - x0) / spacing))
        ny = max(1, math.ceil((y1 - y0) / spacing))
        gx, gy = np.meshgrid(np.arange(nx), np.arange(ny), indexing="xy")
        cells = np.column_stack([gx.reshape(-1), gy.reshape(-1)]).astype(np.float64)
        jitter = rng.random(cells.shape)
        cand = np.array([x0, y0]) + (cells + jitter) * spacing
        cand = cand[shapely.contains_xy(free, cand[:, 0], cand[:, 1])]
        if len(cand) >= int(n):
            xy = cand
            break
        xy = cand if len(cand) > len(xy) else xy
        spacing *= 0.8
    if len(xy) == 0:  # a sliver: fall back to a point that is surely in the free space
        xy = shapely.get_coordinates(free.representative_point())
    if len(xy) > int(n):
        xy = xy[np.round(np.linspace(0, len(xy) - 1, int(n))).astype(np.int64)]
    zs = np.linspace(lo_z, hi_z, int(levels)) if int(levels) > 1 else np.array([lo_z])
    return np.vstack([np.column_stack([xy, np.full(len(xy), z)]) for z in zs])


def reference_points(
    polygon: ArrayLike,
    zmin: float,
    zmax: float,
    n: int,
    *,
    margin: float = 0.3,
    footprints: STRtree | None = None,
    seed: int = 0,
) -> F64:
    """``n`` viewpoints spread over a cell and its height range, for an independent reference.

    The ground positions are :func:`dense_points` (a jittered grid over the free
    space, one height); each gets its own height, stratified over ``[zmin, zmax]``
    (the range cut into ``n`` equal slices in a random order, a uniform height in
    each), so every part of the cell and every part of the height range is sampled.
    Nothing here depends on where the bake puts its points.

    Returns
    -------
    (q, 3) float64
        ``q = n`` points (fewer in a sliver of free space, none without any).
    """
    lo, hi = _check_z(zmin, zmax)
    xy = dense_points(polygon, lo, lo, n, levels=1, margin=margin, footprints=footprints, seed=seed)
    if len(xy) == 0:
        return xy
    rng = np.random.default_rng([int(seed), 0x5EED])
    m = len(xy)
    z = lo + (hi - lo) * (rng.permutation(m) + rng.random(m)) / m
    return np.column_stack([xy[:, :2], z])
