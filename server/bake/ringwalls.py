"""Textured virtual walls outdoors: a ring of walls around a street or grid cell whose PVS is large.

Where culling by the PVS is poor (a square, a sparse OpenStreetMap extract whose
buildings stand in the open) every cell sees most of the scene.  With
``--virtual-walls`` a city's bake closes such a cell's far field with a **ring**: four
walls standing on the sides of the smallest rotated rectangle of the cell's region
(below) pushed out by a distance ``r``.  Everything wholly beyond the ring is carried by the walls' textures
and leaves the cell's geometry PVS; what stands inside the ring or crosses it stays
geometry (and is a transparent hole in every texture of the ring, so its geometry
behind a wall's plane shows through, as indoors: :mod:`~.wallrender`).

**Regions.**  Street cells are short (8 m in the village), and a ring per cell would
send four new textures at every cell border.  So neighbouring cells are grouped into
**regions** (:func:`ring_regions`: grown breadth first while the group's smallest
rotated rectangle stays within ``--wall-region S`` metres square,
:attr:`~.wallplan.WallSettings.region`, 40 by default, and while a ring at the least
distance ``r_min`` around the grown group would keep at most ``K`` of its cells' PVS
objects: past that the ring stands at ``r_min`` and every object inside the grown
rectangle is geometry for all of its cells; on the village the 40 m regions kept 11-12
objects, 3.9 drawn a frame) and the cells of a region share one ring and its textures: walking along a street the textures change only at a
region's border or a zone's.

**Which regions.**  A region gets a ring when its cells' PVS together hold more than
``K`` objects (``--wall-keep K``, :attr:`~.wallplan.WallSettings.keep`) and a ring
removes at least one of them.

**The distance.**  ``r`` is the largest distance on a 1 m grid from ``r_min``
(``--wall-ring-min``, :attr:`~.wallplan.WallSettings.ring_min`) up to the bake's view
distance at which at most ``K`` of those objects reach inside the ring (their box
meets the ring's rectangle); when even ``r_min`` keeps more than ``K``, ``r = r_min``.
So the geometry PVS is the ``K`` or so objects nearest the region, and the walls stand
as far out as that allows: the farther the wall, the wider a zone may be for the
same angle of error, so the fewer textures a ring needs.

**Zones.**  A viewer inside the region is at least ``r`` from every wall of its ring, so
each side is cut into ``n = ceil(L / (2 r tan A))`` zones
(:func:`~walkstream.shared.walls.zone_count`, the paper's equations (3) and (4) with
``x_T = r``; ``L`` the side's length), each sampled at its middle on the region's
centre line (``r`` plus half the rectangle's depth in front of the wall) at eye height above
the ground.  Textures are used from the wall itself on (``x_T`` 0, no blend): no
geometry is left behind the wall to blend with, and the viewer never comes nearer than
``r`` while in the region.  The walls reach from the ground to 1 m over the top of the
highest object of the scene beyond the ring (a point behind the wall projects onto it
below its own height).

Wall ids: ring wall ``k`` (0-3) of cell ``c`` is portal ``4 c + k``, side 0 (one side
each: the inside of the ring); the cells of one region list the same four walls with
the same texture ids.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np
import shapely
from numpy.typing import NDArray

from walkstream.server.bake.viewcell import ViewCell
from walkstream.server.bake.wallplan import WallJob, WallPlan, WallSettings, texture_width
from walkstream.shared.walls import RING_SIDES, WallSide, zone_count

__all__ = ["RingPlan", "plan_ring_walls", "ring_reach", "ring_rectangle", "ring_regions"]

_MIN_HEIGHT = 3.0
"""Least wall height, metres (a ring behind which only low objects stand)."""


@dataclass
class RingPlan:
    """The rings of a city's cells: the walls (:class:`~.wallplan.WallPlan`, ``crossing``
    by portal), each ringed cell's geometry PVS after the cut (``kept``, object ids
    ascending), ring distance (``radius``, metres) and the cell-object pairs the rings
    took out of the geometry PVS (``removed``)."""

    walls: WallPlan
    kept: dict[int, NDArray[np.int64]]
    radius: dict[int, float]
    removed: int = 0


def ring_rectangle(polygon: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The cell outline's smallest rotated rectangle: its centre ``(2,)``, unit axes ``(2, 2)``
    (rows, counter-clockwise) and half sizes ``(2,)`` along them."""
    rect = shapely.minimum_rotated_rectangle(shapely.Polygon(np.asarray(polygon, np.float64)))
    pts = np.asarray(shapely.get_coordinates(rect), np.float64)[:4]
    if len(pts) < 4 or rect.area <= 1e-9:  # a degenerate cell: its box
        lo, hi = np.asarray(polygon).min(axis=0), np.asarray(polygon).max(axis=0)
        pts = np.array([lo, [hi[0], lo[1]], hi, [lo[0], hi[1]]], np.float64)
    centre = pts.mean(axis=0)
    e0, e1 = pts[1] - pts[0], pts[2] - pts[1]
    l0, l1 = max(float(np.linalg.norm(e0)), 1e-6), max(float(np.linalg.norm(e1)), 1e-6)
    u = e0 / l0
    v = np.array([-u[1], u[0]])
    return centre, np.stack([u, v]), np.array([l0 / 2.0, l1 / 2.0])


def ring_reach(boxes: NDArray[np.float64], centre: NDArray[np.float64], axes: NDArray[np.float64],
           half: NDArray[np.float64]) -> NDArray[np.float64]:
    """``(m,)`` for each object box ``(m, 6)`` the least ring distance ``r`` at which it meets
    the rectangle pushed out by ``r`` (0: it meets the cell's rectangle itself): the
    separating-axis gap along the rectangle's two axes (the box's corners projected),
    the larger of the two, as a box's gap along a world axis only adds to it."""
    if len(boxes) == 0:
        return np.zeros(0)
    lo, hi = boxes[:, :2], boxes[:, 3:5]
    corners = np.stack([lo, np.stack([hi[:, 0], lo[:, 1]], 1), hi, np.stack([lo[:, 0], hi[:, 1]], 1)], 1)
    rel = corners - centre  # (m, 4, 2)
    proj = rel @ axes.T  # (m, 4, 2) along u, v
    gap = np.maximum(proj.min(axis=1) - half, -half - proj.max(axis=1))  # (m, 2)
    return np.maximum(gap.max(axis=1), 0.0)


def _known(ids: NDArray[np.int64] | None, all_ids: NDArray[np.int64]) -> NDArray[np.int64]:
    """``ids`` (a cell's PVS; None: none) that have a box."""
    a = np.asarray(ids if ids is not None else np.zeros(0), np.int64).reshape(-1)
    out: NDArray[np.int64] = a[np.isin(a, all_ids)]
    return out


def ring_regions(cells: Sequence[ViewCell], size: float,
                 fits: Callable[[Sequence[ViewCell], NDArray[np.float64]], bool] | None = None) -> list[list[ViewCell]]:
    """The cells grouped into regions that share one ring: from each cell not yet placed
    (in id order), its neighbours are added breadth first while the region's smallest
    rotated rectangle stays within ``size`` by ``size`` metres (a cell larger than that
    is a region alone) and, with ``fits``, while ``fits(cells, outline points (n, 2))``
    holds for the region grown.  The same on every run."""
    by_id = {c.id: c for c in cells}
    placed: set[int] = set()
    out: list[list[ViewCell]] = []
    for cell in sorted(cells, key=lambda c: c.id):
        if cell.id in placed:
            continue
        region = [cell]
        placed.add(cell.id)
        pts = np.asarray(cell.polygon, np.float64)
        queue = list(cell.neighbours)
        while queue:
            nid = queue.pop(0)
            nb = by_id.get(nid)
            if nb is None or nid in placed:
                continue
            both = np.vstack([pts, np.asarray(nb.polygon, np.float64)])
            _c, _a, half = ring_rectangle(both)
            if 2.0 * float(half.max()) > size or (fits is not None and not fits([*region, nb], both)):
                continue
            region.append(nb)
            placed.add(nid)
            pts = both
            queue += [n for n in nb.neighbours if n not in placed]
        out.append(region)
    return out


def plan_ring_walls(
    cells: Sequence[ViewCell],
    pvs: Mapping[int, NDArray[np.int64]],
    boxes: Mapping[int, Sequence[float]],
    settings: WallSettings,
    *,
    view_distance: float = 800.0,
    ground: float = 0.0,
) -> RingPlan:
    """The rings of ``cells`` (the module docstring) from their stored ``pvs`` and every
    object's box ``(minx, miny, minz, maxx, maxy, maxz)``; the same on every run, so
    texture ids are the same on resume.

    An object inside a ring or crossing it stays in the geometry PVS and is a hole in
    every texture of that ring; every other object of the scene is on the textures."""
    alpha = math.radians(settings.error_deg)
    sides: list[WallSide] = []
    jobs: list[WallJob] = []
    crossing: dict[int, tuple[int, ...]] = {}
    kept: dict[int, NDArray[np.int64]] = {}
    radius: dict[int, float] = {}
    removed = 0
    all_ids = np.array(sorted(boxes), np.int64)
    all_boxes = np.array([boxes[int(i)] for i in all_ids], np.float64).reshape(-1, 6)
    r_max = max(settings.ring_min, float(view_distance))

    def fits(group: Sequence[ViewCell], outline: NDArray[np.float64]) -> bool:
        # a region grows only while a ring at the least distance can still keep at most
        # K of its cells' PVS as geometry: past that the ring stands at ring_min and
        # every object inside the grown rectangle is drawn from all of its cells
        ids = np.unique(np.concatenate([_known(pvs.get(c.id), all_ids) for c in group]))
        if len(ids) <= settings.keep:
            return True
        centre, axes, half = ring_rectangle(outline)
        reach = ring_reach(all_boxes[np.searchsorted(all_ids, ids)], centre, axes, half)
        return int((reach <= settings.ring_min).sum()) <= settings.keep

    for region in ring_regions(cells, settings.region, fits):
        own = {c.id: _known(pvs.get(c.id), all_ids) for c in region}
        ids = np.unique(np.concatenate(list(own.values())))
        if len(ids) <= settings.keep:
            continue
        centre, axes, half = ring_rectangle(np.vstack([np.asarray(c.polygon, np.float64) for c in region]))
        reach = ring_reach(all_boxes[np.searchsorted(all_ids, ids)], centre, axes, half)
        # the largest r (1 m grid) keeping at most K objects: just under the (K+1)-th reach
        order = np.sort(reach)
        r = math.floor(float(order[settings.keep]) - 1e-6) if order[settings.keep] > settings.ring_min else settings.ring_min
        r = float(min(max(r, settings.ring_min), r_max))
        meets = set(ids[reach <= r].tolist())
        if len(meets) == len(ids):
            continue
        for c in region:
            inside = np.isin(own[c.id], list(meets))
            kept[c.id] = np.sort(own[c.id][inside])
            radius[c.id] = r
            removed += int((~inside).sum())
        # every scene object meeting the ring stays geometry: a hole in its textures
        every = ring_reach(all_boxes, centre, axes, half) <= r
        hole = tuple(int(i) for i in all_ids[every])
        far = all_boxes[~every]
        top = max(_MIN_HEIGHT, float(far[:, 5].max()) + 1.0 if len(far) else _MIN_HEIGHT)
        out_half = half + r
        corners = [centre + axes[0] * sx * out_half[0] + axes[1] * sy * out_half[1]
                   for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))]  # counter-clockwise
        first = min(c.id for c in region)
        for k in range(RING_SIDES):
            # clockwise along the ring: the hidden space (outside) lies to the left of p0 -> p1
            p0, p1 = corners[(k + 1) % RING_SIDES], corners[k]
            length = float(np.linalg.norm(p1 - p0))
            across = 2.0 * float(out_half[1 - (k % 2)])  # the ring's depth seen from this wall
            zones = zone_count(length, r, alpha)
            ws = WallSide(RING_SIDES * first + k, 0, (float(p0[0]), float(p0[1])), (float(p1[0]), float(p1[1])),
                          ground, ground + top, ground, 0.0, 0.0, across / 2.0, alpha, zones)
            # seen from r on (the region's edge), sampled from the ring's middle
            width = texture_width(length, top, r, across / 2.0, settings)
            tids = tuple(range(len(jobs), len(jobs) + zones))
            row = tuple(ws.to_row())
            jobs += [(tid, row, z, width, hole) for z, tid in enumerate(tids)]
            crossing[ws.portal] = hole
            # every cell of the region lists the same wall (its own portal id), one set of textures
            sides += [replace(ws, portal=RING_SIDES * c.id + k, textures=tids) for c in sorted(region, key=lambda c: c.id)]
    return RingPlan(WallPlan(sides, jobs, crossing), kept, radius, removed)
