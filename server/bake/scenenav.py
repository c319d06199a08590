"""The one navigation graph of a scene: street cells and rooms, joined at the entrance portals.

:class:`SceneGraph` is what every walk of a scene is routed on: the default walks of
the bake (a city's along its streets, an interior's tour through its rooms, a
crossing's ``enter`` walk through its door), ``walkstream path record`` and the routes
of a crossing scene.  It holds the scene's *street part* (:class:`~.navgraph.CellGraph`:
its states are crossings of the portals between street cells, with turn costs), its
*room part* (:class:`~.roomnav.RoomGraph`: its nodes are door thresholds, room
centres and stair ends) and the *entrances* that join them; a city has the first
only, an interior the second, a crossing scene both.  Each part searches with the
one Dijkstra of :mod:`walkstream.shared.nav`.

An entrance is the portal between a street cell and a doorway cell: a route that
crosses it runs along the streets to the point in front of the door
(:attr:`Entrance.front`, in the street cell), straight to the threshold
(:attr:`Entrance.threshold`, just inside the doorway) and on through the rooms.  With
several entrances the shortest sum of the three legs wins.  (The legs are searched
one by one, not as one search over both parts: a room leg's costs then start at zero,
so its sums, and the routes that tie, stay those of the interior alone.)

Heights: the streets are the ground (``z = 0``), an interior placed in a city has its
lowest floor there too (:mod:`~.placement`), so one walk keeps its eye
:data:`~.roomnav.EYE_HEIGHT` above the floor under it all the way.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import shapely

from walkstream.server.bake.navgraph import CellGraph
from walkstream.server.bake.roomnav import EYE_HEIGHT, INDOOR_SPEED_KMH, RoomGraph, walk_path
from walkstream.shared.arrays import F64
from walkstream.shared.errors import RouteError
from walkstream.shared.paths import RecordedPath

__all__ = ["ENTER_NAME", "Entrance", "SceneGraph", "Place", "front_of"]

ENTER_NAME = "enter"
"""Name of the default walk of a crossing scene: from the street in through the door and back."""

Place = str | tuple[float, float] | tuple[float, float, float]
"""Where a walk starts or ends: a room's name, a point ``x, y`` (in a street cell, else
on the interior's lowest storey) or an eye position ``x, y, z`` in the interior."""

_INSIDE = 0.05  # the threshold lies this far inside the doorway (metres)
_IN_FRONT = (10.0, 8.0, 6.0, 4.0, 2.0, 1.0)  # the enter walk starts this far out, the first in a street cell


@dataclass(frozen=True)
class Entrance:
    """Where streets and rooms meet: ``street`` and ``doorway`` cell ids, ``front``
    ``(2,)`` a point of the street cell in front of the door, ``threshold`` ``(3,)``
    a floor point just inside the doorway, ``normal`` ``(2,)`` out of the building."""

    portal: int
    street: int
    doorway: int
    front: F64
    threshold: F64
    normal: F64


def front_of(street: shapely.Geometry, door_middle: F64, normal: F64, floor: float, portal: int, street_id: int,
             doorway: int) -> Entrance:
    """The :class:`Entrance` of a door whose outer face's middle is ``door_middle``."""
    mid = np.asarray(door_middle, np.float64).reshape(2)
    near = np.asarray(shapely.get_coordinates(shapely.shortest_line(street, shapely.Point(mid))))[0]
    centre = np.asarray(street.centroid.coords)[0]
    step = centre - near
    front = near + step * min(1.0, 0.3 / max(float(np.hypot(*step)), 1e-9))
    inner = mid - np.asarray(normal) * _INSIDE
    return Entrance(portal, street_id, doorway, front, np.array([inner[0], inner[1], floor]), np.asarray(normal))


class SceneGraph:
    """Routes through a scene's streets and rooms, joined at entrances (see the module docstring).

    Parameters
    ----------
    streets:
        The street part (the scene's street or grid cells), or None (an interior).
    rooms:
        The room part (the interior's cells, portals and stairs), or None (a city).
    entrances:
        Where they meet (ids as in ``streets`` and ``rooms``); needed when both are given.

    Raises
    ------
    RouteError
        No part, or both without an entrance.
    """

    def __init__(
        self, streets: CellGraph | None = None, rooms: RoomGraph | None = None, entrances: Sequence[Entrance] = ()
    ) -> None:
        if streets is None and rooms is None:
            raise RouteError("the scene has neither street cells nor rooms to walk")
        if streets is not None and rooms is not None and not entrances:
            raise RouteError("the scene has no entrance joining its streets to its rooms")
        self._streets = streets
        self._rooms = rooms
        self.entrances = list(entrances)

    @property
    def streets(self) -> CellGraph:
        """The street part.

        Raises
        ------
        RouteError
            The scene has no street cells (an interior).
        """
        if self._streets is None:
            raise RouteError("the scene has no street cells (an interior): walk it by rooms or X,Y,Z")
        return self._streets

    @property
    def rooms(self) -> RoomGraph:
        """The room part.

        Raises
        ------
        RouteError
            The scene has no rooms (a city).
        """
        if self._rooms is None:
            raise RouteError("the scene has no rooms (a city): walk it by X,Y")
        return self._rooms

    def _where(self, place: Place) -> tuple[str, Any]:
        if self._rooms is None:
            if isinstance(place, str) or len(place) != 2:
                raise RouteError(f"{place!r}: a city scene has no rooms; give a point X,Y")
            return "street", np.array([float(v) for v in place])
        if isinstance(place, str):
            return "room", self.rooms.room_cells(place)[0]
        q = [float(v) for v in place]
        if self._streets is None:
            # an interior alone: a point without a height is on the lowest storey; the
            # room part says which point lies outside its cells
            if len(q) == 2:
                q.append(min(c.zmin for c in self.rooms.cells.values()) + EYE_HEIGHT)
            return "room", np.array(q)
        if len(q) == 2:
            if self.streets.locator.locate(q[0], q[1]) is not None:
                return "street", np.array(q)
            low = min(c.zmin for c in self.rooms.cells.values())
            q.append(low + EYE_HEIGHT)
        if self.rooms.locate(q[0], q[1], q[2]) is None:
            if self.streets.locator.locate(q[0], q[1]) is not None:
                return "street", np.array(q[:2])
            raise RouteError(f"({q[0]:.1f}, {q[1]:.1f}) is outside every street cell and every room of the scene")
        return "room", np.array(q)

    def _street(self, a: F64, b: F64) -> F64:
        xy = self.streets.plan(a, b).xy
        return np.column_stack([xy, np.zeros(len(xy))])

    def _room(self, a: Any, b: Any) -> F64:
        return self.rooms.route(a, b)

    def route(self, start: Place, end: Place) -> F64:
        """Floor points ``(k, 3)`` of the shortest walk from ``start`` to ``end`` (the
        streets at ``z = 0``), through an entrance when one is a street and the other a room.

        Raises
        ------
        RouteError
            An unknown room, a point outside every cell, or no connection.
        """
        (ka, a), (kb, b) = self._where(start), self._where(end)
        if ka == kb == "street":
            return self._street(a, b)
        if ka == kb == "room":
            return self._room(a, b)
        best: tuple[float, F64] | None = None
        errors = []
        for e in self.entrances:
            door = np.array([e.threshold[0], e.threshold[1], e.threshold[2] + EYE_HEIGHT])
            try:
                if ka == "street":
                    legs = [self._street(a, e.front), self._room(door, b)]
                else:
                    legs = [self._room(a, door), self._street(e.front, b)]
            except RouteError as exc:
                errors.append(str(exc))
                continue
            floor = np.concatenate([legs[0], legs[1]])
            length = float(np.linalg.norm(np.diff(floor, axis=0), axis=1).sum())
            if best is None or length < best[0]:
                best = (length, floor)
        if best is None:
            raise RouteError(f"no route between the streets and the rooms: {'; '.join(errors)}")
        return best[1]

    def enter_walk(self, name: str = ENTER_NAME, speed_kmh: float = INDOOR_SPEED_KMH) -> tuple[RecordedPath, str]:
        """From the street in front of the first entrance, through the door to the farthest
        room of its storey, and back out; returns the walk and the room's name."""
        e = self.entrances[0]
        start = None
        for d in _IN_FRONT:
            p = e.front + e.normal * d
            if self.streets.locator.locate(float(p[0]), float(p[1])) is not None:
                start = p
                break
        if start is None:
            start = e.front
        door = self.rooms.locate(float(e.threshold[0]), float(e.threshold[1]), float(e.threshold[2]) + EYE_HEIGHT)
        if door is None:
            raise RouteError("the entrance's threshold is in no cell of the interior")
        storey = self.rooms.cells[door].storey
        dist, _ = self.rooms.distances(self.rooms.members[door][0])
        far = [
            (dist[n], -c) for c, n in self.rooms.centre.items()
            if n in dist and self.rooms.cells[c].storey == storey and self.rooms.cells[c].kind == "room"
        ]
        if not far:
            raise RouteError("no room can be reached from the entrance")
        room = self.rooms.cells[-max(far)[1]]
        there = self.route((float(start[0]), float(start[1])), room.name)
        back = self.route(room.name, (float(start[0]), float(start[1])))
        floor = np.concatenate([there, back[1:]])
        return walk_path(name, floor, speed_kmh, EYE_HEIGHT), room.name

