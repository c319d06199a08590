"""The parts culling: which part boxes of each visible cell to draw (portal culling's step 5).

A visible cell's contents are culled by their boxes (:mod:`walkstream.shared.portals`, step
5): a box is kept when it comes within the fog distance, its clipped, projected rectangle
(:mod:`walkstream.shared.screenrects`) meets one of the cell's VSAs, and it lies between the
frustum's near and far planes.  :func:`cull_boxes` is that test for one cell, as plainly as
it can be written (the reference); :func:`cull_parts` gives every visible cell's answer at
once and must keep every box :func:`cull_boxes` keeps, and few more (tests/test_cullcpu.py,
tests/test_partcull.py).

Cost: at a couple of hundred visible cells a frame (an open hall) the per-cell Python and
numpy's fresh temporaries, not the arithmetic, were most of the time.  So:

- the boxes of a scene are packed once into one coordinate-major array (a
  :class:`PartTable`, cached per ``boxes`` mapping and checked by identity: a cell whose
  ``(lo, hi)`` pair is not the one packed makes the table anew), and a frame gathers its
  visible cells' boxes by index, not by concatenating one array per cell;
- every visible box is projected in one batch from its two corners
  (:func:`~walkstream.shared.screenrects.box_rects_ckm`: 18 products a box, not 72), into
  buffers reused from frame to frame (:func:`~walkstream.shared.screenrects.thread_buffers`:
  a fresh array of a few hundred kB costs more than the step that fills it, which is why
  the boxes were culled in chunks of 1,024 before);
- the per-cell steps (which cells, their VSAs, the answer's slices) are C-level maps over
  the cell lists (one comprehension pads the VSA lists), no Python statement per cell;
- a box that crosses the clip plane (a tour's frame has 70 or so, median: the walls,
  floor and furniture around the eye) is tested by an unclipped superset of its rectangle
  (:func:`~walkstream.shared.screenrects.crossing_rects`, about ten numpy calls for all,
  against some forty to clip them): conservative, not the same, so this keeps every box
  :func:`cull_boxes` keeps and a few more (1.5 % on the generated offices' tours; 10-19 %
  less CPU in their parts culling);
- a frame of a few cells (a tour's 4-40) takes the plain form instead (their arrays
  joined, the eight corners' one product, fresh arrays): there numpy's calls, not the
  boxes, are the cost, and the batch's extra steps made it 10-20 % slower.

``walkstream bench portals --cull`` times it (:mod:`walkstream.benchmarks.cullcpu`).
"""

from __future__ import annotations

import math
import struct
from collections.abc import Mapping
from itertools import chain, repeat
from operator import is_not
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.shared.errors import InputError
from walkstream.shared.frustum import frustum_cull
from walkstream.shared.portals import CULLING_MODES, box_distance
from walkstream.shared.screenrects import (
    BOX_EDGES,
    CENTRE_MARGIN_PX,
    box_corners_ckm,
    box_rects,
    box_rects_ckm,
    rects_ckm,
    thread_buffers,
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
    """A scene's part boxes packed once: every cell's boxes in one coordinate-major array.

    Attributes
    ----------
    lohi : (3, 2, N) float64
        ``lohi[j, 0]`` the lower and ``lohi[j, 1]`` the upper bound of coordinate ``j`` of
        each box, the cells one after another.
    slot : dict of int -> int
        A cell id's index into ``start`` and ``count``.
    start, count : (cells,) int64
        Each cell's first box in ``lohi`` and its number of boxes.
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
        lo = np.concatenate(los) if los else np.zeros((0, 3))
        hi = np.concatenate(his) if his else np.zeros((0, 3))
        self.lohi = np.ascontiguousarray(np.stack([lo.T, hi.T], axis=1))

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

    Handed to :func:`cull_parts` empty (``rects=``), filled by it when it projects the
    boxes as :func:`~walkstream.shared.screenrects.box_rects` does (the eight corners' one
    product: a frame of fewer than :data:`_FEW_BOXES` boxes), left empty otherwise.

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
    e = np.asarray(eye, np.float64).reshape(3)
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
    if len(seen) < _FEW_CELLS:
        out.update(_cull_few(seen, boxes, vsas, e, view, proj, size, fog_m, clip_m, vp, margin_px, rects))
        return out
    table = part_table(boxes, seen)
    nseen = len(seen)
    slot = np.fromiter(map(table.slot.__getitem__, seen), np.int64, nseen)
    counts = table.count[slot]
    ends = np.cumsum(counts)
    total = int(ends[-1])
    if total == 0:
        out.update(zip(seen, map(np.zeros, counts.tolist(), repeat(bool)), strict=True))
        return out
    offsets = ends - counts
    # each visible box's index into the table and its cell's index into ``seen``
    owner = np.repeat(np.arange(nseen), counts)
    idx = np.arange(total) + (table.start[slot] - offsets)[owner]
    work = thread_buffers()
    lohi = np.take(table.lohi, idx, axis=2, out=work.take("lohi", (3, 2, total)), mode="clip")
    keep = np.zeros(total, bool)
    if not math.isinf(fog_m):
        near = box_distance(lohi[:, 0].T, lohi[:, 1].T, e) <= fog_m
        if not near.all():  # only the boxes within the fog are projected
            sub = np.flatnonzero(near)
            if not len(sub):
                out.update(zip(seen, _slices(keep, offsets, ends), strict=True))
                return out
            owner = owner[sub]
            lohi = np.take(lohi, sub, axis=2, out=work.take("lohi_fog", (3, 2, len(sub))), mode="clip")
        else:
            sub = None
    else:
        sub = None
    v = _vsa_table(vsas, seen)
    n = len(owner)
    V, P = np.asarray(view, np.float64), np.asarray(proj, np.float64)
    if n < _FEW_BOXES:  # the eight corners' one product: fewer numpy calls
        lo_b, hi_b = lohi[:, 0].T, lohi[:, 1].T
        rect, front, near_d, far_d = rects_ckm(box_corners_ckm(lo_b, hi_b), BOX_EDGES, V, P, size, clip_m,
                                               margin_px, clip_rest=False)
        if rects is not None:  # the table's rows of these cells, as the triangle test shares them
            rows_lo = table.lohi[:, 0, :].T
            rects.fill(V, P, size, clip_m, margin_px, seen, counts.tolist(), np.take(rows_lo, idx, axis=0),
                       np.take(table.lohi[:, 1, :].T, idx, axis=0), sub, rect, near_d, far_d)
    else:
        rect, front, near_d, far_d = box_rects_ckm(lohi, V, P, size, clip_m, margin_px, work=work, clip_rest=False)
    kmax = v.shape[1]
    # 32-bit pixels (the bounds are clamped to +-1e9): half the bytes to gather and compare
    rect = rect.astype(np.int32)
    # each box's own cell's VSAs ("clip": the indices are valid, and numpy buffers an
    # ``out`` under the default "raise")
    vo = np.take(v, owner, axis=2, out=work.take("vsa", (4, kmax, n), np.int32), mode="clip")
    lo_ = np.maximum(rect[0], vo[0], out=work.take("meet0", (kmax, n), np.int32))
    hi_ = np.minimum(rect[2], vo[2], out=work.take("meet1", (kmax, n), np.int32))
    meet = np.less_equal(lo_, hi_, out=work.take("meetx", (kmax, n), np.bool_))
    np.maximum(rect[1], vo[1], out=lo_)
    np.minimum(rect[3], vo[3], out=hi_)
    meet &= lo_ <= hi_
    got = meet[0].copy() if kmax == 1 else np.logical_or.reduce(meet, axis=0)
    got &= front
    planes = near_far(P)
    if planes is None:
        lo_b, hi_b = lohi[:, 0].T, lohi[:, 1].T
        got[got] = frustum_cull(lo_b[got], hi_b[got], vp)
    else:
        # the frustum's other four planes cannot cull a box whose rectangle meets a
        # VSA: a VSA lies within the viewport, so some point of the box lies inside
        # each of them (by at least a third of a pixel); the near and the far plane
        # are depths
        got &= (far_d >= planes[0]) & (near_d <= planes[1])
    if sub is None:
        keep = got
    else:
        keep[sub] = got
    out.update(zip(seen, _slices(keep, offsets, ends), strict=True))
    return out


def _cull_few(
    seen: list[int],
    boxes: Boxes,
    vsas: dict[int, list[tuple[int, int, int, int]]],
    e: NDArray[np.float64],
    view: ArrayLike,
    proj: ArrayLike,
    size: tuple[int, int],
    fog_m: float,
    clip_m: float,
    vp: NDArray[np.float64],
    margin_px: float = CENTRE_MARGIN_PX,
    rects: PartRects | None = None,
) -> dict[int, NDArray[np.bool_]]:
    """:func:`cull_parts` of a few cells (a tour's 4-40): their arrays joined as they are (no
    table to check), the eight corners' one product, fresh arrays; side by side with the
    batch path this is 10-20 % less CPU at such sizes (numpy's calls, not the boxes, are
    the cost)."""
    pairs = list(map(boxes.__getitem__, seen))
    counts = [len(p[0]) for p in pairs]
    lo = np.concatenate([p[0] for p in pairs]).reshape(-1, 3)
    hi = np.concatenate([p[1] for p in pairs]).reshape(-1, 3)
    keep = np.ones(len(lo), bool) if math.isinf(fog_m) else box_distance(lo, hi, e) <= fog_m
    owner = np.repeat(np.arange(len(seen)), counts)
    idx = None if keep.all() else np.flatnonzero(keep)
    lo_all, hi_all = lo, hi
    if idx is not None:
        lo, hi, owner = lo[idx], hi[idx], owner[idx]
    if len(lo):
        V, P = np.asarray(view, np.float64), np.asarray(proj, np.float64)
        rect, front, near_d, far_d = rects_ckm(box_corners_ckm(lo, hi), BOX_EDGES, V, P, size, clip_m,
                                               margin_px, clip_rest=False)
        if rects is not None:
            rects.fill(V, P, size, clip_m, margin_px, seen, counts, lo_all, hi_all, idx, rect, near_d, far_d)
        v = _vsa_table(vsas, seen)[:, :, owner]
        meet = ((np.maximum(rect[0], v[0]) <= np.minimum(rect[2], v[2]))
                & (np.maximum(rect[1], v[1]) <= np.minimum(rect[3], v[3])))
        got = front & np.any(meet, axis=0)
        planes = near_far(P)
        if planes is None:
            got[got] = frustum_cull(lo[got], hi[got], vp)
        else:  # as in cull_parts
            got &= (far_d >= planes[0]) & (near_d <= planes[1])
    else:
        got = np.zeros(0, bool)
    if idx is None:
        keep = got
    else:
        keep[idx] = got
    n = np.asarray(counts, np.int64)
    ends = np.cumsum(n)
    return dict(zip(seen, _slices(keep, ends - n, ends), strict=True))


def _slices(a: NDArray[np.bool_], starts: NDArray[np.int64], ends: NDArray[np.int64]) -> Any:
    """Views ``a[s:e]`` for each pair (a C-level map: no Python statement per cell)."""
    return map(a.__getitem__, map(slice, starts.tolist(), ends.tolist()))


def _vsa_table(vsas: dict[int, list[tuple[int, int, int, int]]], cells: list[int]) -> NDArray[np.int32]:
    """The cells' VSAs ``(4, kmax, cells)`` as int32, a coordinate of one VSA of every cell
    per row, the shorter lists padded with empty rectangles (which meet nothing)."""
    lists = list(map(vsas.__getitem__, cells))
    kmax = max(map(len, lists))
    # padded in Python (one short list added per cell), then packed as bytes in one C call:
    # fewer numpy calls than padding in numpy, and a third of the CPU of np.fromiter
    pads = [[_NO_PIXEL] * (kmax - i) for i in range(kmax + 1)]
    padded = [have + pads[len(have)] for have in lists]
    ints = struct.pack(f"={4 * kmax * len(cells)}i", *chain.from_iterable(chain.from_iterable(padded)))
    return np.frombuffer(ints, np.int32).reshape(len(cells), kmax, 4).transpose(2, 1, 0)


#: An empty whole-pixel rectangle (no pixel centre): pads a cell's VSAs.
_NO_PIXEL = (1, 1, 0, 0)


#: Visible cells below which a frame takes :func:`_cull_few`.
_FEW_CELLS = 48

#: Boxes below which a frame projects their eight corners with one product
#: (:func:`~walkstream.shared.screenrects.rects_ckm`, as the plain test does): fewer numpy
#: calls, 5-10 % less CPU up to a thousand boxes; above, the two corners' sums
#: (:func:`~walkstream.shared.screenrects.box_rects_ckm`, the same rectangles) take half.
_FEW_BOXES = 1200


def near_far(proj: NDArray[np.float64]) -> tuple[float, float] | None:
    """The near and far planes' depths of a perspective projection (``-z`` in eye space:
    the frustum test's two planes that are not through the eye), or None for another
    kind of projection."""
    (a, b, c, d), (e, f, g, h) = proj[2:].tolist()
    if (a, b, e, f, g, h) != (0.0, 0.0, 0.0, 0.0, -1.0, 0.0):
        return None
    return d / (c - 1.0), d / (c + 1.0)
