"""The default recorded walks the bake stores with every scene: ``SE``, ``SM`` and ``drive``.

:func:`default_paths` picks, deterministically:

``SE``
    A street walk at 15 km/h of at least :data:`SE_SECONDS` seconds, over street and
    crossroad cells: from the middle of the city (from the densest part when the
    buildings are much denser elsewhere, as in real towns: :func:`_start`) to the
    cell farthest away, then on to the next farthest, each time making cells already
    walked through four times as expensive so that the walk keeps finding new
    streets; cut to length.  A network too small for that (its longest route, see
    :func:`longest_walk`, is shorter than the walk) gets its longest route instead,
    which does not repeat itself, and :func:`default_paths` says so.
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
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence

import numpy as np
import shapely
from numpy.typing import ArrayLike, NDArray

from walkstream.server.bake.navgraph import CellGraph
from walkstream.server.bake.viewcell import ViewCell
from walkstream.server.store import CellInfo
from walkstream.shared.arrays import F64
from walkstream.shared.paths import DRIVE_EYE_HEIGHT, RecordedPath

__all__ = [
    "SE_SPEED_KMH",
    "SM_SPEED_KMH",
    "DRIVE_SPEED_KMH",
    "SE_SECONDS",
    "DRIVE_M",
    "default_paths",
    "longest_walk",
]
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


# SE starts at the densest part when the middle has less than this share of its density
_DENSE_SHARE = 0.6
# radius (metres) over which building density is counted
_DENSE_RADIUS = 150.0


def _start(g: CellGraph, inner: list[int], footprints: Sequence[ArrayLike] | None) -> int:
    """The cell SE starts from: the middle of the city, or its densest part.

    Density is the footprint area within :data:`_DENSE_RADIUS` of a cell; the middle
    is kept unless its density is below :data:`_DENSE_SHARE` of the densest cell's.
    """
    cen = g.centroids[inner]
    lo, hi = cen.min(axis=0), cen.max(axis=0)
    middle = int(np.argmin(np.hypot(*(cen - 0.5 * (lo + hi)).T)))
    if not footprints:
        return int(inner[middle])
    polys = [shapely.Polygon(np.asarray(f, dtype=np.float64)) for f in footprints]
    arr = np.array([p if p.is_valid else shapely.make_valid(p) for p in polys], dtype=object)
    pts = shapely.points(cen)
    ci, fi = shapely.STRtree(arr).query(pts, predicate="dwithin", distance=_DENSE_RADIUS)
    density = np.zeros(len(inner))
    np.add.at(density, ci, shapely.area(arr[fi]))
    if density[middle] >= _DENSE_SHARE * density.max():
        return int(inner[middle])
    return int(inner[int(np.argmax(density))])


def longest_walk(
    cells: Iterable[ViewCell | CellInfo] | CellGraph,
    speed_kmh: float = SE_SPEED_KMH,
    name: str = "long",
    *,
    mask: NDArray[np.bool_] | None = None,
) -> RecordedPath | None:
    """The longest walk that does not repeat itself: the longest of the shortest routes.

    Found by a double sweep over the largest connected group of cells (of ``mask``,
    default street and crossroad cells, all cells in a grid scene): from the middle to
    the cell farthest away by route, then from there to the cell farthest from it.
    None when the group has fewer than two cells.
    """
    g = cells if isinstance(cells, CellGraph) else CellGraph(cells)
    if mask is None:
        kinds = np.array(g.kinds)
        mask = np.isin(kinds, ("street", "crossroad"))
        if not mask.any():
            mask = np.ones(len(g), bool)
    groups = g.components(mask)
    if not groups or len(groups[0]) < 2:
        return None
    group = groups[0]
    allowed = np.zeros(len(g), bool)
    allowed[group] = True
    cen = g.centroids[group]
    start = g.centroids[group[int(np.argmin(np.hypot(*(cen - cen.mean(axis=0)).T)))]]
    a = g.centroids[int(np.argmax(np.where(allowed, _finite(g.cell_costs(start, allowed=allowed)), -1)))]
    cost = _finite(g.cell_costs(a, allowed=allowed))
    b = g.centroids[int(np.argmax(np.where(allowed, cost, -1)))]
    route = g.plan(a, b, allowed=allowed)
    if route.length <= 0:
        return None
    return RecordedPath.from_polyline(name, route.xy, speed_kmh)


def _finite(cost: F64) -> F64:
    return np.where(np.isfinite(cost), cost, -1.0)


def default_paths(
    cells: Iterable[ViewCell | CellInfo],
    *,
    footprints: Sequence[ArrayLike] | None = None,
    graph: CellGraph | None = None,
    say: Callable[[str], None] | None = None,
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
    say:
        Called with a line when a path had to be cut short (a small network).

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
    longest = longest_walk(g, SE_SPEED_KMH, "SE", mask=in_group) if not grid else None
    if longest is not None and longest.length_m() < se_m:
        out.append(longest)
        if say is not None:
            say(
                f"SE: the street network is too small for a {SE_SECONDS:.0f} s walk that "
                f"does not repeat itself; SE is its longest route ({longest.length_m():.0f} m, "
                f"{longest.duration:.0f} s)"
            )
    else:
        start = _start(g, inner, footprints) if not grid else nearest(0.5 * (lo + hi))
        se = _chain(g, group, start, se_m, border)
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
