"""Load real building footprints (and optional streets) from a GeoJSON file.

:func:`load_geojson` turns a GeoJSON ``FeatureCollection`` into a
:class:`~walkstream.server.sources.scene.SourceScene`.  The rules, in the order they apply:

Features
    ``Polygon`` / ``MultiPolygon`` features are buildings unless their ``kind``
    property is ``street``, ``crossroad`` or ``square`` (then they are flat street
    pieces; only their exterior ring is used).  Every ``MultiPolygon`` part is its own
    building with source id ``"<fid>#<k>"`` (k = 0-based part index).  ``LineString`` /
    ``MultiLineString`` features with ``kind=street`` or a ``highway`` property are
    streets: the line buffered by ``width / 2`` with flat caps and mitred joins
    (``width`` property in metres, default 10 m), one street piece per line.  The
    feature id is ``feature["id"]``, else property ``id`` or ``@id``, else the
    feature's index in the file.

Coordinates
    The CRS is the file's legacy ``crs`` member (``{"type": "name", "properties":
    {"name": "EPSG:32633"}}``, URN forms accepted); without one the data is lon/lat
    (CRS84).  Geographic data (always read as x = lon, y = lat) is projected with
    pyproj to the WGS 84 UTM zone of the centre of its bounding box (EPSG:326zz
    north, EPSG:327zz south; the Norway/Svalbard zone exceptions are ignored).
    Projected data must be in metres and stays in its CRS.  The scene origin is the
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

    **Default rule** (no usable height or floors): floors = 4 + crc32(feature id) % 3,
    i.e. 4 to 6 floors, deterministic per feature, with the floor height above
    (normally ``default_floor_height``).

    The style seed is the ``style`` property if it is an integer, else
    crc32(feature id) & 0x7fffffff.

Bad features
    Never stop the load; each is reported as a :class:`FeatureIssue`
    (``feature_id`` = the feature id, ``"<fid>#<k>"`` for a MultiPolygon part):

    - unknown geometry type (Point, ...), missing or malformed geometry: skipped;
    - NaN / infinite coordinates, or lon/lat out of range: skipped;
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
import zlib
from pathlib import Path
from typing import Any

import numpy as np
import pyproj
import shapely

from walkstream.server.sources.crs import (
    crs_label,
    outside_lonlat,
    parse_crs_member,
    project,
    utm_epsg,
)
from walkstream.server.sources.features import _IssueLog, _Line, _Part, _Poly
from walkstream.server.sources.heights import _levels, _positive, parse_length
from walkstream.server.sources.jsonfile import read_json_file
from walkstream.server.sources.partywalls import find_party_walls
from walkstream.server.sources.rings import _clean_and_repair, _clean_rings, _dedupe
from walkstream.server.sources.scene import SourceScene
from walkstream.shared.arrays import F64
from walkstream.shared.errors import InputError, SourceError
from walkstream.shared.records import BuildingParams, StreetParams

__all__ = ["DEFAULT_STREET_WIDTH", "load_geojson", "load_geojson_dict", "as_points"]

#: Street width in metres when a street has no usable ``width`` property.
DEFAULT_STREET_WIDTH = 10.0
_STREET_KINDS = ("street", "crossroad", "square")


def load_geojson(
    path: str | os.PathLike[str],
    *,
    name: str | None = None,
    default_floor_height: float = 3.2,
    tol: float = 0.1,
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
    )


def load_geojson_dict(
    obj: dict[str, Any],
    *,
    name: str | None = None,
    default_floor_height: float = 3.2,
    tol: float = 0.1,
    source: str = "<geojson>",
) -> SourceScene:
    """Build a scene from an already parsed GeoJSON object (see :func:`load_geojson`).

    Parameters
    ----------
    obj:
        The parsed JSON: a dict with ``"type": "FeatureCollection"``.
    name:
        Scene name; default: ``obj["name"]`` if it is a string, else ``"geojson"``.
    default_floor_height, tol:
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
    log = _IssueLog()
    polys, lines = _read_features(features, log)
    crs_name, origin = _to_local(polys, lines, src_crs, log)

    buildings_raw: list[_Part] = []
    street_polys: list[_Part] = []
    for poly in polys:
        if poly.local is None:
            continue
        parts = _clean_and_repair(poly, log)
        (buildings_raw if poly.kind is None else street_polys).extend(parts)

    buildings = _make_buildings(buildings_raw, default_floor_height, tol, log)
    streets = _make_streets(street_polys, lines, len(buildings), log)

    if not buildings and not streets:
        skipped = [i for i in log.sorted() if i.action == "skipped"]
        examples = "; ".join(f"{i.feature_id}: {i.problem}" for i in skipped[:3])
        raise SourceError(
            f"{source}: no usable feature ({len(features)} features, {len(skipped)} skipped"
            + (f"; e.g. {examples}" if examples else "")
            + ")"
        )
    return SourceScene(
        name=name,
        crs=crs_name,
        origin=origin,
        buildings=tuple(buildings),
        streets=tuple(streets),
        issues=tuple(log.sorted()),
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


def _read_features(features: list[Any], log: _IssueLog) -> tuple[list[_Poly], list[_Line]]:
    """Sort features into polygons and street lines; skip what cannot be used."""
    polys: list[_Poly] = []
    lines: list[_Line] = []
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
                polys.append(_Poly(index, fid, uid, is_multi, kind, props, ok_rings))
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
                lines.append(_Line(index, fid, uid, props, pts))
        else:
            log.add(index, fid, f"unsupported geometry type {gtype!r}", "skipped")
    return polys, lines


def _to_local(
    polys: list[_Poly], lines: list[_Line], src: pyproj.CRS | None, log: _IssueLog
) -> tuple[str, tuple[float, float]]:
    """Project every coordinate (one vectorised transform) and move it to the origin.

    Fills ``.local`` of each usable polygon and line (left ``None`` for skipped ones)
    and returns the projected CRS name and the origin.
    """
    items: list[_Poly | _Line] = [*polys, *lines]
    geographic = src is None or src.is_geographic
    if geographic:
        # Out-of-range lon/lat usually means projected data without a 'crs' member.
        kept = []
        for it in items:
            rings = it.raw if isinstance(it, _Poly) else [it.raw]
            if not any(outside_lonlat(r).any() for r in rings):
                kept.append(it)
            else:
                log.add(
                    it.index,
                    it.uid,
                    "coordinates outside the lon/lat range (projected data needs a 'crs' member)",
                    "skipped",
                )
        items = kept
    if not items:
        return ("EPSG:4326" if geographic else crs_label(src)), (0.0, 0.0)

    arrays = [r for it in items for r in (it.raw if isinstance(it, _Poly) else [it.raw])]
    allpts = np.concatenate(arrays)
    if geographic:
        lo, hi = allpts.min(axis=0), allpts.max(axis=0)
        epsg = utm_epsg(0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]))
        proj = project(allpts, src, f"EPSG:{epsg}")
        crs_name = f"EPSG:{epsg}"
    else:
        proj = allpts
        crs_name = crs_label(src)

    # Split back per item; drop items the projection could not handle.
    counts = [len(a) for a in arrays]
    chunks = np.split(proj, np.cumsum(counts)[:-1])
    per_item: list[list[F64]] = []
    pos = 0
    for it in items:
        n = len(it.raw) if isinstance(it, _Poly) else 1
        per_item.append(chunks[pos : pos + n])
        pos += n
    finite = [all(np.isfinite(c).all() for c in chs) for chs in per_item]
    for it, ok in zip(items, finite, strict=True):
        if not ok:
            log.add(it.index, it.uid, "coordinates cannot be projected", "skipped")
    good = [chs for chs, ok in zip(per_item, finite, strict=True) if ok]
    if not good:
        return crs_name, (0.0, 0.0)
    allgood = np.concatenate([c for chs in good for c in chs])
    lo, hi = allgood.min(axis=0), allgood.max(axis=0)
    origin = np.round(0.5 * (lo + hi))
    for it, chs, ok in zip(items, per_item, finite, strict=True):
        if not ok:
            continue
        local = [c - origin for c in chs]
        if isinstance(it, _Poly):
            it.local = local
        else:
            it.local = local[0]
    return crs_name, (float(origin[0]), float(origin[1]))


def _make_buildings(
    parts: list[_Part], default_floor_height: float, tol: float, log: _IssueLog
) -> list[BuildingParams]:
    """Heights per feature, party walls over all buildings, then the records."""
    levels: dict[int, tuple[int, float]] = {}
    for part in parts:
        poly = part.poly
        if poly.index in levels:
            continue
        floors, fh, bad, how = _levels(poly.props, poly.fid, default_floor_height)
        levels[poly.index] = (floors, fh)
        if bad:
            log.add(
                poly.index,
                poly.fid,
                f"bad {', '.join(bad)} ignored; {how} ({floors} floors of {fh:.3g} m)",
                "repaired",
            )
    heights = [levels[p.poly.index][0] * levels[p.poly.index][1] for p in parts]
    split, nbh = find_party_walls([p.rings for p in parts], heights, tol=tol)
    out = []
    for i, (part, rings, nh) in enumerate(zip(parts, split, nbh, strict=True)):
        floors, fh = levels[part.poly.index]
        style_prop = part.poly.props.get("style")
        if isinstance(style_prop, int) and not isinstance(style_prop, bool):
            style = style_prop
        else:
            style = zlib.crc32(part.poly.fid.encode("utf-8")) & 0x7FFFFFFF
        out.append(
            BuildingParams(
                id=i,
                rings=tuple(rings),
                neighbour_heights=tuple(nh),
                floors=floors,
                floor_height=fh,
                style=style,
                source_id=part.source_id,
            )
        )
    return out


def _street_width(props: dict[str, Any], index: int, uid: str, log: _IssueLog) -> float:
    raw = props.get("width")
    if raw is None or raw == "":
        return DEFAULT_STREET_WIDTH
    value = parse_length(raw)
    if value is not None and _positive(value):
        return value
    log.add(index, uid, f"bad width={raw!r} ignored; {DEFAULT_STREET_WIDTH:g} m used", "repaired")
    return DEFAULT_STREET_WIDTH


def _make_streets(
    polys: list[_Part], lines: list[_Line], first_id: int, log: _IssueLog
) -> list[StreetParams]:
    """Street pieces from street polygons and buffered street lines."""
    pieces: list[tuple[str, F64, float, str]] = []  # kind, ring, width, source id
    widths: dict[int, float] = {}  # per feature, so a bad width is reported once
    for part in polys:
        if part.poly.index not in widths:
            widths[part.poly.index] = _street_width(
                part.poly.props, part.poly.index, part.poly.uid, log
            )
        width = widths[part.poly.index]
        assert part.poly.kind is not None
        pieces.append((part.poly.kind, part.rings[0], width, part.source_id))

    usable: list[tuple[_Line, F64, float]] = []
    for line in lines:
        if line.local is None:
            continue
        pts = _dedupe(line.local, closed=False)
        if len(pts) < 2:
            log.add(line.index, line.uid, f"fewer than 2 distinct points ({len(pts)})", "skipped")
            continue
        usable.append((line, pts, _street_width(line.props, line.index, line.uid, log)))
    if usable:
        coords = np.concatenate([pts for _, pts, _ in usable])
        which = np.repeat(np.arange(len(usable)), [len(pts) for _, pts, _ in usable])
        geoms = shapely.linestrings(coords, indices=which)
        half = np.array([w / 2 for _, _, w in usable])
        buffered = shapely.buffer(geoms, half, cap_style="flat", join_style="mitre")
        for (line, _, width), shape in zip(usable, buffered, strict=True):
            polygons = [p for p in shapely.get_parts(shape) if isinstance(p, shapely.Polygon)]
            rings = []
            for p in polygons:
                c, _, _ = _clean_rings([np.asarray(p.exterior.coords, np.float64)])
                if c is not None:
                    rings.append(c[0])
            if not rings:
                log.add(line.index, line.uid, "street outline is empty", "skipped")
                continue
            for j, ring in enumerate(rings):
                sid = line.uid if len(rings) == 1 else f"{line.uid}.{j}"
                pieces.append(("street", ring, width, sid))
    return [
        StreetParams(id=first_id + k, kind=kind, ring=ring, width=width, source_id=sid)
        for k, (kind, ring, width, sid) in enumerate(pieces)
    ]
