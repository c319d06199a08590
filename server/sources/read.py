"""Pick the reader of a scene source by its file name: one table, suffix -> reader."""

from __future__ import annotations

import inspect
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

from walkstream.server.sources.geojson import load_geojson
from walkstream.server.sources.osm import load_osm
from walkstream.server.sources.scene import SourceScene
from walkstream.shared.errors import SourceError

__all__ = ["READERS", "read_source"]

#: File name ending (lower case) -> reader.  The longest matching ending wins.
READERS: dict[str, Callable[..., SourceScene]] = {
    ".geojson": load_geojson,
    ".json": load_geojson,
    ".osm": load_osm,
    ".osm.xml": load_osm,
    ".osm.pbf": load_osm,
    ".pbf": load_osm,
}


def read_source(path: str | os.PathLike[str], **options: Any) -> SourceScene:
    """Read a scene source with the reader its file name calls for.

    ``options`` (``network="walk"``, ...) go to the reader; those a reader does not
    take are left out, so one call serves every format.

    Raises
    ------
    SourceError
        No reader for the file's suffix (the message lists them), or the reader's own.
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
