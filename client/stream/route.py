"""Prediction along the cell graph: the cells the viewer may reach next, and at what cost.

A viewer on a street mostly goes on along it, and at a junction takes one of the
continuations, the straighter ones more likely; a car does not turn round on the
spot.  :func:`predict_route` walks the cell graph of the index from the viewer's
cell (Dijkstra): entering a neighbour costs the distance from the point where the
viewer entered the cell (or stands) to the portal into the neighbour, plus a
*turn cost* that grows with the angle between the way the viewer was going and the
way into the neighbour::

    turn_cost(theta) = turn_m * (1 - cos(theta)) / 2

(0 straight on, ``turn_m / 2`` for a right-angle turn, ``turn_m`` to turn back).
The result ranks the cells within a *horizon* of cost: straight ahead first, the
turns at the next junction next, the way back last.  :func:`horizon_m` gives the
horizon in distance, growing with speed so that a car looks further ahead than a
walker, and :func:`turn_cost_m` the turn cost, growing with speed (turning back at
50 km/h takes a while).

The graph and the outlines come from the cell index, so predicting needs no
request; cells whose tile is not held yet are reported as the *frontier*.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from walkstream.client.stream.cellmap import CellMap
from walkstream.shared.arrays import F64

__all__ = ["RouteStep", "Route", "predict_route", "horizon_m", "turn_cost_m"]


@dataclass(frozen=True, slots=True)
class RouteStep:
    """How the viewer may reach a cell.

    Attributes
    ----------
    cell : int
    distance_m : float
        Length of the cheapest way along the graph to the cell's portal (0 for the
        viewer's own cell).
    cost_m : float
        That length plus the turn costs on the way (what the ranking uses).
    via : int or None
        The cell it is entered from on that way (None for the viewer's own cell).
    """

    cell: int
    distance_m: float
    cost_m: float
    via: int | None


@dataclass(frozen=True, slots=True)
class Route:
    """The cells within the horizon, cheapest first, and the frontier."""

    steps: tuple[RouteStep, ...]
    frontier: dict[int, RouteStep]
    """Neighbour ids reached whose outline is not held (their tiles are missing), with the
    step of the held cell they neighbour."""

    def cost(self) -> dict[int, float]:
        """Cell -> cost, metres."""
        return {s.cell: s.cost_m for s in self.steps}


def horizon_m(speed: float, seconds: float, minimum_m: float) -> float:
    """The prediction horizon in distance: ``max(minimum_m, speed * seconds)``.

    >>> horizon_m(14.0, 8.0, 60.0), horizon_m(1.4, 8.0, 60.0)
    (112.0, 60.0)
    """
    return float(max(minimum_m, max(0.0, speed) * max(0.0, seconds)))


def turn_cost_m(speed: float, base_m: float = 10.0, seconds: float = 3.0) -> float:
    """The cost of turning back (``turn_m``): ``base_m + speed * seconds`` metres.

    >>> turn_cost_m(0.0), turn_cost_m(14.0)
    (10.0, 52.0)
    """
    return float(base_m + max(0.0, speed) * seconds)


def _unit(v: F64) -> F64 | None:
    n = float(np.hypot(v[0], v[1]))
    return None if n < 1e-9 else v / n


def _closest_on_segment(seg: F64, p: F64) -> F64:
    a, b = seg[0], seg[1]
    ab = b - a
    den = float(ab @ ab)
    t = 0.0 if den < 1e-12 else min(1.0, max(0.0, float((p - a) @ ab) / den))
    out: F64 = a + t * ab
    return out


def predict_route(
    cellmap: CellMap,
    start: int,
    xy: ArrayLike,
    heading: ArrayLike | None,
    horizon: float,
    turn_m: float,
) -> Route:
    """The cells reachable from ``start`` within ``horizon`` metres of cost.

    Parameters
    ----------
    cellmap : CellMap
        The held outlines and adjacency; ``start`` must be held.
    start : int
        The viewer's cell.
    xy : (2,) float
        The viewer's position.
    heading : (2,) float or None
        The way the viewer goes (any length); None or zero when standing still
        (every way is then straight on).
    horizon : float
        Cells whose cost exceeds this are left out, metres.
    turn_m : float
        The cost of turning back (see the module docs), metres.

    Returns
    -------
    Route
        ``start`` first (cost 0), then the others by cost.
    """
    p0 = np.asarray(xy, dtype=np.float64).reshape(2)
    h0 = None if heading is None else _unit(np.asarray(heading, dtype=np.float64).reshape(2))
    centre: dict[int, F64] = {}

    def centroid(c: int) -> F64:
        got = centre.get(c)
        if got is None:
            got = cellmap.outlines[c].mean(axis=0)
            centre[c] = got
        return got

    steps: list[RouteStep] = []
    frontier: dict[int, RouteStep] = {}
    done: set[int] = set()
    # (cost, tie, cell, distance, entry point, incoming direction, via)
    heap: list[tuple[float, int, int, float, F64, F64 | None, int | None]] = [
        (0.0, 0, start, 0.0, p0, h0, None)
    ]
    tie = 1
    while heap:
        cost, _, c, dist, entry, h, via = heapq.heappop(heap)
        if c in done:
            continue
        done.add(c)
        here = RouteStep(c, dist, cost, via)
        steps.append(here)
        for n in cellmap.neighbours.get(c, ()):
            if n in done:
                continue
            if not cellmap.knows(n):
                frontier.setdefault(n, here)
                continue
            seg = cellmap.portal(c, n)
            exit_pt = _closest_on_segment(seg, entry) if c == start else seg.mean(axis=0)
            leg = float(np.hypot(*(exit_pt - entry)))
            out = _unit(centroid(n) - entry)
            if out is None:
                out = h
            theta = 0.0
            if h is not None and out is not None:
                theta = math.acos(max(-1.0, min(1.0, float(h @ out))))
            step_cost = cost + leg + turn_m * (1.0 - math.cos(theta)) / 2.0
            if step_cost > horizon:
                continue
            heapq.heappush(heap, (step_cost, tie, n, dist + leg, exit_pt, out, c))
            tie += 1
    return Route(tuple(steps), {n: st for n, st in frontier.items() if n not in done})
