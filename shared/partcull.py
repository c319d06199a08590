"""The parts culling: which part boxes of each visible cell to draw (portal culling's step 5).

A visible cell's contents are culled by their boxes (:mod:`walkstream.shared.portals`, step
5): a box is kept when it comes within the fog distance, its clipped, projected rectangle
(:mod:`walkstream.shared.screenrects`) meets one of the cell's VSAs, and it lies between the
frustum's near and far planes.  :func:`cull_boxes` is that test for one cell, as plainly as
it can be written (the reference); :func:`cull_parts` gives every visible cell's answer at
once and must keep every box :func:`cull_boxes` keeps, and few more (tests/test_cullcpu.py,
tests/test_partcull.py).

Cost: at a couple of hundred visible cells a frame (an open hall) the per-cell Python and
numpy's calls, not the arithmetic, were most of the time (docs/benchmarks.md, "The
culling's CPU time").  So:

- the boxes of a scene are packed once into one array (a :class:`PartTable`, cached per
  ``boxes`` mapping and checked by identity: a cell whose ``(lo, hi)`` pair is not the one
  packed makes the table anew); a frame of a few cells (a tour's 4-40) joins its cells'
  arrays instead;
- every visible box is tested in one call of a compiled loop
  (:func:`~walkstream.shared.cullkernels.box_kernel`, numba): the fog, the box projected
  from its two corners with :func:`~walkstream.shared.screenrects.box_rects_ckm`'s
  arithmetic, its cell's VSAs, the near and far planes;
- a box that crosses the clip plane (a tour's frame has 70 or so, median: the walls,
  floor and furniture around the eye) is tested by an unclipped superset of its rectangle
  (:func:`~walkstream.shared.screenrects.crossing_rects`' figures): conservative, not the
  same, so this keeps every box :func:`cull_boxes` keeps and a few more (1.5 % on the
  generated offices' tours);
- the answer's per-cell slices are C-level maps over the cell lists, no Python statement
  per cell.

``walkstream bench portals --cull`` times it (:mod:`walkstream.benchmarks.cullcpu`).
"""

from __future__ import annotations

import math
import struct
from collections.abc import Mapping
from itertools import chain, repeat
from operator import is_not, itemgetter
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.shared.cullkernels import box_kernel
from walkstream.shared.errors import InputError
from walkstream.shared.frustum import frustum_cull
from walkstream.shared.portals import CULLING_MODES, box_distance
from walkstream.shared.screenrects import (
    CENTRE_MARGIN_PX,
    box_rects,
    camera_rows,
)

__all__ = ["PartTable", "PartRects", "part_table", "cull_parts", "cull_boxes", "near_far"]

Boxes = Mapping[int, tuple[NDArray[np.float64], NDArray[np.float64]]]


def cull_boxes(
    lo: ArrayLike,
    hi: ArrayLike,
    vsas: ArrayLike,
    eye: ArrayLike,
    view: ArrayLike,
    proj: ArrayLike,
    size: tuple[int, int],
    *,
    fog_m: float = math.inf,
    clip_m: float = 0.03,
) -> NDArray[np.bool_]:
    """Which of a cell's boxes to draw: within the fog, meeting one of its VSAs, in the frustum.

    Parameters
    ----------
    lo, hi : (n, 3) float
        The boxes of the cell's contents.
    vsas : (k, 4) int64
        The cell's VSAs (:attr:`~walkstream.shared.portals.PortalCull.vsas`).
    eye : (3,) float
    view, proj : (4, 4) float
    size : (int, int)
    fog_m, clip_m : float

    Returns
    -------
    (n,) bool
    """
    lo_ = np.asarray(lo, np.float64).reshape(-1, 3)
    hi_ = np.asarray(hi, np.float64).reshape(-1, 3)
    if len(lo_) == 0:
        return np.zeros(0, bool)
    e = np.asarray(eye, np.float64).reshape(3)
    keep = box_distance(lo_, hi_, e) <= fog_m
    rect, front = box_rects(lo_, hi_, view, proj, size, clip_m)
    v = np.asarray(vsas, np.int64).reshape(-1, 4)
    meet = _meet(rect[:, None, :], v[None, :, :])
    keep &= front & np.any(meet, axis=1)
    vp = np.asarray(proj, np.float64) @ np.asarray(view, np.float64)
    keep[keep] = frustum_cull(lo_[keep], hi_[keep], vp)
    return keep


def _meet(a: NDArray[np.int64], b: NDArray[np.int64]) -> NDArray[np.bool_]:
    """Whether whole-pixel rectangles ``(..., 4)`` share a pixel (broadcast); an empty one
    (``x0 > x1`` or ``y0 > y1``: no pixel centre) meets nothing."""
    return (
        (np.maximum(a[..., 0], b[..., 0]) <= np.minimum(a[..., 2], b[..., 2]))
        & (np.maximum(a[..., 1], b[..., 1]) <= np.minimum(a[..., 3], b[..., 3]))
    )


class PartTable:
    """A scene's part boxes packed once: every cell's boxes in one array.

    Attributes
    ----------
    lo, hi : (N, 3) float64
        Each box's lower and upper corner, the cells one after another.
    slot : dict of int -> int
        A cell id's index into ``start`` and ``count``.
    start, count : (cells,) int64
        Each cell's first box in ``lo``, ``hi`` and its number of boxes.
    src : dict of int -> (lo, hi)
        The pair each cell was packed from (a frame checks its cells against it by identity).
    """

    def __init__(self, boxes: Boxes) -> None:
        cells = list(boxes)
        self.src = {c: boxes[c] for c in cells}
        los = [np.asarray(boxes[c][0], np.float64).reshape(-1, 3) for c in cells]
        his = [np.asarray(boxes[c][1], np.float64).reshape(-1, 3) for c in cells]
        self.count = np.array([len(x) for x in los], np.int64)
        self.start = np.concatenate([[0], np.cumsum(self.count)[:-1]]).astype(np.int64)
        self.slot = {c: i for i, c in enumerate(cells)}
        self.lo = np.concatenate(los) if los else np.zeros((0, 3))
        self.hi = np.concatenate(his) if his else np.zeros((0, 3))

    def current(self, boxes: Boxes, cells: list[int]) -> bool:
        """Whether ``cells`` (all in ``boxes``) are packed from the pairs ``boxes`` holds now."""
        return not any(map(is_not, map(self.src.get, cells), map(boxes.__getitem__, cells)))


#: The tables of the last few ``boxes`` mappings (held, so that an id is never reused).
_TABLES: list[tuple[Boxes, PartTable]] = []


def part_table(boxes: Boxes, cells: list[int]) -> PartTable:
    """The :class:`PartTable` of ``boxes``, current for ``cells`` (made anew when one of their
    ``(lo, hi)`` pairs is not the one packed: a cell loaded, replaced or dropped and loaded
    again).  The arrays must not be changed in place once given."""
    for i, (b, t) in enumerate(_TABLES):
        if b is boxes:
            if t.current(boxes, cells):
                return t
            del _TABLES[i]
            break
    t = PartTable(boxes)
    _TABLES.insert(0, (boxes, t))
    del _TABLES[4:]
    return t


class PartRects:
    """The rectangles :func:`cull_parts` made for a frame's boxes, kept for the kept parts'
    triangle test (:func:`~walkstream.shared.trianglecull.refine_parts`), which tests
    again the parts whose box is not well inside a VSA and so needs the same rectangles.

    Handed to :func:`cull_parts` empty (``rects=``), filled by it with the rectangles
    :func:`~walkstream.shared.screenrects.box_rects` makes (as
    :func:`~walkstream.shared.screenrects.box_rects_ckm` makes them: but for the order of
    three additions in a corner's sums, the same; tests/test_partcull.py) on a frame of a
    few cells or of fewer than :data:`_FEW_BOXES` boxes, left empty otherwise.

    Attributes
    ----------
    view, proj : list of lists of float
        The camera the rectangles were made with (``tolist()`` of its arrays).
    size : (int, int)
    clip_m, margin_px : float
    first : dict of int -> int
        A cell's first row (its boxes' rows follow in order).
    rect : (4, rows) int64
        Each box's rectangle (rows ``x0, y0, x1, y1``), where :attr:`exact`.
    exact : (rows,) bool
        The box lay wholly in front of the clip plane and was projected: its rectangle is
        its clipped one (a box across the plane gets a superset, one beyond the fog none).
    crossing : (rows,) bool
        The box was projected and lies across the clip plane (its rectangle a superset).
    lo, hi : (rows, 3) float64
        The boxes.
    """

    def __init__(self) -> None:
        self.view: list[list[float]] = []
        self.proj: list[list[float]] = []
        self.size = (0, 0)
        self.clip_m = self.margin_px = 0.0
        self.first: dict[int, int] = {}
        self.rect = np.zeros((4, 0), np.int64)
        self.exact = self.crossing = np.zeros(0, bool)
        self.lo = self.hi = np.zeros((0, 3))

    def fill(self, view: NDArray[np.float64], proj: NDArray[np.float64], size: tuple[int, int], clip_m: float,
             margin_px: float, cells: list[int], counts: list[int], lo: NDArray[np.float64], hi: NDArray[np.float64],
             rows: NDArray[np.int64] | None, rect: NDArray[np.int64], near_d: NDArray[np.float64],
             far_d: NDArray[np.float64]) -> None:
        """Keep the rectangles ``rect`` ``(4, m)`` and nearest and farthest depths ``near_d``,
        ``far_d`` ``(m,)`` of the boxes ``rows`` (all when None) of ``lo``, ``hi`` (``cells``'
        boxes, ``counts`` each)."""
        self.view, self.proj, self.size = view.tolist(), proj.tolist(), size
        self.clip_m, self.margin_px = clip_m, margin_px
        self.first = dict(zip(cells, np.cumsum([0, *counts[:-1]]).tolist(), strict=True))
        self.lo, self.hi = lo, hi
        ahead = near_d >= clip_m
        crossing = ~ahead & (far_d >= clip_m)
        if rows is None:
            self.rect, self.exact, self.crossing = rect, ahead, crossing
        else:
            self.rect = np.zeros((4, len(lo)), np.int64)
            self.rect[:, rows] = rect
            self.exact = np.zeros(len(lo), bool)
            self.exact[rows] = ahead
            self.crossing = np.zeros(len(lo), bool)
            self.crossing[rows] = crossing

    def made_for(self, view: NDArray[np.float64], proj: NDArray[np.float64], size: tuple[int, int], clip_m: float,
                 margin_px: float) -> bool:
        """Whether the rectangles were made with this camera and these settings."""
        return (tuple(self.size) == tuple(size) and self.clip_m == clip_m and self.margin_px == margin_px
                and self.view == view.tolist() and self.proj == proj.tolist())


def cull_parts(
    mode: str,
    cells: list[int],
    boxes: Boxes,
    eye: ArrayLike,
    view: ArrayLike,
    proj: ArrayLike,
    size: tuple[int, int],
    *,
    vsas: dict[int, list[tuple[int, int, int, int]]] | None = None,
    fog_m: float = math.inf,
    clip_m: float = 0.03,
    margin_px: float = CENTRE_MARGIN_PX,
    rects: PartRects | None = None,
) -> dict[int, NDArray[np.bool_]]:
    """Which parts of each visible cell to draw, by ``mode`` (:data:`~walkstream.shared.portals.CULLING_MODES`).

    Parameters
    ----------
    mode : str
        ``portals``: boxes against the cell's VSAs, the fog and the frustum
        (:func:`cull_boxes`, every cell at once); ``frustum``: the frustum and the fog;
        ``none``: all.
    cells : list of int
        Visible cells (those without boxes, i.e. not loaded, are left out).
    boxes : mapping of int -> ((n, 3), (n, 3))
        Per cell, its parts' boxes (packed once, :func:`part_table`).
    vsas : dict of int -> list of (x0, y0, x1, y1)
        Per cell its VSAs (``portals`` mode; a cell without is culled whole).
    margin_px : float
        Pixels by which a box's projection is grown before the pixels it covers are taken
        (``portals`` mode; :data:`~walkstream.shared.screenrects.TOUCH_MARGIN_PX` keeps every
        pixel it touches, as the cache's guard view does: :mod:`walkstream.shared.cullcache`).
    rects : PartRects, optional
        Filled with the boxes' rectangles where they are made as the triangle test makes
        them (``portals`` mode), for it to share (:class:`PartRects`).

    Returns
    -------
    dict of int -> (n,) bool
    """
    if mode not in CULLING_MODES:
        raise InputError(f"culling mode {mode!r}: expected one of {', '.join(CULLING_MODES)}")
    e = np.ascontiguousarray(eye, np.float64).reshape(3)
    present = list(filter(boxes.__contains__, cells))
    if mode == "none":
        return {c: np.ones(len(boxes[c][0]), bool) for c in present}
    vp = np.asarray(proj, np.float64) @ np.asarray(view, np.float64)
    if mode == "frustum":
        out: dict[int, NDArray[np.bool_]] = {}
        for c in present:
            lo, hi = boxes[c]
            keep = box_distance(lo, hi, e) <= fog_m
            keep[keep] = frustum_cull(lo[keep], hi[keep], vp)
            out[c] = keep
        return out
    seen = present if vsas is None else list(filter(vsas.__contains__, present))
    out = {}
    if vsas is None or len(seen) < len(present):
        out = {c: np.zeros(len(boxes[c][0]), bool) for c in present if vsas is None or c not in vsas}
    if vsas is None or not seen:
        return out
    if len(seen) < _FEW_CELLS:  # their arrays joined as they are: no table to check
        pairs = list(map(boxes.__getitem__, seen))
        counts = np.fromiter(map(len, map(itemgetter(0), pairs)), np.int64, len(seen))
        # float64 and C order whatever the cells hold: one compiled form of the kernel
        lo = np.concatenate([np.reshape(p[0], (-1, 3)) for p in pairs], dtype=np.float64)
        hi = np.concatenate([np.reshape(p[1], (-1, 3)) for p in pairs], dtype=np.float64)
        first = np.cumsum(counts) - counts
        table = None
    else:
        table = part_table(boxes, seen)
        slot = np.fromiter(map(table.slot.__getitem__, seen), np.int64, len(seen))
        counts, first, lo, hi = table.count[slot], table.start[slot], table.lo, table.hi
    ends = np.cumsum(counts)
    offsets = ends - counts
    if int(ends[-1]) == 0:
        out.update(zip(seen, map(np.zeros, counts.tolist(), repeat(bool)), strict=True))
        return out
    V, P = np.asarray(view, np.float64), np.asarray(proj, np.float64)
    rows, shift = camera_rows(V, P)
    planes = near_far(P)
    want = rects is not None and (table is None or int(ends[-1]) < _FEW_BOXES)
    vsa_rows, vsa_count = _vsa_rows(vsas, seen)
    keep, projected, rect, near_d, far_d = box_kernel(
        lo, hi, first, counts, vsa_rows, np.cumsum(vsa_count) - vsa_count, vsa_count, e, float(fog_m), rows, shift,
        int(size[0]), int(size[1]), float(margin_px), float(clip_m), planes is not None,
        *(planes or (0.0, 0.0)), want)
    if planes is None or want:
        # the rows of ``lo``, ``hi`` of the cells' boxes one after another
        idx = None if table is None else np.arange(int(ends[-1])) + np.repeat(first - offsets, counts)
        lo_s, hi_s = (lo, hi) if idx is None else (lo[idx], hi[idx])
    if planes is None:  # not a perspective projection: the six-plane frustum test
        got = np.flatnonzero(keep)
        keep[got] = frustum_cull(lo_s[got], hi_s[got], vp)
    if want and rects is not None:
        sub = None if projected.all() else np.flatnonzero(projected)
        pick = (lambda a: a) if sub is None else (lambda a: a[..., sub])
        rects.fill(V, P, size, clip_m, margin_px, seen, counts.tolist(), lo_s, hi_s, sub, pick(rect),
                   pick(near_d), pick(far_d))
    out.update(zip(seen, _slices(keep, offsets, ends), strict=True))
    return out


def _slices(a: NDArray[np.bool_], starts: NDArray[np.int64], ends: NDArray[np.int64]) -> Any:
    """Views ``a[s:e]`` for each pair (a C-level map: no Python statement per cell)."""
    return map(a.__getitem__, map(slice, starts.tolist(), ends.tolist()))


def _vsa_rows(vsas: dict[int, list[tuple[int, int, int, int]]], cells: list[int]) -> tuple[
        NDArray[np.int64], NDArray[np.int64]]:
    """The cells' VSAs one after another ``(k, 4)`` int64, and how many each cell has
    ``(cells,)`` (packed into the array in one C call: a third of the CPU of ``np.fromiter``)."""
    lists = list(map(vsas.__getitem__, cells))
    counts = np.fromiter(map(len, lists), np.int64, len(cells))
    k = int(counts.sum())
    out = np.empty((k, 4), np.int64)  # writable: the kernel is compiled for writable arrays
    struct.pack_into(f"={4 * k}q", out.data, 0, *chain.from_iterable(chain.from_iterable(lists)))
    return out, counts


#: Visible cells below which a frame joins their box arrays as they are (a tour's 4-40):
#: no table to check, and a table made anew when the streamer loads a cell costs more.
_FEW_CELLS = 48

#: Boxes below which a frame of many cells keeps its boxes' rectangles for the triangle
#: test (:class:`PartRects`; above, the copies of every box's rows cost more than the
#: triangle test's few candidates' rectangles made there).
_FEW_BOXES = 1200


def near_far(proj: NDArray[np.float64]) -> tuple[float, float] | None:
    """The near and far planes' depths of a perspective projection (``-z`` in eye space:
    the frustum test's two planes that are not through the eye), or None for another
    kind of projection."""
    (a, b, c, d), (e, f, g, h) = proj[2:].tolist()
    if (a, b, e, f, g, h) != (0.0, 0.0, 0.0, 0.0, -1.0, 0.0):
        return None
    return d / (c - 1.0), d / (c + 1.0)
