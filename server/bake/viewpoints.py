"""Named start positions: a few viewpoints spread over the scene, looking down open streets."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import shapely
from numpy.typing import NDArray

from walkstream.server.bake.gridcells import free_share
from walkstream.server.bake.streetcells import polygon_parts
from walkstream.server.bake.viewcell import ViewCell, cell_polygons, footprint_polygons
from walkstream.server.sources.scene import SourceScene
from walkstream.shared.arrays import F64
from walkstream.shared.errors import InputError
from walkstream.shared.records import Viewpoint

__all__ = ["viewpoints"]
# Rays for the viewpoint directions stop after this many metres.
_VIEW_RAY = 400.0




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
    footprints = footprint_polygons(scene)
    tree = shapely.STRtree(footprints)
    grid = all(c.kind == "grid" for c in cells)

    if grid:
        boxes = cell_polygons(cells)
        free = free_share(boxes, footprints)
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
    parts = polygon_parts(region) or polygon_parts(free)
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
