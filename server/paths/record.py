"""A recorded path routed along a finished scene's cells and stored in it (a new scene version)."""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from walkstream.server.bake.navgraph import CellGraph
from walkstream.server.bake.roomnav import EYE_HEIGHT, INDOOR_SPEED_KMH, RoomGraph, walk_path
from walkstream.server.bake.rooms import Portal, RoomCell, StairLink
from walkstream.server.store import SceneReader, write_path
from walkstream.shared.errors import RouteError, StoreError
from walkstream.shared.paths import WALK_EYE_HEIGHT, RecordedPath

__all__ = ["record_path", "interior_graph", "record_interior_path", "Place", "open_existing"]

Place = str | tuple[float, float] | tuple[float, float, float]
"""Where an interior walk starts or ends: a room's name, or a position ``x, y[, z]``
(scene-local metres; ``z`` the eye height, which picks the storey; without it the
lowest storey)."""


# --------------------------------------------------------------------------- storing


def open_existing(db: str | os.PathLike[str], name: str, replace: bool) -> SceneReader:
    """Open the scene ``db`` to add path ``name``: refused when it exists unless ``replace``."""
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
    reader = open_existing(db, name, replace)
    try:
        graph = CellGraph(reader.cells())
    finally:
        reader.close()
    route = graph.plan(from_xy, to_xy, via=via)
    path = RecordedPath.from_polyline(name, route.xy, speed_kmh, eye_height)
    return path, write_path(db, name, path.to_msgpack())


# --------------------------------------------------------------------------- interiors


def interior_graph(reader: SceneReader) -> RoomGraph:
    """The walking graph of an interior scene database."""
    rooms = reader.rooms()
    cells = [
        RoomCell(c.id, c.kind, rooms[c.id].name, rooms[c.id].room, rooms[c.id].storey, np.asarray(c.boundary),
                 c.zmin, c.zmax, np.asarray(rooms[c.id].planes))
        for c in reader.cells()
    ]
    portals = [Portal(p.id, p.kind, p.a, p.b, np.asarray(p.polygon), p.source, p.name) for p in reader.portals()]
    stairs = [StairLink(s.portal, s.lower, s.upper, np.asarray(s.path), s.name) for s in reader.stairs()]
    return RoomGraph(cells, portals, stairs)


def _place(graph: RoomGraph, place: Place) -> int | np.ndarray:
    if isinstance(place, str):
        return graph.room_cells(place)[0]
    q = [float(v) for v in place]
    if len(q) == 2:
        low = min(c.zmin for c in graph.cells.values())
        q.append(low + EYE_HEIGHT)
    return np.array(q, dtype=np.float64)


def record_interior_path(
    db: str | os.PathLike[str],
    name: str,
    start: Place,
    end: Place,
    speed_kmh: float = INDOOR_SPEED_KMH,
    via: Sequence[Place] = (),
    *,
    replace: bool = False,
) -> tuple[RecordedPath, str]:
    """Record a walk through an interior (room to room through doors, up stairs) and store it.

    The eye stays :data:`~walkstream.server.bake.roomnav.EYE_HEIGHT` above the floor
    under it (the storey's floor, or a stair's treads).

    Raises
    ------
    StoreError
        Not a scene database, not an interior, or the name is taken.
    RouteError
        An unknown or ambiguous room name, a position outside every cell, or rooms
        with no walkable connection.
    """
    reader = open_existing(db, name, replace)
    try:
        if reader.meta.kind != "interior":
            raise StoreError(f"{os.fspath(db)}: a city scene: record its paths with --from X,Y --to X,Y")
        graph = interior_graph(reader)
    finally:
        reader.close()
    places = [start, *via, end]
    legs = [graph.route(_place(graph, a), _place(graph, b)) for a, b in zip(places, places[1:], strict=False)]
    floor = np.concatenate([legs[0]] + [leg[1:] for leg in legs[1:]])
    if len(floor) < 2 or float(np.linalg.norm(floor[-1] - floor[0])) < 1e-3 and len(floor) < 3:
        raise RouteError(f"path {name!r}: start and end are the same place")
    path = walk_path(name, floor, speed_kmh)
    return path, write_path(db, name, path.to_msgpack())
