"""A recorded path routed along a finished scene's cells and stored in it (a new scene version)."""

from __future__ import annotations

import os
from collections.abc import Sequence

from numpy.typing import ArrayLike

from walkstream.server.bake.navgraph import CellGraph
from walkstream.server.store import SceneReader, write_path
from walkstream.shared.errors import StoreError
from walkstream.shared.paths import WALK_EYE_HEIGHT, RecordedPath

__all__ = ["record_path"]


# --------------------------------------------------------------------------- storing


def _existing(db: str | os.PathLike[str], name: str, replace: bool) -> SceneReader:
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
    reader = _existing(db, name, replace)
    try:
        graph = CellGraph(reader.cells())
    finally:
        reader.close()
    route = graph.plan(from_xy, to_xy, via=via)
    path = RecordedPath.from_polyline(name, route.xy, speed_kmh, eye_height)
    return path, write_path(db, name, path.to_msgpack())
