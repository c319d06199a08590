"""Walks recorded in a crossing scene: from a street through the entrance into a room, and back."""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np
import shapely

from walkstream.server.bake.crossnav import Entrance, Place, SceneGraph, front_of
from walkstream.server.bake.navgraph import CellGraph
from walkstream.server.bake.placement import door_face
from walkstream.server.bake.roomnav import INDOOR_SPEED_KMH, RoomGraph, walk_path
from walkstream.server.bake.rooms import Portal, RoomCell, StairLink
from walkstream.server.store import SceneReader, write_path
from walkstream.shared.errors import RouteError, StoreError
from walkstream.shared.paths import RecordedPath

__all__ = ["scene_graph", "record_crossing_path"]


def scene_graph(reader: SceneReader) -> SceneGraph:
    """The joined street and room graph of a crossing scene database.

    Raises
    ------
    StoreError
        The scene is not a crossing scene (it has no entrance).
    """
    entrances = reader.entrances()
    if not entrances:
        raise StoreError(f"{reader.path}: not a crossing scene (no entrance joins its streets to rooms)")
    rooms = reader.rooms()
    cells = list(reader.cells())
    city = CellGraph([c for c in cells if c.id not in rooms])
    room_cells = [
        RoomCell(c.id, c.kind, rooms[c.id].name, rooms[c.id].room, rooms[c.id].storey, np.asarray(c.boundary),
                 c.zmin, c.zmax, np.asarray(rooms[c.id].planes))
        for c in cells if c.id in rooms
    ]
    portals = reader.portals()
    by_id = {p.id: p for p in portals}
    inner = [Portal(p.id, p.kind, p.a, p.b, np.asarray(p.polygon), p.source, p.name)
             for p in portals if p.a in rooms and p.b in rooms]
    stairs = [StairLink(s.portal, s.lower, s.upper, np.asarray(s.path), s.name) for s in reader.stairs()]
    graph = RoomGraph(room_cells, inner, stairs)
    by_cell = {c.id: c for c in cells}
    joins: list[Entrance] = []
    for e in entrances:
        doorway = by_cell[e.doorway]
        ends, normal = door_face(by_id[e.portal].polygon, doorway.boundary)
        joins.append(front_of(shapely.Polygon(by_cell[e.street].boundary), ends.mean(axis=0), normal, doorway.zmin,
                              e.portal, e.street, e.doorway))
    return SceneGraph(city, graph, joins)


def record_crossing_path(
    db: str | os.PathLike[str],
    name: str,
    start: Place,
    end: Place,
    speed_kmh: float = INDOOR_SPEED_KMH,
    via: Sequence[Place] = (),
    *,
    replace: bool = False,
) -> tuple[RecordedPath, str]:
    """Record a walk through streets and rooms (in at an entrance, out again) and store it.

    Places are room names or positions (:data:`~walkstream.server.bake.crossnav.Place`);
    the eye stays :data:`~walkstream.server.bake.roomnav.EYE_HEIGHT` above the ground
    or floor under it.

    Raises
    ------
    StoreError
        Not a crossing scene database, or the name is taken.
    RouteError
        An unknown room, a point outside every cell, or no connection.
    """
    reader = SceneReader.open(db)
    try:
        if not replace and name in reader.path_names():
            raise StoreError(
                f"{os.fspath(db)}: a path named {name!r} exists already (--replace, or replace=True, overwrites it)"
            )
        graph = scene_graph(reader)
    finally:
        reader.close()
    places = [start, *via, end]
    legs = [graph.route(a, b) for a, b in zip(places, places[1:], strict=False)]
    floor = np.concatenate([legs[0]] + [leg[1:] for leg in legs[1:]])
    if len(floor) < 2 or float(np.linalg.norm(floor[-1] - floor[0])) < 1e-3 and len(floor) < 3:
        raise RouteError(f"path {name!r}: start and end are the same place")
    path = walk_path(name, floor, speed_kmh)
    return path, write_path(db, name, path.to_msgpack())
