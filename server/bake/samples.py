"""Where a cell's visibility is sampled: box corners moved inside the cell and out of buildings.

:func:`sample_points` gives the bake's points (the 8 corners of a box fitted to the
cell, at the bottom and top of its height range, each moved just inside the cell and
out of any building, optionally the centre too); :func:`dense_points` gives many
more, spread through the cell, for a reference that measures what the sampling
misses.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
import shapely
from numpy.typing import ArrayLike

from walkstream.shared.errors import InputError

if TYPE_CHECKING:
    from shapely import STRtree


from walkstream.shared.arrays import F64

__all__ = ["sample_points", "dense_points"]


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
