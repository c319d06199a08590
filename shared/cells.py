"""View cells as both sides see them: convex outlines, and which cell holds a point.

The bake cuts a scene into cells (:mod:`walkstream.server.bake`), the store keeps
them, the service answers ``locate`` with :class:`CellLocator` and sends the cells'
outlines and adjacency tile by tile (the cell index, tiles of a :class:`TileGrid`),
and the client follows the viewer from outline to outline with :func:`inside_convex`.
The kinds of cell and their visibility models are :mod:`walkstream.shared.scene.cellkinds`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import shapely
from numpy.typing import ArrayLike, NDArray

from walkstream.shared.errors import InputError
from walkstream.shared.scene.cellkinds import cell_kind

__all__ = [
    "INSIDE_TOL",
    "LOCATE_TOL",
    "CellLocator",
    "TileGrid",
    "inside_convex",
    "outline_polygons",
]

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

    @classmethod
    def of_kinds(
        cls, ids: ArrayLike, kinds: Sequence[str], outlines: Sequence[ArrayLike], zranges: ArrayLike
    ) -> CellLocator:
        """A locator of the cells a viewer can stand in, each located as its kind says.

        Cells of a kind no viewer is located in (``outside``) are left out; cells of a
        kind located in 3D (interior cells, which stack storeys) hold a point by their
        height range too, the others (street and grid cells) at any height.  A scene
        with no cell located in 3D gets a 2D locator, as a city always had.

        Parameters
        ----------
        ids : (n,) int
            Cell ids.
        kinds : sequence of str
            Each cell's kind (:data:`~walkstream.shared.scene.cellkinds.CELL_KINDS`).
        outlines : sequence of (m_i, 2) float
            The cells' outlines.
        zranges : (n, 2) float
            ``zmin, zmax`` of each cell.

        >>> sq, street = [[0, 0], [1, 0], [1, 1], [0, 1]], [[1, 0], [2, 0], [2, 1], [1, 1]]
        >>> loc = CellLocator.of_kinds([1, 2, 3], ["street", "room", "room"], [street, sq, sq],
        ...                            [[0, 0], [0, 3], [3, 6]])
        >>> loc.locate(1.5, 0.5, 9.0), loc.locate(0.5, 0.5, 1.0), loc.locate(0.5, 0.5, 4.0)
        (1, 2, 3)
        """
        i = np.asarray(ids, dtype=np.int64).reshape(-1)
        z = np.asarray(zranges, dtype=np.float64).reshape(-1, 2)
        if not len(i) == len(kinds) == len(outlines) == len(z):
            raise InputError(
                f"CellLocator: {len(i)} ids, {len(kinds)} kinds, {len(outlines)} outlines, {len(z)} height ranges"
            )
        models = [cell_kind(k) for k in kinds]
        keep = [n for n, m in enumerate(models) if m.locatable]
        in_3d = any(models[n].located_in_3d for n in keep)
        ranges = [z[n] if models[n].located_in_3d else [-math.inf, math.inf] for n in keep]
        return cls(i[keep], [outlines[n] for n in keep], ranges if in_3d else None)

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


@dataclass(frozen=True, slots=True)
class TileGrid:
    """The square tiles the cell index of a scene is cut into.

    Each cell belongs to exactly one tile (the one holding the mean of its
    outline's vertices); ``reach_m`` bounds how far any cell's outline pokes out of
    its tile's square, so a point can lie only in cells of the tiles whose squares
    are within ``reach_m`` of it (:meth:`tiles_near`).  A scene small enough for
    one index has a ``(1, 1)`` grid.

    Attributes
    ----------
    origin : (2,) float
        South-west corner of tile ``(0, 0)``, scene-local metres.
    tile_m : float
        Side of a tile, metres (> 0).
    shape : (2,) int
        Tiles along x and y (each >= 1).
    reach_m : float
        Largest distance from a cell's outline to its tile's square, metres.
    """

    origin: tuple[float, float]
    tile_m: float
    shape: tuple[int, int]
    reach_m: float

    def __post_init__(self) -> None:
        vals = (*self.origin, self.tile_m, self.reach_m)
        if not all(math.isfinite(v) for v in vals) or self.tile_m <= 0 or self.reach_m < 0:
            raise InputError(f"tile grid: bad origin, tile size or reach {vals}")
        if len(self.shape) != 2 or min(self.shape) < 1 or max(self.shape) > 1 << 16:
            raise InputError(f"tile grid: shape {self.shape} must be two counts in [1, 65536]")

    @property
    def count(self) -> int:
        """Number of tiles."""
        return self.shape[0] * self.shape[1]

    def tile_of(self, xy: ArrayLike) -> tuple[int, int]:
        """The tile whose square holds ``xy`` (clamped to the grid).

        >>> TileGrid((0.0, 0.0), 100.0, (3, 2), 5.0).tile_of([250.0, -10.0])
        (2, 0)
        """
        i, j = self.tiles_of(np.asarray(xy, dtype=np.float64).reshape(1, 2))[0].tolist()
        return int(i), int(j)

    def tiles_of(self, xy: ArrayLike) -> NDArray[np.int64]:
        """Tile index ``(i, j)`` of many points, clamped: ``(k, 2)`` int64 for ``(k, 2)`` points."""
        p = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        hi = np.asarray(self.shape, dtype=np.float64) - 1.0
        # clip before the cast: points far off the grid (or not finite) give edge tiles
        f = np.nan_to_num(np.floor((p - np.asarray(self.origin)) / self.tile_m), nan=0.0)
        out: NDArray[np.int64] = np.clip(f, 0.0, hi).astype(np.int64)
        return out

    def square(self, i: int, j: int) -> tuple[float, float, float, float]:
        """``(minx, miny, maxx, maxy)`` of tile ``(i, j)``."""
        x0 = self.origin[0] + i * self.tile_m
        y0 = self.origin[1] + j * self.tile_m
        return (x0, y0, x0 + self.tile_m, y0 + self.tile_m)

    def tiles_near(self, xy: ArrayLike, radius: float = 0.0) -> list[tuple[float, tuple[int, int]]]:
        """``(distance, tile)`` of the tiles that may hold a cell within ``radius`` of ``xy``.

        Those whose square is within ``radius + reach_m`` of the point, nearest
        first (distance 0 for the tile holding it).

        >>> g = TileGrid((0.0, 0.0), 100.0, (3, 3), 10.0)
        >>> [t for _, t in g.tiles_near([150.0, 150.0])]
        [(1, 1)]
        >>> [t for _, t in g.tiles_near([195.0, 150.0])]
        [(1, 1), (2, 1)]
        """
        p = np.asarray(xy, dtype=np.float64).reshape(2)
        r = max(0.0, float(radius)) + self.reach_m
        if not (np.isfinite(p).all() and math.isfinite(r)):
            return []
        top = np.asarray(self.shape, dtype=np.float64) - 1.0
        o = np.asarray(self.origin)
        # clip before the cast: far-off points give (at most) edge tiles, never overflow
        lo = np.clip(np.floor((p - r - o) / self.tile_m), -1.0, top + 1.0).astype(np.int64)
        hi = np.clip(np.floor((p + r - o) / self.tile_m), -1.0, top + 1.0).astype(np.int64)
        lo = np.maximum(lo, 0)
        hi = np.minimum(hi, np.asarray(self.shape) - 1)
        out = []
        for i in range(int(lo[0]), int(hi[0]) + 1):
            for j in range(int(lo[1]), int(hi[1]) + 1):
                x0, y0, x1, y1 = self.square(i, j)
                dx = max(x0 - p[0], 0.0, p[0] - x1)
                dy = max(y0 - p[1], 0.0, p[1] - y1)
                d = math.hypot(dx, dy)
                if d <= r:
                    out.append((d, (i, j)))
        out.sort()
        return out
