"""Parts kept by their boxes, tested again by their triangles (portal culling's step 5, refined).

The parts culling (:mod:`walkstream.shared.partcull`) keeps a part when its box's
rectangle meets one of its cell's visible screen areas (VSAs).  A box is a loose
stand-in for what it holds: a chair whose box touches a corner of the view while none of
its triangles does, a stair stringer's box reaching round a door's edge, a railing's
balusters edge-on whose box spans pixels that none of their thin triangles covers.  The
triangles of such a part draw nothing, yet the whole part was drawn (on the duplex's
frames facing a wall, 124 triangles drawn for 8 seen).

:func:`refine_parts` takes the parts the box test kept, of at least
:data:`MIN_TRIANGLES` triangles, whose box's rectangle is not well inside one of the
cell's VSAs (:data:`WIDE_PX`), and tests their triangles one by one: each triangle is
clipped at the box test's clip plane and projected; it may draw a pixel of its cell when
its rectangle of pixel centres (the same rule and margin as every rectangle of
:mod:`walkstream.shared.screenrects`) meets one of the cell's VSAs, none of its three
sides' normals separates it from that meeting, and its depths reach between the near and
far planes.  A part none of whose triangles passes is dropped.  It is as conservative as
the box test: a rasteriser draws a pixel only where the pixel's centre is inside a
triangle, a cell shows only inside its VSAs, and a separating axis proves a triangle
(grown by the margin) and a rectangle of centres apart; a rectangle with no pixel centre
(a sliver under a pixel) draws nothing at all.  It only ever drops parts the boxes kept,
never adds one.  (The duplex's tour, 160x120, every 50th frame against the truth:
tightness p95 5.51 -> 2.21, 0 culled pixels either way.)

A head's stand-ins (:attr:`~walkstream.shared.codec.cellmesh.CellMesh.missing`: boxes
with no triangles yet) are never dropped: they stand for triangles still to come.

Cost: every candidate triangle of the frame in one batch (the triangles of each cell
packed once, coordinate-major, and kept with the cell's mesh; a part's triangles taken
as its run, not by a pass over the whole cell), about 2.5 times the boxes' own test per
frame on the duplex's and FZK-Haus's tours (``walkstream bench portals --triangles``).
Parts under :data:`MIN_TRIANGLES` cost less to draw than to test and are left as the
boxes decided.  The work per triangle is cut without changing a figure: a triangle
wholly in front of the clip plane is projected as its three vertices (its sides' six
ends are those, twice), the few across the plane are clipped in plain floats, the
sides' separating test is made only for the (triangle, VSA) pairs whose rectangles
meet, and a frame of more than :data:`_ONE_ROUND` candidate triangles tests each part's
first :data:`_FIRST_ROUND` first and the rest only of the parts none of whose first
showed (a part shows when any of its triangles does, so the same parts are kept).  On
the tours' frames of several thousand triangles this takes the test's p99 from 13-16 ms
to about 5 ms (tests/test_trianglecull.py checks the paths against each other).

The frame's candidates of all its cells are gathered by one index from a
:class:`~walkstream.shared.tritable.TriangleTable` (every cell's triangles in one array,
placed once), not cell by cell, and each part's **witness** (a triangle that showed the
last time the part was tested) is tried first: a witness that shows again proves the
part kept, one that does not sends the part to the test of all its triangles, so the
parts kept are the same and a frame tests about one triangle per part seen.  The box
rectangles are the parts culling's where it made them the same way
(:class:`~walkstream.shared.partcull.PartRects`); only the candidates across the clip
plane are clipped here.  (The tours' captured calls: median 1.20-1.32 -> 0.63-0.70 ms,
p99 4.0-4.2 -> 2.0 ms, the same parts on every call; docs/benchmarks.md.)

The frame's loops are compiled (:mod:`walkstream.shared.trianglekernels`, numba): the
candidates' gather, the rectangles of the boxes across the clip plane, each triangle's
clip, rectangle and sides' test against its VSAs, and the witnesses' rounds, with the
figures of the numpy version (``tests/trianglereference.py``, the reference the tests
check the kernels against), operation for operation.  What is left here is the
frame's bookkeeping: the cells placed in the table, their VSAs, the masks changed.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.shared.partcull import PartRects, near_far
from walkstream.shared.screenrects import (
    BOX_EDGES,
    CENTRE_MARGIN_PX,
    box_corners_ckm,
    rects_ckm,
)
from walkstream.shared.trianglekernels import candidates, take_rects, test_parts
from walkstream.shared.tritable import pack_cell, thread_table

__all__ = ["MIN_TRIANGLES", "WIDE_PX", "TRIANGLE_EDGES", "cell_triangles", "refine_parts"]

#: Parts with fewer triangles are left as the box test decided (cheaper to draw than to test).
MIN_TRIANGLES = 16

#: A kept part whose box's rectangle lies inside one of its cell's VSAs and is at least this
#: many pixel centres wide and high is left as the box test decided (its triangles mostly
#: draw there: the test is not worth its time); only the others -- boxes across a VSA's
#: edge, thin or under a few pixels -- are tested triangle by triangle.
WIDE_PX = 4

#: Candidate triangles up to which a frame tests them all in one batch; above, each part's
#: first :data:`_FIRST_ROUND` triangles are tested first and the rest only of the parts
#: none of whose first showed (a part with many triangles mostly shows by its first).
_ONE_ROUND = 1024
_FIRST_ROUND = 32

#: A triangle's sides as index pairs into its three vertices.
TRIANGLE_EDGES = np.array([[0, 1], [1, 2], [2, 0]], np.int64)

class _Mesh(Protocol):
    @property
    def parts(self) -> tuple[Any, ...]: ...  # CellPart: positions (n, 3), indices (m, 3)

    @property
    def missing(self) -> tuple[int, ...]: ...

    @property
    def _cache(self) -> dict[str, Any]: ...


def cell_triangles(mesh: _Mesh) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """A cell's triangles packed coordinate-major, and where each part's begin (cached on ``mesh``).

    Parameters
    ----------
    mesh : CellMesh
        A decoded cell (:class:`~walkstream.shared.codec.cellmesh.CellMesh`).

    Returns
    -------
    tri : (3, 3, T) float64
        ``tri[j, k, t]``: coordinate ``j`` of vertex ``k`` of triangle ``t``, the parts'
        triangles one after another.
    start : (parts + 1,) int64
        Part ``i``'s triangles are ``tri[:, :, start[i]:start[i + 1]]``.
    """
    tri, start, _lo, _hi = _packed(mesh)
    return tri, start


def _packed(mesh: _Mesh) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]:
    """:func:`~walkstream.shared.tritable.pack_cell` of ``mesh``, made once per mesh."""
    got = mesh._cache.get("triangles_ckm")
    if got is None:
        got = mesh._cache["triangles_ckm"] = pack_cell(mesh)
    return got


def refine_parts(
    masks: dict[int, NDArray[np.bool_]],
    meshes: Mapping[int, _Mesh],
    vsas: Mapping[int, list[tuple[int, int, int, int]]],
    view: ArrayLike,
    proj: ArrayLike,
    size: tuple[int, int],
    *,
    clip_m: float = 0.03,
    min_triangles: int = MIN_TRIANGLES,
    rects: PartRects | None = None,
) -> int:
    """Drop, in place, the kept parts none of whose triangles meets its cell's VSAs.

    Parameters
    ----------
    masks : dict of int -> (parts,) bool
        Per cell, the parts the box test kept (:func:`~walkstream.shared.partcull.cull_parts`
        in ``portals`` mode); changed in place.
    meshes : mapping of int -> CellMesh
        The cells' decoded contents (a cell not here is left alone).
    vsas : mapping of int -> list of (x0, y0, x1, y1)
        Per cell its VSAs (a cell without is left alone).
    view, proj : (4, 4) float
    size : (int, int)
    clip_m : float
        The clip plane of the rectangles (as the box test's).
    min_triangles : int
        Parts with fewer triangles are left alone.
    rects : PartRects, optional
        The parts culling's rectangles of this frame's boxes (``cull_parts(rects=...)``):
        those of the same boxes, made with the same camera wholly in front of the clip
        plane, are taken as they are; the others are made here.

    Returns
    -------
    int
        The number of parts dropped.
    """
    V, P = np.asarray(view, np.float64), np.asarray(proj, np.float64)
    planes = near_far(P)
    if planes is None:  # not a perspective projection (depth is not w): left as the boxes decided
        return 0
    # the cells to test: with VSAs, and decoded as the mask was made (else left as they are)
    cells = [c for c, m in masks.items() if vsas.get(c) and c in meshes and len(meshes[c].parts) == len(m)]
    if not cells:
        return 0
    table = thread_table()
    first = table.place([meshes[c] for c in cells])
    n = [len(masks[c]) for c in cells]
    # the candidates: kept parts of enough triangles, not stand-ins; each one's part in the
    # table, its cell (an index into ``cells``) and its place in its cell's mask
    part, owner, local = candidates(np.concatenate([masks[c] for c in cells]), np.asarray(first, np.int64),
                                    np.asarray(n, np.int64), table.stand_in, table.count, min_triangles)
    if not len(part):
        return 0
    lists = [vsas[c] for c in cells]
    kmax = max(map(len, lists))
    # (cells, kmax, 4): the cells' VSAs, padded with empty rectangles (never met)
    areas = np.array([list(v) + [(1, 1, 0, 0)] * (kmax - len(v)) for v in lists], np.int64)
    brect = np.ascontiguousarray(_box_rects(rects, cells, owner, local, table.lo[part], table.hi[part], V, P, size,
                                            clip_m), np.int64)  # (4, parts)
    # only the parts whose box is not wholly inside a VSA, or is thin there (a box well
    # inside one mostly holds triangles that draw there, and testing them cost 3 times
    # the rest of the culling on the duplex's tour), in two rounds: each part's witness
    # (a triangle that showed when it was last tested), or its triangles (its first
    # _FIRST_ROUND of a frame of many); then the rest of the parts not shown by the first
    # (a part shows when any of its triangles does, each triangle's test its own: the
    # same parts kept).  Compiled: the numpy version's figures (tests/trianglereference.py),
    # operation for operation (shared/trianglekernels.py).
    gone = test_parts(table.tri, table.start, table.count, table.witness, part, owner, brect, areas,
                      np.array([len(v) for v in lists], np.int64), (P @ V)[[0, 1, 3]], 0.5 * size[0], 0.5 * size[1],
                      clip_m, planes[0], planes[1], CENTRE_MARGIN_PX, WIDE_PX, _ONE_ROUND, _FIRST_ROUND)
    for k, i in zip(owner[gone].tolist(), local[gone].tolist(), strict=True):
        masks[cells[k]][i] = False
    return len(gone)


def _box_rects(
    rects: PartRects | None,
    cells: list[int],
    owner: NDArray[np.int64],
    local: NDArray[np.int64],
    lo: NDArray[np.float64],
    hi: NDArray[np.float64],
    view: NDArray[np.float64],
    proj: NDArray[np.float64],
    size: tuple[int, int],
    clip_m: float,
) -> NDArray[np.int64]:
    """The rectangles ``(4, n)`` of the candidates' boxes ``lo``, ``hi`` ``(n, 3)`` (part
    ``local`` of cell ``cells[owner]`` each), as
    :func:`~walkstream.shared.screenrects.box_rects` makes them: the parts culling's
    (``rects``) where it made them so for the same boxes, and those across the clip plane
    clipped as box_rects clips them; all made here otherwise."""
    if rects is not None and rects.made_for(view, proj, size, clip_m, CENTRE_MARGIN_PX):
        first = [rects.first.get(c, -1) for c in cells]
        if min(first) >= 0:
            row = np.asarray(first, np.int64)[owner] + local
            c = np.ascontiguousarray  # the layouts the kernel was compiled for (a no-op mostly)
            rect, taken = take_rects(c(rects.rect, np.int64), c(rects.exact), c(rects.crossing), c(rects.lo, np.float64),
                                     c(rects.hi, np.float64), row, c(lo), c(hi), c(view), c(proj), float(size[0]),
                                     float(size[1]), clip_m, CENTRE_MARGIN_PX)
            if taken:  # those across the clip plane clipped as box_rects clips them
                return rect
    return rects_ckm(box_corners_ckm(lo, hi), BOX_EDGES, view, proj, size, clip_m)[0]
