"""Read OpenStreetMap extracts (``.osm`` XML, ``.osm.pbf``) with pyosmium into a scene.

:func:`load_osm` returns the same :class:`~walkstream.server.sources.scene.SourceScene`
the GeoJSON reader does; after reading, both go through
:func:`~walkstream.server.sources.assemble.assemble_scene` (projection to the UTM zone
of the data, repairs, heights, party walls, the street network).

Buildings
    Closed ways and multipolygon relations (``type=multipolygon`` or
    ``type=building``, assembled by osmium's area handler) tagged ``building=*``
    (not ``no``); holes are kept; each outer ring of a relation is one building
    (source id ``relation/ID#k``).  Heights: ``height``, ``building:height``, else
    ``building:levels`` (+ ``roof:levels``), else the default floors of the
    ``building=*`` value (:data:`~walkstream.server.sources.heights.FLOORS_BY_TYPE`:
    house 2, garage 1, apartments 5, ...; unknown values and ``yes`` 4 to 6).
    ``min_height`` / ``building:min_level`` are not modelled: such a building is
    drawn from the ground (counted in the notes).  ``building:part`` ways and
    relations are left out (the building outline they belong to is drawn whole;
    counted in the notes).
Streets
    Ways tagged ``highway=*`` of the chosen network on the ground
    (:mod:`.osmtags`); closed ways with ``area=yes``, ``area:highway=*`` or
    ``place=square`` (and multipolygons with those tags) are squares.
Extracts cut at their borders
    Ways refer to nodes the file does not hold.  A highway keeps its located
    stretches (each run of at least two located nodes, source id ``way/ID#k``
    when there are several); a building with a missing node is skipped, and so is
    a multipolygon whose rings cannot be closed.  Every such way is reported as a
    :class:`~walkstream.server.sources.scene.FeatureIssue` and counted in the notes.
Areas
    Closed ways and multipolygon relations that are neither, tagged as a typed area
    (``landuse``, ``leisure``, ``natural``, water, ``amenity=parking``, pedestrian
    areas: :func:`~walkstream.server.sources.areatags.area_kind`), assembled by
    osmium's area handler (holes kept: an island is a hole of its lake), clipped to
    the scene (:mod:`.areas`).  An area way with a node missing from the extract and
    a relation whose rings cannot be closed (members missing, cut at the extract's
    edge) are skipped with a line naming the way or relation; a self-intersecting one
    is repaired with ``make_valid``.  Other polygons are ignored.
"""

from __future__ import annotations

import math
import os
import re
from pathlib import Path
from typing import Any

import numpy as np

from walkstream.server.sources.areas import AREA_PREFIX
from walkstream.server.sources.areatags import area_kind
from walkstream.server.sources.assemble import assemble_scene
from walkstream.server.sources.features import IssueLog, LineFeature, PolyFeature
from walkstream.server.sources.osmtags import is_square
from walkstream.server.sources.pbfcheck import check_pbf_framing
from walkstream.server.sources.scene import SourceScene
from walkstream.shared.arrays import F64
from walkstream.shared.errors import InputError, SourceError

__all__ = ["OSM_SUFFIXES", "load_osm"]

#: File name endings read by :func:`load_osm`.
OSM_SUFFIXES = (".osm", ".osm.pbf", ".pbf", ".osm.xml")


def load_osm(
    path: str | os.PathLike[str],
    *,
    name: str | None = None,
    default_floor_height: float = 3.2,
    tol: float = 0.1,
    network: str = "walk",
) -> SourceScene:
    """Load an OpenStreetMap extract (see the module docstring for the rules).

    Parameters
    ----------
    path:
        ``.osm`` (XML) or ``.osm.pbf`` file.
    name:
        Scene name; default: the file name without its suffixes.
    default_floor_height, tol:
        As for :func:`~walkstream.server.sources.geojson.load_geojson`.
    network:
        ``"walk"`` or ``"drive"`` (:func:`~walkstream.server.sources.osmtags.in_network`).

    Returns
    -------
    SourceScene
        Buildings, then street pieces, in metres of the UTM zone of the data.

    Raises
    ------
    SourceError
        The file cannot be read or parsed, or holds no usable building or street.
    """
    if not (math.isfinite(default_floor_height) and default_floor_height > 0):
        raise InputError(
            f"default_floor_height must be a positive number of metres, got {default_floor_height!r}"
        )
    if not (math.isfinite(tol) and tol > 0):
        raise InputError(f"tol must be a positive number of metres, got {tol!r}")
    p = Path(path)
    if not p.is_file():
        raise SourceError(f"{p}: no such file")
    if p.name.lower().endswith(".pbf"):
        check_pbf_framing(p)
    import osmium

    reader = _Reader()
    try:
        reader.read(p)
    except (RuntimeError, ValueError, KeyError, osmium.InvalidLocationError) as exc:
        # osmium reports a malformed file as a RuntimeError with libosmium's text, a
        # coordinate it cannot parse (lat="nan") as InvalidLocationError, neither
        # with the node: find it for the message
        text = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        node = _bad_node(p) if isinstance(exc, osmium.InvalidLocationError) else None
        raise SourceError(f"{p}: not a readable OpenStreetMap file ({node + ': ' if node else ''}{text})") from exc
    stem = p.name
    for suffix in sorted(OSM_SUFFIXES, key=len, reverse=True):
        if stem.lower().endswith(suffix):
            stem = stem[: -len(suffix)]
            break
    return assemble_scene(
        reader.polys,
        reader.lines,
        None,
        reader.log,
        name=stem if name is None else name,
        source=str(p),
        default_floor_height=default_floor_height,
        tol=tol,
        network=network,
        notes=reader.notes(),
        total_features=reader.features,
    )


# --------------------------------------------------------------------------- reading


_NODE_RE = re.compile(rb"<node\b[^>]*>")
_ATTR_RE = re.compile(rb'\b(id|lat|lon)\s*=\s*["\']([^"\']*)["\']')


def _bad_node(path: Path) -> str | None:
    """``node/ID`` of the first XML node whose lat or lon is not a finite number in range."""
    try:
        data = path.read_bytes()
    except OSError:
        return None
    for m in _NODE_RE.finditer(data):
        attrs = {k.decode(): v.decode("utf-8", "replace") for k, v in _ATTR_RE.findall(m.group(0))}
        try:
            lat, lon = float(attrs.get("lat", "")), float(attrs.get("lon", ""))
            if abs(lat) <= 90 and abs(lon) <= 180:
                continue
        except ValueError:
            pass
        return f"node/{attrs.get('id', '?')} lat={attrs.get('lat')!r} lon={attrs.get('lon')!r}"
    return None


def _ring_xy(nodes: Any) -> tuple[F64, int]:
    """``(n, 2)`` lon/lat of a node list (NaN where the node is missing), and how many are missing."""
    xy = np.full((len(nodes), 2), np.nan)
    missing = 0
    for k, n in enumerate(nodes):
        loc = n.location
        if loc.valid():
            xy[k] = (loc.lon, loc.lat)
        else:
            missing += 1
    return xy, missing


class _Reader:
    """Collects polygons and lines from one pass of osmium over a file."""

    def __init__(self) -> None:
        self.polys: list[PolyFeature] = []
        self.lines: list[LineFeature] = []
        self.log = IssueLog()
        self.features = 0
        self.building_relations: set[int] = set()
        self.area_relations: set[int] = set()
        self.skipped_areas = 0
        self.areas_made: set[int] = set()
        self.cut_highways = 0
        self.skipped_buildings = 0
        self.parts = 0
        self.raised = 0

    def read(self, path: Path) -> None:
        import osmium

        fp = osmium.FileProcessor(str(path)).with_locations().with_areas()
        obj: Any
        for obj in fp:
            if obj.is_way():
                self._way(obj)
            elif obj.is_relation():
                tags = dict(obj.tags)
                if tags.get("type") in ("multipolygon", "building") and (
                    _is_building(tags) or is_square(tags)
                ):
                    self.building_relations.add(int(obj.id))
                elif tags.get("type") == "multipolygon" and area_kind(tags) is not None:
                    self.area_relations.add(int(obj.id))
                elif "building:part" in tags:
                    self.parts += 1
            elif obj.is_area() and not obj.from_way():
                self._area(obj)
        for rid in sorted(self.building_relations - self.areas_made):
            self.features += 1
            self.log.add(
                self.features,
                f"relation/{rid}",
                "multipolygon cannot be assembled (members missing from the extract?)",
                "skipped",
            )
            self.skipped_buildings += 1
        for rid in sorted(self.area_relations - self.areas_made):
            self.features += 1
            self.log.add(
                self.features,
                f"relation/{rid}",
                "area multipolygon cannot be assembled (members missing from the extract?)",
                "skipped",
            )
            self.skipped_areas += 1

    def _way(self, way: Any) -> None:
        tags = dict(way.tags)
        if "building:part" in tags and not _is_building(tags):
            self.parts += 1
            return
        building = _is_building(tags)
        square = is_square(tags)
        nodes = way.nodes
        closed = len(nodes) >= 4 and nodes[0].ref == nodes[len(nodes) - 1].ref
        # a closed highway way is a loop of street (with area=yes a square, above)
        area = None if building or square or not closed or "highway" in tags else area_kind(tags)
        if area is not None:
            self._area_way(way, tags, area)
            return
        if not building and not square and "highway" not in tags:
            return
        self.features += 1
        index = self.features
        fid = f"way/{way.id}"
        xy, missing = _ring_xy(nodes)
        if building or (square and closed):
            if missing:
                self.log.add(
                    index,
                    fid,
                    f"{missing} of {len(nodes)} nodes missing from the extract",
                    "skipped",
                )
                if building:
                    self.skipped_buildings += 1
                return
            if not closed:
                self.log.add(index, fid, "building way is not closed", "skipped")
                return
            self._raised(tags)
            kind = None if building else "square"
            self.polys.append(PolyFeature(index, fid, fid, False, kind, tags, [xy]))
            return
        # a street centre line: keep every run of located nodes
        ok = np.isfinite(xy[:, 0])
        runs = _runs(ok)
        if missing:
            self.cut_highways += 1
            kept = sum(b - a for a, b in runs if b - a >= 2)
            self.log.add(
                index,
                fid,
                f"{missing} of {len(nodes)} nodes missing from the extract; "
                f"{kept} located nodes kept",
                "repaired" if kept else "skipped",
            )
        runs = [(a, b) for a, b in runs if b - a >= 2]
        for k, (a, b) in enumerate(runs):
            uid = fid if len(runs) == 1 else f"{fid}#{k}"
            self.lines.append(LineFeature(index, fid, uid, tags, xy[a:b]))

    def _area_way(self, way: Any, tags: dict[str, str], kind: str) -> None:
        """A closed way that is a typed area: kept whole, or skipped when a node is missing."""
        self.features += 1
        fid = f"way/{way.id}"
        xy, missing = _ring_xy(way.nodes)
        if missing:
            self.log.add(self.features, fid, f"area: {missing} of {len(xy)} nodes missing from the extract", "skipped")
            self.skipped_areas += 1
            return
        self.polys.append(PolyFeature(self.features, fid, fid, False, AREA_PREFIX + kind, tags, [xy]))

    def _area(self, area: Any) -> None:
        rid = int(area.orig_id())
        tags = dict(area.tags)
        building = _is_building(tags)
        square = is_square(tags)
        kind = None if building or square else area_kind(tags)
        if not building and not square and kind is None:
            return
        outers = []
        for outer in area.outer_rings():
            ext, miss = _ring_xy(outer)
            holes = [_ring_xy(inner) for inner in area.inner_rings(outer)]
            if miss or any(m for _, m in holes) or len(ext) < 4:
                continue
            outers.append([ext, *(h for h, _ in holes)])
        if not outers:
            return
        self.areas_made.add(rid)
        self.features += 1
        fid = f"relation/{rid}"
        if kind is None:
            self._raised(tags)
        what = None if building else "square" if kind is None else AREA_PREFIX + kind
        for k, rings in enumerate(outers):
            uid = fid if len(outers) == 1 else f"{fid}#{k}"
            self.polys.append(PolyFeature(self.features, fid, uid, len(outers) > 1, what, tags, rings))

    def _raised(self, tags: dict[str, str]) -> None:
        for key in ("min_height", "building:min_level"):
            try:
                if float(tags.get(key, "0").split()[0]) > 0:
                    self.raised += 1
                    return
            except ValueError:
                continue

    def notes(self) -> list[str]:
        out = []
        if self.cut_highways:
            out.append(
                f"{self.cut_highways} highway ways cut at the extract's border "
                "(nodes missing): their located parts kept"
            )
        if self.skipped_buildings:
            out.append(
                f"{self.skipped_buildings} buildings skipped: nodes or members missing from the extract"
            )
        if self.skipped_areas:
            out.append(f"{self.skipped_areas} areas skipped: nodes or members missing from the extract")
        if self.parts:
            out.append(f"{self.parts} building:part objects left out (their building is drawn whole)")
        if self.raised:
            out.append(f"{self.raised} buildings with min_height/building:min_level drawn from the ground")
        return out


def _is_building(tags: dict[str, str]) -> bool:
    value = tags.get("building")
    return value is not None and value not in ("no", "")


def _runs(ok: np.ndarray) -> list[tuple[int, int]]:
    """``[start, end)`` index ranges of the runs of True."""
    padded = np.concatenate([[False], ok, [False]]).astype(np.int8)
    d = np.diff(padded)
    starts = np.flatnonzero(d == 1)
    ends = np.flatnonzero(d == -1)
    return list(zip(starts.tolist(), ends.tolist(), strict=True))
