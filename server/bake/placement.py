"""An interior placed in a city building's footprint, its entrance facing the street.

The interior is moved rigidly (a turn about the vertical and a shift; its lowest
floor put on the city's ground, z = 0) so that

1. its **entrance** (an outer door of :func:`entrance_doors`: a doorway cell with a
   door portal to the outside, on the lowest storey that has one) faces out of one
   edge of the building's footprint, the shell's front on that edge: the door's outer
   face flush with the facade, or behind it by as much as the shell reaches out in
   front of the door (a porch, a roof); the entrance's floor is put on the city's
   ground;
2. the interior's **shell** (the plan of its walls, slabs and roof) reaches at most
   :data:`FIT_TOLERANCE` outside the footprint and overlaps no street cell and no
   other building (5 cm of slack) — what *fits* means;
3. along each footprint edge long enough for the door, the door's middle is tried
   every half metre (and with the shell centred, flush with either end, centred on
   the footprint's centroid); on an edge the position that **matches** best is kept
   (the placed shell and the footprint: area of intersection over area of union), and
   of the edges the one whose point just in front of the door is **nearest a street**,
   crossroad or square cell (ties: the better match, then the earlier edge in the
   footprint's vertex order): :func:`fit_in_footprint`.

Which building and which door are :mod:`~.siting`'s choice.

:func:`moved` moves a baked interior (cells, plane sets, portals, stairs, contents)
rather than cutting the moved model into cells again: room layout is not exactly
invariant under a turn (touching tolerances), and the interior should stay the one
that was baked alone.

A generated office (``walkstream generate interior``) is laid out along x with its
entrance in the west wall: generate it with ``--size LxW`` no larger than the
building's footprint less 0.6 m each way (the outer walls), ``W`` along the street;
when it does not fit, :func:`misfit` says the footprint's size, and
:func:`~.siting.office_size` finds the largest size some building of a city takes
(the bake names it when no building holds the interior).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import shapely

from walkstream.server.bake.interior import InteriorParts
from walkstream.server.bake.roomlayout import Portal, RoomCell, RoomLayout, StairLink
from walkstream.server.bake.roomnav import RoomGraph
from walkstream.server.bake.roomwalks import entrance_cell, tour
from walkstream.server.sources.interior import InteriorScene, mesh_footprint
from walkstream.shared.arrays import F64
from walkstream.shared.errors import InputError

__all__ = [
    "MAX_ENTRANCE_GAP",
    "FIT_TOLERANCE",
    "EntranceDoor",
    "Fit",
    "Placement",
    "door_face",
    "entrance_door",
    "entrance_doors",
    "fit_in_footprint",
    "interior_shell",
    "misfit",
    "moved",
    "place_in_footprint",
]

MAX_ENTRANCE_GAP = 10.0
"""Metres from the facade in front of the door to the nearest street cell, at most (a
front garden; :mod:`~.frontpath` lays a path cell across it)."""
FIT_TOLERANCE = 1.0
"""Metres the placed shell may reach outside the building's footprint (a footprint
traced from aerial images is about this far off the architect's outline)."""

_SLACK = 0.05  # the shell may touch a street cell or a neighbour this much (metres)
_STEP = 0.5  # metres between the positions tried along a facade
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


def entrance_doors(layout: RoomLayout) -> list[EntranceDoor]:
    """The outer doors the interior may be entered by, in order of preference.

    An outer door is a door portal between a doorway cell and the ``outside`` cell (in
    an IFC model: an ``IfcDoor`` that bounds a space and the outside).  Only those of
    the lowest storey that has one are entrances; of them first the doors next to the
    room a tour starts in, then by portal id.

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
    doors.sort(key=lambda p: (p.a + p.b - out not in next_to_room, p.id))
    return [_door_face(p, cells[p.a + p.b - out]) for p in doors]


def entrance_door(layout: RoomLayout, portal: int | None = None) -> EntranceDoor:
    """The outer door the interior is entered by: the first of :func:`entrance_doors`,
    or the one whose portal id is ``portal``.

    Raises
    ------
    InputError
        No doorway of the interior has a door to the outside (or none by ``portal``).
    """
    doors = entrance_doors(layout)
    if portal is None:
        return doors[0]
    hit = [d for d in doors if d.portal == portal]
    if not hit:
        raise InputError(f"the interior has no outer door by portal {portal}")
    return hit[0]


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


def interior_shell(scene: InteriorScene) -> shapely.Polygon:
    """The plan of an interior's walls, slabs and roof (its outer outline, holes filled).

    One polygon: of a plan in parts (a detached shed) the largest, which is what is
    fitted to the footprint and what the stand-in lies inside (a smaller occluder
    keeps the PVS conservative)."""
    parts = [mesh_footprint(e.vertices, e.triangles) for e in scene.elements if e.kind in _SHELL_KINDS and len(e.triangles)]
    parts = [p for p in parts if not p.is_empty]
    if not parts:
        pts = np.concatenate([r.outline for r in scene.rooms])
        return shapely.MultiPoint(pts).convex_hull
    return _outer(shapely.union_all(parts))


@dataclass(frozen=True)
class Fit:
    """One placement of an interior in a footprint and how well it matches.

    ``gap``: metres from the point just in front of the door to the nearest street
    cell; ``match``: the placed shell's plan and the footprint, area of their
    intersection over area of their union (1 = the same outline); ``overhang``:
    metres the shell reaches outside the footprint at most."""

    placement: Placement
    gap: float
    match: float
    overhang: float


def fit_in_footprint(
    door: EntranceDoor,
    shell: shapely.Geometry,
    footprint: F64,
    streets: Sequence[shapely.Geometry],
    *,
    obstacles: Sequence[shapely.Geometry] = (),
    dz: float = 0.0,
) -> Fit | None:
    """The best placement of the module docstring, or None when the shell fits the
    footprint nowhere with its door on a facade.

    Parameters
    ----------
    door, shell:
        The interior's entrance (:func:`entrance_door`) and shell (:func:`interior_shell`),
        in the interior's own frame.
    footprint:
        ``(n, 2)`` the building's outer ring, city-local metres.
    streets:
        The city's street, crossroad and square cells as polygons.
    obstacles:
        What the placed shell may not overlap besides the street cells: the other
        buildings' footprints.
    dz:
        Added to every height (the interior's lowest floor onto the ground).
    """
    ring = np.asarray(footprint, np.float64).reshape(-1, 2)
    poly = shapely.Polygon(ring)
    if not poly.is_valid:
        poly = shapely.make_valid(poly)
    shapely.prepare(poly)
    ccw = shapely.Polygon(ring).exterior.is_ccw
    width = float(np.hypot(*(door.ends[1] - door.ends[0])))
    outline = np.asarray(_outer(shell).exterior.coords)
    centre = np.asarray(_outer(shell).centroid.coords)[0]
    fp_centre = np.asarray(poly.centroid.coords)[0]
    tree = shapely.STRtree(list(streets)) if len(streets) else None
    blocks = [*streets, *obstacles]
    block_tree = shapely.STRtree(blocks) if blocks else None
    facades: list[Fit] = []
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
        moved_pts = turned.xy(outline)
        along = (moved_pts - mid) @ u
        # a door recessed behind the shell's front (a porch, a roof reaching out) sits
        # that far behind the facade
        recess = max(0.0, float(((moved_pts - mid) @ out).max()))
        lo, hi = float(along.min()), float(along.max())
        here: list[Fit] = []
        for t in _positions(length, width, lo, hi, float((fp_centre - a) @ u - (turned.xy(centre[None])[0] - mid) @ u)):
            at = a + u * t
            door_at = at - out * recess
            p = Placement(angle, (float(door_at[0] - mid[0]), float(door_at[1] - mid[1])), dz)
            placed = shapely.Polygon(p.xy(outline))
            over = float(shapely.distance(poly, shapely.points(p.xy(outline))).max())
            if over > FIT_TOLERANCE + 1e-9:
                continue
            if block_tree is not None and len(block_tree.query(placed.buffer(-_SLACK, join_style="mitre"),
                                                                predicate="intersects")):
                continue
            union = float(shapely.union(placed, poly).area)
            match = float(shapely.intersection(placed, poly).area) / max(union, 1e-12)
            front = shapely.Point(at + out * _FRONT)
            gap = math.inf
            if tree is not None:
                near = int(tree.query_nearest(front)[0])
                gap = float(shapely.distance(streets[near], front))
            here.append(Fit(p, gap, match, over))
        if here:
            # on a facade the best match (ties: the door nearer a street)
            facades.append(min(here, key=lambda f: (-round(f.match, 3), f.gap)))
    # of the facades, the one whose door is nearest a street (ties: the better match,
    # then the earlier edge)
    return min(facades, key=lambda f: (round(f.gap, 3), -round(f.match, 3)), default=None)


def _outer(shell: shapely.Geometry) -> shapely.Polygon:
    """The shell as one polygon: its largest part, holes left out."""
    parts = [g for g in shapely.get_parts(shell) if isinstance(g, shapely.Polygon)]
    return shapely.Polygon(max(parts, key=lambda g: g.area).exterior)


def _positions(length: float, width: float, lo: float, hi: float, centred: float) -> list[float]:
    """Where the door's middle is tried along a facade ``length`` long: the shell
    centred on the facade, flush with either end, centred on the footprint's centroid,
    and every :data:`_STEP` metres between, each with the whole door on the facade."""
    first, last = 0.5 * width, length - 0.5 * width
    ts = [0.5 * (length - lo - hi), -lo, length - hi, centred]
    ts += list(np.arange(first, last + 1e-9, _STEP))
    return [float(t) for t in dict.fromkeys(round(t, 6) for t in ts) if first - 1e-9 <= t <= last + 1e-9]


def place_in_footprint(
    door: EntranceDoor,
    shell: shapely.Geometry,
    footprint: F64,
    streets: Sequence[shapely.Geometry],
    *,
    obstacles: Sequence[shapely.Geometry] = (),
    dz: float = 0.0,
    what: str = "the building",
) -> tuple[Placement, float]:
    """The placement of :func:`fit_in_footprint` and the gap (metres) from the facade in
    front of the door to the nearest street cell.

    Raises
    ------
    InputError
        The shell fits in the footprint nowhere with the door on a facade, or the
        door ends more than :data:`MAX_ENTRANCE_GAP` from a street.
    """
    fit = fit_in_footprint(door, shell, footprint, streets, obstacles=obstacles, dz=dz)
    if fit is None:
        raise InputError(f"the interior does not fit {what}: {misfit(door, shell, footprint)}")
    if fit.gap > MAX_ENTRANCE_GAP:
        raise InputError(
            f"the entrance of the interior in {what} is {fit.gap:.1f} m from the nearest street cell "
            f"(at most {MAX_ENTRANCE_GAP:g} m): pick a building on a street"
        )
    return fit.placement, fit.gap


def misfit(door: EntranceDoor, shell: shapely.Geometry, footprint: F64) -> str:
    """Why a shell fits a footprint nowhere: the two sizes (sides of their smallest
    enclosing rectangles) and which rule failed (the tolerance, or the street cells and
    neighbours when the footprint alone would take it)."""
    own = _sides(_outer(shell))
    sides = _sides(shapely.Polygon(np.asarray(footprint, np.float64).reshape(-1, 2)))
    sizes = f"its outline ({own[0]:.1f} x {own[1]:.1f} m outside its walls) against the footprint's ({sides[0]:.1f} x {sides[1]:.1f} m)"
    if fit_in_footprint(door, shell, footprint, []) is None:
        return f"{sizes} leaves it more than {FIT_TOLERANCE:g} m outside wherever a door of it is on a facade"
    return f"{sizes}: wherever it is within {FIT_TOLERANCE:g} m of the footprint it stands over a street cell or a neighbour"


def _sides(g: shapely.Geometry) -> tuple[float, float]:
    c = np.asarray(g.minimum_rotated_rectangle.exterior.coords)[:3]
    s = sorted((float(np.hypot(*(c[1] - c[0]))), float(np.hypot(*(c[2] - c[1])))), reverse=True)
    return s[0], s[1]


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
