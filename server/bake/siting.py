"""Which building of a city an interior goes into, by which door, and how it is placed.

``walkstream bake CITY --interior MODEL [--building ID|auto]``.  The rules (docs/bake.md,
"Crossing scenes", says them for users):

- **Fits.**  An interior fits a building when, turned so that an entrance door faces
  straight out of one edge of the footprint (the door's outer face on that edge, or
  behind it by the shell's porch), its shell (:func:`~.placement.interior_shell`: the
  plan of its walls, slabs and roof) reaches at most :data:`~.placement.FIT_TOLERANCE`
  metres outside the footprint and overlaps no street cell and no other building.
  Along each edge long enough for the door the door is tried every half metre (and
  with the shell centred, flush with either end, centred on the footprint); on an edge
  the position with the best *match* is kept (area of the shell and footprint's
  intersection over their union), and of the edges the one whose door is nearest a
  street cell (:func:`~.placement.fit_in_footprint`).
- **Near a street.**  The door's front is at most :data:`~.placement.MAX_ENTRANCE_GAP`
  metres from a street cell, and when it is more than :data:`~.frontpath.PATH_FROM`
  away a front path cell (:mod:`~.frontpath`) can be laid to it without crossing
  another building or street cell.
- **The entrance.**  The outer doors of the lowest storey that has one (a door portal
  from a doorway cell to the outside; in an IFC model an ``IfcDoor`` between a space
  and the outside), each tried: the door that fits with its front nearest a street is
  the entrance (within :data:`DOOR_TIE` metres the one first in
  :func:`~.placement.entrance_doors`' order: next to the room a tour starts in, then
  the lower portal id); the others stay doors to the outside, drawn but not walked
  through from the street.  A model without an outer door is refused.
- **``--building ID``** (an object id or a source feature id) takes that building;
  **``auto``** (or none) takes, of the buildings the interior fits near a street, the
  one it matches best (ties: the door nearer a street, then the lower id), so a real
  model lands on the footprint of its size and shape.

When nothing fits, the error names the building (or the best candidate) and why, on
one line.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import shapely

from walkstream.server.bake.frontpath import PATH_FROM, STREET_KINDS, front_path
from walkstream.server.bake.placement import (
    FIT_TOLERANCE,
    MAX_ENTRANCE_GAP,
    EntranceDoor,
    Fit,
    Placement,
    entrance_doors,
    fit_in_footprint,
    interior_shell,
    misfit,
)
from walkstream.server.bake.roomlayout import RoomLayout
from walkstream.server.bake.rooms import room_layout
from walkstream.server.bake.viewcell import ViewCell
from walkstream.server.sources.interior import InteriorScene
from walkstream.server.sources.scene import SourceScene
from walkstream.shared.arrays import F64
from walkstream.shared.errors import InputError

__all__ = ["DOOR_TIE", "Siting", "office_size", "pick_building", "site_interior", "street_cells"]

DOOR_TIE = 0.5
"""Metres within which two outer doors count as equally near a street (the one first in
:func:`~.placement.entrance_doors`' order is then the entrance)."""


@dataclass(frozen=True)
class Siting:
    """Where an interior goes: ``index`` in the scene's buildings, the ``door`` (in the
    interior's own frame), the ``fit`` (placement, gap, match), and ``path`` ``(4, 2)``,
    the front path cell's outline, or None when the door is on the street."""

    index: int
    door: EntranceDoor
    fit: Fit
    path: F64 | None

    @property
    def placement(self) -> Placement:
        """The interior's move into the city."""
        return self.fit.placement


def street_cells(cells: Sequence[ViewCell]) -> tuple[list[ViewCell], list[shapely.Geometry]]:
    """The cells an entrance may face (every cell of a city without streets) and their polygons."""
    street = [c for c in cells if c.kind in STREET_KINDS] or list(cells)
    return street, [shapely.Polygon(c.polygon) for c in street]


def _within_reach(shell: shapely.Geometry, footprint: shapely.Geometry) -> bool:
    """Whether the footprint's enclosing rectangle could hold the shell's, less the
    tolerance each way (a quick test before trying every edge)."""
    def sides(g: shapely.Geometry) -> list[float]:
        c = np.asarray(g.minimum_rotated_rectangle.exterior.coords)[:3]
        return sorted((float(np.hypot(*(c[1] - c[0]))), float(np.hypot(*(c[2] - c[1])))))

    own, fp = sides(shell), sides(footprint)
    return own[0] <= fp[0] + 2 * FIT_TOLERANCE and own[1] <= fp[1] + 2 * FIT_TOLERANCE


def _try(
    scene: SourceScene, cells: Sequence[ViewCell], doors: Sequence[EntranceDoor], shell: shapely.Geometry,
    k: int, dz: float, tree: shapely.STRtree, footprints: list[shapely.Geometry],
) -> tuple[Siting | None, str]:
    """The siting in building ``k`` with the first door that fits, or None and why not."""
    b = scene.buildings[k]
    street, polys = street_cells(cells)
    others = [footprints[i] for i in tree.query(footprints[k]) if i != k]
    far = None
    found: list[tuple[float, int, Siting]] = []
    for rank, door in enumerate(doors):
        fit = fit_in_footprint(door, shell, b.rings[0], polys, obstacles=others, dz=dz)
        if fit is None:
            continue
        if fit.gap > MAX_ENTRANCE_GAP:
            far = fit.gap if far is None else min(far, fit.gap)
            continue
        if fit.gap <= PATH_FROM:
            found.append((fit.gap, rank, Siting(k, door, fit, None)))
            continue
        p = fit.placement
        ends, normal = p.xy(door.ends), p.turn(door.normal)
        front = shapely.Point(ends.mean(axis=0) + 0.1 * normal)
        s = int(shapely.STRtree(polys).query_nearest(front)[0])
        path = front_path(ends, normal, polys[s], [g for i, g in enumerate(polys) if i != s] + others)
        if path is not None:
            found.append((fit.gap, rank, Siting(k, door, fit, path)))
            continue
        far = fit.gap if far is None else min(far, fit.gap)
    if found:
        # the door nearest a street; within DOOR_TIE of it, the door first in preference
        near = min(g for g, _, _ in found)
        return min((f for f in found if f[0] <= near + DOOR_TIE), key=lambda f: f[1])[2], ""
    if far is not None:
        return None, (f"its door would be {far:.1f} m from the nearest street cell (at most "
                      f"{MAX_ENTRANCE_GAP:g} m, with a front path clear of other buildings and streets)")
    return None, misfit(doors[0], shell, b.rings[0])


def site_interior(
    scene: SourceScene, cells: Sequence[ViewCell], interior: InteriorScene, building: str | None,
    *, layout: RoomLayout | None = None,
) -> Siting:
    """The building, door and placement of the module docstring.

    ``layout`` is the interior's (:func:`~.rooms.room_layout`), if already made.

    Raises
    ------
    InputError
        One line: no building by that id, or the building (``auto``: any) the interior
        does not fit, and why.
    """
    doors = entrance_doors(layout if layout is not None else room_layout(interior))
    shell = interior_shell(interior)
    dz = -doors[0].zmin  # the entrance's floor on the ground
    footprints = [shapely.Polygon(b.rings[0]) for b in scene.buildings]
    tree = shapely.STRtree(footprints)
    if building not in (None, "auto"):
        want = str(building)
        hits = [k for k, b in enumerate(scene.buildings) if str(b.id) == want or b.source_id == want]
        if not hits:
            raise InputError(f"--building {want}: no building with that object or feature id")
        k = hits[0]
        b = scene.buildings[k]
        got, why = _try(scene, cells, doors, shell, k, dz, tree, footprints)
        if got is None:
            raise InputError(f"the interior does not fit building {b.id} ({b.source_id}): {why}{_hint(interior)}")
        return got
    best: Siting | None = None
    # the match is at most the smaller area over the larger: buildings are tried in the
    # order of that bound, and once it falls below the best match found the search ends
    bound = sorted((-min(fp.area, shell.area) / max(fp.area, shell.area, 1e-12), k) for k, fp in enumerate(footprints))
    for neg, k in bound:
        if best is not None and -neg < round(best.fit.match, 3):
            break
        if len(scene.buildings[k].rings) != 1 or not _within_reach(shell, footprints[k]):
            continue
        got, _ = _try(scene, cells, doors, shell, k, dz, tree, footprints)
        if got is not None and (best is None or (-round(got.fit.match, 3), got.fit.gap, got.index)
                                < (-round(best.fit.match, 3), best.fit.gap, best.index)):
            best = got
    if best is None:
        more = ""
        sizes = [(abs(footprints[k].area - shell.area), k) for k, b in enumerate(scene.buildings) if len(b.rings) == 1]
        if sizes:
            k = min(sizes)[1]
            b = scene.buildings[k]
            _, why = _try(scene, cells, doors, shell, k, dz, tree, footprints)
            more = f"; the nearest in size, building {b.id} ({b.source_id}): {why}"
        sides = sorted(_sides(shell), reverse=True)
        raise InputError(f"no building of the city holds the interior ({sides[0]:.1f} x {sides[1]:.1f} m) "
                         f"with its entrance near a street{more}{_hint(interior, scene, cells)}")
    return best


def _sides(g: shapely.Geometry) -> list[float]:
    c = np.asarray(g.minimum_rotated_rectangle.exterior.coords)[:3]
    return [float(np.hypot(*(c[1] - c[0]))), float(np.hypot(*(c[2] - c[1])))]


def _hint(interior: InteriorScene, scene: SourceScene | None = None, cells: Sequence[ViewCell] = ()) -> str:
    """For a generated office, the size that would fit (it can be generated again)."""
    if not interior.source_format.startswith("walkstream-interior"):
        return ""
    if scene is None:
        return ": make it smaller (walkstream generate interior --size LxW) or pick another --building"
    hint = office_size(scene, list(cells))
    return (f": a generated office of --size {hint[0]:g}x{hint[1]:g} fits building {hint[2]}" if hint
            else ": make it smaller (walkstream generate interior --size LxW)")


def pick_building(
    scene: SourceScene, cells: Sequence[ViewCell], interior: InteriorScene, building: str | None,
    *, layout: RoomLayout | None = None,
) -> tuple[int, Placement, float]:
    """:func:`site_interior`'s building (its position in ``scene.buildings``), placement
    and the door's distance to the street cell."""
    s = site_interior(scene, cells, interior, building, layout=layout)
    return s.index, s.placement, s.fit.gap


def office_size(scene: SourceScene, cells: list[ViewCell], *, near: float = 1.0) -> tuple[float, float, str] | None:
    """The largest generated office (``walkstream generate interior --size LxW``) that fits a
    building of the city with its entrance on a street.

    A generated office enters by its west wall, ``W`` long, and reaches ``L`` inwards;
    its outer walls add 0.3 m on each side.  Of the rectangular footprints (at least
    97 % of their smallest enclosing rectangle) with a side at most ``near`` metres
    from a street cell, the one with the largest ``L x W`` (whole metres, 0.1 m of
    slack) is taken.

    Returns
    -------
    (L, W, building) or None
        The size and the building's feature id; None when no building has room for
        the smallest office (10 x 8 m).
    """
    _, polys = street_cells(cells)
    streets = shapely.union_all(polys)
    best: tuple[float, float, float, str] | None = None
    for b in scene.buildings:
        fp = shapely.Polygon(b.rings[0])
        rect = fp.minimum_rotated_rectangle
        if len(b.rings) != 1 or fp.area < 0.97 * rect.area:
            continue
        c = np.asarray(rect.exterior.coords)[:4]
        for k in range(4):
            side, other = c[(k + 1) % 4] - c[k], c[(k + 2) % 4] - c[(k + 1) % 4]
            mid = shapely.Point(0.5 * (c[k] + c[(k + 1) % 4]))
            if streets.distance(mid) > near:
                continue
            w = math.floor(float(np.hypot(*side)) - 0.7)
            length = math.floor(float(np.hypot(*other)) - 0.7)
            if length < 10 or w < 8:
                continue
            if best is None or length * w > best[0] * best[1]:
                best = (float(length), float(w), 0.0, b.source_id or str(b.id))
    return None if best is None else (best[0], best[1], best[3])
