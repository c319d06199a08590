"""Every cell's triangles in one array, for the kept parts' triangle test (:mod:`.trianglecull`).

The triangle test takes a frame's candidate triangles from several cells.  Taken cell
by cell, each cell cost some ten numpy calls (its parts' runs, their gather, the
joins), more than its triangles' arithmetic at a tour's few hundred.  A
:class:`TriangleTable` holds the triangles of every cell it has been handed,
coordinate-major in one array (each cell's parts one after another, each part a run),
and per part its run, its box and whether it is a stand-in, numbered across the
cells: a frame's candidates of all its cells are gathered by one index.

It also keeps per part the **witness**: the place in its run of a triangle that showed
the last time the part was tested (or -1).  The triangle test tries a part's witness
first; a part shows when any of its triangles does, and each triangle's test is its
own (:func:`~walkstream.shared.trianglecull.refine_parts`), so a witness that shows
again proves the part kept, and one that does not sends the part to the test of all its
triangles: the parts kept are the same, the triangles tested fewer (the eye moves a
few centimetres a frame, and a part seen stays seen through the same triangle).

A cell is placed once (by the mesh's identity; the table holds the mesh, so an identity
is never reused while placed).  The array grows as cells come; when it would grow
while holding more than twice the triangles of the cells a frame asks for (cells the
walk left, or replaced by a whole one after their head), it is made anew from those
cells alone.  One table per thread (:func:`thread_table`).
"""

from __future__ import annotations

import threading
from collections.abc import Sequence
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

__all__ = ["TriangleTable", "pack_cell", "thread_table"]


class _Mesh(Protocol):
    @property
    def parts(self) -> tuple[Any, ...]: ...  # CellPart: positions (n, 3), indices (m, 3)

    @property
    def missing(self) -> tuple[int, ...]: ...


def pack_cell(mesh: _Mesh) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]:
    """A cell's triangles coordinate-major ``(3, 3, T)`` (``[j, k, t]``: coordinate ``j`` of
    vertex ``k`` of triangle ``t``), where each part's begin ``(parts + 1,)``, and the
    parts' boxes ``(parts, 3)`` (lower, upper) of their triangles' vertices (zeros for a
    part without triangles).  All parts in one gather and one reduction each (a cell of
    30 parts cost 0.5 ms part by part, the tail of the triangle test's frames)."""
    pos = [np.asarray(p.positions, np.float64).reshape(-1, 3) for p in mesh.parts]
    idx = [np.asarray(p.indices, np.int64).reshape(-1, 3) for p in mesh.parts]
    counts = np.array([len(i) for i in idx], np.int64)
    start = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    lo = np.zeros((len(idx), 3))
    hi = np.zeros((len(idx), 3))
    if not int(start[-1]):
        return np.zeros((3, 3, 0)), start, lo, hi
    # each part's indices moved past the parts' vertices before it: one gather for all
    offset = np.cumsum([0, *map(len, pos[:-1])])
    tri = np.concatenate(pos)[np.concatenate(idx) + np.repeat(offset, counts)[:, None]]  # (T, 3, 3)
    some = np.flatnonzero(counts)  # the parts with triangles: their runs of vertices one after another
    at = 3 * start[some]
    vertices = tri.reshape(-1, 3)
    lo[some] = np.minimum.reduceat(vertices, at, axis=0)
    hi[some] = np.maximum.reduceat(vertices, at, axis=0)
    return np.ascontiguousarray(tri.transpose(2, 1, 0)), start, lo, hi


class TriangleTable:
    """The triangles of the cells handed to :meth:`place`, and their parts (module docstring).

    Attributes
    ----------
    tri : (3, 3, capacity) float64
        The triangles, coordinate-major (the first :attr:`used` are valid).
    start, count : (parts,) int64
        Each part's first triangle in :attr:`tri` and its number of triangles.
    lo, hi : (parts, 3) float64
        Each part's box (of its triangles' vertices).
    stand_in : (parts,) bool
        A head's stand-in (:attr:`~walkstream.shared.codec.cellmesh.CellMesh.missing`).
    witness : (parts,) int64
        The place in its run of the triangle that showed when the part was last tested, or -1.
    """

    def __init__(self) -> None:
        self.tri = np.zeros((3, 3, 0))
        self.used = 0
        self.start = np.zeros(0, np.int64)
        self.count = np.zeros(0, np.int64)
        self.lo = np.zeros((0, 3))
        self.hi = np.zeros((0, 3))
        self.stand_in = np.zeros(0, bool)
        self.witness = np.zeros(0, np.int64)
        self._slot: dict[int, tuple[_Mesh, int, int]] = {}  # id(mesh) -> (mesh, first part, triangles)

    @property
    def parts(self) -> int:
        """Parts placed."""
        return len(self.start)

    def place(self, meshes: Sequence[_Mesh]) -> list[int]:
        """Each mesh's first part in the table (its parts are numbered on from there),
        placing those not in it yet."""
        slot = self._slot
        got = [slot.get(id(m)) for m in meshes]
        if all(s is not None and s[0] is m for s, m in zip(got, meshes, strict=True)):
            return [s[1] for s in got if s is not None]
        packs = {id(m): (m, pack_cell(m)) for s, m in zip(got, meshes, strict=True) if s is None or s[0] is not m}
        new = sum(p[0].shape[2] for _m, p in packs.values())
        if self.used + new > self.tri.shape[2]:
            live = new + sum(s[2] for s, m in zip(got, meshes, strict=True) if s is not None and s[0] is m)
            if self.used > 2 * live:  # mostly cells no frame asks for now: made anew from these
                keep = {id(m): m for m in meshes if id(m) not in packs}
                self.__init__()  # type: ignore[misc]
                packs = {k: (m, pack_cell(m)) for k, m in keep.items()} | packs
                new = sum(p[0].shape[2] for _m, p in packs.values())
            grown = np.empty((3, 3, max(self.used + new, 2 * self.tri.shape[2], 4096)))
            grown[:, :, :self.used] = self.tri[:, :, :self.used]
            self.tri = grown
        starts, counts, los, his, stands = [self.start], [self.count], [self.lo], [self.hi], [self.stand_in]
        first = len(self.start)
        for key, (m, (tri, start, lo, hi)) in packs.items():
            t = tri.shape[2]
            self.tri[:, :, self.used:self.used + t] = tri
            starts.append(start[:-1] + self.used)
            counts.append(np.diff(start))
            los.append(lo)
            his.append(hi)
            stand = np.zeros(len(lo), bool)
            if m.missing:
                stand[np.asarray(m.missing, np.int64)] = True
            stands.append(stand)
            self._slot[key] = (m, first, t)
            first += len(lo)
            self.used += t
        self.start = np.concatenate(starts)
        self.count = np.concatenate(counts)
        self.lo = np.concatenate(los).reshape(-1, 3)
        self.hi = np.concatenate(his).reshape(-1, 3)
        self.stand_in = np.concatenate(stands)
        self.witness = np.concatenate([self.witness, np.full(len(self.start) - len(self.witness), -1, np.int64)])
        return [self._slot[id(m)][1] for m in meshes]


_LOCAL = threading.local()


def thread_table() -> TriangleTable:
    """The calling thread's :class:`TriangleTable` (made on first use)."""
    got: TriangleTable | None = getattr(_LOCAL, "table", None)
    if got is None:
        got = _LOCAL.table = TriangleTable()
    return got
