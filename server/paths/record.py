"""A recorded path routed on a finished scene's navigation graph and stored in it (a new scene version).

Every scene kind routes on its one graph (:func:`~.graph.scene_graph`): a city's path
along its streets (:func:`record_path`), a walk through an interior's rooms or from a
crossing scene's streets into its rooms and out (:func:`record_walk`).
"""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from walkstream.server.bake.roomnav import INDOOR_SPEED_KMH, walk_path
from walkstream.server.bake.scenenav import Place
from walkstream.server.paths.graph import scene_graph
from walkstream.server.store import SceneReader, write_path
from walkstream.shared.errors import RouteError, StoreError
from walkstream.shared.paths import WALK_EYE_HEIGHT, RecordedPath

__all__ = ["open_existing", "record_path", "record_walk"]


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
    """Record a path along the street part of a scene's graph and store it in a finished scene.

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
        graph = scene_graph(reader).streets
    finally:
        reader.close()
    route = graph.plan(from_xy, to_xy, via=via)
    path = RecordedPath.from_polyline(name, route.xy, speed_kmh, eye_height)
    return path, write_path(db, name, path.to_msgpack())


# --------------------------------------------------------------------------- rooms and crossings


def record_walk(
    db: str | os.PathLike[str],
    name: str,
    start: Place,
    end: Place,
    speed_kmh: float = INDOOR_SPEED_KMH,
    via: Sequence[Place] = (),
    *,
    replace: bool = False,
) -> tuple[RecordedPath, str]:
    """Record a walk through an interior or a crossing scene and store it: room to room
    through doors, up stairs, and between streets and rooms through an entrance.

    Places are room names or positions (:data:`~walkstream.server.bake.scenenav.Place`);
    the eye stays :data:`~walkstream.server.bake.roomnav.EYE_HEIGHT` above the ground or
    floor under it (the storey's floor, or a stair's treads).

    Raises
    ------
    StoreError
        Not a scene database, a city (record its paths with :func:`record_path`), or
        the name is taken.
    RouteError
        An unknown or ambiguous room name, a position outside every cell, or no
        walkable connection.
    """
    reader = open_existing(db, name, replace)
    try:
        if reader.meta.kind == "city":
            raise StoreError(f"{os.fspath(db)}: a city scene: record its paths with --from X,Y --to X,Y")
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
