"""A GeoJSON line (a walk someone recorded) read into scene-local metres.

:func:`read_linestring` takes a GeoJSON ``LineString`` (or ``MultiLineString``, a
``Feature`` holding one, or a ``FeatureCollection`` with exactly one line feature):
coordinates in the file's declared ``crs`` (default lon/lat) are projected to the
scene's CRS with pyproj and moved by the scene origin.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pyproj

from walkstream.server.sources.crs import outside_lonlat, parse_crs_member, project
from walkstream.server.sources.geojson import as_points
from walkstream.server.sources.jsonfile import read_json_file
from walkstream.server.sources.rings import bound_vertices
from walkstream.shared.arrays import F64
from walkstream.shared.errors import InputError, SourceError

__all__ = ["MAX_LINE_POINTS", "line_to_scene", "read_linestring"]
_MAX_GEOJSON_BYTES = 256 << 20
#: Points a path keeps: a day's walk logged every second is 86,400; a longer line is
#: simplified to 5 cm, and refused if that is not enough
#: (:func:`~walkstream.server.sources.rings.bound_vertices`).
MAX_LINE_POINTS = 100_000


# --------------------------------------------------------------------------- GeoJSON lines


def read_linestring(
    source: str | os.PathLike[str] | Mapping[str, Any], crs: str, origin: Sequence[float]
) -> F64:
    """The one line of a GeoJSON object in scene-local metres.

    Parameters
    ----------
    source:
        A ``.geojson`` file or the parsed object: a ``LineString`` or
        ``MultiLineString`` geometry, a ``Feature`` with one, or a
        ``FeatureCollection`` with exactly one line feature (other features are
        ignored).  The parts of a ``MultiLineString`` are joined in order.
    crs:
        The scene's CRS (``SceneMeta.crs``), projected metres.
    origin:
        The scene origin in that CRS.

    Returns
    -------
    numpy.ndarray
        ``(n, 2) float64`` vertices, repeated ones dropped.

    Raises
    ------
    SourceError
        Unreadable file, not JSON, no line or several, malformed or out-of-range
        coordinates, or an unusable CRS.
    """
    if isinstance(source, Mapping):
        obj: Any = source
        label = "<geojson>"
    elif not isinstance(source, str | os.PathLike):
        raise SourceError(f"expected a GeoJSON object or file, got {type(source).__name__}")
    else:
        label = str(Path(source))
        obj = read_json_file(source, _MAX_GEOJSON_BYTES)
    if not isinstance(obj, Mapping):
        raise SourceError(f"{label}: expected a GeoJSON object, got {type(obj).__name__}")
    src_crs = parse_crs_member(obj.get("crs"), label)
    geom = _the_line(obj, label)
    gtype, coords = geom.get("type"), geom.get("coordinates")
    parts = coords if gtype == "MultiLineString" else [coords]
    if not isinstance(parts, list) or not parts:
        raise SourceError(f"{label}: malformed {gtype} coordinates")
    arrays = []
    for k, part in enumerate(parts):
        pts = as_points(part)
        if isinstance(pts, str):
            where = f" (part {k})" if gtype == "MultiLineString" else ""
            raise SourceError(f"{label}: {gtype}{where}: {pts}")
        arrays.append(pts)
    raw = np.concatenate(arrays)
    geographic = src_crs is None or src_crs.is_geographic
    if geographic:
        bad = np.flatnonzero(outside_lonlat(raw))
        if len(bad):
            i = int(bad[0])
            raise SourceError(
                f"{label}: position {i} ({raw[i, 0]}, {raw[i, 1]}) is outside the lon/lat "
                "range (projected data needs a 'crs' member)"
            )
    return line_to_scene(raw, src_crs, crs, origin, label)


def line_to_scene(
    raw: F64,
    src_crs: pyproj.CRS | None,
    crs: str,
    origin: Sequence[float],
    label: str,
    *,
    point: str = "position",
    line: str = "line",
) -> F64:
    """Project a read line into scene-local metres, repeated positions dropped.

    A position within 1 mm of the last one kept is dropped (so a track of points
    0.5 mm apart thins out instead of collapsing); more than :data:`MAX_LINE_POINTS`
    are simplified to 5 cm.

    Parameters
    ----------
    raw:
        ``(n, 2) float64`` positions in ``src_crs`` (``None``: lon/lat).
    crs, origin:
        The scene's CRS (projected metres) and origin in it.
    label:
        The source named in errors (a file name).
    point, line:
        What the source calls a position and the line (GPX: point, track).

    Returns
    -------
    numpy.ndarray
        ``(m, 2) float64`` vertices, ``m >= 2``.

    Raises
    ------
    InputError
        If ``crs`` is unknown or not projected.
    SourceError
        If a position cannot be projected, or fewer than 2 distinct ones are left.
    """
    try:
        dst = pyproj.CRS.from_user_input(crs)
    except pyproj.exceptions.CRSError as exc:
        raise InputError(f"scene CRS {crs!r} is not a known CRS") from exc
    if not dst.is_projected:
        raise InputError(f"scene CRS {crs!r} is not projected: cannot place a {line} in metres")
    xy = project(raw, src_crs, dst) - np.asarray(origin, dtype=np.float64)[:2]
    if not np.isfinite(xy).all():
        i = int(np.flatnonzero(~np.isfinite(xy).all(axis=1))[0])
        raise SourceError(f"{label}: {point} {i} cannot be projected to {crs}")
    bounded, note = bound_vertices(xy, closed=False, limit=MAX_LINE_POINTS)
    if bounded is None:
        raise SourceError(f"{label}: the {line}: {note}")
    xy = bounded
    if len(xy) < 2:
        raise SourceError(f"{label}: the {line} has fewer than 2 distinct {point}s")
    return xy


def _the_line(obj: Mapping[str, Any], label: str) -> Mapping[str, Any]:
    gtype = obj.get("type")
    if gtype in ("LineString", "MultiLineString"):
        return obj
    if gtype == "Feature":
        geom = obj.get("geometry")
        if not isinstance(geom, Mapping) or geom.get("type") not in (
            "LineString",
            "MultiLineString",
        ):
            got = geom.get("type") if isinstance(geom, Mapping) else geom
            raise SourceError(f"{label}: the Feature's geometry is {got!r}, not a LineString")
        return geom
    if gtype == "FeatureCollection":
        feats = obj.get("features")
        if not isinstance(feats, list):
            raise SourceError(f"{label}: FeatureCollection has no 'features' list")
        lines = [
            f["geometry"]
            for f in feats
            if isinstance(f, Mapping)
            and isinstance(f.get("geometry"), Mapping)
            and f["geometry"].get("type") in ("LineString", "MultiLineString")
        ]
        if len(lines) != 1:
            raise SourceError(
                f"{label}: expected exactly one LineString feature, found {len(lines)} "
                f"(among {len(feats)} features)"
            )
        return lines[0]
    raise SourceError(
        f"{label}: expected a GeoJSON LineString, MultiLineString, Feature or "
        f"FeatureCollection, got type {gtype!r:.60}"
    )
