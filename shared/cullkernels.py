"""The culling's hot loops compiled: the portal walk and the parts culling's box test.

A frame's culling at a couple of hundred visible cells (an open hall) cost some 3 ms of
CPU in numpy and Python, nearly all of it per-call overhead: tens of numpy calls per
batch and a Python statement per portal tested (docs/benchmarks.md, "The culling's CPU
time").  These kernels are those loops compiled once by numba (``@njit(cache=True)``:
the machine code is kept in ``__pycache__`` beside this file and loaded, not compiled,
by later processes), each one call per frame:

- :func:`walk_kernel` is :func:`~walkstream.shared.portals.cull_portals`' FIFO walk over
  the portals' rectangle table, step for step (the same cells, VSAs, depths and counts as
  the reference walk, :mod:`walkstream.benchmarks.portalwalk`);
- :func:`box_kernel` is :func:`~walkstream.shared.partcull.cull_parts`' test of every
  visible box: the fog, the projection from the box's two corners with the same IEEE
  operations in the same order as :func:`~walkstream.shared.screenrects.box_rects_ckm`
  (a box across the clip plane gets :func:`~walkstream.shared.screenrects.crossing_rects`'
  superset), the cell's VSAs, and the frustum's near and far planes as depths.

No fast-math: every sum and product is the one numpy makes (tests/test_cullkernels.py
checks the rectangles and depths against the numpy functions).  :func:`warm_up` runs
each kernel once on a tiny input, so that a replay or a client pays the compile (or
the cache's load) before its first timed frame.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

__all__ = ["walk_kernel", "box_kernel", "warm_up"]


@njit(cache=True)
def walk_kernel(target: NDArray[np.int64], row_start: NDArray[np.int64], what: NDArray[np.int8],
                rect: NDArray[np.int64], start: int, w: int, h: int, limit: int,
                max_vsas: int) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64],
                                        NDArray[np.int64], int, int]:  # pragma: no cover - compiled
    """The FIFO portal walk from cell index ``start`` (:func:`~walkstream.shared.portals.cull_portals`).

    ``target`` ``(m,)`` each directed portal's target cell index, ``row_start`` ``(cells + 1,)``
    each cell's first portal row, ``what`` ``(m,)`` 0 culled, 1 passed through, 2 its
    rectangle ``rect[:, row]`` ``(4, m)``; the viewport ``w`` x ``h``; ``limit`` the portals
    passed at most; ``max_vsas`` the VSAs a cell keeps before they become their bounding
    rectangle.

    Returns the cell indices in the order first reached ``(n,)``, each one's depth ``(n,)``,
    their VSAs one after another ``(k, 4)`` and how many each ``(n,)``, the portals opened
    and the portal tests made.
    """
    nc = len(row_start) - 1
    slots = max(max_vsas, 1) + 1  # a list holds one more than max_vsas before it is merged
    bound = np.empty((nc, 4), np.int64)
    lists = np.empty((nc, slots, 4), np.int64)
    nlist = np.zeros(nc, np.int64)
    depth = np.zeros(nc, np.int64)
    seen = np.zeros(nc, np.bool_)
    queued = np.zeros(nc, np.bool_)
    order = np.empty(nc, np.int64)
    # a ring: a cell is in the queue at most once (``queued``), so nc slots hold it
    ring = np.empty(nc, np.int64)
    head = 0
    size = 0
    bound[start, 0], bound[start, 1], bound[start, 2], bound[start, 3] = 0, 0, w - 1, h - 1
    lists[start, 0, :] = bound[start]
    nlist[start] = 1
    seen[start] = True
    queued[start] = True
    order[0] = start
    norder = 1
    ring[0] = start
    size = 1
    opened = 0
    tested = 0
    while size > 0:
        c = ring[head]
        head = (head + 1) % nc
        size -= 1
        queued[c] = False
        dn = depth[c] + 1
        if dn > limit:
            continue
        vx0, vy0, vx1, vy1 = bound[c, 0], bound[c, 1], bound[c, 2], bound[c, 3]
        for r in range(row_start[c], row_start[c + 1]):
            k = what[r]
            if k == 0:
                continue
            t = target[r]
            tested += 1
            if k == 1:
                a0, a1, a2, a3 = vx0, vy0, vx1, vy1
            else:
                a0, a1, a2, a3 = max(rect[0, r], vx0), max(rect[1, r], vy0), min(rect[2, r], vx1), min(rect[3, r], vy1)
                if a0 > a2 or a1 > a3:
                    continue
            opened += 1
            if not seen[t]:  # the first visit
                seen[t] = True
                bound[t, 0], bound[t, 1], bound[t, 2], bound[t, 3] = a0, a1, a2, a3
                lists[t, 0, 0], lists[t, 0, 1], lists[t, 0, 2], lists[t, 0, 3] = a0, a1, a2, a3
                nlist[t] = 1
                depth[t] = dn
                order[norder] = t
                norder += 1
                ring[(head + size) % nc] = t
                size += 1
                queued[t] = True
                continue
            # is the new VSA covered by one the cell has (nothing to do), or does it
            # cover some (they go, the others keep their order)?
            n = nlist[t]
            covered = False
            drop = False
            for j in range(n):
                q0, q1, q2, q3 = lists[t, j, 0], lists[t, j, 1], lists[t, j, 2], lists[t, j, 3]
                if q0 <= a0 and q1 <= a1 and q2 >= a2 and q3 >= a3:
                    covered = True
                    break
                if a0 <= q0 and a1 <= q1 and a2 >= q2 and a3 >= q3:
                    drop = True
            if covered:
                continue
            if drop:
                kept = 0
                for j in range(n):
                    q0, q1, q2, q3 = lists[t, j, 0], lists[t, j, 1], lists[t, j, 2], lists[t, j, 3]
                    if not (a0 <= q0 and a1 <= q1 and a2 >= q2 and a3 >= q3):
                        lists[t, kept, 0], lists[t, kept, 1], lists[t, kept, 2], lists[t, kept, 3] = q0, q1, q2, q3
                        kept += 1
                n = kept
            lists[t, n, 0], lists[t, n, 1], lists[t, n, 2], lists[t, n, 3] = a0, a1, a2, a3
            n += 1
            if n > max_vsas:  # merged into their bounding rectangle
                for j in range(1, n):
                    lists[t, 0, 0] = min(lists[t, 0, 0], lists[t, j, 0])
                    lists[t, 0, 1] = min(lists[t, 0, 1], lists[t, j, 1])
                    lists[t, 0, 2] = max(lists[t, 0, 2], lists[t, j, 2])
                    lists[t, 0, 3] = max(lists[t, 0, 3], lists[t, j, 3])
                n = 1
            nlist[t] = n
            b0, b1, b2, b3 = bound[t, 0], bound[t, 1], bound[t, 2], bound[t, 3]
            if a0 >= b0 and a1 >= b1 and a2 <= b2 and a3 <= b3:
                continue  # the cell's rectangle did not grow: not looked through again
            bound[t, 0], bound[t, 1], bound[t, 2], bound[t, 3] = min(a0, b0), min(a1, b1), max(a2, b2), max(a3, b3)
            if dn < depth[t]:
                depth[t] = dn
            if not queued[t]:
                ring[(head + size) % nc] = t
                size += 1
                queued[t] = True
    cells = order[:norder].copy()
    counts = np.empty(norder, np.int64)
    total = 0
    for i in range(norder):
        counts[i] = nlist[cells[i]]
        total += counts[i]
    vsas = np.empty((total, 4), np.int64)
    row = 0
    for i in range(norder):
        c = cells[i]
        for j in range(counts[i]):
            vsas[row, :] = lists[c, j]
            row += 1
    depths = np.empty(norder, np.int64)
    for i in range(norder):
        depths[i] = depth[cells[i]]
    return cells, depths, vsas, counts, opened, tested


@njit(cache=True)
def _pixel_lo(b: float, half: float, margin: float) -> int:  # pragma: no cover - compiled
    """The first pixel centre at or after NDC bound ``b`` (``screenrects._pixels4``' steps)."""
    p = (b + 1.0) * half
    p = max(min(p, 1e9), -1e9)
    return math.ceil((p - 0.5) + -margin)


@njit(cache=True)
def _pixel_hi(b: float, half: float, margin: float) -> int:  # pragma: no cover - compiled
    """The last pixel centre at or before NDC bound ``b``."""
    p = (b + 1.0) * half
    p = max(min(p, 1e9), -1e9)
    return math.floor((p - 0.5) + margin)


@njit(cache=True)
def box_kernel(lo: NDArray[np.float64], hi: NDArray[np.float64], first: NDArray[np.int64],
               count: NDArray[np.int64], vsas: NDArray[np.int64], vsa_first: NDArray[np.int64],
               vsa_count: NDArray[np.int64], eye: NDArray[np.float64], fog_m: float, rows: NDArray[np.float64],
               shift: NDArray[np.float64], w: int, h: int, margin_px: float, clip_m: float, planes: bool,
               near_plane: float, far_plane: float, want: bool) -> tuple[
                   NDArray[np.bool_], NDArray[np.bool_], NDArray[np.int64], NDArray[np.float64],
                   NDArray[np.float64]]:  # pragma: no cover - compiled
    """Which boxes of the visible cells to draw (:func:`~walkstream.shared.partcull.cull_parts`).

    Cell ``i``'s boxes are rows ``first[i]:first[i] + count[i]`` of ``lo``, ``hi`` ``(N, 3)``;
    its VSAs rows ``vsa_first[i]:vsa_first[i] + vsa_count[i]`` of ``vsas`` ``(k, 4)``.  The
    camera as :func:`~walkstream.shared.screenrects.camera_rows` gives it (``rows``
    ``(3, 3)``, ``shift`` ``(3,)``).  A box is kept when it lies within ``fog_m`` of ``eye``,
    its rectangle meets one of its cell's VSAs, some of it lies in front of the clip plane
    and (``planes``) its depths reach between ``near_plane`` and ``far_plane``.

    Returns, per box of the cells one after another, whether it is kept and whether it was
    projected (within the fog); with ``want`` also its rectangle ``(4, n)`` and nearest and
    farthest corner depth (empty arrays without).
    """
    n = 0
    for i in range(len(count)):
        n += count[i]
    keep = np.zeros(n, np.bool_)
    projected = np.zeros(n, np.bool_)
    m = n if want else 0
    rect = np.empty((4, m), np.int64)
    near = np.empty(m, np.float64)
    far = np.empty(m, np.float64)
    hw, hh = w * 0.5, h * 0.5
    cross_margin = margin_px + 1e-6
    foggy = not math.isinf(fog_m)
    e0, e1, e2 = eye[0], eye[1], eye[2]
    qx = np.empty(8)
    qy = np.empty(8)
    qz = np.empty(8)
    o = 0
    for c in range(len(count)):
        v0 = vsa_first[c]
        v1 = v0 + vsa_count[c]
        for b in range(first[c], first[c] + count[c]):
            lx, ly, lz, ux, uy, uz = lo[b, 0], lo[b, 1], lo[b, 2], hi[b, 0], hi[b, 1], hi[b, 2]
            if foggy:
                # box_distance's sums in numpy's einsum order
                g0 = max(max(lx - e0, e0 - ux), 0.0)
                g1 = max(max(ly - e1, e1 - uy), 0.0)
                g2 = max(max(lz - e2, e2 - uz), 0.0)
                if not math.sqrt((g0 * g0 + g2 * g2) + g1 * g1) <= fog_m:
                    o += 1
                    continue
            projected[o] = True
            # the eight corners' x and y numerators and depths from the two bounds of
            # each coordinate (box_rects_ckm: the x term and the shift first, then y, then z)
            for r in range(3):
                px0 = rows[r, 0] * lx + shift[r]
                px1 = rows[r, 0] * ux + shift[r]
                py0, py1 = rows[r, 1] * ly, rows[r, 1] * uy
                pz0, pz1 = rows[r, 2] * lz, rows[r, 2] * uz
                out = qx if r == 0 else (qy if r == 1 else qz)
                out[0] = (px0 + py0) + pz0
                out[1] = (px0 + py0) + pz1
                out[2] = (px0 + py1) + pz0
                out[3] = (px0 + py1) + pz1
                out[4] = (px1 + py0) + pz0
                out[5] = (px1 + py0) + pz1
                out[6] = (px1 + py1) + pz0
                out[7] = (px1 + py1) + pz1
            nd = qz[0]
            fd = qz[0]
            for j in range(1, 8):
                nd = min(nd, qz[j])
                fd = max(fd, qz[j])
            if fd < clip_m:  # wholly behind the clip plane: the empty rectangle
                x0, y0, x1, y1 = 1, 1, 0, 0
            elif nd >= clip_m:  # wholly in front: the corners' projections bound it
                xl = xh = qx[0] / qz[0]
                yl = yh = qy[0] / qz[0]
                for j in range(1, 8):
                    x = qx[j] / qz[j]
                    y = qy[j] / qz[j]
                    xl, xh, yl, yh = min(xl, x), max(xh, x), min(yl, y), max(yh, y)
                x0, y0 = _pixel_lo(xl, hw, margin_px), _pixel_lo(yl, hh, margin_px)
                x1, y1 = _pixel_hi(xh, hw, margin_px), _pixel_hi(yh, hh, margin_px)
            else:  # across it: crossing_rects' unclipped superset
                d = max(qz[0], clip_m)
                xl = xh = qx[0] / d
                yl = yh = qy[0] / d
                nxl = nxh = qx[0]
                nyl = nyh = qy[0]
                for j in range(1, 8):
                    d = max(qz[j], clip_m)
                    x = qx[j] / d
                    y = qy[j] / d
                    xl, xh, yl, yh = min(xl, x), max(xh, x), min(yl, y), max(yh, y)
                    nxl, nxh, nyl, nyh = min(nxl, qx[j]), max(nxh, qx[j]), min(nyl, qy[j]), max(nyh, qy[j])
                xl, yl = min(xl, nxl / clip_m), min(yl, nyl / clip_m)
                xh, yh = max(xh, nxh / clip_m), max(yh, nyh / clip_m)
                x0, y0 = _pixel_lo(xl, hw, cross_margin), _pixel_lo(yl, hh, cross_margin)
                x1, y1 = _pixel_hi(xh, hw, cross_margin), _pixel_hi(yh, hh, cross_margin)
            if want:
                rect[0, o], rect[1, o], rect[2, o], rect[3, o] = x0, y0, x1, y1
                near[o], far[o] = nd, fd
            got = False
            # of the frustum's six planes only the near and the far one can cull a box whose
            # rectangle meets a VSA (a VSA lies within the viewport, so some point of the box
            # lies inside each side plane): the two are tested as depths
            if fd >= clip_m and (not planes or (fd >= near_plane and nd <= far_plane)):
                for j in range(v0, v1):
                    if (max(x0, vsas[j, 0]) <= min(x1, vsas[j, 2])
                            and max(y0, vsas[j, 1]) <= min(y1, vsas[j, 3])):
                        got = True
                        break
            keep[o] = got
            o += 1
    return keep, projected, rect, near, far


def warm_up() -> None:
    """Run each kernel once on a tiny input: compiled now (or loaded from the cache), not
    inside the first frame that culls."""
    one = np.zeros(1, np.int64)
    walk_kernel(one, np.array([0, 1], np.int64), np.zeros(1, np.int8), np.zeros((4, 1), np.int64), 0, 4, 4, 2, 4)
    box = np.zeros((1, 3))
    box_kernel(box, box + 1.0, one, one + 1, np.zeros((1, 4), np.int64), one, one + 1, np.zeros(3), 1.0,
               np.eye(3), np.zeros(3), 4, 4, 0.125, 0.03, True, 0.1, 10.0, True)
