"""The navigation graph of a scene's view cells: routes from point to point through the cells.

The nodes are the view cells and the edges join neighbour cells through their
*portal*, the boundary segment the two cells share.  A route from a point to a point
runs from the start through the midpoints of the portals it crosses to the end.
Every cell is convex, so each leg (between two points on the boundary of, or inside,
one cell) stays inside that cell: on street cells a route never leaves the street
space and never passes through a building.  (Grid cells also cover parts of
building blocks, so there a route is only as good as the grid.)

The search is Dijkstra over portal crossings: crossing cell ``c`` from portal ``p``
to portal ``q`` costs the distance between the two midpoints, plus
:data:`TURN_COST` metres per radian that the leg turns away from straight through
the portals (so a route keeps to one street instead of zig-zagging through a grid
city, where many staircases are equally short).  The polyline is then straightened:
a vertex is dropped when it lies within :data:`STRAIGHTEN_TOL` of the line through
its kept neighbours and that line stays inside the route's cells.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import shapely
from numpy.typing import ArrayLike, NDArray

from walkstream.server.bake.viewcell import ViewCell, cell_locator, cell_polygons
from walkstream.server.store import CellInfo
from walkstream.shared.arrays import F64, I64
from walkstream.shared.errors import InputError, RouteError
from walkstream.shared.nav import shortest_paths

__all__ = ["TURN_COST", "STRAIGHTEN_TOL", "Route", "CellGraph"]


#: Metres of extra cost per radian of turning inside a cell (about 16 m per corner).
TURN_COST = 10.0
#: Metres a dropped vertex may lie off the straightened polyline.
STRAIGHTEN_TOL = 1.0
# tolerance (metres) for two cells' boundaries to count as shared
_SHARED_TOL = 1e-4
# portals shorter than this (metres) are not walked through
_MIN_PORTAL = 0.5




@dataclass(frozen=True)
class Route:
    """A route through the cells.

    Attributes
    ----------
    xy:
        ``(k, 2) float64`` polyline, scene-local metres, start to end.
    cells:
        Ids of the cells the route passes through, in order (each once per visit).
    """

    xy: F64
    cells: tuple[int, ...]

    @property
    def length(self) -> float:
        """Length of the polyline in metres."""
        return _polyline_length(self.xy)


# --------------------------------------------------------------------------- the graph


def _view_cells(cells: Iterable[ViewCell | CellInfo]) -> list[ViewCell]:
    out = []
    for c in cells:
        if isinstance(c, ViewCell):
            out.append(c)
            continue
        try:
            out.append(
                ViewCell(
                    id=c.id,
                    kind=c.kind,
                    polygon=c.boundary,
                    zmin=c.zmin,
                    zmax=c.zmax,
                    neighbours=tuple(int(n) for n in c.neighbours),
                )
            )
        except ValueError as exc:
            raise InputError(f"cell {c.id}: cannot be used for routes ({exc})") from exc
    out.sort(key=lambda c: c.id)
    return out


def _angle(ux: float, uy: float, vx: float, vy: float) -> float:
    """Unsigned angle between two vectors (0 for a zero vector)."""
    return abs(math.atan2(ux * vy - uy * vx, ux * vx + uy * vy))


def _polyline_length(xy: F64) -> float:
    return float(np.hypot(*np.diff(xy, axis=0).T).sum()) if len(xy) > 1 else 0.0


class CellGraph:
    """The navigation graph of a scene's view cells (see the module docstring).

    Parameters
    ----------
    cells:
        The cells: :class:`~walkstream.server.bake.viewcell.ViewCell` (during the bake) or
        :class:`~walkstream.server.store.records.CellInfo` (``SceneReader.cells()``).

    Attributes
    ----------
    cells:
        The cells as :class:`~walkstream.server.bake.viewcell.ViewCell`, sorted by id.  Internally
        cells are referred to by their *position* in this list; ``index`` maps a
        cell id to its position and ``ids`` a position to its id.
    portal_cells:
        ``(m, 2) int64`` positions of the two cells ``(a, b)`` of each portal.
    portal_ends, portal_mid, portal_normal:
        ``(m, 2, 2)`` end points, ``(m, 2)`` midpoints and ``(m, 2)`` unit normals
        (pointing from ``a`` into ``b``) of the portals.
    cell_portals:
        For each cell position, the indices of its portals.

    Raises
    ------
    InputError
        No cells, or duplicate cell ids.
    """

    def __init__(self, cells: Iterable[ViewCell | CellInfo]) -> None:
        self.cells = _view_cells(cells)
        if not self.cells:
            raise InputError("routes need at least one view cell")
        ids = [c.id for c in self.cells]
        if len(set(ids)) != len(ids):
            raise InputError("cells: duplicate cell ids")
        self.index = {cid: k for k, cid in enumerate(ids)}
        self.ids = np.array(ids, dtype=np.int64)
        self.kinds = [c.kind for c in self.cells]
        self.polys = cell_polygons(self.cells)
        self.centroids = np.array([c.centroid for c in self.cells], dtype=np.float64)
        self.areas = np.array([c.area for c in self.cells], dtype=np.float64)
        self.locator = cell_locator(self.cells)
        self._tree = shapely.STRtree(self.polys)
        self._portals()

    def __len__(self) -> int:
        return len(self.cells)

    # -- portals -------------------------------------------------------------

    def _portals(self) -> None:
        """Shared boundary segment, midpoint and unit normal (a -> b) of each neighbour pair."""
        pairs = sorted(
            {
                (min(k, self.index[n]), max(k, self.index[n]))
                for k, c in enumerate(self.cells)
                for n in c.neighbours
                if n in self.index and n != c.id
            }
        )
        a = np.array([p[0] for p in pairs], dtype=np.int64)
        b = np.array([p[1] for p in pairs], dtype=np.int64)
        ends = np.zeros((len(pairs), 2, 2))
        ok = np.zeros(len(pairs), bool)
        if pairs:
            grown = shapely.buffer(self.polys[b], _SHARED_TOL, quad_segs=1, join_style="mitre")
            shared = shapely.intersection(shapely.boundary(self.polys[a]), grown)
            coords, which = shapely.get_coordinates(shared, return_index=True)
            bounds = np.searchsorted(which, np.arange(len(pairs) + 1))
            for k in range(len(pairs)):
                pts = coords[bounds[k] : bounds[k + 1]]
                if len(pts) < 2:
                    continue
                # the shared boundary of two convex cells is one segment: its ends
                # are the two points farthest apart
                p = pts[int(np.argmax(np.hypot(*(pts - pts[0]).T)))]
                q = pts[int(np.argmax(np.hypot(*(pts - p).T)))]
                if float(np.hypot(*(q - p))) >= _MIN_PORTAL:
                    ends[k] = (p, q)
                    ok[k] = True
        self.portal_cells = np.column_stack([a[ok], b[ok]]).reshape(-1, 2)
        self.portal_ends = ends[ok]
        self.portal_mid = self.portal_ends.mean(axis=1).reshape(-1, 2)
        seg = self.portal_ends[:, 1] - self.portal_ends[:, 0]
        normal = (
            np.column_stack([-seg[:, 1], seg[:, 0]])
            / np.maximum(np.hypot(seg[:, 0], seg[:, 1]), 1e-12)[:, None]
        )
        # orient from cell a into cell b
        towards = self.centroids[self.portal_cells[:, 1]] - self.portal_mid
        flip = np.einsum("ij,ij->i", normal, towards) < 0
        normal[flip] *= -1
        self.portal_normal = normal
        self.cell_portals: list[list[int]] = [[] for _ in self.cells]
        for k, (pa, pb) in enumerate(self.portal_cells.tolist()):
            self.cell_portals[pa].append(k)
            self.cell_portals[pb].append(k)

    # -- locating ------------------------------------------------------------

    def locate(self, xy: ArrayLike, what: str = "point") -> int:
        """Position (index into :attr:`cells`) of the cell containing a point.

        Raises
        ------
        RouteError
            The point is outside every cell (the message gives the nearest cell).
        """
        p = np.asarray(xy, dtype=np.float64).reshape(-1)
        if p.shape != (2,) or not np.isfinite(p).all():
            raise RouteError(f"{what}: expected finite X,Y, got {xy!r}")
        cid = self.locator.locate(float(p[0]), float(p[1]))
        if cid is None:
            pt = shapely.Point(p)
            near = int(self._tree.query_nearest(pt)[0])
            dist = float(shapely.distance(self.polys[near], pt))
            raise RouteError(
                f"{what} ({p[0]:.1f}, {p[1]:.1f}) is outside every view cell "
                f"(nearest: cell {self.cells[near].id}, {dist:.1f} m away)"
            )
        return self.index[cid]

    # -- search --------------------------------------------------------------

    def _state(self, k: int, into: int) -> int:
        # state 2k: crossed portal k from its cell a into b; 2k + 1: from b into a
        return 2 * k + (0 if self.portal_cells[k, 1] == into else 1)

    def _into(self, s: int) -> int:
        return int(self.portal_cells[s >> 1, 1 - (s & 1)])

    def _normal(self, s: int) -> tuple[float, float]:
        n = self.portal_normal[s >> 1]
        sign = 1.0 if s & 1 == 0 else -1.0
        return sign * float(n[0]), sign * float(n[1])

    def _search(
        self,
        start: F64,
        start_cell: int,
        *,
        target: F64 | None = None,
        target_cell: int = -1,
        allowed: NDArray[np.bool_] | None = None,
        factor: F64 | None = None,
        heading: tuple[float, float] | None = None,
        heading_cost: float = TURN_COST,
        turn_cost: float = TURN_COST,
    ) -> tuple[F64, I64, int, float]:
        """Dijkstra over portal crossings (:func:`~walkstream.shared.nav.shortest_paths`).

        Returns the cost of every state, the predecessor of every state (-1: the
        start), and, with a target, the state the best route reaches the target cell
        by (-1 for the start cell itself, -2 when unreachable) and its total cost.
        """
        m = 2 * len(self.portal_cells)
        mid = self.portal_mid
        fac = factor if factor is not None else np.ones(len(self.cells))
        end_state, end_cost = -2, math.inf
        sx, sy = float(start[0]), float(start[1])
        if target is not None and target_cell == start_cell:
            end_state = -1
            end_cost = float(np.hypot(*(target - start))) * float(fac[start_cell])
        seeds = []
        for k in self.cell_portals[start_cell]:
            other = int(self.portal_cells[k, 0] + self.portal_cells[k, 1] - start_cell)
            if allowed is not None and not allowed[other]:
                continue
            s = self._state(k, other)
            lx, ly = float(mid[k, 0]) - sx, float(mid[k, 1]) - sy
            nx, ny = self._normal(s)
            cost = math.hypot(lx, ly) * float(fac[start_cell]) + turn_cost * _angle(lx, ly, nx, ny)
            if heading is not None:
                cost += heading_cost * _angle(heading[0], heading[1], lx, ly)
            seeds.append((s, cost))

        def expand(s: int, d: float) -> Iterator[tuple[int, float]]:
            nonlocal end_state, end_cost
            c = self._into(s)
            k0 = s >> 1
            mx, my = float(mid[k0, 0]), float(mid[k0, 1])
            inx, iny = self._normal(s)
            if target is not None and c == target_cell:
                lx, ly = float(target[0]) - mx, float(target[1]) - my
                total = (
                    d + math.hypot(lx, ly) * float(fac[c]) + turn_cost * _angle(inx, iny, lx, ly)
                )
                if total < end_cost:
                    end_cost, end_state = total, s
            for k in self.cell_portals[c]:
                if k == k0:
                    continue
                other = int(self.portal_cells[k, 0] + self.portal_cells[k, 1] - c)
                if allowed is not None and not allowed[other]:
                    continue
                s2 = self._state(k, other)
                lx, ly = float(mid[k, 0]) - mx, float(mid[k, 1]) - my
                ox, oy = self._normal(s2)
                yield s2, (
                    d
                    + math.hypot(lx, ly) * float(fac[c])
                    + turn_cost * (_angle(inx, iny, lx, ly) + _angle(lx, ly, ox, oy))
                )

        dist, prev = shortest_paths(m, seeds, expand, stop=lambda d: d >= end_cost)
        return dist, prev, end_state, end_cost

    def _states_to(self, prev: I64, s: int) -> list[int]:
        out = []
        while s >= 0:
            out.append(s)
            s = int(prev[s])
        return out[::-1]

    def cell_costs(
        self,
        start: ArrayLike,
        *,
        allowed: NDArray[np.bool_] | None = None,
        factor: F64 | None = None,
        heading: tuple[float, float] | None = None,
        heading_cost: float = TURN_COST,
    ) -> F64:
        """Route cost from a point to every cell (``inf`` where unreachable).

        The cost of a cell is that of the cheapest way into it; the start cell costs 0.
        Indexed like :attr:`cells`.  Arguments as for :meth:`plan`.
        """
        p = np.asarray(start, dtype=np.float64)
        sc = self.locate(p, "start")
        dist, _, _, _ = self._search(
            p, sc, allowed=allowed, factor=factor, heading=heading, heading_cost=heading_cost
        )
        out = np.full(len(self.cells), np.inf)
        out[sc] = 0.0
        if len(dist):
            into = np.where(
                np.arange(len(dist)) % 2 == 0,
                self.portal_cells[np.arange(len(dist)) // 2, 1],
                self.portal_cells[np.arange(len(dist)) // 2, 0],
            )
            np.minimum.at(out, into, dist)
        return out

    def plan(
        self,
        from_xy: ArrayLike,
        to_xy: ArrayLike,
        *,
        via: Sequence[ArrayLike] = (),
        allowed: NDArray[np.bool_] | None = None,
        factor: F64 | None = None,
        heading: tuple[float, float] | None = None,
        heading_cost: float = TURN_COST,
        straighten: bool = True,
    ) -> Route:
        """The cheapest route from a point through ``via`` points to a point.

        Parameters
        ----------
        from_xy, to_xy:
            Start and end, scene-local metres; each must lie in a cell.
        via:
            Points to pass through on the way, in order.
        allowed:
            ``(n,) bool`` over :attr:`cells`: the cells the route may enter (the
            start and end cells are always allowed).
        factor:
            ``(n,) float`` cost per metre in each cell (default 1).
        heading:
            The direction the walker faces at the start; turning away from it costs
            ``heading_cost`` metres per radian (at the start only; at a via point
            the arrival direction counts with :data:`TURN_COST`).
        straighten:
            Drop nearly collinear vertices (see the module docstring).

        Raises
        ------
        RouteError
            A point outside every cell, or two consecutive points not connected.
        """
        names = ["from"] + [f"via {i + 1}" for i in range(len(via))] + ["to"]
        points = [np.asarray(p, dtype=np.float64).reshape(-1) for p in (from_xy, *via, to_xy)]
        cells = [self.locate(p, n) for p, n in zip(points, names, strict=True)]
        xy: list[F64] = [points[0]]
        visited: list[int] = [cells[0]]
        for i in range(len(points) - 1):
            a, b, ca, cb = points[i], points[i + 1], cells[i], cells[i + 1]
            ok = None
            if allowed is not None:
                ok = allowed.copy()
                ok[ca] = ok[cb] = True
            _, prev, end, _ = self._search(
                a,
                ca,
                target=b,
                target_cell=cb,
                allowed=ok,
                factor=factor,
                heading=heading,
                heading_cost=heading_cost if i == 0 else TURN_COST,
            )
            if end == -2:
                raise RouteError(
                    f"no route from {names[i]} ({a[0]:.1f}, {a[1]:.1f}) in cell "
                    f"{self.cells[ca].id} to {names[i + 1]} ({b[0]:.1f}, {b[1]:.1f}) in cell "
                    f"{self.cells[cb].id}: the cells are not connected"
                )
            states = self._states_to(prev, end) if end >= 0 else []
            for s in states:
                xy.append(self.portal_mid[s >> 1])
                visited.append(self._into(s))
            xy.append(b)
            d = b - xy[-2]
            if float(np.hypot(*d)) > 0:
                heading = (float(d[0]), float(d[1]))
        pts = np.array(xy, dtype=np.float64)
        seq = [visited[0]] + [c for p, c in zip(visited, visited[1:], strict=False) if c != p]
        if straighten:
            pts = self._straighten(pts, seq)
        return Route(pts, tuple(int(self.cells[c].id) for c in seq))

    def route(self, from_xy: ArrayLike, to_xy: ArrayLike, **kw: Any) -> F64:
        """The polyline of :meth:`plan` (``(k, 2)`` local metres); same arguments."""
        return self.plan(from_xy, to_xy, **kw).xy

    def _straighten(self, pts: F64, cells: Sequence[int], tol: float = STRAIGHTEN_TOL) -> F64:
        """Greedily drop vertices within ``tol`` of a chord that stays inside the cells."""
        # repeated points (a route ending on a portal midpoint) first
        keep = [0] + [
            i for i in range(1, len(pts)) if float(np.hypot(*(pts[i] - pts[i - 1]))) > 1e-6
        ]
        pts = pts[keep]
        if len(pts) <= 2:
            return pts
        corridor = shapely.union_all(
            shapely.buffer(self.polys[sorted(set(cells))], 1e-6, quad_segs=1, join_style="mitre")
        )
        shapely.prepare(corridor)

        def ok(i: int, j: int) -> bool:
            a, b = pts[i], pts[j]
            ab = b - a
            n = float(np.hypot(*ab))
            if n < 1e-9:
                return False  # a U-turn point: never straightened away
            mids = pts[i + 1 : j]
            off = np.abs(ab[0] * (mids[:, 1] - a[1]) - ab[1] * (mids[:, 0] - a[0])) / n
            along = ((mids - a) @ ab) / (n * n)
            if (off > tol).any() or (along <= 0).any() or (along >= 1).any():
                return False
            return bool(corridor.covers(shapely.LineString([a, b])))

        out = [0]
        i = 0
        while i < len(pts) - 1:
            j = i + 1
            while j + 1 < len(pts) and ok(i, j + 1):
                j += 1
            out.append(j)
            i = j
        return pts[out]

    # -- regions -------------------------------------------------------------

    def border(self) -> NDArray[np.bool_]:
        """``(n,) bool``: cells touching the outline of the union of all cells.

        Holes (the building blocks between streets) do not count: only the outer
        ring of each connected part of the navigation space.
        """
        grown = shapely.buffer(self.polys, 1e-3, quad_segs=1, join_style="mitre")
        union = shapely.union_all(grown)
        rings = [
            shapely.get_exterior_ring(p)
            for p in shapely.get_parts(union)
            if isinstance(p, shapely.Polygon)
        ]
        if not rings:
            return np.zeros(len(self.cells), bool)
        outline = shapely.multilinestrings(rings)
        return np.asarray(shapely.dwithin(self.polys, outline, 0.01), dtype=bool)

    def components(self, mask: NDArray[np.bool_]) -> list[list[int]]:
        """Connected groups of the masked cells (positions), largest first, then by first position."""
        seen = ~mask.copy()
        groups = []
        for start in range(len(self.cells)):
            if seen[start]:
                continue
            seen[start] = True
            group, stack = [], [start]
            while stack:
                c = stack.pop()
                group.append(c)
                for k in self.cell_portals[c]:
                    o = int(self.portal_cells[k, 0] + self.portal_cells[k, 1] - c)
                    if not seen[o]:
                        seen[o] = True
                        stack.append(o)
            groups.append(sorted(group))
        groups.sort(key=lambda g: (-len(g), g[0]))
        return groups
