"""What the viewer needs next and when: the cells along the predicted way, their records,
their objects, and the index tiles (a pure function of what the client knows).

:func:`plan_needs` takes the viewer's cell, position and motion and the held part of
the cell index and answers, in seconds until needed:

* ``need`` -- the cells whose objects are wanted: the viewer's cell (0 s) and those
  the route (:func:`~walkstream.client.stream.route.predict_route`) reaches within
  ``reach_m`` of cost, each at its cost over the speed;
* ``records`` -- the cells whose records are wanted: the same within
  ``reach_records_m`` (a little further: a cell's objects can be asked for only once
  its record is in), each within the objects' reach at its *distance* over the
  speed: the turn cost decides which cells are wanted, but a cell round a corner is
  entered as soon as the way there is walked, and a late record leaves the viewer
  with nothing to count; beyond the objects' reach at its *cost* over the speed:
  its objects are not wanted yet, so its record is needed no sooner than they, and
  the side streets of a junction the route passes (many records on a close-meshed
  network) do not go before the street it goes on along;
* ``tiles`` -- the index tiles wanted: those around the viewer (0 s), those the
  route runs through and into (a neighbour whose tile is not held), and, when the
  viewer is outside every held cell, those within ``reach_m``.

Outside every held cell (or before any index tile arrived) the cells that the
straight least-squares extrapolation of the motion enters are wanted too.
:func:`wanted_objects` turns ``need`` into the objects to fetch, keyed
``(seconds, -ACH)`` so that sorting puts the soonest and most visible first.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from walkstream.client.stream.cellmap import CellMap
from walkstream.client.stream.route import predict_route
from walkstream.shared.cells import TileGrid
from walkstream.shared.wire import CellRecord

__all__ = ["Tile", "Needs", "tile_key", "tile_of_key", "plan_needs", "wanted_objects"]

Tile = tuple[int, int] | None
"""An index tile ``(i, j)``, or None for the whole-scene index."""


def tile_key(tile: Tile) -> int:
    """The cache id of an index tile (``-1`` for the whole-scene index).

    >>> tile_key((2, 3)), tile_of_key(tile_key((2, 3))), tile_key(None)
    (131075, (2, 3), -1)
    """
    return -1 if tile is None else tile[0] * 65536 + tile[1]


def tile_of_key(key: int) -> Tile:
    """The tile of a :func:`tile_key`."""
    return None if key < 0 else (key // 65536, key % 65536)


@dataclass(frozen=True)
class Needs:
    """What is wanted, in seconds until needed (see the module docs)."""

    need: dict[int, float]
    records: dict[int, float]
    tiles: dict[Tile, float]


def plan_needs(
    cellmap: CellMap,
    grid: TileGrid | None,
    xy: ArrayLike,
    velocity: ArrayLike,
    heading: ArrayLike | None,
    *,
    reach_m: float,
    reach_records_m: float,
    turn_m: float,
    min_speed: float,
    prefetch: bool = True,
) -> Needs:
    """The cells, records and index tiles wanted, and when (see the module docs).

    Parameters
    ----------
    cellmap : CellMap
        The held outlines and adjacency; its ``current`` is the viewer's cell.
    grid : TileGrid or None
        The tiles of the cell index (None before the manifest arrived).
    xy, velocity : (2,) float
        The viewer's position (m) and velocity (m/s).
    heading : (2,) float or None
        The way the viewer last went (None: no preference); used while it moves.
    reach_m, reach_records_m : float
        Horizons of cost for objects and for records, metres.
    turn_m : float
        The cost of turning back (:func:`~walkstream.client.stream.route.turn_cost_m`).
    min_speed : float
        Need times assume at least this speed, m/s.
    prefetch : bool
        False: only the viewer's own cell (and the tiles under it).
    """
    p = np.asarray(xy, dtype=np.float64).reshape(2)
    v = np.asarray(velocity, dtype=np.float64).reshape(2)
    need: dict[int, float] = {}
    records: dict[int, float] = {}
    tiles: dict[Tile, float] = {}
    cur = cellmap.current
    speed = float(np.hypot(*v))
    v_eff = max(speed, min_speed)

    def want_tile(t: Tile, s: float) -> None:
        if t not in tiles or tiles[t] > s:
            tiles[t] = s

    if cur is not None:
        need[cur] = records[cur] = 0.0
    if grid is not None:
        for _d, tile in grid.tiles_near(p):
            want_tile(tile, 0.0)  # the viewer may be in a cell of any of these
    if prefetch and cur is not None and cellmap.knows(cur):
        route = predict_route(
            cellmap, cur, p, heading if speed > 0.3 else None, reach_records_m, turn_m
        )
        for s in route.steps:
            t = s.cost_m / v_eff
            # a turn makes a cell less likely, not later: if the viewer takes it, it is
            # there after the distance alone, so its record (small) is due by that
            # where its objects are wanted; beyond, its record is needed no sooner than they
            records.setdefault(s.cell, (s.distance_m if s.cost_m <= reach_m else s.cost_m) / v_eff)
            if s.cost_m <= reach_m:
                need.setdefault(s.cell, t)
            on = cellmap.tile_of.get(s.cell)
            if grid is not None and on is not None:
                want_tile(on, t)  # the tiles it runs through
        if grid is not None:
            # the route runs into cells whose tile is missing: the tiles around the
            # held cell it leaves from
            for st in route.frontier.values():
                poly = cellmap.outlines[st.cell]
                lo, hi = poly.min(axis=0), poly.max(axis=0)
                for _d, tile in grid.tiles_near(
                    (lo + hi) / 2.0, float(np.hypot(*(hi - lo))) / 2.0
                ):
                    want_tile(tile, st.cost_m / v_eff)
    found = cur is not None and cellmap.find(p, cur) == cur
    if grid is not None and not found:
        # outside every held cell: look around (the track ahead may enter cells)
        for d, tile in grid.tiles_near(p, reach_m):
            want_tile(tile, d / v_eff)
    if prefetch and not found and speed > 0.2:
        step = max(0.05, min(0.5, 2.0 / speed))
        dts = np.arange(step, reach_m / speed + 1e-9, step)
        track = p[None, :] + dts[:, None] * v[None, :]
        for dt, cell in zip(dts.tolist(), cellmap.find_along(track, None), strict=True):
            if cell is not None:
                need.setdefault(cell, dt)
                records.setdefault(cell, dt)
    return Needs(need, records, tiles)


def wanted_objects(
    need: Mapping[int, float], cells: Mapping[int, CellRecord], has: Callable[[int], bool]
) -> dict[int, tuple[float, float]]:
    """Object id -> ``(seconds until needed, -ACH)`` for the PVS objects of the needed
    cells whose records are held, leaving out those ``has`` says are held already.

    An object in several PVS gets its most urgent key.
    """
    wanted: dict[int, tuple[float, float]] = {}
    for cell, t in need.items():
        rec = cells.get(cell)
        if rec is None:
            continue
        ids, ach = rec.streamed()  # a ring's far field too (drawn while a texture is missing)
        for oid, a in zip(ids.tolist(), ach.tolist(), strict=True):
            if has(oid):
                continue
            key = (t, -a)
            old = wanted.get(oid)
            if old is None or key < old:
                wanted[oid] = key
    return wanted
