"""Recorded paths made from a scene's view cells: routes, default walks, GeoJSON lines.

The navigation graph
--------------------
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

Default paths
-------------
:func:`default_paths` picks, deterministically:

``SE``
    A street walk at 15 km/h of at least :data:`SE_SECONDS` seconds, over street and
    crossroad cells: from the middle of the city to the cell farthest away, then on
    to the next farthest, each time making cells already walked through four times
    as expensive so that the walk keeps finding new streets; cut to length.
``SM``
    A mixed walk at 5 km/h: along a street away from a square, a U-turn, back the
    same way, then across the square from one side to the other.  The square is the
    largest connected group of ``square`` cells; in a grid scene it is the largest
    connected group of open grid cells (almost free of buildings, when footprints
    are given), in a street scene without squares the crossroad with the most
    neighbours.
``drive``
    A drive at 50 km/h with the eye at 1.2 m over at least :data:`DRIVE_M` metres
    (when the city has that much street), chained like ``SE`` from the south-west.

GeoJSON lines
-------------
:func:`import_linestring` turns a GeoJSON ``LineString`` (or ``MultiLineString``, a
``Feature`` holding one, or a ``FeatureCollection`` with exactly one line feature)
into a path: coordinates in the file's declared ``crs`` (default lon/lat) are
projected to the scene's CRS with pyproj and moved by the scene origin.

:func:`record_path` and :func:`import_path` store a new path in a finished scene
with :func:`server.store.write_path`, which makes a new scene version.
"""

from __future__ import annotations

import heapq
import math
import os
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyproj
import shapely
from numpy.typing import ArrayLike, NDArray

from walkstream.server.cells import ViewCell, cell_locator, cell_polygons
from walkstream.server.sources.geojson import _as_points, _parse_crs, read_json_file
from walkstream.server.store import CellInfo, SceneReader, write_path
from walkstream.shared.errors import InputError, RouteError, SourceError, StoreError
from walkstream.shared.paths import DRIVE_EYE_HEIGHT, WALK_EYE_HEIGHT, RecordedPath

__all__ = [
    "CellGraph",
    "Route",
    "TURN_COST",
    "CLIP_GAP",
    "STRAIGHTEN_TOL",
    "SE_SECONDS",
    "SE_SPEED_KMH",
    "SM_SPEED_KMH",
    "DRIVE_SPEED_KMH",
    "DRIVE_M",
    "default_paths",
    "import_linestring",
    "read_linestring",
    "record_path",
    "import_path",
]

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

#: Metres of extra cost per radian of turning inside a cell (about 16 m per corner).
TURN_COST = 10.0
#: Metres a dropped vertex may lie off the straightened polyline.
STRAIGHTEN_TOL = 1.0
#: Gaps (metres) outside the cells that a clipped GeoJSON line may bridge.
CLIP_GAP = 60.0
#: Speeds of the default paths, km/h.
SE_SPEED_KMH = 15.0
SM_SPEED_KMH = 5.0
DRIVE_SPEED_KMH = 50.0
#: The street walk lasts this many seconds (the paper's SE: at least 3 minutes).
SE_SECONDS = 200.0
#: The drive covers this many metres when the city allows.
DRIVE_M = 2100.0

# cells already walked through cost this many times more for the next leg of a chain
_REVISIT_FACTOR = 4.0
# a chained walk turning away from where it was heading pays this per radian (a
# U-turn about 190 m): it goes on round the block rather than back
_GO_ON_COST = 60.0
# cells on the outline of the navigation space cost this many times more
_BORDER_FACTOR = 3.0
_MAX_LEGS = 60
# SM: the stretch walked before the U-turn, metres along the route
_SM_OUT = (60.0, 160.0)
# grid cells at least this free of buildings count as open space (tried in order)
_OPEN_SHARES = (0.95, 0.85, 0.7)
# an open area crossed by SM has at most this many grid cells (a big square or park)
_MAX_OPEN_CELLS = 80
# grid cells freer than this hold (next to) no building: not walked through by
# SE and drive, which keep to the built-up part
_EMPTY_SHARE = 0.97
# tolerance (metres) for two cells' boundaries to count as shared
_SHARED_TOL = 1e-4
# portals shorter than this (metres) are not walked through
_MIN_PORTAL = 0.5
_MAX_GEOJSON_BYTES = 256 << 20




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
        The cells: :class:`server.cells.ViewCell` (during the bake) or
        :class:`server.store.CellInfo` (``SceneReader.cells()``).

    Attributes
    ----------
    cells:
        The cells as :class:`server.cells.ViewCell`, sorted by id.  Internally
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
        """Dijkstra over portal crossings.

        Returns the cost of every state, the predecessor of every state (-1: the
        start), and, with a target, the state the best route reaches the target cell
        by (-1 for the start cell itself, -2 when unreachable) and its total cost.
        """
        m = 2 * len(self.portal_cells)
        dist = np.full(m, np.inf)
        prev = np.full(m, -1, np.int64)
        done = np.zeros(m, bool)
        mid = self.portal_mid
        fac = factor if factor is not None else np.ones(len(self.cells))
        heap: list[tuple[float, int]] = []
        end_state, end_cost = -2, math.inf
        sx, sy = float(start[0]), float(start[1])
        if target is not None and target_cell == start_cell:
            end_state = -1
            end_cost = float(np.hypot(*(target - start))) * float(fac[start_cell])
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
            if cost < dist[s]:
                dist[s] = cost
                heapq.heappush(heap, (cost, s))
        while heap:
            d, s = heapq.heappop(heap)
            if done[s]:
                continue
            if d >= end_cost:
                break
            done[s] = True
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
                if done[s2]:
                    continue
                lx, ly = float(mid[k, 0]) - mx, float(mid[k, 1]) - my
                ox, oy = self._normal(s2)
                cost = (
                    d
                    + math.hypot(lx, ly) * float(fac[c])
                    + turn_cost * (_angle(inx, iny, lx, ly) + _angle(lx, ly, ox, oy))
                )
                if cost < dist[s2]:
                    dist[s2] = cost
                    prev[s2] = s
                    heapq.heappush(heap, (cost, s2))
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


# --------------------------------------------------------------------------- default paths


def _cut(xy: F64, length: float) -> F64:
    """The first ``length`` metres of a polyline."""
    seg = np.hypot(*np.diff(xy, axis=0).T)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    if length >= cum[-1]:
        return xy
    i = int(np.searchsorted(cum, length, side="right")) - 1
    f = (length - cum[i]) / seg[i] if seg[i] > 0 else 0.0
    return np.vstack([xy[: i + 1], xy[i] + f * (xy[i + 1] - xy[i])])


def _join(parts: Sequence[F64]) -> F64:
    out = [parts[0]]
    for p in parts[1:]:
        out.append(p[1:] if np.allclose(p[0], out[-1][-1]) else p)
    return np.vstack(out)


def _chain(
    g: CellGraph, group: Sequence[int], start: int, target_m: float, border: NDArray[np.bool_]
) -> tuple[F64, list[int]] | None:
    """Walk from cell ``start`` to the farthest cell, and on, until ``target_m`` metres.

    Border cells (on the outline of the navigation space, looking out at empty land)
    cost :data:`_BORDER_FACTOR` times more and are not chosen as targets unless
    every cell is on the border.
    """
    allowed = np.zeros(len(g), bool)
    allowed[list(group)] = True
    targets = allowed & ~border
    if not targets.any():
        targets = allowed
    # legs end at crossroads where there are some: the next leg can turn left or
    # right there instead of going back
    cross = targets & (np.array(g.kinds) == "crossroad")
    if cross.sum() >= 2:
        targets = cross
    base = np.where(border, _BORDER_FACTOR, 1.0)
    used = np.zeros(len(g), bool)
    pos = g.centroids[start]
    parts: list[F64] = []
    visited: list[int] = []
    total = 0.0
    heading: tuple[float, float] | None = None
    for _ in range(_MAX_LEGS):
        factor = base * np.where(used, _REVISIT_FACTOR, 1.0)
        cost = g.cell_costs(
            pos, allowed=allowed, factor=factor, heading=heading, heading_cost=_GO_ON_COST
        )
        here = g.locate(pos)
        cost[here] = -np.inf
        cost[~targets | ~np.isfinite(cost)] = -np.inf
        if not np.isfinite(cost).any():
            break
        target = int(np.argmax(cost))  # first of the farthest: deterministic
        r = g.plan(
            pos,
            g.centroids[target],
            allowed=allowed,
            factor=factor,
            heading=heading,
            heading_cost=_GO_ON_COST,
        )
        parts.append(r.xy)
        cells = [g.index[c] for c in r.cells]
        visited.extend(cells)
        used[cells] = True
        total += r.length
        pos = g.centroids[target]
        d = r.xy[-1] - r.xy[-2]
        heading = (float(d[0]), float(d[1]))
        if total >= target_m:
            break
    if not parts:
        return None
    return _cut(_join(parts), target_m), visited


def _free_share(g: CellGraph, footprints: Sequence[ArrayLike] | None) -> F64 | None:
    """Share of each cell not covered by footprints (overlaps counted twice)."""
    if footprints is None:
        return None
    polys = [shapely.Polygon(np.asarray(f, dtype=np.float64)) for f in footprints]
    polys = [p if p.is_valid else shapely.make_valid(p) for p in polys]
    built = np.zeros(len(g))
    if polys:
        arr = np.array(polys, dtype=object)
        ci, fi = shapely.STRtree(arr).query(g.polys, predicate="intersects")
        if len(ci):
            np.add.at(built, ci, shapely.area(shapely.intersection(g.polys[ci], arr[fi])))
    return np.asarray(1.0 - np.clip(built / np.maximum(g.areas, 1e-12), 0.0, 1.0))


def _has_door(g: CellGraph, group: Sequence[int], streets: NDArray[np.bool_]) -> bool:
    inside = set(group)
    return any(
        streets[o] and o not in inside
        for k in group
        for p in g.cell_portals[k]
        for o in g.portal_cells[p].tolist()
    )


def _open_region(
    g: CellGraph, streets: NDArray[np.bool_], free: F64 | None, border: NDArray[np.bool_]
) -> list[int] | None:
    """The square (or open area) the mixed walk crosses, as cell positions.

    Street cells: the largest group of square cells by area (else the crossroad
    with the most neighbours).  Grid cells: the largest group of open cells (free
    of buildings, see :data:`_OPEN_SHARES`; without footprints, cells with four
    neighbours) that is enclosed, i.e. has no cell on the outline of the scene,
    and at most :data:`_MAX_OPEN_CELLS` cells (failing that, the largest such group
    that is not enclosed, or a single open cell).  Every choice must have a way
    out to the streets.
    """
    kinds = np.array(g.kinds)
    squares = kinds == "square"
    if squares.any():
        groups = [grp for grp in g.components(squares) if _has_door(g, grp, streets)]
        if groups:
            return max(groups, key=lambda grp: (float(g.areas[grp].sum()), -grp[0]))
    if (kinds == "grid").all():
        nb4 = np.array([len(g.cell_portals[k]) >= 4 for k in range(len(g))])
        masks = [free >= share for share in _OPEN_SHARES] if free is not None else [nb4]

        def enclosed(grp: list[int]) -> bool:
            return not any(
                border[o]
                for k in grp
                for p in g.cell_portals[k]
                for o in g.portal_cells[p].tolist()
            )

        fallback: list[int] | None = None
        for mask in masks:
            groups = [
                grp
                for grp in g.components(mask & ~border)
                if len(grp) <= _MAX_OPEN_CELLS and _has_door(g, grp, streets)
            ]
            good = [grp for grp in groups if len(grp) >= 2 and enclosed(grp)]
            if good:
                return max(good, key=lambda grp: (float(g.areas[grp].sum()), -grp[0]))
            if groups and fallback is None:
                fallback = max(groups, key=lambda grp: (float(g.areas[grp].sum()), -grp[0]))
        return fallback
    cross = np.flatnonzero((kinds == "crossroad") & streets)
    if not len(cross):
        return None
    best = max(cross.tolist(), key=lambda k: (len(g.cell_portals[k]), -k))
    return [best]


def _mixed(
    g: CellGraph, streets: NDArray[np.bool_], free: F64 | None, border: NDArray[np.bool_]
) -> F64 | None:
    """Out along a street, a U-turn, back, and across a square (see the module docstring)."""
    region = _open_region(g, streets, free, border)
    if not region:
        return None
    inside = np.zeros(len(g), bool)
    inside[region] = True
    # portals from the region to walkable cells outside it: (portal, outside, inside)
    doors = []
    for k, (a, b) in enumerate(g.portal_cells.tolist()):
        if inside[a] and not inside[b] and streets[b]:
            doors.append((k, b, a))
        elif inside[b] and not inside[a] and streets[a]:
            doors.append((k, a, b))
    # cross through the middle, from one side to the opposite one: prefer doors
    # that face away from each other with the chord between them square to both,
    # then a long chord passing near the region's centre
    centre = (g.centroids[region] * g.areas[region, None]).sum(axis=0) / g.areas[region].sum()
    best: tuple[bool, bool, float, int, int] | None = None
    for i, (ki, oi, _) in enumerate(doors):
        ni = g.portal_normal[ki] * (1.0 if g.portal_cells[ki, 1] == oi else -1.0)
        for kj, oj, _ in doors[i + 1 :]:
            if oi == oj or g.cells[oj].id in g.cells[oi].neighbours:
                continue
            nj = g.portal_normal[kj] * (1.0 if g.portal_cells[kj, 1] == oj else -1.0)
            mi, mj = g.portal_mid[ki], g.portal_mid[kj]
            d = float(np.hypot(*(mi - mj)))
            if d <= 0:
                continue
            u = (mj - mi) / d
            square = min(abs(float(u @ ni)), abs(float(u @ nj))) >= 0.9
            score = d - 2.0 * float(np.hypot(*(0.5 * (mi + mj) - centre)))
            key = (bool(float(ni @ nj) < -0.5), square, score, oi, oj)
            if best is None or key[:3] > best[:3]:
                best = key
    if best is None:
        return None
    *_, entry, leave = best
    through = inside.copy()
    through[[entry, leave]] = True
    a, x = g.centroids[entry], g.centroids[leave]
    cross = g.plan(a, x, allowed=through)

    # the stretch out and back: away from the square along the streets
    outside = streets & ~inside
    away = a - centre
    heading = (float(away[0]), float(away[1])) if float(np.hypot(*away)) > 0 else None
    cost = g.cell_costs(a, allowed=outside, heading=heading)
    lo, hi = _SM_OUT
    cand = np.flatnonzero(outside & ~border & (cost >= lo) & (cost <= hi))
    if not len(cand):
        cand = np.flatnonzero(outside & (cost >= lo) & (cost <= hi))
    if not len(cand):
        cand = np.flatnonzero(outside & np.isfinite(cost) & (cost <= hi) & (cost > 0))
    if not len(cand):
        return cross.xy
    far = np.hypot(*(g.centroids[cand] - centre).T)
    turn = int(cand[int(np.argmax(far))])
    out = g.plan(a, g.centroids[turn], allowed=outside, heading=heading)
    return _join([out.xy, out.xy[::-1], cross.xy])


def default_paths(
    cells: Iterable[ViewCell | CellInfo],
    *,
    footprints: Sequence[ArrayLike] | None = None,
    graph: CellGraph | None = None,
) -> list[RecordedPath]:
    """The default recorded paths of a scene: ``SE``, ``SM`` and ``drive``.

    See the module docstring for what each is.  Deterministic: the same cells give
    the same paths.  A path the cells cannot support (no two connected cells, no
    open area with two sides) is left out, so the list may be shorter.

    Parameters
    ----------
    cells:
        The scene's view cells (street or grid cells).
    footprints:
        Building footprint rings (``(n, 2)`` local metres), used in grid scenes to
        find the largest open area for ``SM``.
    graph:
        A :class:`CellGraph` of the same cells, if one was already built.

    Returns
    -------
    list[RecordedPath]
        In the order SE, SM, drive (those that could be made).
    """
    g = graph if graph is not None else CellGraph(cells)
    kinds = np.array(g.kinds)
    grid = bool((kinds == "grid").all())
    free = _free_share(g, footprints) if grid else None
    if grid:
        # walks keep to the built-up part; open land around the data is left out
        streets = free < _EMPTY_SHARE if free is not None else np.ones(len(g), bool)
    else:
        streets = np.isin(kinds, ("street", "crossroad"))
    if not streets.any():
        streets = np.ones(len(g), bool)
    groups = g.components(streets)
    out: list[RecordedPath] = []
    if not groups or len(groups[0]) < 2:
        return out
    group = groups[0]
    in_group = np.zeros(len(g), bool)
    in_group[group] = True
    border = g.border()
    inner = [k for k in group if not border[k]] or list(group)
    cen = g.centroids[inner]
    lo, hi = cen.min(axis=0), cen.max(axis=0)

    def nearest(p: F64) -> int:
        return int(inner[int(np.argmin(np.hypot(*(cen - p).T)))])

    se_m = SE_SPEED_KMH / 3.6 * SE_SECONDS
    se = _chain(g, group, nearest(0.5 * (lo + hi)), se_m, border)
    if se is not None:
        out.append(RecordedPath.from_polyline("SE", se[0], SE_SPEED_KMH))
    sm = _mixed(g, in_group, free, border)
    if sm is not None and len(sm) >= 2:
        out.append(RecordedPath.from_polyline("SM", sm, SM_SPEED_KMH))
    drive = _chain(g, group, nearest(lo), DRIVE_M, border)
    if drive is not None:
        out.append(
            RecordedPath.from_polyline(
                "drive", drive[0], DRIVE_SPEED_KMH, eye_height=DRIVE_EYE_HEIGHT, turn_seconds=2.0
            )
        )
    return out


# --------------------------------------------------------------------------- GeoJSON lines


def read_linestring(
    source: str | os.PathLike[str] | Mapping[str, Any], crs: str, origin: Sequence[float]
) -> F64:
    """The one line of a GeoJSON object in scene-local metres.

    Parameters
    ----------
    source:
        A ``.geojson`` file or the parsed object: a ``LineString`` or
        ``MultiLineString`` geometry, a ``Feature`` with one, or a
        ``FeatureCollection`` with exactly one line feature (other features are
        ignored).  The parts of a ``MultiLineString`` are joined in order.
    crs:
        The scene's CRS (``SceneMeta.crs``), projected metres.
    origin:
        The scene origin in that CRS.

    Returns
    -------
    numpy.ndarray
        ``(n, 2) float64`` vertices, repeated ones dropped.

    Raises
    ------
    SourceError
        Unreadable file, not JSON, no line or several, malformed or out-of-range
        coordinates, or an unusable CRS.
    """
    if isinstance(source, Mapping):
        obj: Any = source
        label = "<geojson>"
    elif not isinstance(source, str | os.PathLike):
        raise SourceError(f"expected a GeoJSON object or file, got {type(source).__name__}")
    else:
        label = str(Path(source))
        obj = read_json_file(source, _MAX_GEOJSON_BYTES)
    if not isinstance(obj, Mapping):
        raise SourceError(f"{label}: expected a GeoJSON object, got {type(obj).__name__}")
    src_crs = _parse_crs(obj.get("crs"), label)
    geom = _the_line(obj, label)
    gtype, coords = geom.get("type"), geom.get("coordinates")
    parts = coords if gtype == "MultiLineString" else [coords]
    if not isinstance(parts, list) or not parts:
        raise SourceError(f"{label}: malformed {gtype} coordinates")
    arrays = []
    for k, part in enumerate(parts):
        pts = _as_points(part)
        if isinstance(pts, str):
            where = f" (part {k})" if gtype == "MultiLineString" else ""
            raise SourceError(f"{label}: {gtype}{where}: {pts}")
        arrays.append(pts)
    raw = np.concatenate(arrays)
    geographic = src_crs is None or src_crs.is_geographic
    if geographic:
        bad = np.flatnonzero((np.abs(raw[:, 1]) > 90) | (raw[:, 0] < -180) | (raw[:, 0] > 360))
        if len(bad):
            i = int(bad[0])
            raise SourceError(
                f"{label}: position {i} ({raw[i, 0]}, {raw[i, 1]}) is outside the lon/lat "
                "range (projected data needs a 'crs' member)"
            )
    try:
        dst = pyproj.CRS.from_user_input(crs)
    except pyproj.exceptions.CRSError as exc:
        raise InputError(f"scene CRS {crs!r} is not a known CRS") from exc
    if not dst.is_projected:
        raise InputError(f"scene CRS {crs!r} is not projected: cannot place a line in metres")
    transformer = pyproj.Transformer.from_crs(
        src_crs if src_crs is not None else "OGC:CRS84", dst, always_xy=True
    )
    x, y = transformer.transform(raw[:, 0], raw[:, 1])
    ox, oy = (float(v) for v in origin)
    xy = np.column_stack([np.asarray(x, np.float64) - ox, np.asarray(y, np.float64) - oy])
    if not np.isfinite(xy).all():
        i = int(np.flatnonzero(~np.isfinite(xy).all(axis=1))[0])
        raise SourceError(f"{label}: position {i} cannot be projected to {crs}")
    keep = np.concatenate([[True], np.hypot(*np.diff(xy, axis=0).T) > 1e-3])
    xy = xy[keep]
    if len(xy) < 2:
        raise SourceError(f"{label}: the line has fewer than 2 distinct positions")
    return xy


def _the_line(obj: Mapping[str, Any], label: str) -> Mapping[str, Any]:
    gtype = obj.get("type")
    if gtype in ("LineString", "MultiLineString"):
        return obj
    if gtype == "Feature":
        geom = obj.get("geometry")
        if not isinstance(geom, Mapping) or geom.get("type") not in (
            "LineString",
            "MultiLineString",
        ):
            got = geom.get("type") if isinstance(geom, Mapping) else geom
            raise SourceError(f"{label}: the Feature's geometry is {got!r}, not a LineString")
        return geom
    if gtype == "FeatureCollection":
        feats = obj.get("features")
        if not isinstance(feats, list):
            raise SourceError(f"{label}: FeatureCollection has no 'features' list")
        lines = [
            f["geometry"]
            for f in feats
            if isinstance(f, Mapping)
            and isinstance(f.get("geometry"), Mapping)
            and f["geometry"].get("type") in ("LineString", "MultiLineString")
        ]
        if len(lines) != 1:
            raise SourceError(
                f"{label}: expected exactly one LineString feature, found {len(lines)} "
                f"(among {len(feats)} features)"
            )
        return lines[0]
    raise SourceError(
        f"{label}: expected a GeoJSON LineString, MultiLineString, Feature or "
        f"FeatureCollection, got type {gtype!r:.60}"
    )


def _inside_intervals(g: CellGraph, xy: F64) -> F64:
    """Stretches of a polyline inside the cells, as ``(k, 2)`` distances along it, in order.

    Worked out segment by segment, so a line that crosses or runs over itself is
    measured right.
    """
    seg_len = np.hypot(*np.diff(xy, axis=0).T)
    start = np.concatenate([[0.0], np.cumsum(seg_len)])
    segs = shapely.linestrings(np.stack([xy[:-1], xy[1:]], axis=1))
    si, ci = g._tree.query(segs, predicate="intersects")
    if not len(si):
        return np.zeros((0, 2))
    parts = shapely.intersection(segs[si], g.polys[ci])
    out = []
    for s_idx, geom in zip(si.tolist(), parts, strict=True):
        a, d = xy[s_idx], xy[s_idx + 1] - xy[s_idx]
        n2 = float(d @ d)
        for piece in shapely.get_parts(geom):
            if not isinstance(piece, shapely.LineString) or piece.length <= 0:
                continue
            c = np.asarray(piece.coords)[:, :2]
            f = np.clip((c - a) @ d / n2, 0.0, 1.0) * seg_len[s_idx] + start[s_idx]
            out.append((float(f.min()), float(f.max())))
    if not out:
        return np.zeros((0, 2))
    out.sort()
    merged = [list(out[0])]
    for lo, hi in out[1:]:
        if lo <= merged[-1][1] + 1e-6:  # touching cells: one stretch
            merged[-1][1] = max(merged[-1][1], hi)
        else:
            merged.append([lo, hi])
    return np.array(merged, dtype=np.float64)


def _substring(xy: F64, lo: float, hi: float) -> F64:
    """The part of a polyline between two distances along it."""
    seg = np.hypot(*np.diff(xy, axis=0).T)
    cum = np.concatenate([[0.0], np.cumsum(seg)])

    def at(s: float) -> F64:
        i = min(int(np.searchsorted(cum, s, side="right")) - 1, len(seg) - 1)
        f = (s - cum[i]) / seg[i] if seg[i] > 0 else 0.0
        return np.asarray(xy[i] + f * (xy[i + 1] - xy[i]), dtype=np.float64)

    mid = xy[(cum > lo) & (cum < hi)]
    return np.vstack([at(lo), mid, at(hi)])


def import_linestring(
    source: str | os.PathLike[str] | Mapping[str, Any],
    crs: str,
    origin: Sequence[float],
    speed_kmh: float,
    name: str,
    clip_to: Iterable[ViewCell | CellInfo] | CellGraph | None = None,
    *,
    cells: Iterable[ViewCell | CellInfo] | CellGraph | None = None,
    eye_height: float = WALK_EYE_HEIGHT,
    max_gap: float = CLIP_GAP,
) -> tuple[RecordedPath, float | None]:
    """A recorded path along a GeoJSON line (see :func:`read_linestring`).

    Parameters
    ----------
    source, crs, origin:
        The line and the scene's CRS and origin (``SceneReader.meta``).
    speed_kmh, name, eye_height:
        As for :meth:`shared.paths.RecordedPath.from_polyline`.
    clip_to:
        The scene's cells: keep only the longest stretch of the line inside them.
        Gaps of up to ``max_gap`` metres (a street corner where a grid cell was
        dropped for being almost all building) do not end a stretch; the longest
        is the one with the most metres inside.
    cells:
        The scene's cells, only to measure how much of the line lies inside them.

    Returns
    -------
    tuple
        The path, and the metres of the (whole, unclipped) line inside the cells
        (None when no cells were given).

    Raises
    ------
    SourceError
        A bad file (see :func:`read_linestring`).
    RouteError
        With ``clip_to``: no part of the line lies inside the cells.
    """
    xy = read_linestring(source, crs, origin)
    area = clip_to if clip_to is not None else cells
    if area is None:
        return RecordedPath.from_polyline(name, xy, speed_kmh, eye_height), None
    g = area if isinstance(area, CellGraph) else CellGraph(area)
    spans = _inside_intervals(g, xy)
    inside = float((spans[:, 1] - spans[:, 0]).sum())
    if clip_to is not None:
        xy = _longest_inside(g, xy, max_gap)
    return RecordedPath.from_polyline(name, xy, speed_kmh, eye_height), inside


def _longest_inside(g: CellGraph, xy: F64, max_gap: float) -> F64:
    """The longest stretch of a polyline inside the cells, bridging gaps up to ``max_gap`` m."""
    spans = _inside_intervals(g, xy)
    if not len(spans):
        raise RouteError("the line lies entirely outside the scene's view cells")
    runs = [[spans[0, 0], spans[0, 1], spans[0, 1] - spans[0, 0]]]
    for lo, hi in spans[1:]:
        if lo - runs[-1][1] <= max_gap:
            runs[-1][1] = hi
            runs[-1][2] += hi - lo
        else:
            runs.append([lo, hi, hi - lo])
    # the most metres inside; the earliest of equals
    lo, hi, _ = max(runs, key=lambda r: (r[2], -r[0]))
    return _substring(xy, float(lo), float(hi))


# --------------------------------------------------------------------------- storing


def _existing(db: str | os.PathLike[str], name: str, replace: bool) -> SceneReader:
    reader = SceneReader.open(db)
    if not replace and name in reader.path_names():
        reader.close()
        raise StoreError(
            f"{os.fspath(db)}: a path named {name!r} exists already (--replace, or replace=True, overwrites it)"
        )
    return reader


def record_path(
    db: str | os.PathLike[str],
    name: str,
    from_xy: ArrayLike,
    to_xy: ArrayLike,
    speed_kmh: float,
    via: Sequence[ArrayLike] = (),
    *,
    replace: bool = False,
    eye_height: float = WALK_EYE_HEIGHT,
) -> tuple[RecordedPath, str]:
    """Record a path along the street graph and store it in a finished scene.

    Parameters
    ----------
    db:
        The scene database.
    name:
        Path name.
    from_xy, to_xy, via:
        Start, end and points in between, scene-local metres.
    speed_kmh, eye_height:
        Timing and eye height of the path.
    replace:
        Overwrite a path of the same name (refused otherwise).

    Returns
    -------
    tuple
        The path and the new scene version.

    Raises
    ------
    StoreError
        Not a scene database, or the name is taken and ``replace`` is false.
    RouteError
        A point outside every cell, or no route.
    """
    reader = _existing(db, name, replace)
    try:
        graph = CellGraph(reader.cells())
    finally:
        reader.close()
    route = graph.plan(from_xy, to_xy, via=via)
    path = RecordedPath.from_polyline(name, route.xy, speed_kmh, eye_height)
    return path, write_path(db, name, path.to_msgpack())


def import_path(
    db: str | os.PathLike[str],
    name: str,
    file: str | os.PathLike[str] | Mapping[str, Any],
    speed_kmh: float,
    clip: bool = False,
    *,
    replace: bool = False,
    eye_height: float = WALK_EYE_HEIGHT,
) -> tuple[RecordedPath, str, float]:
    """Import a GeoJSON line as a path of a finished scene (see :func:`import_linestring`).

    Parameters
    ----------
    db, name, replace, eye_height:
        As for :func:`record_path`.
    file:
        The GeoJSON file (or parsed object).
    speed_kmh:
        Speed, km/h.
    clip:
        Keep only the longest stretch inside the cells (see :func:`import_linestring`).

    Returns
    -------
    tuple
        The path, the new scene version and the metres of the line inside the cells.

    Raises
    ------
    SourceError
        A bad GeoJSON file.
    RouteError
        No part of the line lies inside the scene's cells.
    StoreError
        Not a scene database, or the name is taken and ``replace`` is false.
    """
    reader = _existing(db, name, replace)
    try:
        meta = reader.meta
        graph = CellGraph(reader.cells())
    finally:
        reader.close()
    path, inside = import_linestring(
        file,
        meta.crs,
        meta.origin,
        speed_kmh,
        name,
        clip_to=graph if clip else None,
        cells=graph,
        eye_height=eye_height,
    )
    assert inside is not None
    if inside <= 0:
        raise RouteError(
            f"{os.fspath(file) if not isinstance(file, Mapping) else 'the line'}: no part of "
            f"the line lies inside the view cells of {os.fspath(db)} (a line for another "
            "place, or in another CRS?)"
        )
    return path, write_path(db, name, path.to_msgpack()), inside
