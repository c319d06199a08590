"""The cells the client knows about, which one the viewer is in, and the graph between them.

The client learns cells from the cell index (:class:`~walkstream.shared.wire.CellIndex`),
tile by tile: every cell's convex outline, eye-height range and neighbours.  With
the tiles around it the client follows the viewer from cell to cell and sees the
cells ahead without asking the server.  A tile can be forgotten again (the cache
evicted it); its cells' outlines go with it, their ids stay known as neighbours of
the cells that remain.

The viewer keeps the last cell it was known to be in when it steps outside all
cells, and a point on the shared boundary of two cells stays in the cell it was
already in (the outline test is inclusive), so the current cell never flickers.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.shared.arrays import F64
from walkstream.shared.cells import INSIDE_TOL, inside_convex
from walkstream.shared.scene.cellkinds import CELL_KINDS, visibility_of

__all__ = ["CellMap", "nearest_point", "portal_between"]

Tile = tuple[int, int] | None


def portal_between(a: F64, b: F64, tol: float = 0.05) -> F64:
    """The segment two adjacent convex outlines share: ``(2, 2)``, its end points.

    The longest overlap of an edge of ``a`` with an edge of ``b`` lying on the same
    line (within ``tol`` metres); outlines that only touch (or, after centimetre
    rounding, miss each other by a hair) give the segment between their two
    closest vertices; outlines that overlap (sections may) give the long axis of their
    overlap through its centre.

    >>> a = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [0.0, 1.0]])
    >>> b = np.array([[2.0, 0.5], [3.0, 0.5], [3.0, 2.0], [2.0, 2.0]])
    >>> portal_between(a, b).tolist()
    [[2.0, 0.5], [2.0, 1.0]]
    """
    a0, a1 = a, np.roll(a, -1, axis=0)
    b0, b1 = b, np.roll(b, -1, axis=0)
    d = a1 - a0  # (n, 2)
    length = np.hypot(d[:, 0], d[:, 1])
    ok = length > 1e-9
    u = np.zeros_like(d)
    u[ok] = d[ok] / length[ok, None]

    # distance of b's edge end points from each of a's edge lines: (n, m)
    def off(p: F64) -> NDArray[np.float64]:
        rel = p[None, :, :] - a0[:, None, :]
        out: NDArray[np.float64] = np.abs(u[:, None, 0] * rel[..., 1] - u[:, None, 1] * rel[..., 0])
        return out

    on_line = (off(b0) <= tol) & (off(b1) <= tol) & ok[:, None]
    best, seg = 0.0, None
    if on_line.any():
        for i, j in zip(*np.nonzero(on_line), strict=True):
            t0 = float(np.dot(b0[j] - a0[i], u[i]))
            t1 = float(np.dot(b1[j] - a0[i], u[i]))
            lo, hi = max(0.0, min(t0, t1)), min(float(length[i]), max(t0, t1))
            if hi - lo > best:
                best = hi - lo
                seg = np.stack([a0[i] + lo * u[i], a0[i] + hi * u[i]])
    if seg is not None:
        return seg
    over = _overlap(a, b)
    if over is not None:
        # overlapping cells (sections overlap where they add field points): the
        # overlap's long axis through its centre, where the way from one into the
        # other runs (two closest vertices could be a far corner of a long overlap)
        c = over.mean(axis=0)
        rel = over - c
        w, v = np.linalg.eigh(rel.T @ rel)
        u = v[:, int(np.argmax(w))]
        t = rel @ u
        return np.stack([c + float(t.min()) * u, c + float(t.max()) * u])
    dd = np.hypot(*(a[:, None, :] - b[None, :, :]).transpose(2, 0, 1))
    i, j = np.unravel_index(np.argmin(dd), dd.shape)
    p = (a[i] + b[j]) / 2.0
    return np.stack([p, p])


def _overlap(a: F64, b: F64, min_area: float = 1e-4) -> F64 | None:
    """The vertices of the overlap of two convex outlines (``a`` clipped by each edge of
    ``b``), or None when they overlap by less than ``min_area`` square metres."""
    sb = 1.0 if _area2(b) >= 0 else -1.0
    poly = a
    for p0, p1 in zip(b, np.roll(b, -1, axis=0), strict=True):
        if len(poly) == 0:
            return None
        e = p1 - p0
        side = sb * (e[0] * (poly[:, 1] - p0[1]) - e[1] * (poly[:, 0] - p0[0]))  # >= 0: inside
        out: list[F64] = []
        for k in range(len(poly)):
            q0, q1, s0, s1 = poly[k], poly[(k + 1) % len(poly)], side[k], side[(k + 1) % len(poly)]
            if s0 >= 0:
                out.append(q0)
            if (s0 >= 0) != (s1 >= 0):
                out.append(q0 + (q1 - q0) * (s0 / (s0 - s1)))
        poly = np.array(out).reshape(-1, 2)
    if len(poly) < 3 or abs(_area2(poly)) / 2.0 < min_area:
        return None
    return poly


def _area2(p: F64) -> float:
    return float(np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1]))


class CellMap:
    """Outlines and adjacency of the cells of the index tiles held.

    The outlines are also kept stacked (padded to the longest) so that many points
    are tested against every known cell in one vectorised step.

    Attributes
    ----------
    outlines : dict
        Cell id -> ``(m, 2)`` outline, for the cells of the tiles held.
    neighbours : dict
        Cell id -> ids of its neighbours (some may be in tiles not held).
    kinds : dict
        Cell id -> kind.
    tiles : dict
        Tile -> ids of its cells.
    tile_of : dict
        Cell id -> its tile, for the cells held.
    current : int or None
        The cell the viewer is in (or was last in).
    """

    def __init__(self) -> None:
        self.outlines: dict[int, F64] = {}
        self.neighbours: dict[int, tuple[int, ...]] = {}
        self.kinds: dict[int, str] = {}
        self.tiles: dict[Tile, tuple[int, ...]] = {}
        self.tile_of: dict[int, Tile] = {}
        self.current: int | None = None
        self._portals: dict[tuple[int, int], F64] = {}
        self._stack: tuple[NDArray[np.int64], F64, F64, F64] | None = None

    def add_cells(
        self,
        ids: Sequence[int],
        outlines: Sequence[F64],
        neighbours: Sequence[Sequence[int]],
        kinds: Sequence[str] | None = None,
        tile: Tile = None,
    ) -> None:
        """Learn cells: their outlines, neighbours and kinds, as those of ``tile``.

        Cells whose visible set is walked through portals
        (:func:`~walkstream.shared.scene.cellkinds.visibility_of`: a crossing scene's rooms) are left out: they are the room streamer's, and the
        map tracks the viewer over the cells with a PVS."""
        keep = [k for k in range(len(ids))
                if kinds is None or kinds[k] not in CELL_KINDS or visibility_of(kinds[k]) != "portals"]
        if len(keep) < len(ids):
            ids = [ids[k] for k in keep]
            outlines = [outlines[k] for k in keep]
            neighbours = [neighbours[k] for k in keep]
            kinds = [kinds[k] for k in keep] if kinds is not None else None
        ids = [int(c) for c in ids]
        for k, c in enumerate(ids):
            self.outlines[c] = np.asarray(outlines[k], dtype=np.float64).reshape(-1, 2)
            self.neighbours[c] = tuple(sorted(int(n) for n in neighbours[k]))
            self.kinds[c] = kinds[k] if kinds is not None else ""
            self.tile_of[c] = tile
        self.tiles[tile] = tuple(sorted(set(self.tiles.get(tile, ())) | set(ids)))
        self._stack = None

    def forget_tile(self, tile: Tile) -> list[int]:
        """Drop the cells of ``tile`` (its outlines, neighbours, portals); their ids."""
        ids = list(self.tiles.pop(tile, ()))
        gone = set(ids)
        for c in ids:
            self.outlines.pop(c, None)
            self.neighbours.pop(c, None)
            self.kinds.pop(c, None)
            self.tile_of.pop(c, None)
        self._portals = {k: v for k, v in self._portals.items() if not (set(k) & gone)}
        self._stack = None
        return ids

    def knows(self, cid: int) -> bool:
        """Whether cell ``cid``'s outline is held."""
        return cid in self.outlines

    def portal(self, a: int, b: int) -> F64:
        """The segment cells ``a`` and ``b`` share, ``(2, 2)`` (both must be held)."""
        key = (a, b) if a < b else (b, a)
        seg = self._portals.get(key)
        if seg is None:
            seg = portal_between(self.outlines[key[0]], self.outlines[key[1]])
            seg.flags.writeable = False
            self._portals[key] = seg
        return seg

    def _stacked(self) -> tuple[NDArray[np.int64], F64, F64, F64]:
        if self._stack is None:
            ids = np.array(sorted(self.outlines), dtype=np.int64)
            v = max((len(self.outlines[i]) for i in ids.tolist()), default=3)
            a = np.zeros((len(ids), v, 2))
            e = np.zeros((len(ids), v, 2))
            scale = np.zeros(len(ids))
            for k, i in enumerate(ids.tolist()):
                poly = self.outlines[i]
                n = len(poly)
                a[k, :n] = poly
                e[k, :n] = np.roll(poly, -1, axis=0) - poly
                # padding edges repeat the first vertex with a zero edge: always "on" it
                a[k, n:] = poly[0]
                scale[k] = INSIDE_TOL * max(1.0, float(np.abs(poly).max()))
            self._stack = (ids, a, e, scale)
        return self._stack

    def inside_all(self, pts: ArrayLike) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
        """``(ids, inside)``: every known cell id (ascending) and an (m, n) containment matrix."""
        ids, a, e, scale = self._stacked()
        p = np.asarray(pts, dtype=np.float64).reshape(-1, 2)
        if len(ids) == 0:
            return ids, np.zeros((len(p), 0), dtype=bool)
        d = p[:, None, None, :] - a[None, :, :, :]  # (m, n, v, 2)
        cr = e[None, :, :, 0] * d[..., 1] - e[None, :, :, 1] * d[..., 0]
        s = scale[None, :, None]
        inside = np.all(cr >= -s, axis=2) | np.all(cr <= s, axis=2)
        return ids, inside

    def find(self, xy: ArrayLike, prefer: int | None = None) -> int | None:
        """A known cell containing ``xy``: ``prefer`` if it does, then its neighbours, then any."""
        p = np.asarray(xy, dtype=np.float64).reshape(1, 2)
        if prefer is not None and prefer in self.outlines:
            if inside_convex(self.outlines[prefer], p)[0]:
                return prefer
            for n in self.neighbours.get(prefer, ()):
                if n in self.outlines and inside_convex(self.outlines[n], p)[0]:
                    return n
        ids, inside = self.inside_all(p)
        hit = np.flatnonzero(inside[0])
        return int(ids[hit[0]]) if len(hit) else None

    def find_along(self, pts: ArrayLike, start: int | None) -> list[int | None]:
        """The cell of each point of a track: stay in the previous point's cell while it
        contains the point (so boundaries do not flicker), else the lowest id containing it."""
        ids, inside = self.inside_all(pts)
        col = {int(i): k for k, i in enumerate(ids.tolist())}
        out: list[int | None] = []
        last = start
        for row in inside:
            if last is not None and last in col and row[col[last]]:
                out.append(last)
                continue
            hit = np.flatnonzero(row)
            last = int(ids[hit[0]]) if len(hit) else None
            out.append(last)
        return out

    def update(self, xy: ArrayLike) -> tuple[int | None, bool]:
        """Move the viewer to ``xy``: ``(current cell, found)``.

        ``found`` is False when ``xy`` is outside every known outline; the current
        cell is then kept (the last known one).
        """
        cid = self.find(xy, self.current)
        if cid is None:
            return self.current, False
        self.current = cid
        return cid, True

    def distance_to(self, cid: int, xy: ArrayLike) -> float:
        """Distance from ``xy`` to cell ``cid``'s outline (0 inside); inf if unknown."""
        poly = self.outlines.get(cid)
        if poly is None:
            return float("inf")
        p = np.asarray(xy, dtype=np.float64).reshape(2)
        return float(np.hypot(*(nearest_point(poly, p) - p)))


def nearest_point(poly: F64, xy: ArrayLike) -> NDArray[np.float64]:
    """``(2,)`` the point of the convex outline ``poly`` ``(n, 2)`` nearest ``xy`` ``(2,)``:
    ``xy`` itself when inside, else the nearest point of its boundary (where a walker
    coming from ``xy`` enters the cell)."""
    p = np.asarray(xy, dtype=np.float64).reshape(2)
    if inside_convex(poly, p[None, :])[0]:
        return p
    a = np.asarray(poly, np.float64)
    ab = np.roll(a, -1, axis=0) - a
    t = np.clip(np.einsum("ij,ij->i", p - a, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-12), 0.0, 1.0)
    q = a + t[:, None] * ab
    out: NDArray[np.float64] = q[int(np.argmin(np.einsum("ij,ij->i", q - p, q - p)))]
    return out
