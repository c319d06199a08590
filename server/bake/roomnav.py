"""Walking through an interior: from room to room through doors and open portals, up stairs.

:class:`RoomGraph` is built from a baked interior's cells, portals and stairs (as the
bake makes them or as the scene database gives them back).  Its nodes are the
middles of the walkable portals at floor level (a door's threshold: the middle of the
portal's bottom edge, on the portal; the middle of an open stretch between two rooms),
the centre of every room cell and the two ends of every stair; within a convex cell
every pair of its nodes is joined, and a stair joins its ends along its walking line.
Routes are shortest paths (the one Dijkstra of :mod:`walkstream.shared.nav`).

A walker has a body: a leg inside a cell keeps :data:`CLEARANCE` (0.3 m, a person's
half-width) from the cell's walls and from what stands in it (the obstacles given:
furniture, machines, columns).  Each node steps into the cell to its nearest point of
the cell's walkable floor (the outline shrunk by the clearance, less the obstacles
grown by it: :func:`~.floorroute.walkable_floor`; straight through a door, since the
door's node is in its middle), and the leg runs between those points: straight where
the floor holds the line, else bent around the obstacles on the shortest way
(:class:`~.floorroute.FloorRoutes`).  A cell too narrow for the clearance (a doorway
through a wall, a slim leftover), or two nodes that furniture parts, is crossed on the
straight line between its nodes, as before.

Positions are located in 3D: a point's height picks the storey (the cells' height
ranges), its ``x, y`` the cell among that storey's; a recorded walk keeps its eye
:data:`EYE_HEIGHT` above the floor it walks on (the storey's floor, or a stair's
treads).
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence

import numpy as np
import shapely
import shapely.ops

from walkstream.server.bake.floorroute import FloorObstacle, FloorRoutes, walkable_floor
from walkstream.server.bake.roomlayout import Portal, RoomCell, StairLink
from walkstream.shared.arrays import F64
from walkstream.shared.cells import CellLocator
from walkstream.shared.errors import RouteError
from walkstream.shared.nav import shortest_paths
from walkstream.shared.paths import RecordedPath, wrap_angle

__all__ = [
    "CLEARANCE",
    "EYE_HEIGHT",
    "INDOOR_SPEED_KMH",
    "RoomGraph",
    "walk_path",
]

EYE_HEIGHT = 1.6
"""Eye height of a walker indoors, above the floor under it (metres)."""
INDOOR_SPEED_KMH = 4.0
"""Walking speed indoors (km/h)."""
CLEARANCE = 0.3
"""How far a walk inside a cell keeps from the cell's walls (metres): a person's half-width."""

_WALKABLE = frozenset({"door", "opening", "virtual", "split", "wall"})


class RoomGraph:
    """Routes through an interior (see the module docstring).

    Parameters
    ----------
    cells, portals, stairs:
        The interior (:func:`~.rooms.room_layout`'s, or read back from a scene
        database); the ``outside`` cell is ignored.
    obstacles:
        What stands on the floors (a cell's legs go around those that block its floor).
    """

    def __init__(
        self, cells: Sequence[RoomCell], portals: Sequence[Portal], stairs: Sequence[StairLink],
        obstacles: Sequence[FloorObstacle] = (),
    ) -> None:
        self.obstacles = list(obstacles)
        self._free: dict[int, shapely.Geometry | None] = {}
        self._routes: dict[int, FloorRoutes] = {}
        self.cells = {c.id: c for c in cells if c.kind != "outside"}
        ids = sorted(self.cells)
        self.locator = CellLocator(
            ids, [self.cells[i].outline for i in ids], [[self.cells[i].zmin, self.cells[i].zmax] for i in ids]
        )
        self.nodes: list[F64] = []
        self.node_cell: list[int] = []
        self.centre: dict[int, int] = {}
        members: dict[int, list[int]] = {i: [] for i in ids}
        self.members = members
        self.adj: dict[int, list[tuple[int, float, F64 | None]]] = {}
        for p in portals:
            if p.kind not in _WALKABLE or p.a not in self.cells or p.b not in self.cells:
                continue
            mid = _bottom_middle(p.polygon)
            z = max(self.cells[p.a].zmin, self.cells[p.b].zmin)
            n = self._node([mid[0], mid[1], z], p.a, members)
            members[p.b].append(n)
        for s in stairs:
            if s.lower not in self.cells or s.upper not in self.cells:
                continue
            a = self._node(s.path[0], s.lower, members)
            b = self._node(s.path[-1], s.upper, members)
            length = float(np.linalg.norm(np.diff(s.path, axis=0), axis=1).sum())
            self._edge(a, b, length, s.path)
        # the doors' and stairs' nodes first: they say which pieces of a floor are walked
        # (:meth:`free`), so a room's middle steps onto a piece a door leads to
        rooms = [i for i in ids if self.cells[i].kind == "room"]
        # a cell of a room with no floor to stand on (an alcove its cupboards fill) is no
        # place to walk to where another cell of the room has some: the room is visited there
        roomy = {self.cells[i].room for i in rooms if self.free(i) is not None}
        for i in rooms:
            c = self.cells[i]
            if self.free(i) is None and c.room in roomy:
                continue
            poly = shapely.Polygon(c.outline)
            mp = poly.centroid if poly.contains(poly.centroid) else poly.representative_point()
            # a room's middle is often its table's (or its stair's): the walk goes to the
            # nearest free floor
            self.centre[i] = self._node(self.step_in(i, np.array([mp.x, mp.y, c.zmin])), i, members)
        for cid, nodes in members.items():
            for x in range(len(nodes)):
                for y in range(x + 1, len(nodes)):
                    self._leg(cid, nodes[x], nodes[y])

    def _leg(self, cell: int, a: int, b: int) -> None:
        """Join nodes ``a`` and ``b`` of ``cell`` by a leg that keeps the clearance."""
        pa, pb = self.step_in(cell, self.nodes[a]), self.step_in(cell, self.nodes[b])
        inner = np.array([pa, pb])
        free = self.free(cell)
        if free is not None:
            if cell not in self._routes:
                self._routes[cell] = FloorRoutes(free)
            bent = self._routes[cell].route(pa, pb)
            if bent is not None and len(bent) > 2:
                s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(bent, axis=0), axis=1))])
                z = pa[2] + (pb[2] - pa[2]) * s / max(float(s[-1]), 1e-12)
                inner = np.column_stack([bent, z])
        line = np.concatenate([self.nodes[a][None], inner, self.nodes[b][None]])
        keep = np.concatenate([[True], np.linalg.norm(np.diff(line, axis=0), axis=1) > 1e-6])
        line = line[keep]
        if len(line) < 2:
            line = np.array([self.nodes[a], self.nodes[b]])
        self._edge(a, b, float(np.linalg.norm(np.diff(line, axis=0), axis=1).sum()), line)

    def free(self, cell: int) -> shapely.Geometry | None:
        """The part of ``cell``'s floor a walker's middle may stand on: its outline shrunk
        by :data:`CLEARANCE`, less the obstacles on its floor grown by it
        (:func:`~.floorroute.walkable_floor`); None where nothing is left (a doorway, a
        slim cell)."""
        if cell not in self._free:
            c = self.cells[cell]
            outline = shapely.Polygon(c.outline)
            feet = [o.footprint for o in self.obstacles if o.blocks(c.zmin) and o.footprint.intersects(outline)]
            self._free[cell] = _reached(walkable_floor(outline, feet, CLEARANCE),
                                        [self.nodes[n] for n in self.members.get(cell, ())])
        return self._free[cell]

    def step_in(self, cell: int, xyz: F64) -> F64:
        """Where a walker at floor point ``xyz`` of ``cell`` stands with its clearance: the
        nearest point of :meth:`free` (``xyz`` itself where it is in it, or none is left)."""
        free = self.free(cell)
        if free is None:
            return xyz
        p = shapely.Point(float(xyz[0]), float(xyz[1]))
        if free.covers(p):
            return xyz
        q = shapely.ops.nearest_points(free, p)[0]
        return np.array([q.x, q.y, xyz[2]], dtype=np.float64)

    def _node(self, xyz: Sequence[float] | F64, cell: int, members: dict[int, list[int]]) -> int:
        self.nodes.append(np.asarray(xyz, dtype=np.float64).reshape(3))
        self.node_cell.append(cell)
        members[cell].append(len(self.nodes) - 1)
        return len(self.nodes) - 1

    def _edge(self, a: int, b: int, cost: float, line: F64 | None) -> None:
        self.adj.setdefault(a, []).append((b, cost, line))
        self.adj.setdefault(b, []).append((a, cost, None if line is None else line[::-1]))

    # -- locating -----------------------------------------------------------

    def locate(self, x: float, y: float, z: float) -> int | None:
        """The cell at an eye (or any) position; ``None`` outside every cell."""
        return self.locator.locate(x, y, z)

    def room_cells(self, name: str) -> list[int]:
        """Room cells whose room name is ``name`` (any case), else contains it (if that is
        one room); largest first.

        Raises
        ------
        RouteError
            No room, or several rooms, match (the message lists some).
        """
        want = name.strip().lower()
        rooms = {c.name for c in self.cells.values() if c.kind == "room"}
        exact = [r for r in rooms if r.lower() == want]
        match = exact or [r for r in rooms if want in r.lower()]
        if not match:
            sample = ", ".join(sorted(rooms)[:8])
            raise RouteError(f"no room named {name!r} (rooms: {sample}{', ...' if len(rooms) > 8 else ''})")
        if len(set(match)) > 1:
            raise RouteError(f"room {name!r} is ambiguous: {', '.join(sorted(match)[:6])}")
        cells = [c for c in self.cells.values() if c.kind == "room" and c.name == match[0]]
        return [c.id for c in sorted(cells, key=lambda c: -shapely.Polygon(c.outline).area)]

    # -- routing ------------------------------------------------------------

    def _start_node(self, cell: int, xyz: F64 | None) -> int:
        if xyz is None:
            return self.centre.get(cell, next(n for n, c in enumerate(self.node_cell) if c == cell))
        others = list(self.members[cell])
        n = self._node(xyz, cell, self.members)
        for m in others:
            self._leg(cell, n, m)
        return n

    def distances(self, start: int) -> tuple[dict[int, float], dict[int, int]]:
        """Dijkstra (:func:`~walkstream.shared.nav.shortest_paths`) from node ``start``: ``(distance,
        previous node)`` of every reachable node."""
        adj = self.adj

        def expand(n: int, d: float) -> Iterator[tuple[int, float]]:
            for m, w, _ in adj.get(n, ()):
                yield m, d + w

        far, before = shortest_paths(len(self.nodes), [(start, 0.0)], expand, tol=1e-12)
        reached = np.flatnonzero(np.isfinite(far)).tolist()
        dist = {n: float(far[n]) for n in reached}
        prev = {n: int(before[n]) for n in reached if before[n] >= 0}
        return dist, prev

    def polyline(self, nodes: Sequence[int]) -> F64:
        """Floor points ``(k, 3)`` along a node sequence (stairs along their lines)."""
        pts = [self.nodes[nodes[0]]]
        for a, b in zip(nodes, nodes[1:], strict=False):
            line = next((ln for m, _, ln in self.adj.get(a, ()) if m == b and ln is not None), None)
            if line is not None:
                pts += list(line[1:])
            else:
                pts.append(self.nodes[b])
        return np.array(pts, dtype=np.float64)

    def route_nodes(self, a: int, b: int) -> list[int]:
        """Node sequence of the shortest route from node ``a`` to node ``b``.

        Raises
        ------
        RouteError
            ``b`` cannot be reached from ``a``.
        """
        dist, prev = self.distances(a)
        if b not in dist:
            raise RouteError(
                f"no route from {self.cells[self.node_cell[a]].name} to {self.cells[self.node_cell[b]].name}: "
                "no walkable door, opening or stair connects them"
            )
        out = [b]
        while out[-1] != a:
            out.append(prev[out[-1]])
        return out[::-1]

    def route(self, start: F64 | int, end: F64 | int) -> F64:
        """Floor points ``(k, 3)`` of the shortest walk between two cells (ids: from or to
        their centre) or two eye positions ``(3,)`` (located in 3D).

        Raises
        ------
        RouteError
            A position outside every cell, or no walkable connection.
        """
        nodes = []
        for p in (start, end):
            if isinstance(p, int | np.integer):
                nodes.append(self._start_node(int(p), None))
                continue
            q = np.asarray(p, dtype=np.float64).reshape(3)
            cid = self.locate(float(q[0]), float(q[1]), float(q[2]))
            if cid is None:
                raise RouteError(f"({q[0]:.2f}, {q[1]:.2f}, {q[2]:.2f}) is outside every cell of the interior")
            floor = self.cells[cid].zmin
            nodes.append(self._start_node(cid, np.array([q[0], q[1], floor])))
        return self.polyline(self.route_nodes(nodes[0], nodes[1]))


def _reached(free: shapely.Geometry | None, entries: Sequence[F64]) -> shapely.Geometry | None:
    """The pieces of a walkable floor ``free`` that a walker coming in at floor points
    ``entries`` (a cell's doors and stairs) steps onto: each entry's nearest piece.  A piece
    no entry leads to (beyond a stair that fills the room's middle, behind furniture wall
    to wall) is not walked to; with no entry, every piece is kept."""
    pieces = list(getattr(free, "geoms", [free])) if free is not None else []
    if len(pieces) < 2 or not entries:
        return free
    keep = sorted({int(np.argmin([g.distance(shapely.Point(float(e[0]), float(e[1]))) for g in pieces]))
                   for e in entries})
    return pieces[keep[0]] if len(keep) == 1 else shapely.MultiPolygon([pieces[k] for k in keep])


def _bottom_middle(polygon: F64) -> F64:
    """The middle of a portal's bottom edge ``(2,)``: halfway between the two farthest
    apart points at its lowest height (a door's threshold, however many vertices lie on it)."""
    bottom = polygon[polygon[:, 2] <= polygon[:, 2].min() + 1e-6][:, :2]
    if len(bottom) < 2:
        return polygon[:, :2].mean(axis=0)
    d = np.linalg.norm(bottom[:, None, :] - bottom[None, :, :], axis=2)
    i, j = np.unravel_index(int(np.argmax(d)), d.shape)
    return 0.5 * (bottom[i] + bottom[j])


def walk_path(name: str, floor: F64, speed_kmh: float = INDOOR_SPEED_KMH, eye: float = EYE_HEIGHT) -> RecordedPath:
    """A recorded path along floor points ``(k, 3)``, the eye ``eye`` above them.

    Timed and turned like :meth:`RecordedPath.from_polyline` over the ground plan (its
    turns on the spot kept: a U-turn is made standing, also on a walk with stairs);
    key points are added where the floor starts or stops rising (a stair's ends), so
    that the eye follows the treads and not a straight line between far-apart key
    points.
    """
    pts = np.asarray(floor, dtype=np.float64).reshape(-1, 3)
    keep = np.concatenate([[True], np.hypot(*np.diff(pts[:, :2], axis=0).T) > 1e-3])
    pts = pts[keep]
    base = RecordedPath.from_polyline(name, pts[:, :2], speed_kmh, eye)
    t, xyz, yaw, pitch = base.t, base.xyz, base.yaw, base.pitch
    # arclength of every floor point and of every key (keys follow the polyline in order)
    s_pts = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts[:, :2], axis=0).T))])
    s_key = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xyz[:, :2], axis=0).T))])
    s_key = np.minimum(s_key, s_pts[-1])
    # where the slope of the floor changes, a key point of its own
    slope = np.diff(pts[:, 2]) / np.maximum(np.diff(s_pts), 1e-9)
    breaks = s_pts[1:-1][np.abs(np.diff(slope)) > 1e-6]
    extra = [s for s in breaks if np.min(np.abs(s_key - s)) > 1e-3]
    if extra:
        # the new keys lie strictly between keys of distinct arclength, so their time and
        # place interpolate along the legs; the keys already there keep theirs, those of a
        # turn on the spot (equal arclength, increasing times) included
        s_new = np.asarray(extra, dtype=np.float64)
        seg = np.clip(np.searchsorted(s_key, s_new, side="right") - 1, 0, len(s_key) - 2)
        f = (s_new - s_key[seg]) / np.maximum(s_key[seg + 1] - s_key[seg], 1e-12)
        t_new = t[seg] + f * (t[seg + 1] - t[seg])
        xy_new = xyz[seg, :2] + f[:, None] * (xyz[seg + 1, :2] - xyz[seg, :2])
        # between keys the yaw is steady except over a walked corner: interpolate it the short way
        yaw_new = wrap_angle(yaw[seg] + f * wrap_angle(yaw[seg + 1] - yaw[seg]))
        order = np.argsort(np.concatenate([t, t_new]), kind="stable")
        t = np.concatenate([t, t_new])[order]
        xy = np.concatenate([xyz[:, :2], xy_new])[order]
        yaw = np.concatenate([yaw, yaw_new])[order]
        s_key = np.concatenate([s_key, s_new])[order]
        xyz = np.column_stack([xy, np.zeros(len(t))])
        pitch = np.zeros(len(t))
    z = np.interp(s_key, s_pts, pts[:, 2]) + eye
    xyz = np.column_stack([xyz[:, 0], xyz[:, 1], z])
    return RecordedPath(name, t, xyz, yaw, pitch, base.speed_kmh)
