"""The second half of every reader of real data: polygons and street lines into a scene.

A reader (:mod:`.geojson`, :mod:`.osm`) turns its file into working records
(:mod:`.features`: polygons with a kind, street lines, both with their properties
or tags); :func:`assemble_scene` does the rest the same way for every format:
projection to local metres (:func:`_to_local`, the CRS rules of :mod:`.crs`),
cleaning and repair (:mod:`.rings`), heights (:mod:`.heights`) and party walls
(:mod:`.partywalls`) of buildings, and the street network (:mod:`.osmtags` picks
the ways, :mod:`.network` cuts them into crossroads and street pieces).
"""

from __future__ import annotations

import dataclasses
import zlib
from collections import Counter

import numpy as np
import pyproj
import shapely

from walkstream.server.sources.areas import AREA_PREFIX, make_areas, scene_box
from walkstream.server.sources.crs import crs_label, metric_crs, outside_lonlat, project
from walkstream.server.sources.features import CleanPart, IssueLog, LineFeature, PolyFeature
from walkstream.server.sources.heights import floor_levels, is_positive, parse_length
from walkstream.server.sources.network import NetArea, NetLine, split_holes, street_network
from walkstream.server.sources.osmtags import (
    NETWORKS,
    ground_layer,
    in_network,
    is_passage,
    street_width,
)
from walkstream.server.sources.partywalls import find_party_walls
from walkstream.server.sources.rings import bound_vertices, clean_and_repair_all
from walkstream.server.sources.scene import SourceScene
from walkstream.shared.arrays import F64
from walkstream.shared.errors import InputError, SourceError
from walkstream.shared.landmarks import PLAIN, landmark_kind
from walkstream.shared.records import BuildingParams, StreetParams

__all__ = ["DEFAULT_STREET_WIDTH", "MAX_PROJECTED", "assemble_scene"]

#: Width in metres of a ``kind=street`` line or polygon without ``highway`` or ``width``.
DEFAULT_STREET_WIDTH = 10.0
#: Metres from a projected CRS's origin beyond which a feature is skipped (the Earth's
#: circumference is 4e7 m, so no real position is this far).
MAX_PROJECTED = 1e8
#: Skipped features named in the scene's notes (the rest are counted).
_SHOWN_SKIPS = 5


def assemble_scene(
    polys: list[PolyFeature],
    lines: list[LineFeature],
    src_crs: pyproj.CRS | None,
    log: IssueLog,
    *,
    name: str,
    source: str,
    default_floor_height: float,
    tol: float,
    network: str = "walk",
    notes: list[str] | None = None,
    total_features: int | None = None,
) -> SourceScene:
    """Project, clean and build the buildings and the street network of a source.

    ``polys`` have ``kind`` None (a building), ``"square"`` (a street area, holes
    kept), ``"street"`` / ``"crossroad"`` (a ready street piece) or ``"area:<kind>"``
    (a typed area, :mod:`.areas`: clipped to the scene, ids after the streets); ``lines`` are
    street centre lines whose ``props`` decide network, layer and width
    (:mod:`.osmtags`).  ``notes`` (the reader's own remarks) come first in the
    scene's notes.

    Raises
    ------
    SourceError
        No usable building or street at all.
    InputError
        An unknown ``network``.
    """
    if network not in NETWORKS:
        raise InputError(f"--network: expected one of {', '.join(NETWORKS)}, got {network!r}")
    crs_name, origin = _to_local(polys, lines, src_crs, log)
    buildings_raw: list[CleanPart] = []
    pieces: list[CleanPart] = []
    areas: list[CleanPart] = []
    typed: list[CleanPart] = []
    projected = [poly for poly in polys if poly.local is not None]
    for poly, parts in zip(projected, clean_and_repair_all(projected, log), strict=True):
        if poly.kind is not None and poly.kind.startswith(AREA_PREFIX):
            typed.extend(parts)
        elif poly.kind == "square":
            areas.extend(parts)
        elif poly.kind is None:
            buildings_raw.extend(parts)
        else:
            pieces.extend(parts)
    buildings = _make_buildings(buildings_raw, default_floor_height, tol, log)
    out_notes = list(notes or [])
    streets, passages = _make_streets(pieces, areas, lines, len(buildings), network, log, out_notes)
    box = scene_box([b.rings[0] for b in buildings] + [s.ring for s in streets])
    typed_areas = make_areas(typed, len(buildings) + len(streets), box, log)
    if not buildings and not streets:
        skipped = [i for i in log.sorted() if i.action == "skipped"]
        examples = "; ".join(f"{i.feature_id}: {i.problem}" for i in skipped[:3])
        count = total_features if total_features is not None else len(polys) + len(lines)
        raise SourceError(
            f"{source}: no usable feature ({count} features, {len(skipped)} skipped"
            + (f"; e.g. {examples}" if examples else "")
            + ")"
            + ("".join(f"; {n}" for n in out_notes))
        )
    issues = log.sorted()
    skipped = [i for i in issues if i.action == "skipped"]
    if skipped:
        # one line the bake prints: how many were skipped, and the first few by id
        shown = "; ".join(f"{i.feature_id}: {i.problem}" for i in skipped[:_SHOWN_SKIPS])
        more = f"; {len(skipped) - _SHOWN_SKIPS} more" if len(skipped) > _SHOWN_SKIPS else ""
        out_notes.append(f"skipped {len(skipped)} feature(s): {shown}{more}")
    return SourceScene(
        name=name,
        crs=crs_name,
        origin=origin,
        buildings=tuple(buildings),
        streets=tuple(streets),
        issues=tuple(issues),
        passages=frozenset(passages),
        notes=tuple(out_notes),
        areas=tuple(typed_areas),
    )


# --------------------------------------------------------------------------- projection


def _to_local(
    polys: list[PolyFeature], lines: list[LineFeature], src: pyproj.CRS | None, log: IssueLog
) -> tuple[str, tuple[float, float]]:
    """Project every coordinate (one vectorised transform) and move it to the origin.

    Fills ``.local`` of each usable polygon and line (left ``None`` for skipped ones)
    and returns the projected CRS name and the origin.
    """
    items: list[PolyFeature | LineFeature] = [*polys, *lines]
    geographic = src is None or src.is_geographic
    if geographic:
        # Out-of-range lon/lat usually means projected data without a 'crs' member.
        kept = []
        for it in items:
            rings = it.raw if isinstance(it, PolyFeature) else [it.raw]
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
    else:
        # Nothing on Earth is further than MAX_PROJECTED from a projected CRS's origin;
        # beyond it the centre of the bounding box (the scene origin) is meaningless.
        kept = []
        for it in items:
            rings = it.raw if isinstance(it, PolyFeature) else [it.raw]
            if all(float(np.abs(r).max()) <= MAX_PROJECTED for r in rings):
                kept.append(it)
            else:
                log.add(
                    it.index, it.uid, f"coordinates beyond {MAX_PROJECTED:.0e} m of the CRS origin", "skipped"
                )
        items = kept
    if not items:
        return ("EPSG:4326" if geographic else crs_label(src)), (0.0, 0.0)

    arrays = [r for it in items for r in (it.raw if isinstance(it, PolyFeature) else [it.raw])]
    allpts = np.concatenate(arrays)
    # lon/lat, and projections not true to scale here (Web Mercator), go to UTM
    crs_name = metric_crs(src, allpts)
    proj = allpts if crs_name == crs_label(src) and not geographic else project(allpts, src, crs_name)

    # Split back per item; drop items the projection could not handle.
    counts = [len(a) for a in arrays]
    chunks = np.split(proj, np.cumsum(counts)[:-1])
    per_item: list[list[F64]] = []
    pos = 0
    for it in items:
        n = len(it.raw) if isinstance(it, PolyFeature) else 1
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
        if isinstance(it, PolyFeature):
            it.local = local
        else:
            it.local = local[0]
    return crs_name, (float(origin[0]), float(origin[1]))




def _make_buildings(
    parts: list[CleanPart], default_floor_height: float, tol: float, log: IssueLog
) -> list[BuildingParams]:
    """Heights per feature, party walls over all buildings, then the records."""
    levels: dict[int, tuple[int, float]] = {}
    for part in parts:
        poly = part.poly
        if poly.index in levels:
            continue
        floors, fh, bad, how = floor_levels(poly.props, poly.fid, default_floor_height)
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
                kind=_landmark(part, log),
            )
        )
    return _within_module_limit(out, parts, log)


def _landmark(part: CleanPart, log: IssueLog) -> int:
    """The landmark kind of a footprint's ``landmark`` property; a bad one is ignored and reported."""
    value = part.poly.props.get("landmark")
    try:
        return landmark_kind(value)
    except InputError as exc:
        log.add(part.poly.index, part.poly.fid, f"bad {exc} ignored; a plain building", "repaired")
        return PLAIN


def _within_module_limit(
    buildings: list[BuildingParams], parts: list[CleanPart], log: IssueLog
) -> list[BuildingParams]:
    """The buildings the grammar can derive within its module limit, ids renumbered.

    The building grammar makes about 1.1 modules per floor and metre of wall at LOD 2,
    so only a building whose floors × perimeter reaches half the limit is
    derived here (once, at LOD 2, the largest); one over the limit is skipped and
    named instead of ending the bake where its objects are written.
    """
    from walkstream.shared.buildings import default_grammar, derive_building
    from walkstream.shared.errors import DerivationLimitError

    grammar = default_grammar()
    out: list[BuildingParams] = []
    if not buildings:
        return out
    rings = [r for b in buildings for r in b.rings]
    counts = [len(r) for r in rings]
    owner = np.repeat(np.arange(len(buildings)), [len(b.rings) for b in buildings])
    closed = shapely.linearrings(np.concatenate(rings), indices=np.repeat(np.arange(len(rings)), counts))
    walls = np.bincount(owner, weights=shapely.length(closed), minlength=len(buildings))
    for b, part, wall in zip(buildings, parts, walls.tolist(), strict=True):
        if b.floors * wall >= grammar.max_modules / 2:
            try:
                derive_building(b, 2, grammar)
            except DerivationLimitError as exc:
                log.add(part.poly.index, part.source_id, f"{b.floors} floors, {wall:.0f} m of wall: {exc}", "skipped")
                continue
        out.append(b if b.id == len(out) else dataclasses.replace(b, id=len(out)))
    return out




# --------------------------------------------------------------------------- streets


def _line_width(line: LineFeature, log: IssueLog) -> float:
    props = line.props
    if "highway" in props:
        width, note = street_width(props)
        if note:
            log.add(line.index, line.uid, f"{note}; {width:g} m used", "repaired")
        return width
    raw = props.get("width")
    if raw is None or raw == "":
        return DEFAULT_STREET_WIDTH
    value = parse_length(raw)
    if value is not None and is_positive(value):
        return value
    log.add(line.index, line.uid, f"bad width={raw!r} ignored; {DEFAULT_STREET_WIDTH:g} m used", "repaired")
    return DEFAULT_STREET_WIDTH


def _left_out(counts: Counter[str], network: str) -> str | None:
    """One line for the summary: what the network left out on purpose."""
    if not counts:
        return None
    parts = []
    for what, n in sorted(counts.items(), key=lambda t: (-t[1], t[0])):
        parts.append(f"{n} {what}")
    return f"left out of the {network} network: " + ", ".join(parts)


def _make_streets(
    pieces: list[CleanPart],
    areas: list[CleanPart],
    lines: list[LineFeature],
    first_id: int,
    network: str,
    log: IssueLog,
    notes: list[str],
) -> tuple[list[StreetParams], list[int]]:
    """Street pieces: given pieces as they are, lines and areas through the network."""
    out: list[tuple[str, F64, float, str, bool]] = []  # kind, ring, width, source id, passage
    for part in pieces:
        assert part.poly.kind is not None
        width = _line_width(LineFeature(part.poly.index, part.poly.fid, part.poly.uid, part.poly.props, part.rings[0]), log)
        shape = shapely.Polygon(part.rings[0], part.rings[1:])
        for k, piece in enumerate(split_holes(shape)):
            ring = np.asarray(piece.exterior.coords, np.float64)[:-1]
            sid = part.source_id if k == 0 else f"{part.source_id}.{k}"
            out.append((part.poly.kind, ring, width, sid, False))

    left: Counter[str] = Counter()
    net_lines: list[NetLine] = []
    for line in lines:
        if line.local is None:
            continue
        props = line.props
        if "highway" in props and not in_network(props, network):
            left[f"{props.get('highway')} ways"] += 1
            continue
        ground, why = ground_layer(props)
        if not ground:
            left["tunnels" if why == "tunnel" else f"ways on {why}"] += 1
            continue
        pts, note = bound_vertices(line.local, closed=False)
        if pts is None:
            log.add(line.index, line.uid, str(note), "skipped")
            continue
        if note:
            log.add(line.index, line.uid, note, "repaired")
        if len(pts) < 2:
            log.add(line.index, line.uid, f"fewer than 2 distinct points ({len(pts)})", "skipped")
            continue
        net_lines.append(NetLine(line.uid, pts, _line_width(line, log), is_passage(props)))
    net_areas: list[NetArea] = []
    for part in areas:
        if network != "walk" and not part.poly.props.get("kind"):
            left["squares (pedestrian areas)"] += 1
            continue
        net_areas.append(NetArea(part.source_id, tuple(part.rings)))
    net = street_network(net_lines, net_areas)
    for uid, problem in net.skipped:
        log.add(-1, uid, problem, "skipped")
    for p in net.pieces:
        out.append((p.kind, p.ring, p.width, p.source_id, p.passage))
    note = _left_out(left, network)
    if note:
        notes.append(note)
    if net_lines:
        notes.append(
            f"street network ({network}): {len(net_lines)} ways, {net.junctions} junction nodes "
            f"in {net.clusters} crossroads, {net.components} connected part(s)"
        )
    streets = [
        StreetParams(id=first_id + k, kind=kind, ring=ring, width=width, source_id=sid)
        for k, (kind, ring, width, sid, _) in enumerate(out)
    ]
    passages = [first_id + k for k, t in enumerate(out) if t[4]]
    return streets, passages
