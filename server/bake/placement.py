"""An interior placed in a city building's footprint, its entrance facing the street.

The interior is moved rigidly (a turn about the vertical and a shift; its lowest
floor put on the city's ground, z = 0) so that

1. its **entrance** (the outer door of :func:`entrance_door`: a doorway cell with a
   door portal to the outside, on the lowest storey that has one, next to the room a
   tour starts in) faces out of one edge of the building's footprint, the shell's
   front on that edge: the door's outer face flush with the facade, or behind it by
   as much as the shell reaches out in front of the door (a porch, a roof); the
   entrance's floor is put on the city's ground;
2. the interior's **shell** (the plan of its walls, slabs and roof) lies inside the
   footprint (5 cm of slack);
3. the door faces the **nearest street cell**: of the footprint edges long enough
   for the door, each tried with the door at the edge's middle, then slid to either
   end, the placement kept is the one whose point just in front of the door is
   closest to a street, crossroad or square cell (ties: the earlier edge, in the
   footprint's vertex order).

:func:`moved` moves a baked interior (cells, plane sets, portals, stairs, contents)
rather than cutting the moved model into cells again: room layout is not exactly
invariant under a turn (touching tolerances), and the interior should stay the one
that was baked alone.

A generated office (``walkstream generate interior``) is laid out along x with its
entrance in the west wall: generate it with ``--size LxW`` no larger than the
building's footprint less 0.6 m each way (the outer walls), ``W`` along the street;
when it does not fit, :func:`place_in_footprint` says the footprint's size, and
:func:`~.crossing.office_size` finds the largest size some building of a city takes
(the bake names it when no building holds the interior).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import shapely

from walkstream.server.bake.interior import InteriorParts
from walkstream.server.bake.roomnav import RoomGraph
from walkstream.server.bake.rooms import Portal, RoomCell, RoomLayout, StairLink
from walkstream.server.bake.roomwalks import entrance_cell, tour
from walkstream.server.sources.interior import InteriorScene, mesh_footprint
from walkstream.shared.arrays import F64
from walkstream.shared.errors import InputError

__all__ = [
    "MAX_ENTRANCE_GAP",
    "EntranceDoor",
    "Placement",
    "door_face",
    "entrance_door",
    "interior_shell",
    "moved",
    "place_in_footprint",
]

MAX_ENTRANCE_GAP = 3.0
"""Metres from the facade in front of the door to the nearest street cell, at most."""

_SLACK = 0.05  # the shell may stick out of the footprint this much (metres)
_FRONT = 0.1  # the point probed for the nearest street lies this far in front of the door
_SHELL_KINDS = ("wall", "slab", "roof")


@dataclass(frozen=True)
class EntranceDoor:
    """The interior's entrance: its doorway cell, the portal from that cell to the
    outside, and the door's outer face (``ends`` ``(2, 2)``, floor and head heights,
    ``normal`` ``(2,)`` unit, out of the building)."""

    doorway: int
    portal: int
    ends: F64
    zmin: float
    zmax: float
    normal: F64

    @property
    def middle(self) -> F64:
        """``(2,)`` the middle of the door's outer face."""
        return np.asarray(self.ends.mean(axis=0))


@dataclass(frozen=True)
class Placement:
    """A rigid move of an interior into a city: local point ``p`` goes to
    ``R(angle) p + shift`` and heights ``z`` to ``z + dz``."""

    angle: float
    shift: tuple[float, float]
    dz: float

    def xy(self, pts: F64) -> F64:
        """Moved ``(n, 2)`` points."""
        p = np.asarray(pts, np.float64).reshape(-1, 2)
        c, s = math.cos(self.angle), math.sin(self.angle)
        return np.column_stack([c * p[:, 0] - s * p[:, 1] + self.shift[0], s * p[:, 0] + c * p[:, 1] + self.shift[1]])

    def xyz(self, pts: F64) -> F64:
        """Moved ``(n, 3)`` points."""
        p = np.asarray(pts, np.float64).reshape(-1, 3)
        return np.column_stack([self.xy(p[:, :2]), p[:, 2] + self.dz])

    def turn(self, v: F64) -> F64:
        """A turned direction ``(2,)``."""
        c, s = math.cos(self.angle), math.sin(self.angle)
        return np.array([c * v[0] - s * v[1], s * v[0] + c * v[1]])


def entrance_door(layout: RoomLayout) -> EntranceDoor:
    """The outer door the interior is entered by (see the module docstring).

    Raises
    ------
    InputError
        No doorway of the interior has a door to the outside.
    """
    cells = {c.id: c for c in layout.cells}
    out = layout.outside
    doors = [p for p in layout.portals if p.kind == "door" and out in (p.a, p.b) and cells[p.a + p.b - out].kind == "doorway"]
    if not doors:
        raise InputError("the interior has no outer door to enter it by (a door from a doorway to the outside)")
    low = min(cells[p.a + p.b - out].storey for p in doors)
    doors = [p for p in doors if cells[p.a + p.b - out].storey == low]
    room = entrance_cell(layout.cells, layout.portals)
    next_to_room = {q.a + q.b - room for q in layout.portals if room in (q.a, q.b)}
    best = min(doors, key=lambda p: (p.a + p.b - out not in next_to_room, p.id))
    return _door_face(best, cells[best.a + best.b - out])


def _door_face(p: Portal, doorway: RoomCell) -> EntranceDoor:
    ends, normal = door_face(p.polygon, doorway.outline)
    return EntranceDoor(doorway.id, p.id, ends, float(p.polygon[:, 2].min()), float(p.polygon[:, 2].max()), normal)


def door_face(polygon: F64, outline: F64) -> tuple[F64, F64]:
    """The ends ``(2, 2)`` of a door portal's bottom edge and its unit normal ``(2,)``
    pointing away from the cell of ``outline`` (out of the building for an outer door)."""
    poly = np.asarray(polygon, np.float64).reshape(-1, 3)
    low = poly[poly[:, 2] <= poly[:, 2].min() + 1e-6][:, :2]
    d = np.hypot(*(low - low[0]).T)
    ends = np.array([low[0], low[int(np.argmax(d))]])
    seg = ends[1] - ends[0]
    n = np.array([seg[1], -seg[0]]) / max(float(np.hypot(*seg)), 1e-12)
    centre = np.asarray(outline, np.float64).mean(axis=0)
    if float(n @ (ends.mean(axis=0) - centre)) < 0:
        n = -n
    return ends, n


def interior_shell(scene: InteriorScene) -> shapely.Geometry:
    """The plan of an interior's walls, slabs and roof (its outer outline, holes filled)."""
    parts = [mesh_footprint(e.vertices, e.triangles) for e in scene.elements if e.kind in _SHELL_KINDS and len(e.triangles)]
    parts = [p for p in parts if not p.is_empty]
    if not parts:
        pts = np.concatenate([r.outline for r in scene.rooms])
        return shapely.MultiPoint(pts).convex_hull
    union = shapely.union_all(parts)
    polys = [g for g in shapely.get_parts(union) if isinstance(g, shapely.Polygon)]
    return shapely.union_all([shapely.Polygon(g.exterior) for g in polys])


def place_in_footprint(
    door: EntranceDoor,
    shell: shapely.Geometry,
    footprint: F64,
    streets: Sequence[shapely.Geometry],
    *,
    dz: float = 0.0,
    what: str = "the building",
) -> tuple[Placement, float]:
    """The placement of the module docstring and the gap (metres) from the facade in
    front of the door to the nearest street cell.

    Parameters
    ----------
    door, shell:
        The interior's entrance (:func:`entrance_door`) and shell (:func:`interior_shell`),
        in the interior's own frame.
    footprint:
        ``(n, 2)`` the building's outer ring, city-local metres.
    streets:
        The city's street, crossroad and square cells as polygons.
    dz:
        Added to every height (the interior's lowest floor onto the ground).

    Raises
    ------
    InputError
        The shell fits in the footprint nowhere with the door on an edge, or the
        door ends more than :data:`MAX_ENTRANCE_GAP` from a street.
    """
    ring = np.asarray(footprint, np.float64).reshape(-1, 2)
    poly = shapely.Polygon(ring)
    if not poly.is_valid:
        poly = shapely.make_valid(poly)
    room = poly.buffer(_SLACK, join_style="mitre")
    shapely.prepare(room)
    ccw = shapely.Polygon(ring).exterior.is_ccw
    width = float(np.hypot(*(door.ends[1] - door.ends[0])))
    shell_pts = np.asarray(shapely.get_coordinates(shell))
    tree = shapely.STRtree(list(streets)) if len(streets) else None
    best: tuple[float, Placement] | None = None
    for k in range(len(ring)):
        a, b = ring[k], ring[(k + 1) % len(ring)]
        e = b - a
        length = float(np.hypot(*e))
        if length < width + 0.2:
            continue
        u = e / length
        out = np.array([u[1], -u[0]]) if ccw else np.array([-u[1], u[0]])
        angle = math.atan2(out[1], out[0]) - math.atan2(door.normal[1], door.normal[0])
        turned = Placement(angle, (0.0, 0.0), dz)
        mid = turned.xy(door.middle[None])[0]
        moved_pts = turned.xy(shell_pts)
        along = (moved_pts - mid) @ u
        # a door recessed behind the shell's front (a porch, a roof reaching out) sits
        # that far behind the facade
        recess = max(0.0, float(((moved_pts - mid) @ out).max()))
        lo, hi = float(along.min()), float(along.max())
        # the door at the edge's middle, then the shell flush with either end
        for t in (0.5 * (length - lo - hi), -lo, length - hi):
            if not -1e-9 <= t <= length:
                continue
            at = a + u * t
            door_at = at - out * recess
            p = Placement(angle, (float(door_at[0] - mid[0]), float(door_at[1] - mid[1])), dz)
            moved = shapely.Polygon(p.xy(np.asarray(shell.exterior.coords))) if isinstance(shell, shapely.Polygon) else None
            if moved is None or not room.contains(moved):
                continue
            front = shapely.Point(at + out * _FRONT)
            gap = math.inf
            if tree is not None:
                near = int(tree.query_nearest(front)[0])
                gap = float(shapely.distance(streets[near], front))
            if best is None or gap < best[0] - 1e-9:
                best = (gap, p)
    if best is None:
        size = poly.minimum_rotated_rectangle
        c = np.asarray(size.exterior.coords)[:3]
        sides = sorted((float(np.hypot(*(c[1] - c[0]))), float(np.hypot(*(c[2] - c[1])))), reverse=True)
        ext = shell.minimum_rotated_rectangle
        d = np.asarray(ext.exterior.coords)[:3]
        own = sorted((float(np.hypot(*(d[1] - d[0]))), float(np.hypot(*(d[2] - d[1])))), reverse=True)
        raise InputError(
            f"the interior ({own[0]:.1f} x {own[1]:.1f} m outside its walls) does not fit {what} "
            f"({sides[0]:.1f} x {sides[1]:.1f} m) with its entrance on the facade: make it smaller "
            "(walkstream generate interior --size LxW) or pick another --building"
        )
    if best[0] > MAX_ENTRANCE_GAP:
        raise InputError(
            f"the entrance of the interior in {what} is {best[0]:.1f} m from the nearest street cell "
            f"(at most {MAX_ENTRANCE_GAP:g} m): pick a building on a street"
        )
    return best[1], best[0]


def moved(baked: InteriorParts, p: Placement) -> InteriorParts:
    """A baked interior moved rigidly by ``p``: cells (outlines, plane sets, heights),
    portals, stairs and contents; the walking graph rebuilt and the tour walked again.

    The layout is not cut again in the city's frame, so the interior of a crossing
    scene has exactly the cells, portals and contents of the interior alone.
    """
    lay = baked.layout
    cells = [
        RoomCell(c.id, c.kind, c.name, c.room, c.storey, p.xy(c.outline), c.zmin + p.dz, c.zmax + p.dz,
                 _planes(c.planes, p))
        for c in lay.cells
    ]
    portals = [Portal(q.id, q.kind, q.a, q.b, p.xyz(q.polygon), q.source, q.name) for q in lay.portals]
    stairs = [StairLink(st.portal, st.lower, st.upper, p.xyz(st.path), st.name) for st in lay.stairs]
    layout = RoomLayout(cells, portals, stairs, lay.ranges + p.dz, list(lay.notes), lay.sources)
    parts = {cid: [(e, m, p.xyz(v), t) for e, m, v, t in ps] for cid, ps in baked.parts.items()}
    graph = RoomGraph(cells, portals, stairs)
    walk, coverage = tour(graph, baked.start)
    return InteriorParts(layout, parts, list(baked.notes), graph, baked.start, walk, coverage)


def _planes(planes: F64, p: Placement) -> F64:
    """Plane rows ``(nx, ny, nz, d)`` (inside where ``n . x + d <= 0``) after the move."""
    if not len(planes):
        return np.asarray(planes, np.float64).reshape(0, 4)
    n = np.column_stack([p.xy(planes[:, :2]) - np.asarray(p.shift), planes[:, 2]])
    t = np.array([p.shift[0], p.shift[1], p.dz])
    return np.column_stack([n, planes[:, 3] - n @ t])
