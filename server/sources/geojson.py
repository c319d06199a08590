"""Load real building footprints (and optional streets) from a GeoJSON file.

:func:`load_geojson` turns a GeoJSON ``FeatureCollection`` into a
:class:`~walkstream.server.sources.scene.SourceScene`.  The rules, in the order they apply:

Features
    ``Polygon`` / ``MultiPolygon`` features are buildings, except:

    - a ``kind`` property ``street``, ``crossroad`` or ``square``: a flat street
      piece as it is (holes kept, see :mod:`.network` for how);
    - a street area (:func:`~walkstream.server.sources.osmtags.is_square`:
      ``area:highway``, ``place=square``, ``highway=*`` with ``area=yes``): a square of
      the street network;
    - a typed area: a polygon without a ``building`` property (or with ``building=no``)
      whose ``kind`` is an area kind (``water``, ``grass``, ``parking``, ...:
      :data:`~walkstream.shared.areakinds.AREA_KINDS`) or whose tags make one
      (``landuse``, ``leisure``, ``natural``, water, ``amenity=parking``:
      :func:`~walkstream.server.sources.areatags.area_kind`); holes kept, clipped to
      the scene (:mod:`.areas`);
    - a polygon without a ``building`` property (or with ``building=no``) that has
      one of :data:`NOT_BUILDING_KEYS` and is no area: not a building; left out and
      counted in the scene's notes.

    Every ``MultiPolygon`` part is its own building with source id ``"<fid>#<k>"``
    (k = 0-based part index).  ``LineString`` / ``MultiLineString`` features with
    ``kind=street`` or a ``highway`` property are street centre lines: the ways of the
    chosen network (``network``, :mod:`.osmtags`) on the ground become the street
    network (:mod:`.network`: noded, junction regions, street pieces); the width is
    the ``width`` property, else ``lanes`` or the ``highway`` class
    (:func:`~walkstream.server.sources.osmtags.street_width`), else 10 m.  The
    feature id is ``feature["id"]``, else property ``id`` or ``@id``, else the
    feature's index in the file.

Coordinates
    The CRS is the file's legacy ``crs`` member (``{"type": "name", "properties":
    {"name": "EPSG:32633"}}``, URN forms accepted); without one the data is lon/lat
    (CRS84).  Geographic data (always read as x = lon, y = lat) is projected with
    pyproj to the WGS 84 UTM zone of the centre of its bounding box (EPSG:326zz
    north, EPSG:327zz south; the Norway/Svalbard zone exceptions are ignored).
    Projected data must be in metres; it stays in its CRS unless that CRS is not
    true to scale where the data lies (scale off by more than 0.1 %, e.g. Web
    Mercator EPSG:3857, whose distances grow by 1/cos(latitude)): then it is
    reprojected to the UTM zone of the data.  The scene origin is the
    centre of the projected bounding box rounded to whole metres; rings are stored as
    float64 local coordinates (projected minus origin), so precision is kept even
    millions of metres from the CRS origin.

Rings
    Exteriors become counter-clockwise, holes clockwise; the closing vertex, repeated
    vertices (within 1 mm) and collinear vertices (within 1 mm of the line through
    their neighbours) are removed.  Only then are party walls found
    (:func:`~walkstream.server.sources.partywalls.find_party_walls` with ``tol``), and the split
    vertices that adds are kept.

Heights
    Height (metres) comes from the first valid property of ``height``,
    ``building:height``, ``est_height``: a number or a string such as ``"12 m"``,
    ``"12.5m"``, ``"12,5"`` (a comma is a decimal comma) or ``"40 ft"`` / ``"40'"``
    (feet).  Floors come from ``building:levels``, ``levels`` or ``floors`` (numbers or
    numeric strings, rounded to whole floors).  Floor height is the ``floor_height``
    property if valid, else ``default_floor_height``.  With height and floors, floor
    height = height / floors.  With height only, floors = max(1, round(height / floor
    height)) and floor height = height / floors.  With floors only, the floor height
    above is used.

    ``roof:levels`` adds to the floors given.  **Default rule** (no usable height or
    floors): the floors of the ``building`` value's type in
    :data:`~walkstream.server.sources.heights.FLOORS_BY_TYPE` (house 2, garage 1,
    apartments 5, ...), else 4 + crc32(feature id) % 3, i.e. 4 to 6 floors,
    deterministic per feature, with the floor height above (normally
    ``default_floor_height``).

    The style seed is the ``style`` property if it is an integer, else
    crc32(feature id) & 0x7fffffff.

Bad features
    Never stop the load; each is reported as a :class:`FeatureIssue`
    (``feature_id`` = the feature id, ``"<fid>#<k>"`` for a MultiPolygon part):

    - unknown geometry type (Point, ...), missing or malformed geometry: skipped;
    - NaN / infinite coordinates (an integer of more than 400 digits is read as NaN),
      lon/lat out of range, or projected coordinates beyond 1e8 m: skipped;
    - a ring of more than 5,000 vertices: simplified to 5 cm, skipped if still over
      (:func:`~walkstream.server.sources.rings.bound_vertices`);
    - a height over 1,000 m, more than 200 floors: ignored like a bad value; a building
      the grammar cannot derive within its module limit: skipped;
    - fewer than 3 distinct points (2 for a street line): skipped;
    - area below 0.01 m² (after cleaning): skipped;
    - a degenerate hole (fewer than 3 points or area below 0.01 m²): hole dropped,
      repaired;
    - self-intersection (shapely ``is_valid`` false): repaired with
      ``shapely.make_valid``; each polygonal part of at least 0.01 m² becomes a
      building (source id ``"<fid>#<j>"``, or ``"<fid>#<k>.<j>"`` for a MultiPolygon
      part), smaller parts are dropped; skipped if no part is left;
    - negative, zero, NaN or unparsable height / floors / floor height / width: the
      value is ignored and the rules above go on without it (for heights and floors
      usually the default rule): repaired.

    :class:`~walkstream.shared.errors.SourceError` is raised only when the file cannot be read,
    is not JSON, is not a FeatureCollection, declares a CRS that is unknown or not in
    metres / degrees, or has no usable feature at all."""

from __future__ import annotations

import math
import os
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

from walkstream.server.sources.areas import AREA_PREFIX
from walkstream.server.sources.areatags import area_kind
from walkstream.server.sources.assemble import assemble_scene
from walkstream.server.sources.crs import parse_crs_member
from walkstream.server.sources.features import IssueLog, LineFeature, PolyFeature
from walkstream.server.sources.jsonfile import read_json_file
from walkstream.server.sources.osmtags import is_square
from walkstream.server.sources.scene import SourceScene
from walkstream.shared.arrays import F64
from walkstream.shared.errors import InputError, SourceError

__all__ = ["NOT_BUILDING_KEYS", "load_geojson", "load_geojson_dict", "as_points"]

_STREET_KINDS = ("street", "crossroad", "square")
#: A polygon with one of these properties and no ``building`` is not a building.
NOT_BUILDING_KEYS = (
    "landuse", "leisure", "natural", "amenity", "waterway", "water", "place",
    "boundary", "highway", "area:highway", "man_made", "parking", "surface",
    "landcover", "tourism", "historic", "barrier", "railway", "aeroway", "power",
)  # fmt: skip


def load_geojson(
    path: str | os.PathLike[str],
    *,
    name: str | None = None,
    default_floor_height: float = 3.2,
    tol: float = 0.1,
    network: str = "walk",
) -> SourceScene:
    """Load a GeoJSON FeatureCollection of footprints (and streets) into a scene.

    See the module docstring for the rules (CRS, heights, repairs).

    Parameters
    ----------
    path:
        The ``.geojson`` file (UTF-8).
    name:
        Scene name; default: the file name without its suffix.
    default_floor_height:
        Floor height in metres (> 0) where a feature has no ``floor_height``.
    tol:
        Party-wall tolerance in metres, see
        :func:`~walkstream.server.sources.partywalls.find_party_walls`.
    network:
        ``"walk"`` or ``"drive"``: which ``highway`` ways become the street network
        (:func:`~walkstream.server.sources.osmtags.in_network`).

    Returns
    -------
    SourceScene
        Buildings (ids 0..B-1), then street pieces (ids B..), in scene-local metres,
        with ``crs`` the projected CRS (``"EPSG:NNNN"``), ``origin`` its local (0, 0)
        and ``issues`` one :class:`FeatureIssue` per skipped or repaired feature.

    Raises
    ------
    SourceError
        The file cannot be read, is not JSON, not a FeatureCollection, has an
        unusable CRS, or has no usable feature.
    """
    p = Path(path)
    obj = read_json_file(p)
    return load_geojson_dict(
        obj,
        name=p.stem if name is None else name,
        default_floor_height=default_floor_height,
        tol=tol,
        source=str(p),
        network=network,
    )


def load_geojson_dict(
    obj: dict[str, Any],
    *,
    name: str | None = None,
    default_floor_height: float = 3.2,
    tol: float = 0.1,
    source: str = "<geojson>",
    network: str = "walk",
) -> SourceScene:
    """Build a scene from an already parsed GeoJSON object (see :func:`load_geojson`).

    Parameters
    ----------
    obj:
        The parsed JSON: a dict with ``"type": "FeatureCollection"``.
    name:
        Scene name; default: ``obj["name"]`` if it is a string, else ``"geojson"``.
    default_floor_height, tol, network:
        As for :func:`load_geojson`.
    source:
        How error messages name the input (the file path for :func:`load_geojson`).

    Returns
    -------
    SourceScene
        As for :func:`load_geojson`.

    Raises
    ------
    SourceError
        ``obj`` is not a FeatureCollection, its CRS is unusable, or it has no
        usable feature.
    InputError
        ``default_floor_height`` or ``tol`` is not a positive number.
    """
    if not (math.isfinite(default_floor_height) and default_floor_height > 0):
        raise InputError(
            f"default_floor_height must be a positive number of metres, got {default_floor_height!r}"
        )
    if not (math.isfinite(tol) and tol > 0):
        raise InputError(f"tol must be a positive number of metres, got {tol!r}")
    if not isinstance(obj, dict) or obj.get("type") != "FeatureCollection":
        got = obj.get("type") if isinstance(obj, dict) else type(obj).__name__
        raise SourceError(f"{source}: not a GeoJSON FeatureCollection (type is {got!r})")
    features = obj.get("features")
    if not isinstance(features, list):
        raise SourceError(f"{source}: FeatureCollection has no 'features' list")
    if name is None:
        name = obj["name"] if isinstance(obj.get("name"), str) else "geojson"

    src_crs = parse_crs_member(obj.get("crs"), source)
    log = IssueLog()
    not_buildings: Counter[str] = Counter()
    polys, lines = _read_features(features, log, not_buildings)
    notes = []
    if not_buildings:
        notes.append(
            "not buildings (left out): "
            + ", ".join(f"{n} {k}" for k, n in sorted(not_buildings.items(), key=lambda t: (-t[1], t[0])))
        )
    return assemble_scene(
        polys,
        lines,
        src_crs,
        log,
        name=name,
        source=source,
        default_floor_height=default_floor_height,
        tol=tol,
        network=network,
        notes=notes,
        total_features=len(features),
    )


def _feature_id(feat: dict[str, Any], props: dict[str, Any], index: int) -> str:
    for v in (feat.get("id"), props.get("id"), props.get("@id")):
        if v is not None and v != "":
            return str(v)
    return str(index)


def as_points(coords: object) -> F64 | str:
    """An ``(n, 2) float64`` array from GeoJSON positions, or the problem as text."""
    try:
        arr = np.asarray(coords, dtype=np.float64)
    except (TypeError, ValueError):
        return "malformed coordinates"
    if arr.ndim != 2 or arr.shape[0] == 0 or arr.shape[1] < 2:
        return "malformed coordinates"
    arr = np.ascontiguousarray(arr[:, :2])
    if not np.isfinite(arr).all():
        return "NaN or infinite coordinates"
    return arr


def _polygon_kind(props: dict[str, Any], kind: str | None) -> str | None:
    """``kind`` of a polygon feature: a street kind, ``"square"``, ``"area:<kind>"`` (a
    typed area), None (a building) or ``"-key=value"`` for a polygon that is neither."""
    if kind is not None:
        return kind
    building = props.get("building")
    if building not in (None, "", "no", False):
        return None
    if is_square(props):
        return "square"
    area = area_kind(props)
    if area is not None:
        return AREA_PREFIX + area
    for key in NOT_BUILDING_KEYS:
        if props.get(key) not in (None, ""):
            return f"-{key}={props[key]}"
    return None


def _read_features(
    features: list[Any], log: IssueLog, not_buildings: Counter[str]
) -> tuple[list[PolyFeature], list[LineFeature]]:
    """Sort features into polygons and street lines; skip what cannot be used."""
    polys: list[PolyFeature] = []
    lines: list[LineFeature] = []
    for index, feat in enumerate(features):
        if not isinstance(feat, dict) or feat.get("type") != "Feature":
            log.add(index, str(index), "not a GeoJSON Feature", "skipped")
            continue
        props = feat.get("properties")
        props = props if isinstance(props, dict) else {}
        fid = _feature_id(feat, props, index)
        geom = feat.get("geometry")
        if not isinstance(geom, dict):
            log.add(index, fid, "no geometry", "skipped")
            continue
        gtype = geom.get("type")
        coords = geom.get("coordinates")
        kind_prop = props.get("kind")
        kind = kind_prop.lower() if isinstance(kind_prop, str) else None
        kind = kind if kind in _STREET_KINDS else None

        if gtype in ("Polygon", "MultiPolygon"):
            kind = _polygon_kind(props, kind)
            if kind is not None and kind.startswith("-"):
                not_buildings[kind[1:].split("=")[0]] += 1
                continue
            is_multi = gtype == "MultiPolygon"
            if not isinstance(coords, list) or (is_multi and not coords):
                log.add(index, fid, f"malformed {gtype} coordinates", "skipped")
                continue
            for k, part in enumerate(coords if is_multi else [coords]):
                uid = f"{fid}#{k}" if is_multi else fid
                if not isinstance(part, list) or not part:
                    log.add(index, uid, "polygon without rings", "skipped")
                    continue
                rings = [as_points(r) for r in part]
                bad = next((r for r in rings if isinstance(r, str)), None)
                if bad is not None:
                    log.add(index, uid, str(bad), "skipped")
                    continue
                ok_rings = [r for r in rings if not isinstance(r, str)]
                polys.append(PolyFeature(index, fid, uid, is_multi, kind, props, ok_rings))
        elif gtype in ("LineString", "MultiLineString"):
            if kind in ("crossroad", "square"):
                log.add(index, fid, f"a {kind} must be a Polygon, got {gtype}", "skipped")
                continue
            if kind != "street" and "highway" not in props:
                log.add(
                    index, fid, f"{gtype} is not a street (no kind=street or highway)", "skipped"
                )
                continue
            is_multi = gtype == "MultiLineString"
            if not isinstance(coords, list) or (is_multi and not coords):
                log.add(index, fid, f"malformed {gtype} coordinates", "skipped")
                continue
            for k, part in enumerate(coords if is_multi else [coords]):
                uid = f"{fid}#{k}" if is_multi else fid
                pts = as_points(part)
                if isinstance(pts, str):
                    log.add(index, uid, pts, "skipped")
                    continue
                lines.append(LineFeature(index, fid, uid, props, pts))
        else:
            log.add(index, fid, f"unsupported geometry type {gtype!r}", "skipped")
    return polys, lines
