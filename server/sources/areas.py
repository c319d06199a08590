"""Typed areas of a source: cleaned polygons clipped to the scene and made into records.

The readers hand polygons whose kind is ``"area:<kind>"``
(:func:`~walkstream.server.sources.areatags.area_kind`); they are cleaned and, where
invalid (self-intersecting), repaired with shapely's ``make_valid`` or skipped with a
line naming the feature, as buildings are
(:func:`~walkstream.server.sources.rings.clean_and_repair`).  Each is then clipped to
the scene: the box around every building and street piece grown by
:data:`AREA_MARGIN_M` on each side (a forest or a lake running far out of the extract
is kept only where the walk can see it), simplified to :data:`AREA_SIMPLIFY_M` (an
area's outline is seen from far, mostly at a grazing angle) and split into one
:class:`~walkstream.shared.records.AreaParams` per polygon, holes kept.
"""

from __future__ import annotations

import numpy as np
import shapely

from walkstream.server.sources.features import CleanPart, IssueLog
from walkstream.shared.areakinds import AREA_KINDS
from walkstream.shared.arrays import F64
from walkstream.shared.records import AreaParams

__all__ = ["AREA_MARGIN_M", "AREA_SIMPLIFY_M", "AREA_PREFIX", "make_areas", "scene_box"]

#: A polygon's ``kind`` starts with this when it is a typed area: ``"area:water"``.
AREA_PREFIX = "area:"
#: Metres the scene's box grows by on each side before areas are clipped to it.
AREA_MARGIN_M = 50.0
#: Tolerance of the simplification of an area's outline, metres.
AREA_SIMPLIFY_M = 0.5
#: Areas (after clipping) smaller than this many square metres are left out.
MIN_AREA_M2 = 1.0


def scene_box(rings: list[F64], margin: float = AREA_MARGIN_M) -> tuple[float, float, float, float] | None:
    """``(minx, miny, maxx, maxy)`` around ``rings`` grown by ``margin``; None without rings."""
    if not rings:
        return None
    pts = np.concatenate([np.asarray(r, np.float64).reshape(-1, 2) for r in rings])
    lo, hi = pts.min(axis=0) - margin, pts.max(axis=0) + margin
    return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])


def make_areas(
    parts: list[CleanPart], first_id: int, box: tuple[float, float, float, float] | None, log: IssueLog
) -> list[AreaParams]:
    """Areas of the cleaned ``parts`` (ids from ``first_id`` on), clipped to ``box``.

    A part wholly outside the box is left out (counted by the caller); one that
    clipping leaves too small is left out too.
    """
    out: list[AreaParams] = []
    if box is None:
        return out
    clip = shapely.box(*box)
    for part in parts:
        assert part.poly.kind is not None and part.poly.kind.startswith(AREA_PREFIX)
        kind = part.poly.kind[len(AREA_PREFIX) :]
        assert kind in AREA_KINDS, kind
        shape = shapely.Polygon(part.rings[0], part.rings[1:])
        inside = shapely.intersection(shape, clip)
        if inside.is_empty:
            continue
        inside = shapely.simplify(inside, AREA_SIMPLIFY_M, preserve_topology=True)
        polygons = [g for g in shapely.get_parts(inside) if isinstance(g, shapely.Polygon) and g.area >= MIN_AREA_M2]
        if not shapely.covers(clip, shape):
            log.add(part.poly.index, part.source_id, f"clipped to the scene ({len(polygons)} part(s) kept)", "repaired")
        for k, g in enumerate(polygons):
            rings = [np.asarray(g.exterior.coords, np.float64)[:-1, :2]]
            rings += [np.asarray(i.coords, np.float64)[:-1, :2] for i in g.interiors]
            sid = part.source_id if len(polygons) == 1 else f"{part.source_id}.{k}"
            out.append(AreaParams(first_id + len(out), kind, tuple(rings), sid))
    return out
