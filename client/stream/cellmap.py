"""The cells the client knows about, and which one the viewer is in.

A cell record carries its own convex outline and those of its neighbours, so the
client can follow the viewer from cell to cell without asking the server; it asks
(``locate``) only when the viewer is outside every outline it knows.  The viewer
keeps the last cell it was known to be in when it steps outside all cells, and a
point on the shared boundary of two cells stays in the cell it was already in
(the outline test is inclusive), so the current cell never flickers.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.shared.cells import INSIDE_TOL, inside_convex

__all__ = ["CellMap"]





class CellMap:
    """Outlines of the cells seen so far (fetched records and their neighbours).

    The outlines are also kept stacked (padded to the longest) so that many points
    are tested against every known cell in one vectorised step.
    """

    def __init__(self) -> None:
        self.outlines: dict[int, NDArray[np.float64]] = {}
        self.neighbours: dict[int, tuple[int, ...]] = {}
        self.current: int | None = None
        self._stack: (
            tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]
            | None
        ) = None

    def add_record(
        self, cid: int, boundary: NDArray[np.float64], neighbours: Mapping[int, NDArray[np.float64]]
    ) -> None:
        """Learn a fetched cell's outline and its neighbours' outlines."""
        self.outlines[cid] = boundary
        for n, b in neighbours.items():
            self.outlines.setdefault(n, b)
        self.neighbours[cid] = tuple(sorted(neighbours))
        self._stack = None

    def _stacked(
        self,
    ) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
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
                if inside_convex(self.outlines[n], p)[0]:
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
        cell is then kept (the last known one), and the caller may ask the server.
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
        if inside_convex(poly, p[None, :])[0]:
            return 0.0
        a = poly
        b = np.roll(poly, -1, axis=0)
        ab = b - a
        t = np.clip(
            np.einsum("ij,ij->i", p - a, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-12),
            0,
            1,
        )
        d = a + t[:, None] * ab - p
        return float(np.sqrt(np.min(np.einsum("ij,ij->i", d, d))))
