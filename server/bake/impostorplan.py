"""Which objects of each cell are impostors, and which images that takes (the bake's plan of images).

For a cell and the buildings of its PVS (Brosnan et al., section 5):

- *far*: the building's box is at least ``distance`` (D) from every point of the
  cell (the distance between the cell's polygon and the box's footprint, so a wide
  cell whose middle comes near the building does not count as far by its corners);
- *complex*: the building has more than ``complex_triangles`` (N) triangles at LOD2.

Each far or complex building gets the images of the direction bins
(:mod:`walkstream.shared.impostors`) that the directions from its centre to the cell
fall in, at the coarsest level whose bins keep the angular error at or under the
bound A from the cell's nearest point; a building that no level up to
:data:`~walkstream.shared.impostors.MAX_LEVEL` serves there stays geometry in that
cell.  The directions from the centre to a cell (which lies wholly outside the
building) span an azimuth interval bounded by the cell's corners (the azimuth along a
straight edge seen from outside it is monotonic) and an elevation interval bounded by
the nearest and farthest horizontal distances at the lowest and highest eye heights;
every bin of that box is listed.  An image is keyed by ``(object, level, azimuth
bin, elevation bin)`` on one grid for every cell, so cells needing the same key share
one image, made at the largest size any of them needs
(:func:`~walkstream.shared.impostors.texels_needed` at the cell's nearest point, a
power of two capped at S).

The plan is a pure function of the cells, their PVS and the objects, so a resumed
bake plans the same images under the same ids and makes only those not yet stored.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import shapely
from numpy.typing import NDArray

from walkstream.server.bake.impostorrender import ImageJob
from walkstream.server.bake.impostorsettings import ImpostorSettings
from walkstream.server.bake.viewcell import ViewCell
from walkstream.shared.impostors import (
    bin_of,
    eye_distance,
    half_side,
    image_size,
    level_for,
    level_step,
    texels_needed,
)

__all__ = ["CellImpostor", "ImpostorPlan", "plan_impostors"]


@dataclass(frozen=True, slots=True)
class CellImpostor:
    """One object drawn as an impostor from a cell: its bins and their images.

    ``images[j * n_az + i]`` is the image id of azimuth bin ``(az0 + i) % bins`` and
    elevation bin ``el0 + j`` at ``level``.
    """

    object: int
    level: int
    az0: int
    n_az: int
    el0: int
    n_el: int
    images: tuple[int, ...]

    def to_row(self) -> list[int]:
        """The stored row: ``[object, level, az0, n_az, el0, n_el, *images]``."""
        return [self.object, self.level, self.az0, self.n_az, self.el0, self.n_el, *self.images]


@dataclass
class ImpostorPlan:
    """Every image to make (:data:`~.impostorrender.ImageJob`, ids from 1 in key order)
    and each cell's impostors, by cell id."""

    jobs: list[ImageJob] = field(default_factory=list)
    cells: dict[int, list[CellImpostor]] = field(default_factory=dict)
    far: int = 0
    complex: int = 0
    too_near: int = 0
    """Far or complex (cell, object) pairs left as geometry: no level keeps the bound."""


def plan_impostors(
    cells: Sequence[ViewCell],
    pvs: Mapping[int, NDArray[np.int64]],
    boxes: Mapping[int, tuple[float, float, float, float, float, float]],
    tris2: Mapping[int, int],
    settings: ImpostorSettings,
) -> ImpostorPlan:
    """The images and cell lists of a city (see the module docstring).

    Parameters
    ----------
    cells:
        The PVS cells.
    pvs:
        Each cell's PVS (object ids), by cell id.
    boxes, tris2:
        The buildings' boxes and LOD2 triangles by object id (street pieces are not
        listed: the ground is never an impostor).
    settings:
        D, A, S, N and the target view.
    """
    ids = np.array(sorted(boxes), np.int64)
    box = np.array([boxes[i] for i in ids.tolist()], np.float64).reshape(-1, 6)
    centre = (box[:, :3] + box[:, 3:]) / 2.0
    radius = np.linalg.norm(box[:, 3:] - box[:, :3], axis=1) / 2.0
    tri = np.array([tris2.get(i, 0) for i in ids.tolist()], np.int64)
    footprints = shapely.box(box[:, 0], box[:, 1], box[:, 3], box[:, 4])
    centres2d = shapely.points(centre[:, :2])
    bound = math.radians(settings.error_deg)
    wanted: dict[tuple[int, int, int, int], int] = {}  # key -> size
    raw: dict[int, list[tuple[int, int, list[int], list[int]]]] = {}
    plan = ImpostorPlan()
    for cell in cells:
        seen = np.asarray(pvs.get(cell.id, np.zeros(0, np.int64)), np.int64)
        k = np.searchsorted(ids, seen)
        ok = (k < len(ids)) & (ids[np.minimum(k, len(ids) - 1)] == seen) if len(ids) else np.zeros(len(seen), bool)
        k = k[ok]
        if len(k) == 0:
            continue
        poly = shapely.Polygon(np.asarray(cell.polygon)[:, :2])
        far = shapely.distance(poly, footprints[k]) >= settings.distance
        big = tri[k] > settings.complex_triangles
        plan.far += int(far.sum())
        plan.complex += int((big & ~far).sum())
        rows = []
        chosen = k[far | big]
        corners = np.asarray(cell.polygon)[:, :2]
        near = shapely.distance(poly, centres2d[chosen])
        levels = level_for(radius[chosen], near, bound)
        side = radius[chosen]
        if settings.projection == "perspective":  # the square holds the silhouette from the sampling eye
            side = half_side(side, eye_distance(side, np.maximum(levels, 0), bound, settings.distance))
        sizes = image_size(texels_needed(side, near, settings.view_height, settings.fov_deg), settings.size)
        for j, o in enumerate(chosen.tolist()):
            if near[j] <= radius[o] or levels[j] < 0:  # reaching into the bounding sphere, or too near the bound
                plan.too_near += 1
                continue
            level, size = int(levels[j]), int(sizes[j])
            az_bins, el_bins = _bins(corners, cell.zmin, cell.zmax, centre[o], float(near[j]), level)
            for ia in az_bins:
                for ie in el_bins:
                    key = (int(ids[o]), level, ia, ie)
                    wanted[key] = max(wanted.get(key, 0), size)
            rows.append((int(ids[o]), level, az_bins, el_bins))
        raw[cell.id] = rows
    image_id = {key: n + 1 for n, key in enumerate(sorted(wanted))}
    plan.jobs = [(image_id[key], *key, wanted[key]) for key in sorted(wanted)]
    for cid, rows in raw.items():
        plan.cells[cid] = [
            CellImpostor(oid, level, az[0], len(az), el[0], len(el),
                         tuple(image_id[(oid, level, ia, ie)] for ie in el for ia in az))
            for oid, level, az, el in rows
        ]
    return plan


def _bins(
    corners: NDArray[np.float64],
    zmin: float,
    zmax: float,
    centre: NDArray[np.float64],
    near: float,
    level: int,
) -> tuple[list[int], list[int]]:
    """The azimuth and elevation bins at ``level`` of the directions from ``centre`` to a
    cell (its ``corners``, eye heights ``zmin`` .. ``zmax``, nearest at ``near``)."""
    step = level_step(level)
    d = corners - centre[:2]
    az = np.arctan2(d[:, 1], d[:, 0])
    ref = az[0]
    rel = (az - ref + math.pi) % (2.0 * math.pi) - math.pi
    lo, hi = ref + rel.min(), ref + rel.max()
    far = float(np.hypot(d[:, 0], d[:, 1]).max())
    els = [math.atan2(z - centre[2], h) for z in (zmin, zmax) for h in (near, far)]
    n_az = int(round(2.0 * math.pi / step))
    a0, _ = bin_of(level, lo, 0.0)
    a1, _ = bin_of(level, hi, 0.0)
    span = (int(a1) - int(a0)) % n_az
    _, e0 = bin_of(level, 0.0, min(els))
    _, e1 = bin_of(level, 0.0, max(els))
    return [(int(a0) + i) % n_az for i in range(span + 1)], list(range(int(e0), int(e1) + 1))
