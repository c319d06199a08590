"""A GPX track (a walk someone recorded with a phone or a GPS) read into scene-local metres.

:func:`read_gpx` takes the points of every track segment of the file, in order (else
its routes, else its waypoints), as lon/lat (WGS 84, what GPX stores), projects them
to the scene's CRS with pyproj and moves them by the scene origin.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from walkstream.server.sources.crs import outside_lonlat
from walkstream.server.sources.geojsonlines import line_to_scene
from walkstream.shared.arrays import F64
from walkstream.shared.errors import SourceError

__all__ = ["read_gpx"]
_MAX_GPX_BYTES = 256 << 20


def read_gpx(path: str | os.PathLike[str], crs: str, origin: Sequence[float]) -> F64:
    """The track of a GPX file in scene-local metres.

    Parameters
    ----------
    path:
        The ``.gpx`` file.
    crs, origin:
        The scene's CRS (projected metres) and origin in it.

    Returns
    -------
    numpy.ndarray
        ``(n, 2) float64`` vertices, repeated ones dropped.

    Raises
    ------
    SourceError
        Unreadable or malformed file, no track points, out-of-range coordinates.
    """
    import gpxpy
    import gpxpy.gpx

    p = Path(path)
    try:
        if p.stat().st_size > _MAX_GPX_BYTES:
            raise SourceError(f"{p}: larger than {_MAX_GPX_BYTES >> 20} MiB")
        text = p.read_text(encoding="utf-8-sig")
    except OSError as exc:
        raise SourceError(f"{p}: cannot read file: {exc.strerror or exc}") from exc
    except UnicodeDecodeError as exc:
        raise SourceError(f"{p}: not GPX: not UTF-8 text ({exc.reason})") from exc
    try:
        gpx = gpxpy.parse(text)
    except (gpxpy.gpx.GPXException, ValueError) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise SourceError(f"{p}: not GPX: {first}") from exc
    pts = [
        (pt.longitude, pt.latitude)
        for track in gpx.tracks
        for segment in track.segments
        for pt in segment.points
    ]
    if not pts:
        pts = [(pt.longitude, pt.latitude) for route in gpx.routes for pt in route.points]
    if not pts:
        pts = [(pt.longitude, pt.latitude) for pt in gpx.waypoints]
    if not pts:
        raise SourceError(f"{p}: the GPX file has no track, route or waypoint")
    raw = np.asarray(pts, dtype=np.float64)
    bad = np.flatnonzero(~np.isfinite(raw).all(axis=1) | outside_lonlat(raw))
    if len(bad):
        i = int(bad[0])
        raise SourceError(f"{p}: point {i} ({raw[i, 0]}, {raw[i, 1]}) is not a lon/lat position")
    return line_to_scene(raw, None, crs, origin, str(p), point="point", line="track")
