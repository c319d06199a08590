"""Which reader a source file gets: one plain table of file-name endings.

:func:`read_source` is what the bake calls; a new source format is one row of
:data:`READERS` (the longest matching ending wins, case-insensitive).  A city source
(GeoJSON, OpenStreetMap) comes back as a :class:`~.scene.SourceScene`, an interior
(IFC, a ``walkstream-interior`` file) as an :class:`~.interior.InteriorScene`.
"""

from __future__ import annotations

import inspect
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

from walkstream.server.sources.interior import InteriorScene
from walkstream.server.sources.scene import SourceScene
from walkstream.shared.errors import SourceError

__all__ = ["READERS", "read_source"]


def _geojson(path: Path, network: str = "walk") -> SourceScene:
    from walkstream.server.sources.geojson import load_geojson

    return load_geojson(path, network=network)


def _json(path: Path, network: str = "walk") -> SourceScene | InteriorScene:
    # .json is GeoJSON unless the file says it is a walkstream-interior
    from walkstream.server.sources.interiorfile import is_interior_file, load_interior

    return load_interior(path) if is_interior_file(path) else _geojson(path, network)


def _osm(path: Path, network: str = "walk") -> SourceScene:
    from walkstream.server.sources.osm import load_osm

    return load_osm(path, network=network)


def _ifc(path: Path, threads: int | None = None) -> InteriorScene:
    from walkstream.server.sources.ifc import load_ifc

    return load_ifc(path, threads=threads)


READERS: dict[str, Callable[..., SourceScene | InteriorScene]] = {
    ".geojson": _geojson,
    ".json": _json,
    ".osm": _osm,
    ".osm.xml": _osm,
    ".osm.pbf": _osm,
    ".pbf": _osm,
    ".ifc": _ifc,
}
"""File-name ending (lower case) -> reader.  The longest matching ending wins."""


def read_source(path: str | os.PathLike[str], **options: Any) -> SourceScene | InteriorScene:
    """Read a scene source with the reader its file name ends in (:data:`READERS`).

    Parameters
    ----------
    path:
        The source file.
    options:
        Passed on to the reader (``network="walk"`` for street networks, ``threads``
        for IFC tessellation); those a reader does not take are left out, so one call
        serves every format.

    Raises
    ------
    SourceError
        No reader for the file's ending (the message lists them), or the reader's own
        (one line naming the file).
    """
    p = Path(path)
    low = p.name.lower()
    match = [s for s in READERS if low.endswith(s)]
    if not match:
        raise SourceError(
            f"{p}: unknown source format; expected a file ending in {', '.join(sorted(READERS))}"
        )
    reader = READERS[max(match, key=len)]
    params = inspect.signature(reader).parameters
    return reader(p, **{k: v for k, v in options.items() if k in params})
