"""The shortest walk between two points of a floor with obstacles on it.

A room's walkable floor is its outline shrunk by a walker's clearance, less the
footprints of what stands in it (furniture, machines, shelves) grown by the same
clearance: a polygon with holes, or several pieces where furniture closes a gap.  The
shortest walk inside such a polygon bends only at its vertices, so it is found on the
visibility graph of the vertices (every pair joined by a segment that stays on the
floor) with the project's one Dijkstra
(:func:`~walkstream.shared.nav.shortest_paths`).

:class:`FloorRoutes` keeps one floor's vertices and their visibility, so the many legs
of a room (every pair of its doors) are each one small search.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np
import shapely

from walkstream.shared.arrays import F64
from walkstream.shared.nav import shortest_paths

__all__ = ["BODY_HEIGHT", "FloorObstacle", "FloorRoutes", "walkable_floor"]

_TOUCH = 1e-6
"""Slack (metres) of the coverage tests: a segment along the floor's edge stays on it."""


BODY_HEIGHT = 2.0
"""How high above its floor a walker needs the way clear (metres): a person and a margin."""


@dataclass(frozen=True, slots=True)
class FloorObstacle:
    """Something that stands in a room: its footprint (scene-local ``x, y``) and the
    height range it fills."""

    footprint: shapely.Geometry
    bottom: float
    top: float

    def blocks(self, floor: float) -> bool:
        """Whether a walker on a floor at height ``floor`` walks into it (it reaches
        between the floor and :data:`BODY_HEIGHT` above)."""
        return self.bottom < floor + BODY_HEIGHT and self.top > floor + 0.05


def walkable_floor(outline: shapely.Geometry, obstacles: Sequence[shapely.Geometry], clearance: float) -> shapely.Geometry | None:
    """The floor a walker's middle may stand on: ``outline`` shrunk by ``clearance``,
    less every obstacle footprint grown by it (mitred corners: a box stays four corners).

    Returns None where nothing is left (a doorway, a slim cell, a room filled by
    furniture).
    """
    free = outline.buffer(-clearance, join_style="mitre")
    if obstacles and not free.is_empty:
        grown = shapely.union_all([o.buffer(clearance, join_style="mitre") for o in obstacles])
        free = free.difference(grown)
    if free.is_empty:
        return None
    parts = [g for g in getattr(free, "geoms", [free]) if isinstance(g, shapely.Polygon) and g.area > 1e-6]
    if not parts:
        return None
    return parts[0] if len(parts) == 1 else shapely.MultiPolygon(parts)


class FloorRoutes:
    """Shortest walks on one walkable floor (see the module docstring).

    Parameters
    ----------
    floor:
        A :func:`walkable_floor` (Polygon or MultiPolygon).
    """

    def __init__(self, floor: shapely.Geometry) -> None:
        self.floor = floor
        self._cover = floor.buffer(_TOUCH)
        shapely.prepare(self._cover)
        rings: list[F64] = []
        for poly in getattr(floor, "geoms", [floor]):
            for ring in [poly.exterior, *poly.interiors]:
                rings.append(np.asarray(ring.coords, np.float64)[:-1, :2])
        self.vertices: F64 = np.concatenate(rings) if rings else np.zeros((0, 2))
        n = len(self.vertices)
        i, j = np.triu_indices(n, 1)
        seen = self.clear(self.vertices[i], self.vertices[j])
        self._adj: list[list[tuple[int, float]]] = [[] for _ in range(n)]
        length = np.linalg.norm(self.vertices[j] - self.vertices[i], axis=1)
        for a, b, w in zip(i[seen].tolist(), j[seen].tolist(), length[seen].tolist(), strict=True):
            self._adj[a].append((b, w))
            self._adj[b].append((a, w))

    def clear(self, a: F64, b: F64) -> np.ndarray:
        """Whether each segment ``a[k] -> b[k]`` (``(m, 2)`` each) stays on the floor."""
        if not len(a):
            return np.zeros(0, bool)
        lines = shapely.linestrings(np.stack([a, b], axis=1))
        return np.asarray(shapely.covers(self._cover, lines), bool)

    def route(self, a: F64, b: F64) -> F64 | None:
        """The shortest walk ``(k, 2)`` from ``a`` to ``b`` (both on the floor) that stays
        on it, ends included; None where no walk joins them (the two lie on pieces of
        the floor that furniture parts)."""
        a2, b2 = np.asarray(a, np.float64)[:2], np.asarray(b, np.float64)[:2]
        if self.clear(a2[None], b2[None])[0]:
            return np.array([a2, b2])
        n = len(self.vertices)
        if not n:
            return None
        src, dst = n, n + 1
        from_a = self.clear(np.repeat(a2[None], n, 0), self.vertices)
        to_b = self.clear(self.vertices, np.repeat(b2[None], n, 0))
        da = np.linalg.norm(self.vertices - a2, axis=1)
        db = np.linalg.norm(self.vertices - b2, axis=1)
        adj = self._adj

        def expand(s: int, d: float) -> Iterator[tuple[int, float]]:
            if s == src:
                for v in np.flatnonzero(from_a).tolist():
                    yield v, d + float(da[v])
                return
            if s == dst:
                return
            for v, w in adj[s]:
                yield v, d + w
            if to_b[s]:
                yield dst, d + float(db[s])

        dist, prev = shortest_paths(n + 2, [(src, 0.0)], expand, stop=None, tol=1e-12)
        if not np.isfinite(dist[dst]):
            return None
        chain = [dst]
        while chain[-1] != src:
            chain.append(int(prev[chain[-1]]))
        pts = [a2 if s == src else b2 if s == dst else self.vertices[s] for s in chain[::-1]]
        return np.array(pts, np.float64)
