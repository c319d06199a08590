"""The default recorded walk of an interior: ``tour``.

:func:`tour` starts in the room by the entrance (a room next to a doorway that leads
outside; else the largest room of the lowest storey), then walks to the nearest room
it has not yet passed through, again and again, until every room it can reach is
passed (so it covers every storey with a reachable room), at
:data:`~.roomnav.INDOOR_SPEED_KMH` with the eye :data:`~.roomnav.EYE_HEIGHT` above
the floor, up and down the stairs on their treads.  Rooms it cannot reach (two homes
with no door between them, an attic with no stair) are reported, not walked.  The
nearest-first order keeps the walk from criss-crossing the building: it does one
storey, climbs, does the next.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import shapely

from walkstream.server.bake.roomlayout import Portal, RoomCell
from walkstream.server.bake.roomnav import (
    CLEARANCE,
    EYE_HEIGHT,
    INDOOR_SPEED_KMH,
    RoomGraph,
    walk_path,
)
from walkstream.shared.arrays import F64
from walkstream.shared.errors import RouteError
from walkstream.shared.paths import RecordedPath

__all__ = ["TOUR_NAME", "TOUR_MIN_SECONDS", "entrance_cell", "rooms_along", "tour"]

TOUR_NAME = "tour"
"""Name of the default interior walk."""
TOUR_MIN_SECONDS = 180.0
"""A tour of a building large enough lasts at least this long (the paper's walks: 3 minutes)."""


def entrance_cell(cells: Sequence[RoomCell], portals: Sequence[Portal]) -> int:
    """The room cell a tour starts in: next to a doorway leading outside (the largest
    such on the lowest storey), else the largest room cell of the lowest storey."""
    by_id = {c.id: c for c in cells}
    outside = {c.id for c in cells if c.kind == "outside"}
    outer_doorways = {
        (p.a if p.b in outside else p.b)
        for p in portals
        if p.kind == "door" and (p.a in outside or p.b in outside)
    }
    near = {
        (p.b if p.a in outer_doorways else p.a)
        for p in portals
        if (p.a in outer_doorways) != (p.b in outer_doorways) and p.kind == "door"
    }
    rooms = [c for c in cells if c.kind == "room"]
    if not rooms:
        raise RouteError("the interior has no room cell to start a tour in")
    low = min(c.storey for c in rooms)

    def area(c: RoomCell) -> float:
        return float(c.polygon.area)

    cand = [by_id[i] for i in near if i in by_id and by_id[i].kind == "room"]
    cand = [c for c in cand if c.storey == min((d.storey for d in cand), default=low)] or [
        c for c in rooms if c.storey == low
    ]
    return max(cand, key=area).id


def rooms_along(graph: RoomGraph, floor: F64, step: float = 0.4) -> tuple[set[str], set[int]]:
    """The rooms and storeys a walk along floor points ``(k, 3)`` passes through."""
    seg = np.diff(floor, axis=0)
    lengths = np.linalg.norm(seg, axis=1)
    pts = [floor[:1]]
    for p, d, n in zip(floor[:-1], seg, lengths, strict=True):
        k = max(1, int(np.ceil(n / step)))
        pts.append(p + d * (np.arange(1, k + 1) / k)[:, None])
    q = np.concatenate(pts)
    ids = graph.locator.locate_many(np.column_stack([q[:, :2], q[:, 2] + 0.5]))
    rooms, storeys = set(), set()
    for cid in np.unique(ids[ids >= 0]).tolist():
        c = graph.cells[cid]
        if c.room is not None:
            rooms.add(c.room)
            storeys.add(c.storey)
    return rooms, storeys


def _across(outline: F64, z: float, obstacles: Sequence[shapely.Geometry]) -> F64:
    """A walk across a lone room and back, along its longer side: the line nearest the
    middle that keeps :data:`~.roomnav.CLEARANCE` from every obstacle (furniture
    footprints), else the line farthest from them.

    Returns
    -------
    (3, 3) float64 floor points
    """
    a, b = outline.min(axis=0), outline.max(axis=0)
    along = 0 if b[0] - a[0] >= b[1] - a[1] else 1
    across = 1 - along
    lo, hi = a[across] + CLEARANCE, b[across] - CLEARANCE
    mid = 0.5 * (a[across] + b[across])
    offsets = np.linspace(lo, hi, 41) if hi > lo else np.array([mid])
    offsets = offsets[np.argsort(np.abs(offsets - mid), kind="stable")]
    s0, s1 = a[along] + 0.4, b[along] - 0.4
    best: tuple[float, float] | None = None
    for c in offsets.tolist():
        ends = np.zeros((2, 2))
        ends[:, along] = (s0, s1)
        ends[:, across] = c
        gap = min((shapely.LineString(ends).distance(o) for o in obstacles), default=np.inf)
        if gap >= CLEARANCE:
            best = (gap, c)
            break
        if best is None or gap > best[0]:
            best = (gap, c)
    assert best is not None
    pts = np.zeros((3, 3))
    pts[:, along] = (s0, s1, s0)
    pts[:, across] = best[1]
    pts[:, 2] = z
    return pts


def tour(
    graph: RoomGraph, start: int, speed_kmh: float = INDOOR_SPEED_KMH, *,
    obstacles: Sequence[shapely.Geometry] = (),
) -> tuple[RecordedPath, dict[str, Any]]:
    """The ``tour`` walk from cell ``start`` (see the module docstring).

    ``obstacles`` (furniture footprints, scene-local) keep a lone room's walk across it
    clear of them (:data:`~.roomnav.CLEARANCE`): a single open hall full of machines.

    Returns
    -------
    path:
        The recorded walk.
    coverage:
        ``rooms`` (all rooms), ``reachable`` (rooms reachable from the start),
        ``visited``, ``storeys_reachable``, ``storeys_visited``, ``unreachable``
        (names of up to 10 rooms the walk cannot reach) and ``seconds``.
    """
    room_cells: dict[str, list[int]] = {}
    for cell in graph.cells.values():
        if cell.room is not None and cell.kind == "room":
            room_cells.setdefault(cell.room, []).append(cell.id)
    names = {cell.room: cell.name for cell in graph.cells.values() if cell.room is not None}
    cur = graph.centre[start]
    dist0, _ = graph.distances(cur)
    reachable = {r for r, cs in room_cells.items() if any(graph.centre.get(c) in dist0 for c in cs)}
    storeys_reachable = {graph.cells[c].storey for r in reachable for c in room_cells[r]}
    visited: set[str] = set()
    storeys: set[int] = set()
    parts: list[F64] = [graph.nodes[cur][None, :]]
    v0, s0 = rooms_along(graph, parts[0])
    visited |= v0
    storeys |= s0
    while True:
        dist, prev = graph.distances(cur)
        best: tuple[float, int] | None = None
        for r in reachable - visited:
            for cid in room_cells[r]:
                n = graph.centre.get(cid)
                if n is not None and n in dist and (best is None or dist[n] < best[0]):
                    best = (dist[n], n)
        if best is None:
            break
        target = best[1]
        nodes = [target]
        while nodes[-1] != cur:
            nodes.append(prev[nodes[-1]])
        leg = graph.polyline(nodes[::-1])
        got, st = rooms_along(graph, leg)
        visited |= got | {graph.cells[graph.node_cell[target]].room or ""}
        storeys |= st | {graph.cells[graph.node_cell[target]].storey}
        parts.append(leg[1:])
        cur = target
    floor = np.concatenate(parts)
    if len(floor) < 2:
        # one room and nowhere to go: walk across it and back
        only = graph.cells[start]
        floor = _across(only.outline, only.zmin, obstacles)
    path = walk_path(TOUR_NAME, floor, speed_kmh, EYE_HEIGHT)
    visited.discard("")
    unreachable = sorted(names[r] for r in set(room_cells) - reachable)
    return path, {
        "rooms": len(room_cells),
        "reachable": len(reachable),
        "visited": len(visited & reachable),
        "storeys_reachable": len(storeys_reachable),
        "storeys_visited": len(storeys & storeys_reachable),
        "unreachable": unreachable[:10],
        "unreachable_count": len(unreachable),
        "seconds": path.duration,
        "long_enough": path.duration >= TOUR_MIN_SECONDS,
    }
