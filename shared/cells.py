"""View cells as both sides see them: the kinds, convex outlines, and which cell holds a point.

The bake cuts a scene into cells (:mod:`walkstream.server.bake`), the store keeps
them, the service answers ``locate`` with :class:`CellLocator`, and the client
follows the viewer from outline to outline with :func:`inside_convex`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import shapely
from numpy.typing import ArrayLike, NDArray

from walkstream.shared.errors import InputError

__all__ = ["CELL_KINDS", "LOCATABLE_KINDS", "INSIDE_TOL", "LOCATE_TOL", "CellLocator", "inside_convex", "outline_polygons"]

CELL_KINDS: tuple[str, ...] = ("crossroad", "street", "square", "grid", "room", "doorway", "outside")
"""Every kind of view cell, in the order the bake numbers cells by kind.

Interiors use the last three: ``room`` (a convex part of a room), ``doorway`` (the
opening of a door or inner window through a thick wall, so that an eye standing in it
is in a cell) and ``outside`` (one per interior: everything seen through windows and
outer doors; no viewer is ever located in it).
"""

LOCATABLE_KINDS: frozenset[str] = frozenset(k for k in CELL_KINDS if k != "outside")
"""The kinds a viewer can be located in (every kind but ``outside``)."""

LOCATE_TOL = 1e-6
"""A point this close to a cell (metres) is in it: points on shared edges find a cell."""

INSIDE_TOL = 1e-7
"""Relative tolerance of :func:`inside_convex`: times the largest coordinate, at least 1."""


def outline_polygons(outlines: Sequence[ArrayLike]) -> NDArray[np.object_]:
    """Shapely Polygons of outlines with any vertex counts, as one ``(n,)`` object array.

    ``shapely.polygons`` takes one ``(n, m, 2)`` array, so outlines of different
    vertex counts are built from one flat coordinate array and ring indices instead.

    >>> p = outline_polygons([[[0, 0], [1, 0], [1, 1]], [[0, 0], [2, 0], [2, 2], [0, 2]]])
    >>> [round(float(a), 3) for a in shapely.area(p)]
    [0.5, 4.0]
    """
    if len(outlines) == 0:
        return np.empty(0, object)
    rings = [np.asarray(o, dtype=np.float64).reshape(-1, 2) for o in outlines]
    counts = np.array([len(r) for r in rings])
    if (counts < 3).any():
        k = int(np.flatnonzero(counts < 3)[0])
        raise InputError(f"outline {k}: expected >= 3 vertices, got {counts[k]}")
    coords = np.concatenate(rings)
    index = np.repeat(np.arange(len(rings)), counts)
    return np.asarray(shapely.polygons(shapely.linearrings(coords, indices=index)), dtype=object)


class CellLocator:
    """Find the cell containing a point.

    Built once from the cells' ids and convex outlines (a shapely STRtree); queries
    are vectorised.  A point within :data:`LOCATE_TOL` of several cells (e.g. exactly
    on a shared edge) gets the lowest of their ids, so the answer is deterministic.

    With ``zranges`` (interiors, where storeys stack cells over each other) a point
    may carry a height: a cell holds it when its outline holds ``(x, y)`` and
    ``zmin <= z < zmax`` (the storey's height decides); a point given without a
    height is located in 2D as in a city.

    Parameters
    ----------
    ids : (n,) int
        Cell ids; they need not be positions.
    outlines : sequence of (m_i, 2) float
        The cells' outlines, scene-local metres, any vertex counts.
    zranges : (n, 2) float, optional
        ``zmin, zmax`` of each cell's volume, metres.

    >>> sq = [[0, 0], [1, 0], [1, 1], [0, 1]]
    >>> loc = CellLocator([7, 8], [sq, sq], zranges=[[0.0, 3.0], [3.0, 6.0]])
    >>> loc.locate(0.5, 0.5, 1.6), loc.locate(0.5, 0.5, 4.6), loc.locate(0.5, 0.5, 9.0)
    (7, 8, None)
    """

    def __init__(
        self, ids: ArrayLike, outlines: Sequence[ArrayLike], zranges: ArrayLike | None = None
    ) -> None:
        self._ids = np.asarray(ids, dtype=np.int64).reshape(-1)
        if len(self._ids) != len(outlines):
            raise InputError(f"CellLocator: {len(self._ids)} ids but {len(outlines)} outlines")
        self._polys = outline_polygons(outlines)
        self._tree = shapely.STRtree(self._polys)
        self._z: NDArray[np.float64] | None = None
        if zranges is not None:
            z = np.asarray(zranges, dtype=np.float64).reshape(-1, 2)
            if len(z) != len(self._ids):
                raise InputError(f"CellLocator: {len(self._ids)} ids but {len(z)} height ranges")
            self._z = z

    def __len__(self) -> int:
        return len(self._ids)

    def locate(self, x: float, y: float, z: float | None = None) -> int | None:
        """Id of the cell containing ``(x, y[, z])``, or ``None`` outside every cell."""
        pt = [[x, y]] if z is None else [[x, y, z]]
        cid = int(self.locate_many(np.array(pt, dtype=np.float64))[0])
        return None if cid < 0 else cid

    def locate_many(self, xy: ArrayLike) -> NDArray[np.int64]:
        """Cell ids of many points.

        Parameters
        ----------
        xy : (k, 2) or (k, 3) float
            Points, scene-local metres; a third column is the height, used when the
            locator has height ranges.

        Returns
        -------
        (k,) int64
            Cell ids, ``-1`` for points outside every cell.
        """
        arr = np.asarray(xy, dtype=np.float64)
        cols = arr.shape[-1] if arr.ndim == 2 and arr.shape[-1] in (2, 3) else 2
        arr = arr.reshape(-1, cols)
        pts = arr[:, :2]
        out = np.full(len(pts), -1, np.int64)
        if len(pts) == 0 or len(self._ids) == 0:
            return out
        p, t = self._tree.query(shapely.points(pts), predicate="dwithin", distance=LOCATE_TOL)
        if self._z is not None and cols == 3 and len(p):
            z = arr[p, 2]
            keep = (z >= self._z[t, 0] - LOCATE_TOL) & (z < self._z[t, 1])
            p, t = p[keep], t[keep]
        if len(p):
            big = np.iinfo(np.int64).max
            best = np.full(len(pts), big, np.int64)
            np.minimum.at(best, p, self._ids[t])
            hit = best != big
            out[hit] = best[hit]
        return out


def inside_convex(poly: NDArray[np.float64], pts: ArrayLike) -> NDArray[np.bool_]:
    """Whether each point lies in the convex polygon ``poly`` (boundary included).

    Works for either orientation.  ``pts`` is ``(m, 2)``; returns ``(m,)`` bool.

    >>> square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    >>> inside_convex(square, [[0.5, 0.5], [1.0, 0.5], [1.5, 0.5]]).tolist()
    [True, True, False]
    """
    p = np.asarray(pts, dtype=np.float64).reshape(-1, 2)
    a = poly
    b = np.roll(poly, -1, axis=0)
    e = b - a  # (n, 2)
    # cross of every edge with every (point - edge start): (m, n)
    cr = e[None, :, 0] * (p[:, None, 1] - a[None, :, 1]) - e[None, :, 1] * (
        p[:, None, 0] - a[None, :, 0]
    )
    scale = INSIDE_TOL * max(1.0, float(np.abs(poly).max()))
    return np.all(cr >= -scale, axis=1) | np.all(cr <= scale, axis=1)
