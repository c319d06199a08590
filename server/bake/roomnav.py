"""Walking through an interior: from room to room through doors and open portals, up stairs.

:class:`RoomGraph` is built from a baked interior's cells, portals and stairs (as the
bake makes them or as the scene database gives them back).  Its nodes are the
middles of the walkable portals at floor level (a door's threshold, the middle of an
open stretch between two rooms), the centre of every room cell and the two ends of
every stair; within a convex cell every pair of its nodes is joined by a straight
line (it stays inside the cell), and a stair joins its ends along its walking line.
Routes are shortest paths (the one Dijkstra of :mod:`walkstream.shared.nav`).

Positions are located in 3D: a point's height picks the storey (the cells' height
ranges), its ``x, y`` the cell among that storey's; a recorded walk keeps its eye
:data:`EYE_HEIGHT` above the floor it walks on (the storey's floor, or a stair's
treads).
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence

import numpy as np
import shapely

from walkstream.server.bake.rooms import Portal, RoomCell, StairLink
from walkstream.shared.arrays import F64
from walkstream.shared.cells import CellLocator
from walkstream.shared.errors import RouteError
from walkstream.shared.nav import shortest_paths
from walkstream.shared.paths import RecordedPath

__all__ = [
    "EYE_HEIGHT",
    "INDOOR_SPEED_KMH",
    "RoomGraph",
    "walk_path",
]

EYE_HEIGHT = 1.6
"""Eye height of a walker indoors, above the floor under it (metres)."""
INDOOR_SPEED_KMH = 4.0
"""Walking speed indoors (km/h)."""

_WALKABLE = frozenset({"door", "opening", "virtual", "split"})


class RoomGraph:
    """Routes through an interior (see the module docstring).

    Parameters
    ----------
    cells, portals, stairs:
        The interior (:func:`~.rooms.room_layout`'s, or read back from a scene
        database); the ``outside`` cell is ignored.
    """

    def __init__(self, cells: Sequence[RoomCell], portals: Sequence[Portal], stairs: Sequence[StairLink]) -> None:
        self.cells = {c.id: c for c in cells if c.kind != "outside"}
        ids = sorted(self.cells)
        self.locator = CellLocator(
            ids, [self.cells[i].outline for i in ids], [[self.cells[i].zmin, self.cells[i].zmax] for i in ids]
        )
        self.nodes: list[F64] = []
        self.node_cell: list[int] = []
        self.centre: dict[int, int] = {}
        members: dict[int, list[int]] = {i: [] for i in ids}
        for i in ids:
            c = self.cells[i]
            if c.kind == "room":
                poly = shapely.Polygon(c.outline)
                p = poly.centroid if poly.contains(poly.centroid) else poly.representative_point()
                self.centre[i] = self._node([p.x, p.y, c.zmin], i, members)
        self.adj: dict[int, list[tuple[int, float, F64 | None]]] = {}
        for p in portals:
            if p.kind not in _WALKABLE or p.a not in self.cells or p.b not in self.cells:
                continue
            bottom = p.polygon[p.polygon[:, 2] <= p.polygon[:, 2].min() + 1e-6]
            mid = bottom[:, :2].mean(axis=0) if len(bottom) else p.polygon[:, :2].mean(axis=0)
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
        self.members = members
        for nodes in members.values():
            for x in range(len(nodes)):
                for y in range(x + 1, len(nodes)):
                    a, b = nodes[x], nodes[y]
                    self._edge(a, b, float(np.linalg.norm(self.nodes[a] - self.nodes[b])), None)

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
            self._edge(n, m, float(np.linalg.norm(self.nodes[n] - self.nodes[m])), None)
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


def walk_path(name: str, floor: F64, speed_kmh: float = INDOOR_SPEED_KMH, eye: float = EYE_HEIGHT) -> RecordedPath:
    """A recorded path along floor points ``(k, 3)``, the eye ``eye`` above them.

    Timed and turned like :meth:`RecordedPath.from_polyline` over the ground plan;
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
        s_all = np.concatenate([s_key, extra])
        order = np.argsort(s_all, kind="stable")
        tt = np.interp(s_all, s_key, t)[order]
        xx = np.interp(s_all, s_key, xyz[:, 0])[order]
        yy = np.interp(s_all, s_key, xyz[:, 1])[order]
        # yaw: take the key before (turns happen at keys; between them the yaw is steady)
        idx = np.clip(np.searchsorted(s_key, s_all, side="right") - 1, 0, len(yaw) - 1)
        idx[: len(s_key)] = np.arange(len(s_key))
        ww = yaw[idx][order]
        s_sorted = s_all[order]
        # keys with the same arclength (turning on the spot) keep their time order
        t, xyz, yaw = tt, np.column_stack([xx, yy, np.zeros(len(tt))]), ww
        s_key = s_sorted
        pitch = np.zeros(len(t))
        _, first = np.unique(np.round(t, 9), return_index=True)
        t, xyz, yaw, pitch, s_key = t[first], xyz[first], yaw[first], pitch[first], s_key[first]
    z = np.interp(s_key, s_pts, pts[:, 2]) + eye
    xyz = np.column_stack([xyz[:, 0], xyz[:, 1], z])
    return RecordedPath(name, t, xyz, yaw, pitch, base.speed_kmh)
