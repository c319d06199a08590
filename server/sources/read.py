"""Which reader a source file gets: one plain table of file-name endings.

:func:`read_source` is what the bake calls; a new source format is one row of
:data:`READERS` (the longest matching ending wins, case-insensitive).  A city source
comes back as a :class:`~.scene.SourceScene`, an interior as an
:class:`~.interior.InteriorScene`.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

from walkstream.server.sources.interior import InteriorScene
from walkstream.server.sources.scene import SourceScene

__all__ = ["READERS", "read_source"]


def _geojson(path: Path, **_options: Any) -> SourceScene:
    from walkstream.server.sources.geojson import load_geojson

    return load_geojson(path)


def _json(path: Path, **options: Any) -> SourceScene | InteriorScene:
    # .json is GeoJSON unless the file says it is a walkstream-interior
    from walkstream.server.sources.interiorfile import is_interior_file, load_interior

    return load_interior(path) if is_interior_file(path) else _geojson(path, **options)


def _ifc(path: Path, **options: Any) -> InteriorScene:
    from walkstream.server.sources.ifc import load_ifc

    return load_ifc(path, threads=options.get("threads"))


READERS: dict[str, Callable[..., SourceScene | InteriorScene]] = {
    ".geojson": _geojson,
    ".json": _json,
    ".ifc": _ifc,
}
"""File-name ending -> reader.  Any other ending is read as GeoJSON, as before."""


def read_source(path: str | os.PathLike[str], **options: Any) -> SourceScene | InteriorScene:
    """Read a scene source with the reader its file name ends in (:data:`READERS`).

    Parameters
    ----------
    path:
        The source file.
    options:
        Passed on to the reader (e.g. ``threads`` for IFC tessellation); readers
        ignore what they do not use.

    Raises
    ------
    SourceError
        From the reader: the file cannot be read as that format (one line naming it).
    """
    p = Path(path)
    name = p.name.lower()
    for ending in sorted(READERS, key=len, reverse=True):
        if name.endswith(ending):
            return READERS[ending](p, **options)
    return _geojson(p, **options)
