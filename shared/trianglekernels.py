"""The kept parts' triangle test compiled (numba): one loop per frame instead of numpy calls.

:func:`~walkstream.shared.trianglecull.refine_parts` hands the frame's work here: the
candidate parts gathered from the frame's cells (:func:`candidates`), the parts
culling's rectangles of their boxes taken (:func:`take_rects`), and the test of their
triangles against their cells' VSAs with the witnesses' two rounds
(:func:`test_parts`).  At a tour's median frame the numpy version was some 150 calls on
a few hundred triangles, each call's own cost most of its time; here each is a loop.

**The same figures, operation for operation**, as the numpy version
(``_shows`` in ``tests/trianglereference.py``, kept as the reference the tests check
against): the clip coordinates are made as numpy's matrix product makes them here
(OpenBLAS's kernel: each row a chain of fused multiply-adds, ``fma(m2, z, fma(m1, y, m0 *
x))``, then the translation added), every other step in the same IEEE operations in the
same order (no ``fastmath``, so nothing is fused or reordered); the ends of a triangle's
sides, its rectangle of pixel centres, the rectangles' meeting, the sides' separating
test and each part's next witness (of the (triangle, VSA) pairs that showed, the largest
rectangle; of equal ones the last in the numpy version's order: by VSA, then triangle)
follow the numpy version's.  So the same parts are kept and the same witnesses carried.

Compiled on first call (seconds) and cached in ``__pycache__`` (``cache=True``);
:func:`warm_up` compiles or loads them, for callers to do before any timed frame.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic
from numpy.typing import NDArray

__all__ = ["candidates", "take_rects", "test_parts", "warm_up"]


@intrinsic
def _fma_ir(typingctx, a, b, c):  # numba's intrinsic protocol: the types in, the signature and the code out
    """``a * b + c`` rounded once (LLVM's ``llvm.fma``), as OpenBLAS's kernels compute."""
    sig = types.float64(types.float64, types.float64, types.float64)

    def codegen(context, builder, signature, args):
        d = ir.DoubleType()
        fn = builder.module.declare_intrinsic("llvm.fma", [d], ir.FunctionType(d, [d, d, d]))
        return builder.call(fn, args)

    return sig, codegen


_fma: Any = _fma_ir  # called in the kernels as fma(a, b, c) (the intrinsic's typing context is numba's)


@njit(cache=True, error_model="numpy")
def candidates(mask: NDArray[np.bool_], first: NDArray[np.int64], n: NDArray[np.int64],
               stand_in: NDArray[np.bool_], count: NDArray[np.int64],
               min_triangles: int) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """The kept parts to test of a frame's cells: ``mask`` the cells' masks one after
    another (cell ``k``'s ``n[k]`` parts, its first in the table ``first[k]``), kept, not a
    stand-in and of at least ``min_triangles`` triangles.  Returns each one's part in the
    table, its cell (an index into the cells) and its place in its cell's mask."""
    rows = mask.shape[0]
    part = np.empty(rows, np.int64)
    owner = np.empty(rows, np.int64)
    local = np.empty(rows, np.int64)
    got = 0
    row = 0
    for k in range(n.shape[0]):
        for i in range(n[k]):
            if mask[row]:
                p = first[k] + i
                if not stand_in[p] and count[p] >= min_triangles:
                    part[got] = p
                    owner[got] = k
                    local[got] = i
                    got += 1
            row += 1
    return part[:got], owner[:got], local[:got]


@njit(cache=True, error_model="numpy")
def take_rects(rect: NDArray[np.int64], exact: NDArray[np.bool_], crossing: NDArray[np.bool_],
               rlo: NDArray[np.float64], rhi: NDArray[np.float64], row: NDArray[np.int64],
               lo: NDArray[np.float64], hi: NDArray[np.float64], view: NDArray[np.float64],
               proj: NDArray[np.float64], w: float, h: float, clip_m: float,
               margin: float) -> tuple[NDArray[np.int64], bool]:
    """The rectangles ``(4, n)`` of boxes ``lo``, ``hi`` ``(n, 3)`` from the parts culling's
    (:class:`~walkstream.shared.partcull.PartRects`' arrays, the boxes' rows ``row``): taken
    where :attr:`exact`, clipped here (:func:`_clip_box`) where across the clip plane.
    False with them when a box differs from its row's or one neither exact nor across the
    plane is met (all then to be made anew)."""
    n = row.shape[0]
    out = np.empty((4, n), np.int64)
    for i in range(n):
        r = row[i]
        for j in range(3):
            if rlo[r, j] != lo[i, j] or rhi[r, j] != hi[i, j]:
                return out, False
        if exact[r]:
            for j in range(4):
                out[j, i] = rect[j, r]
        elif crossing[r]:
            _clip_box(lo, hi, i, view, proj, w, h, clip_m, margin, out)
        else:
            return out, False
    return out, True


#: A box's edges as corner pairs (:data:`~walkstream.shared.screenrects.BOX_EDGES`; corner
#: ``c`` takes coordinate ``j`` from the upper corner where bit ``j`` of ``c`` is set).
_EDGES = ((0, 1), (2, 3), (4, 5), (6, 7), (0, 2), (1, 3), (4, 6), (5, 7), (0, 4), (1, 5), (2, 6), (3, 7))


@njit(cache=True, error_model="numpy")
def _clip_box(lo: NDArray[np.float64], hi: NDArray[np.float64], i: int, view: NDArray[np.float64],
              proj: NDArray[np.float64], w: float, h: float, clip_m: float, margin: float,
              out: NDArray[np.int64]) -> None:
    """Box ``i``'s rectangle of pixel centres clipped at depth ``clip_m`` into ``out[:, i]``
    (:func:`~walkstream.shared.screenrects.clipped_box_rects`: its corners in eye space as
    numpy's product makes them, the corners in front and the edges' crossings of the plane
    projected, the same operations as ``_clipped_few``)."""
    ex, ey, ez = np.empty(8), np.empty(8), np.empty(8)
    for c in range(8):
        x = hi[i, 0] if c & 1 else lo[i, 0]
        y = hi[i, 1] if c & 2 else lo[i, 1]
        z = hi[i, 2] if c & 4 else lo[i, 2]
        ex[c] = _fma(view[0, 2], z, _fma(view[0, 1], y, view[0, 0] * x)) + view[0, 3]
        ey[c] = _fma(view[1, 2], z, _fma(view[1, 1], y, view[1, 0] * x)) + view[1, 3]
        ez[c] = _fma(view[2, 2], z, _fma(view[2, 1], y, view[2, 0] * x)) + view[2, 3]
    p00, p02, p11, p12 = proj[0, 0], proj[0, 2], proj[1, 1], proj[1, 2]
    big = 1e30
    xlo = ylo = big
    xhi = yhi = -big
    for c in range(8):
        d = -ez[c]
        if d >= clip_m:
            px, py = (p00 * ex[c] + p02 * ez[c]) / d, (p11 * ey[c] + p12 * ez[c]) / d
            xlo, xhi, ylo, yhi = min(xlo, px), max(xhi, px), min(ylo, py), max(yhi, py)
    for a, b in _EDGES:
        da, db = -ez[a], -ez[b]
        if (da - clip_m) * (db - clip_m) < 0:
            t = (clip_m - da) / (db - da)
            x = ex[a] + t * (ex[b] - ex[a])
            y = ey[a] + t * (ey[b] - ey[a])
            z = ez[a] + t * (ez[b] - ez[a])
            px, py = (p00 * x + p02 * z) / -z, (p11 * y + p12 * z) / -z
            xlo, xhi, ylo, yhi = min(xlo, px), max(xhi, px), min(ylo, py), max(yhi, py)
    out[0, i] = int(np.ceil(_pixel(xlo, w) - 0.5 - margin))
    out[1, i] = int(np.ceil(_pixel(ylo, h) - 0.5 - margin))
    out[2, i] = int(np.floor(_pixel(xhi, w) - 0.5 + margin))
    out[3, i] = int(np.floor(_pixel(yhi, h) - 0.5 + margin))


@njit(cache=True, error_model="numpy")
def _pixel(ndc: float, wh: float) -> float:
    """An NDC bound in pixels (``_clipped_few``'s ``(ndc + 1) / 2 * wh`` within +-1e9)."""
    q = (ndc + 1.0) * 0.5 * wh
    if q < -1e9:
        q = -1e9
    if q > 1e9:
        q = 1e9
    return q


@njit(cache=True, error_model="numpy")
def _clip_end(X: NDArray[np.float64], Y: NDArray[np.float64], W: NDArray[np.float64], d: NDArray[np.float64],
              far: int, i: int, j: int, a: int, s: float, sx: float, sy: float) -> tuple[float, float]:
    """Window x, y of end ``a`` (``i`` or ``j``) of side ``(i, j)`` clipped at the plane
    (``_clipped_ends``: the vertex in front, the crossing interpolated from ``i`` to ``j``,
    or the farthest vertex in front)."""
    b = j if a == i else i
    if d[a] >= 0:
        px, py, pw = X[a], Y[a], W[a]
    elif d[b] >= 0:
        px, py, pw = X[i] + (X[j] - X[i]) * s, Y[i] + (Y[j] - Y[i]) * s, W[i] + (W[j] - W[i]) * s
    else:
        px, py, pw = X[far], Y[far], W[far]
    return _window(px / pw, sx), _window(py / pw, sy)


@njit(cache=True, error_model="numpy")
def _window(ndc: float, half: float) -> float:
    """Window coordinate of an NDC one (pixel centres at whole numbers), within +-1e9
    (``np.clip``'s bounds; a NaN stays one)."""
    v = (ndc + 1.0) * half - 0.5
    if v > 1e9:
        v = 1e9
    if v < -1e9:
        v = -1e9
    return v


@njit(cache=True, error_model="numpy")
def _triangle(tri: NDArray[np.float64], t: int, m: NDArray[np.float64], sx: float, sy: float, clip_m: float,
              near: float, far: float, ex: NDArray[np.float64], ey: NDArray[np.float64],
              scratch: NDArray[np.float64]) -> bool:
    """Triangle ``t``'s six side ends in window coordinates into ``ex``, ``ey`` (its
    vertices twice, or clipped at depth ``clip_m``); False when it is wholly behind the
    clip plane or its depths miss the near and far planes.  ``scratch`` ``(4, 3)``: room
    for its clip coordinates and depths beyond the plane (made once per round)."""
    X, Y, W, d = scratch[0], scratch[1], scratch[2], scratch[3]
    for k in range(3):
        x, y, z = tri[0, k, t], tri[1, k, t], tri[2, k, t]
        X[k] = _fma(m[0, 2], z, _fma(m[0, 1], y, m[0, 0] * x)) + m[0, 3]
        Y[k] = _fma(m[1, 2], z, _fma(m[1, 1], y, m[1, 0] * x)) + m[1, 3]
        W[k] = _fma(m[2, 2], z, _fma(m[2, 1], y, m[2, 0] * x)) + m[2, 3]
    near_d = min(W[0], min(W[1], W[2]))
    far_d = max(W[0], max(W[1], W[2]))
    if not (far_d >= clip_m) or not (far_d >= near) or not (near_d <= far):
        return False
    if near_d >= clip_m:  # wholly in front: the sides' ends are the vertices
        for k in range(3):
            x = _window(X[k] / W[k], sx)
            y = _window(Y[k] / W[k], sy)
            ex[2 * k], ey[2 * k] = x, y
            ex[(2 * k + 5) % 6], ey[(2 * k + 5) % 6] = x, y  # ends 0,1 1,2 2,0
        return True
    for k in range(3):
        d[k] = W[k] - clip_m
    fa = 0  # the first of the farthest in front
    for k in (1, 2):
        if d[k] > d[fa]:
            fa = k
    for e, (i, j) in enumerate(((0, 1), (1, 2), (2, 0))):
        s = 0.0 if d[i] == d[j] else d[i] / (d[i] - d[j])
        ex[2 * e], ey[2 * e] = _clip_end(X, Y, W, d, fa, i, j, i, s, sx, sy)
        ex[2 * e + 1], ey[2 * e + 1] = _clip_end(X, Y, W, d, fa, i, j, j, s, sx, sy)
    return True


@njit(cache=True, error_model="numpy")
def _apart(ex: NDArray[np.float64], ey: NDArray[np.float64], b0: float, b1: float, b2: float, b3: float,
           margin: float) -> bool:
    """Whether a side's normal separates the ends ``ex``, ``ey`` grown by ``margin`` from
    the rectangle of pixel centres ``(b0, b1, b2, b3)`` (``_separated``, negated)."""
    cx, cy, hx, hy = b0 + b2, b1 + b3, b2 - b0, b3 - b1
    for s in range(3):
        nx = ey[2 * s] - ey[2 * s + 1]
        ny = ex[2 * s + 1] - ex[2 * s]
        lo = hi = nx * ex[0] + ny * ey[0]
        for e in range(1, 6):
            v = nx * ex[e] + ny * ey[e]
            lo = min(lo, v)
            hi = max(hi, v)
        anx, any_ = abs(nx), abs(ny)
        grow = margin * (anx + any_)
        lo -= grow
        hi += grow
        c = nx * cx + ny * cy
        r = anx * hx + any_ * hy
        if not (c - r <= 2.0 * hi) or not (c + r >= 2.0 * lo):
            return True
    return False


@njit(cache=True, error_model="numpy")
def _round(tri: NDArray[np.float64], first: NDArray[np.int64], many: NDArray[np.int64],
           who: NDArray[np.int64], start: NDArray[np.int64], owner: NDArray[np.int64],
           areas: NDArray[np.int64], nareas: NDArray[np.int64], m: NDArray[np.float64], sx: float, sy: float,
           clip_m: float, near: float, far: float, margin: float, shown: NDArray[np.bool_],
           found: NDArray[np.int64]) -> None:
    """Test part ``who[i]``'s triangles ``first[i] ..`` (``many[i]``), setting ``shown`` and
    its next witness ``found`` (the place in its run of the triangle whose rectangle cut to
    a VSA holds the most pixel centres; of equal ones the last VSA, then the last
    triangle: the numpy version's stable sort)."""
    ex = np.empty(6)
    ey = np.empty(6)
    scratch = np.empty((4, 3))
    for i in range(who.shape[0]):
        p = who[i]
        cell = owner[p]
        best = -1.0
        best_v = -1
        for t in range(first[i], first[i] + many[i]):
            if not _triangle(tri, t, m, sx, sy, clip_m, near, far, ex, ey, scratch):
                continue
            x0, y0, x1, y1 = ex[0], ey[0], ex[0], ey[0]
            for e in range(1, 6):
                x0, y0 = min(x0, ex[e]), min(y0, ey[e])
                x1, y1 = max(x1, ex[e]), max(y1, ey[e])
            x0, y0 = np.ceil(x0 - margin), np.ceil(y0 - margin)
            x1, y1 = np.floor(x1 + margin), np.floor(y1 + margin)
            for v in range(nareas[cell]):
                l0, l1 = max(x0, float(areas[cell, v, 0])), max(y0, float(areas[cell, v, 1]))
                h0, h1 = min(x1, float(areas[cell, v, 2])), min(y1, float(areas[cell, v, 3]))
                if not (l0 <= h0 and l1 <= h1) or _apart(ex, ey, l0, l1, h0, h1, margin):
                    continue
                score = (h0 - l0 + 1.0) * (h1 - l1 + 1.0)
                if score > best or (score == best and v >= best_v):
                    best, best_v = score, v
                    found[p] = t - start[p]
                    shown[p] = True


@njit(cache=True, error_model="numpy")
def test_parts(tri: NDArray[np.float64], start: NDArray[np.int64], count: NDArray[np.int64],
               witness: NDArray[np.int64], part: NDArray[np.int64], owner: NDArray[np.int64],
               brect: NDArray[np.int64], areas: NDArray[np.int64], nareas: NDArray[np.int64],
               m: NDArray[np.float64], sx: float, sy: float, clip_m: float, near: float, far: float,
               margin: float, wide_px: int, one_round: int, first_round: int) -> NDArray[np.int64]:
    """The candidates (``part`` in the table, ``owner`` their cells, ``brect`` ``(4, n)``
    their boxes' rectangles) none of whose triangles may draw a pixel centre in one of its
    cell's VSAs ``areas[owner, :nareas[owner]]`` (rows ``x0, y0, x1, y1``): their places
    among the candidates.  ``m`` the rows x, y, w of ``proj @ view``.  The witnesses of the
    parts tested are set in ``witness`` (the table's, in place).

    A part whose box's rectangle lies inside a VSA and is at least ``wide_px`` pixel
    centres wide and high is left as the boxes decided; the others are tested in two
    rounds (each part's witness, or its first ``first_round`` triangles when the parts
    without one hold more than ``one_round``; then the rest of the parts not shown)."""
    n = part.shape[0]
    test = np.empty(n, np.int64)
    nt = 0
    for i in range(n):
        cell = owner[i]
        wide = brect[2, i] - brect[0, i] >= wide_px - 1 and brect[3, i] - brect[1, i] >= wide_px - 1
        inside = False
        if wide:
            for v in range(nareas[cell]):
                if (brect[0, i] >= areas[cell, v, 0] and brect[1, i] >= areas[cell, v, 1]
                        and brect[2, i] <= areas[cell, v, 2] and brect[3, i] <= areas[cell, v, 3]):
                    inside = True
                    break
        if not inside:
            test[nt] = i
            nt += 1
    test = test[:nt]
    tpart = part[test]
    towner = owner[test]
    tstart = start[tpart]
    tcount = count[tpart]
    has = witness[tpart] >= 0
    loose = 0
    for i in range(nt):
        if not has[i]:
            loose += tcount[i]
    cap = first_round if loose > one_round else -1
    first = np.empty(nt, np.int64)
    many = np.empty(nt, np.int64)
    for i in range(nt):
        if has[i]:
            first[i], many[i] = tstart[i] + witness[tpart[i]], 1
        else:
            first[i], many[i] = tstart[i], tcount[i] if cap < 0 else min(tcount[i], cap)
    shown = np.zeros(nt, np.bool_)
    found = np.full(nt, -1, np.int64)
    who = np.arange(nt)
    _round(tri, first, many, who, tstart, towner, areas, nareas, m, sx, sy, clip_m, near, far, margin, shown, found)
    # the second round: a failed witness's part whole, a part tested in part on from there
    two = np.empty(nt, np.int64)
    first2 = np.empty(nt, np.int64)
    many2 = np.empty(nt, np.int64)
    k = 0
    for i in range(nt):
        if not shown[i] and many[i] < tcount[i]:
            two[k] = i
            first2[k] = tstart[i] if has[i] else tstart[i] + many[i]
            many2[k] = tcount[i] if has[i] else tcount[i] - many[i]
            k += 1
    if k:
        _round(tri, first2[:k], many2[:k], two[:k], tstart, towner, areas, nareas, m, sx, sy, clip_m, near, far,
               margin, shown, found)
    for i in range(nt):
        witness[tpart[i]] = found[i]
    gone = np.empty(nt, np.int64)
    g = 0
    for i in range(nt):
        if not shown[i]:
            gone[g] = test[i]
            g += 1
    return gone[:g]


def warm_up() -> None:
    """Compile the kernels, or load them from the cache, on a tiny frame (a second or so
    cold, milliseconds cached): for a caller to do before its first timed frame."""
    tri = np.zeros((3, 3, 1))
    tri[2, :, 0] = -1.0
    tri[0, 1, 0] = tri[1, 2, 0] = 1.0
    one = np.zeros(1, np.int64)
    part, owner, _local = candidates(np.ones(1, np.bool_), one, one + 1, np.zeros(1, np.bool_), one + 1, 1)
    box = np.array([[-1.0, -1.0, -2.0]]), np.array([[1.0, 1.0, 1.0]])  # across the clip plane
    take_rects(np.zeros((4, 1), np.int64), np.zeros(1, np.bool_), np.ones(1, np.bool_), box[0], box[1], one,
               box[0], box[1], np.eye(4), np.eye(4), 160.0, 120.0, 0.03, 0.125)
    m = np.eye(4)[[0, 1, 3]]
    m[2, 2] = -1.0
    test_parts(tri, one, one + 1, one - 1, part, owner, np.zeros((4, 1), np.int64),
               np.array([[[0, 0, 9, 9]]], np.int64), one + 1, m, 80.0, 60.0, 0.03, 0.05, 100.0, 0.125, 4, 1024, 32)
