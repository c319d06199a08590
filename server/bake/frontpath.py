"""The front path: a view cell from the street to a placed building's door.

A real house stands back from its street (a front garden, a yard: 3 to 10 m in the
OSM extracts); the street cells end at the street space, so the ground between the
street and the door belongs to no cell.  A walk that crossed it would be located
nowhere, and the street cell's PVS, sampled on the street, would stand for what the
walker sees from the garden.  So a crossing scene whose door lies more than
:data:`PATH_FROM` metres from its street cell gets one more street cell: the
quadrilateral from the door's outer face (widened to at least :data:`PATH_WIDTH`) to
the stretch of the street cell's nearest edge in front of it.  It shares that stretch
with the street cell (a portal of the street graph), has the street cell's eye
heights, and gets its PVS and ACH like every other cell; the entrance portal joins it
to the doorway.  It must not cross another building or another street cell: where it
would, the placement is refused (:func:`front_path` returns None).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np
import shapely
from shapely.geometry.polygon import orient

from walkstream.server.bake.viewcell import ViewCell
from walkstream.shared.arrays import F64

__all__ = ["PATH_FROM", "PATH_WIDTH", "STREET_KINDS", "front_path", "with_front_path"]

STREET_KINDS = ("street", "crossroad", "square")
"""The cell kinds an entrance may face (every cell of a city without streets)."""

PATH_FROM = 0.5
"""Metres between the door and its street cell from which a front path is laid."""
PATH_WIDTH = 2.0
"""Metres wide a front path is at least (the door's width plus half a metre each side)."""

_MIN_SHARED = 0.6  # the stretch shared with the street is at least this long (the street graph walks >= 0.5 m)
_OVERLAP = 1e-3  # square metres of overlap with a street cell or a building counted as none


def front_path(
    ends: F64,
    normal: F64,
    street: shapely.Geometry,
    blocked: Sequence[shapely.Geometry] = (),
) -> F64 | None:
    """The front path's outline ``(4, 2)``, counter-clockwise, or None when it cannot
    be laid.

    Parameters
    ----------
    ends:
        ``(2, 2)`` the ends of the door's outer face, city-local metres.
    normal:
        ``(2,)`` unit, out of the building.
    street:
        The (convex) street cell the door faces.
    blocked:
        What the path may not overlap: the other street cells, the other buildings.
    """
    ends = np.asarray(ends, np.float64).reshape(2, 2)
    n = np.asarray(normal, np.float64).reshape(2)
    mid = ends.mean(axis=0)
    u = np.array([-n[1], n[0]])
    half = max(0.5 * float(np.hypot(*(ends[1] - ends[0]))) + 0.5, 0.5 * PATH_WIDTH)
    ring = np.asarray(street.exterior.coords)[:-1]
    front = shapely.Point(mid + 0.1 * n)
    # the street cell's edge nearest the door, and the stretch of it in front of the door
    k = min(range(len(ring)), key=lambda i: shapely.LineString([ring[i], ring[(i + 1) % len(ring)]]).distance(front))
    a, b = ring[k], ring[(k + 1) % len(ring)]
    e = b - a
    length = float(np.hypot(*e))
    if length < _MIN_SHARED:
        return None
    v = e / length
    near = np.asarray(shapely.get_coordinates(shapely.shortest_line(shapely.LineString([a, b]), front)))[0]
    t = float((near - a) @ v)
    lo, hi = max(0.0, t - half), min(length, t + half)
    if hi - lo < _MIN_SHARED:
        return None
    quad = shapely.convex_hull(shapely.MultiPoint([mid - u * half, mid + u * half, a + v * hi, a + v * lo]))
    if not isinstance(quad, shapely.Polygon) or quad.area < 0.5:
        return None
    if shapely.intersection(quad, street).area > _OVERLAP:
        return None
    if any(shapely.intersection(quad, g).area > _OVERLAP for g in blocked if quad.intersects(g)):
        return None
    return np.asarray(orient(quad, 1.0).exterior.coords)[:-1]


def with_front_path(cells: Sequence[ViewCell], path: F64, front: F64) -> list[ViewCell]:
    """``cells`` and the front path ``path`` (:func:`front_path`) as one more street
    cell (id ``len(cells)``), neighbour of the street cell nearest ``front`` (the point
    just in front of the door), with that cell's eye heights."""
    street = [c for c in cells if c.kind in STREET_KINDS] or list(cells)
    polys = [shapely.Polygon(c.polygon) for c in street]
    s = street[int(shapely.STRtree(polys).query_nearest(shapely.Point(np.asarray(front, np.float64)))[0])]
    new = ViewCell(len(cells), "street", np.asarray(path, np.float64), s.zmin, s.zmax, (s.id,))
    return [replace(c, neighbours=(*c.neighbours, new.id)) if c.id == s.id else c for c in cells] + [new]
