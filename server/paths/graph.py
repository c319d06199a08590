"""The navigation graph of a finished scene database, whatever its kind.

:func:`scene_graph` reads a city (its street part), an interior (its room part) or a
crossing scene (both, joined at its entrances) into the one
:class:`~walkstream.server.bake.scenenav.SceneGraph` that ``walkstream path record``
routes on.
"""

from __future__ import annotations

import numpy as np
import shapely

from walkstream.server.bake.navgraph import CellGraph
from walkstream.server.bake.placement import door_face
from walkstream.server.bake.roomlayout import Portal, RoomCell, StairLink
from walkstream.server.bake.roomnav import RoomGraph
from walkstream.server.bake.scenenav import Entrance, SceneGraph, front_of
from walkstream.server.store import CellInfo, RoomInfo, SceneReader

__all__ = ["interior_graph", "scene_graph"]


def _room_part(reader: SceneReader, cells: list[CellInfo], rooms: dict[int, RoomInfo]) -> RoomGraph:
    room_cells = [
        RoomCell(c.id, c.kind, rooms[c.id].name, rooms[c.id].room, rooms[c.id].storey, np.asarray(c.boundary),
                 c.zmin, c.zmax, np.asarray(rooms[c.id].planes))
        for c in cells if c.id in rooms
    ]
    inner = [Portal(p.id, p.kind, p.a, p.b, np.asarray(p.polygon), p.source, p.name)
             for p in reader.portals() if p.a in rooms and p.b in rooms]
    stairs = [StairLink(s.portal, s.lower, s.upper, np.asarray(s.path), s.name) for s in reader.stairs()]
    return RoomGraph(room_cells, inner, stairs)


def interior_graph(reader: SceneReader) -> RoomGraph:
    """The room part of a scene database's graph (its rooms, doorways, portals and stairs)."""
    return _room_part(reader, list(reader.cells()), reader.rooms())


def scene_graph(reader: SceneReader) -> SceneGraph:
    """The navigation graph of a scene database: its street cells, its rooms and the
    entrances joining them (see :class:`~walkstream.server.bake.scenenav.SceneGraph`).

    Raises
    ------
    RouteError
        The scene has rooms and street cells but no entrance joining them.
    InputError
        A street cell cannot be used for routes.
    """
    cells = list(reader.cells())
    rooms = reader.rooms()
    street_cells = [c for c in cells if c.id not in rooms]
    streets = CellGraph(street_cells) if street_cells else None
    room_part = _room_part(reader, cells, rooms) if rooms else None
    by_portal = {p.id: p for p in reader.portals()}
    by_cell = {c.id: c for c in cells}
    joins: list[Entrance] = []
    for e in reader.entrances():
        doorway = by_cell[e.doorway]
        ends, normal = door_face(by_portal[e.portal].polygon, doorway.boundary)
        joins.append(front_of(shapely.Polygon(by_cell[e.street].boundary), ends.mean(axis=0), normal, doorway.zmin,
                              e.portal, e.street, e.doorway))
    return SceneGraph(streets, room_part, joins)
