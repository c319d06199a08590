"""One shortest-path search (Dijkstra) for every navigation graph of a scene.

Streets route over portal crossings with turn costs
(:class:`~walkstream.server.bake.navgraph.CellGraph`), rooms over door thresholds,
room centres and stair ends (:class:`~walkstream.server.bake.roomnav.RoomGraph`): the
street part and the room part of a scene's one navigation graph, joined at its
entrances (:class:`~walkstream.server.bake.scenenav.SceneGraph`).  Each graph says what its states are and
what stepping from a settled state costs; the search itself lives here once.

The caller's ``expand`` gives the *total* cost of each next state (not an edge
weight to add), so a graph whose costs are sums of several terms keeps its own order
of additions and its routes stay bit for bit what they were.  Ties go to the lower
state number (the heap holds ``(cost, state)`` pairs).
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Callable, Iterable

import numpy as np

from walkstream.shared.arrays import F64, I64

__all__ = ["shortest_paths"]


def shortest_paths(
    size: int,
    seeds: Iterable[tuple[int, float]],
    expand: Callable[[int, float], Iterable[tuple[int, float]]],
    *,
    stop: Callable[[float], bool] | None = None,
    tol: float = 0.0,
) -> tuple[F64, I64]:
    """Dijkstra over states ``0 .. size - 1``.

    Parameters
    ----------
    size:
        Number of states.
    seeds:
        ``(state, cost)`` of the states reachable from the start without a
        predecessor; a seed is kept when it is cheaper than an earlier seed of the
        same state.
    expand:
        Called once per settled state with its cost; yields ``(next state, total
        cost)`` pairs.  Settled states are skipped.
    stop:
        Called with the cost of the next state to settle; the search ends when it
        returns true (a target reached more cheaply than anything left).
    tol:
        A state's cost is lowered only by more than this.

    Returns
    -------
    dist, prev:
        ``(size,)`` cost of every state (``inf`` where unreached) and its
        predecessor (``-1`` for a seed or an unreached state).

    >>> edges = {0: [(1, 2.0), (2, 5.0)], 1: [(2, 1.0)], 2: []}
    >>> d, p = shortest_paths(3, [(0, 0.0)], lambda s, c: ((t, c + w) for t, w in edges[s]))
    >>> d.tolist(), p.tolist()
    ([0.0, 2.0, 3.0], [-1, 0, 1])
    """
    dist = np.full(size, math.inf)
    prev = np.full(size, -1, np.int64)
    done = np.zeros(size, bool)
    heap: list[tuple[float, int]] = []
    for s, cost in seeds:
        if cost < dist[s] - tol:
            dist[s] = cost
            heapq.heappush(heap, (cost, s))
    while heap:
        d, s = heapq.heappop(heap)
        if done[s]:
            continue
        if stop is not None and stop(d):
            break
        done[s] = True
        for s2, cost in expand(s, d):
            if done[s2]:
                continue
            if cost < dist[s2] - tol:
                dist[s2] = cost
                prev[s2] = s
                heapq.heappush(heap, (cost, s2))
    return dist, prev
