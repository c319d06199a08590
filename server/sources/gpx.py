"""A GPX track (a walk someone recorded with a phone or a GPS) read into scene-local metres.

:func:`read_gpx` takes the points of every track segment of the file, in order (else
its routes, else its waypoints), as lon/lat (WGS 84, what GPX stores), projects them
to the scene's CRS with pyproj and moves them by the scene origin.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from xml.parsers import expat

import numpy as np

from walkstream.server.sources.crs import outside_lonlat
from walkstream.server.sources.geojsonlines import line_to_scene
from walkstream.shared.arrays import F64
from walkstream.shared.errors import SourceError

__all__ = ["read_gpx"]
_MAX_GPX_BYTES = 256 << 20
_POINT_TAGS = ("trkpt", "rtept", "wpt")


def _points(p: Path) -> dict[str, list[tuple[str, str]]]:
    """(lon, lat) text of every track, route and way point, in file order, by kind.

    Read with expat's streaming parser, one callback per element and nothing kept
    but the two attributes: a track of 1,000,000 points takes a few seconds and
    little memory (gpxpy, which builds an object per point, took 73 s).

    Raises
    ------
    ExpatError
        Not XML.
    SourceError
        Not a ``gpx`` document.
    """
    found: dict[str, list[tuple[str, str]]] = {t: [] for t in _POINT_TAGS}
    root: list[str] = []

    def start(name: str, attrs: list[str]) -> None:
        tag = name[name.rfind("}") + 1 :]
        if not root:
            root.append(tag)
            if tag != "gpx":
                raise SourceError(f"{p}: not GPX: the root element is <{tag}>, not <gpx>")
        pts = found.get(tag)
        if pts is not None:
            a = dict(zip(attrs[::2], attrs[1::2], strict=True))
            pts.append((a.get("lon", ""), a.get("lat", "")))

    parser = expat.ParserCreate(namespace_separator="}")
    parser.ordered_attributes = True
    parser.StartElementHandler = start
    with p.open("rb") as fh:
        parser.ParseFile(fh)
    return found


def _lonlat(p: Path, kind: str, pts: list[tuple[str, str]]) -> F64:
    """The points as an ``(n, 2)`` array; a point that is not two numbers is named."""
    try:
        return np.asarray(pts, dtype=np.float64)
    except ValueError:
        for i, (lon, lat) in enumerate(pts):
            try:
                float(lon), float(lat)
            except ValueError:
                raise SourceError(f"{p}: {kind} {i}: lat={lat!r} lon={lon!r} is not a position") from None
        raise


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
    p = Path(path)
    try:
        if p.stat().st_size > _MAX_GPX_BYTES:
            raise SourceError(f"{p}: larger than {_MAX_GPX_BYTES >> 20} MiB")
        found = _points(p)
    except OSError as exc:
        raise SourceError(f"{p}: cannot read file: {exc.strerror or exc}") from exc
    except expat.ExpatError as exc:
        raise SourceError(f"{p}: not GPX: {exc}") from exc
    kind = next((k for k in _POINT_TAGS if found[k]), None)
    if kind is None:
        raise SourceError(f"{p}: the GPX file has no track, route or waypoint")
    raw = _lonlat(p, kind, found[kind])
    bad = np.flatnonzero(~np.isfinite(raw).all(axis=1) | outside_lonlat(raw))
    if len(bad):
        i = int(bad[0])
        raise SourceError(f"{p}: point {i} ({raw[i, 0]}, {raw[i, 1]}) is not a lon/lat position")
    return line_to_scene(raw, None, crs, origin, str(p), point="point", line="track")
