"""Cut a source scene down to a box (``--bbox``, ``--bbox-crs``).

Objects that cross the box are clipped to it (not kept or dropped by their centre):
a building cut by the box keeps the part inside (each part of at least
:data:`~walkstream.server.sources.rings.MIN_AREA` m² becomes a building, source id
``"<id>.<k>"`` when there are several) and party walls are found again over the kept
buildings; a street piece and an area keep their parts inside (an area's holes too).  A box in lon/lat
(``bbox_crs="lonlat"``) is projected to the scene's CRS and its bounding box there
is used.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import shapely

from walkstream.server.sources.crs import outside_lonlat, project
from walkstream.server.sources.partywalls import find_party_walls
from walkstream.server.sources.rings import MIN_AREA
from walkstream.server.sources.scene import SourceScene
from walkstream.shared.arrays import F64
from walkstream.shared.errors import InputError
from walkstream.shared.geometry import signed_area
from walkstream.shared.records import AreaParams, BuildingParams, StreetParams

__all__ = ["local_bbox", "clip_scene"]

Box = tuple[float, float, float, float]


def local_bbox(scene: SourceScene, bbox: Box, bbox_crs: str = "local") -> Box:
    """``bbox`` in scene-local metres: as given (``"local"``), or a lon/lat box projected.

    Raises
    ------
    InputError
        A bad CRS name, or lon/lat out of range.
    """
    x0, y0, x1, y1 = (float(v) for v in bbox)
    if not (np.isfinite([x0, y0, x1, y1]).all() and x1 > x0 and y1 > y0):
        raise InputError(f"--bbox: expected MINX,MINY,MAXX,MAXY with MIN < MAX, got {bbox}")
    if bbox_crs == "local":
        return x0, y0, x1, y1
    if bbox_crs != "lonlat":
        raise InputError(f"--bbox-crs: expected local or lonlat, got {bbox_crs!r}")
    t = np.linspace(0.0, 1.0, 17)
    edge = np.concatenate(
        [
            np.column_stack([x0 + (x1 - x0) * t, np.full_like(t, y0)]),
            np.column_stack([np.full_like(t, x1), y0 + (y1 - y0) * t]),
            np.column_stack([x0 + (x1 - x0) * t, np.full_like(t, y1)]),
            np.column_stack([np.full_like(t, x0), y0 + (y1 - y0) * t]),
        ]
    )
    if outside_lonlat(edge).any():
        raise InputError(f"--bbox {bbox}: not a lon/lat box (longitude, latitude in degrees)")
    xy = project(edge, None, scene.crs) - np.asarray(scene.origin)
    if not np.isfinite(xy).all():
        raise InputError(f"--bbox {bbox}: cannot be projected to the scene's {scene.crs}")
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])


def clip_scene(scene: SourceScene, bbox: Box, bbox_crs: str = "local") -> SourceScene:
    """The scene clipped to ``bbox`` (see the module docstring).

    Ids are renumbered densely (buildings first) so PVS id lists stay compact.

    Raises
    ------
    InputError
        Nothing of the scene lies inside the box.
    """
    box = shapely.box(*local_bbox(scene, bbox, bbox_crs))
    shapely.prepare(box)
    rings: list[list[F64]] = []
    kept: list[BuildingParams] = []
    for b in scene.buildings:
        poly = shapely.Polygon(b.rings[0], b.rings[1:])
        if box.contains(poly):
            rings.append(list(b.rings))
            kept.append(b)
            continue
        if not box.intersects(poly):
            continue
        parts = [p for p in _parts(shapely.intersection(poly, box)) if p.area >= MIN_AREA]
        for k, part in enumerate(parts):
            rings.append(_rings(part))
            sid = b.source_id if len(parts) == 1 else f"{b.source_id}.{k}"
            kept.append(replace(b, source_id=sid))
    buildings: list[BuildingParams] = []
    if kept:
        split, nbh = find_party_walls(rings, [b.height for b in kept])
        buildings = [
            replace(b, id=i, rings=tuple(r), neighbour_heights=tuple(n))
            for i, (b, r, n) in enumerate(zip(kept, split, nbh, strict=True))
        ]
    streets: list[StreetParams] = []
    passages: set[int] = set()
    for s in scene.streets:
        poly = shapely.Polygon(s.ring)
        if box.contains(poly):
            parts = [poly]
        elif box.intersects(poly):
            parts = [p for p in _parts(shapely.intersection(poly, box)) if p.area >= MIN_AREA]
        else:
            continue
        for k, part in enumerate(parts):
            sid = s.source_id if len(parts) == 1 else f"{s.source_id}.{k}"
            new = len(buildings) + len(streets)
            if s.id in scene.passages:
                passages.add(new)
            ring = np.asarray(s.ring) if part is poly else _rings(part)[0]
            streets.append(replace(s, id=new, ring=ring, source_id=sid))
    if not buildings and not streets:
        raise InputError(f"--bbox {bbox}: no object of the scene lies inside it")
    areas: list[AreaParams] = []
    for a in scene.areas:
        poly = shapely.Polygon(a.rings[0], a.rings[1:])
        if not box.intersects(poly):
            continue
        parts = [poly] if box.contains(poly) else [p for p in _parts(shapely.intersection(poly, box)) if p.area >= MIN_AREA]
        for k, part in enumerate(parts):
            sid = a.source_id if len(parts) == 1 else f"{a.source_id}.{k}"
            kept_rings = a.rings if part is poly else tuple(_rings(part))
            areas.append(replace(a, id=len(buildings) + len(streets) + len(areas), rings=kept_rings, source_id=sid))
    return replace(
        scene, buildings=tuple(buildings), streets=tuple(streets), passages=frozenset(passages), areas=tuple(areas)
    )


def _parts(geom: shapely.Geometry) -> list[shapely.Polygon]:
    return [
        p
        for g in shapely.get_parts(geom)
        for p in shapely.get_parts(g)
        if isinstance(p, shapely.Polygon) and not p.is_empty
    ]


def _rings(poly: shapely.Polygon) -> list[F64]:
    """Exterior CCW and holes CW, without closing vertices."""
    ext = np.asarray(poly.exterior.coords, np.float64)[:-1, :2]
    out = [ext if signed_area(ext) > 0 else ext[::-1].copy()]
    for hole in poly.interiors:
        h = np.asarray(hole.coords, np.float64)[:-1, :2]
        out.append(h if signed_area(h) < 0 else h[::-1].copy())
    return out
