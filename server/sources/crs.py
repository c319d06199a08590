"""Coordinate reference systems of sources: the declared CRS, the lon/lat check, UTM zones.

Geographic data (x = lon, y = lat) is projected to the WGS 84 UTM zone of its centre
(EPSG:326zz north, EPSG:327zz south; the Norway/Svalbard exceptions are ignored);
projected data must be in metres, and true to scale where the data lies: a projected
CRS whose scale there is off by more than :data:`MAX_SCALE_ERROR` (Web Mercator,
EPSG:3857, stretches distances by 1/cos(latitude)) is reprojected to the UTM zone of
the data as well (:func:`metric_crs`).  Every reader of lon/lat coordinates checks them
with :func:`outside_lonlat` first: out-of-range values usually mean projected data
without a ``crs`` member.
"""

from __future__ import annotations

import math

import numpy as np
import pyproj
from numpy.typing import NDArray

from walkstream.shared.arrays import F64
from walkstream.shared.errors import SourceError

__all__ = [
    "MAX_SCALE_ERROR",
    "parse_crs_member",
    "utm_epsg",
    "crs_label",
    "outside_lonlat",
    "project",
    "scale_error",
    "metric_crs",
]

#: A projected CRS whose point scale at the data differs from 1 by more than this
#: is reprojected to UTM (0.1 %: UTM itself stays within 0.04 % near its meridian).
MAX_SCALE_ERROR = 1e-3

# ------------------------------------------------------------------------- reading


def parse_crs_member(crs: object, source: str) -> pyproj.CRS | None:
    """The declared CRS, or None for the GeoJSON default (lon/lat, CRS84)."""
    if crs is None:
        return None
    crs_name = None
    if isinstance(crs, dict) and crs.get("type") == "name":
        props = crs.get("properties")
        if isinstance(props, dict):
            crs_name = props.get("name")
    if not isinstance(crs_name, str):
        raise SourceError(
            f"{source}: unsupported 'crs' member {crs!r}; expected "
            '{"type": "name", "properties": {"name": "EPSG:NNNN"}}'
        )
    try:
        parsed = pyproj.CRS.from_user_input(crs_name)
    except pyproj.exceptions.CRSError as exc:
        raise SourceError(f"{source}: unknown CRS {crs_name!r} in the 'crs' member") from exc
    if parsed.is_geographic:
        return parsed
    if not parsed.is_projected:
        raise SourceError(f"{source}: CRS {crs_name!r} is neither geographic nor projected")
    unit = parsed.axis_info[0].unit_conversion_factor if parsed.axis_info else 0.0
    if unit != 1.0:
        raise SourceError(
            f"{source}: projected CRS {crs_name!r} is not in metres "
            f"({parsed.axis_info[0].unit_name if parsed.axis_info else 'unknown unit'})"
        )
    return parsed


# ---------------------------------------------------------------------- projection


def utm_epsg(lon: float, lat: float) -> int:
    """EPSG code of the WGS 84 UTM zone containing (lon, lat)."""
    zone = int(math.floor((lon + 180.0) / 6.0)) % 60 + 1
    return (32600 if lat >= 0 else 32700) + zone


def crs_label(crs: pyproj.CRS | None) -> str:
    if crs is None:
        return "EPSG:4326"
    epsg = crs.to_epsg()
    return f"EPSG:{epsg}" if epsg is not None else crs.to_string()


def outside_lonlat(points: NDArray[np.float64]) -> NDArray[np.bool_]:
    """``(n,)`` bool: the ``(n, 2)`` lon/lat points that are outside the lon/lat range.

    Longitudes from -180 to 360 (some data uses 0 to 360) and latitudes from -90 to
    90 are in range.

    >>> outside_lonlat(np.array([[16.37, 48.21], [600000.0, 5340000.0]])).tolist()
    [False, True]
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    return (np.abs(p[:, 1]) > 90) | (p[:, 0] < -180) | (p[:, 0] > 360)


def project(points: F64, src: pyproj.CRS | None, dst: str | pyproj.CRS) -> F64:
    """``(n, 2)`` points from ``src`` (None: lon/lat, CRS84) to ``dst``, x/y order both sides.

    Points that cannot be projected come out non-finite; the caller says which.
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    transformer = pyproj.Transformer.from_crs(
        src if src is not None else "OGC:CRS84", dst, always_xy=True
    )
    x, y = transformer.transform(p[:, 0], p[:, 1])
    return np.column_stack([np.asarray(x, np.float64), np.asarray(y, np.float64)])


def scale_error(crs: pyproj.CRS, lon: float, lat: float) -> float:
    """How far the point scale of a projected CRS at (lon, lat) is from 1 (both axes).

    >>> round(scale_error(pyproj.CRS("EPSG:3857"), 25.0, 60.0), 3)
    1.0
    >>> scale_error(pyproj.CRS("EPSG:32633"), 15.0, 48.0) < 1e-3
    True
    """
    f = pyproj.Proj(crs).get_factors(lon, lat)
    return float(max(abs(f.meridional_scale - 1.0), abs(f.parallel_scale - 1.0)))


def metric_crs(src: pyproj.CRS | None, points: F64) -> str:
    """The CRS (``"EPSG:NNNN"``) a source's ``(n, 2)`` points are stored in.

    Lon/lat (``src`` None or geographic) goes to the UTM zone of the points' centre;
    a WGS 84 UTM zone (the target itself) stays as it is; another projected CRS stays
    unless its scale there is off by more than :data:`MAX_SCALE_ERROR`, then it goes
    to the UTM zone of the points too.

    >>> metric_crs(pyproj.CRS("EPSG:3857"), np.array([[2.87e6, 8.49e6], [2.87e6 + 10, 8.49e6]]))
    'EPSG:32635'
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    lo, hi = p.min(axis=0), p.max(axis=0)
    centre = 0.5 * (lo + hi)
    if src is None or src.is_geographic:
        return f"EPSG:{utm_epsg(float(centre[0]), float(centre[1]))}"
    epsg = src.to_epsg()
    if epsg is not None and (32601 <= epsg <= 32660 or 32701 <= epsg <= 32760):
        return crs_label(src)
    lon, lat = project(centre[None, :], src, "OGC:CRS84")[0]
    if not (math.isfinite(lon) and math.isfinite(lat)):
        return crs_label(src)
    if scale_error(src, float(lon), float(lat)) <= MAX_SCALE_ERROR:
        return crs_label(src)
    return f"EPSG:{utm_epsg(float(lon), float(lat))}"
