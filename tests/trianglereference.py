"""The kept parts' triangle test in numpy: the reference the compiled kernels
(:mod:`walkstream.shared.trianglekernels`) are checked against, operation for operation.

It was the product's test before the kernels (shared/trianglecull.py); kept here, with
the tests, so the kernels' figures have an independent statement of what they compute.
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np
from numpy.typing import NDArray

from walkstream.shared.screenrects import CENTRE_MARGIN_PX
from walkstream.shared.trianglecull import TRIANGLE_EDGES

#: Each side's two ends in turn, as vertex indices (the sides of :data:`TRIANGLE_EDGES`).
_SIDE_ENDS = TRIANGLE_EDGES.reshape(-1)


@functools.lru_cache(maxsize=16)
def _half(size: tuple[int, int]) -> NDArray[np.float64]:
    """Half the viewport's width and height ``(2, 1, 1)``, by which :func:`_shows` scales x
    and y (made once per size; read only)."""
    half = np.array([[[0.5 * size[0]]], [[0.5 * size[1]]]])
    half.flags.writeable = False
    return half


def _shows(
    pts: NDArray[np.float64],
    vsa: NDArray[np.int64],
    view: NDArray[np.float64],
    proj: NDArray[np.float64],
    size: tuple[int, int],
    clip_m: float,
    planes: tuple[float, float],
    scored: bool = False,
) -> Any:
    """Whether each triangle ``pts`` ``(3, 3, n)`` may draw a pixel centre inside one of its
    VSAs ``vsa`` ``(4, k, n)`` (coordinate-major: ``vsa[:, j, t]`` the ``j``-th VSA of
    triangle ``t``, padded with empty rectangles).

    The triangle is clipped at depth ``clip_m`` (each side's part in front of that plane:
    a side's line projects to a line) and projected; it may draw there when its rectangle
    of pixel centres (:func:`~walkstream.shared.screenrects.ndc_pixels`' rule and margin)
    meets the VSA, no side's normal separates the two (a separating axis proves them
    apart: a triangle across a corner of a door's rectangle, or a long beam's face
    passing beside the view, whose screen box reaches into it while the triangle does
    not), and its depths reach between the near and far planes (``planes``).  Each
    triangle's answer is its own (elementwise: the same alone as in any batch).

    Cost: the same figures as testing every triangle's six side ends against every padded
    VSA, with less work: a triangle wholly in front of the plane (most) is its three
    vertices (its sides' ends are those, twice), the few across it are clipped in plain
    floats (:func:`_clipped_ends`), and only the triangles whose rectangle meets a VSA
    within the depths get their sides' test, against those VSAs alone; x and y go side
    by side, one numpy call for both.
    """
    n = pts.shape[2]
    # clip coordinates x, y and w (= depth) of each vertex: linear in the point, so a
    # side's crossing of the clip plane is interpolated in them
    m = (proj @ view)[[0, 1, 3]]
    h = (m[:, :3] @ pts.reshape(3, -1) + m[:, 3:]).reshape(3, 3, n)
    depth = h[2]
    near_d, far_d = depth.min(axis=0), depth.max(axis=0)
    front = far_d >= clip_m
    cut = np.flatnonzero((near_d < clip_m) & front)  # across the plane: clipped
    # window coordinates with pixel i's centre at i, of the three vertices ``(2, 3, n)``;
    # a triangle across the plane or wholly behind it is overwritten below (its
    # divisions unseen)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        xy = np.divide(h[:2], depth)
        xy += 1.0
        xy *= _half((int(size[0]), int(size[1])))
        xy -= 0.5
        np.minimum(xy, 1e9, out=xy)  # np.clip's bounds
        np.maximum(xy, -1e9, out=xy)
    b = np.empty((4, n))  # x and y low, x and y high
    np.minimum.reduce(xy, axis=1, out=b[:2])
    np.maximum.reduce(xy, axis=1, out=b[2:])
    ends = None
    if len(cut):
        ends = np.stack(_clipped_ends(h[:, :, cut], depth[:, cut] - clip_m, size))  # (2, 6, cut)
        b[:2, cut] = ends.min(axis=1)
        b[2:, cut] = ends.max(axis=1)
    b[:2] -= CENTRE_MARGIN_PX
    np.ceil(b[:2], out=b[:2])
    b[2:] += CENTRE_MARGIN_PX
    np.floor(b[2:], out=b[2:])
    # each triangle's rectangle cut to each of its VSAs: the pixel centres it may draw there
    lo = np.maximum(b[:2, None, :], vsa[:2])  # (2, k, n)
    hi = np.minimum(b[2:, None, :], vsa[2:])
    ok = lo <= hi
    meet = ok[0] & ok[1]  # (k, n)
    on = front & meet.any(axis=0) & (far_d >= planes[0]) & (near_d <= planes[1])
    vi, ti = np.nonzero(meet & on)  # the (VSA, triangle) pairs left to the sides' test
    if not len(ti):
        return (on, ti, np.zeros(0)) if scored else on
    # each pair's triangle's side ends (2, 6, pairs): its vertices twice, or its clipped ends
    e = xy[:, _SIDE_ENDS[:, None], ti]
    if ends is not None:
        row = np.full(n, -1, np.int64)
        row[cut] = np.arange(len(cut))
        r = row[ti]
        w = np.flatnonzero(r >= 0)
        if len(w):
            e[:, :, w] = ends[:, :, r[w]]
    bl, bh = lo[:, vi, ti], hi[:, vi, ti]
    ok2 = _separated(e[0], e[1], bl[0], bl[1], bh[0], bh[1])
    out = np.zeros(n, bool)
    out[ti[ok2]] = True
    if not scored:
        return out
    size2 = bh - bl
    size2 += 1.0
    return out, ti[ok2], (size2[0] * size2[1])[ok2]


def _clipped_ends(h: NDArray[np.float64], d: NDArray[np.float64], size: tuple[int, int]) -> tuple[
        NDArray[np.float64], NDArray[np.float64]]:
    """The window coordinates ``(6, m)`` x and y of the ends in front of the clip plane of
    the sides of triangles across it: clip coordinates ``h`` ``(3, 3, m)`` and the
    vertices' depths beyond the plane ``d`` ``(3, m)`` (some vertex in front, some behind).
    A side's line projects to a line, so a side crossing the plane ends where it crosses
    (interpolated in ``h``); a side wholly behind ends at the triangle's vertex farthest in
    front.  Plain Python floats (a frame clips a few dozen triangles): the same IEEE
    operations as numpy's, so the same figures."""
    sx, sy = 0.5 * size[0], 0.5 * size[1]
    if h.shape[2] > _FEW_CUT:
        return _clipped_ends_np(h, d, sx, sy)
    xs: list[list[float]] = []
    ys: list[list[float]] = []
    for (X, Y, W), dd in zip(h.transpose(2, 0, 1).tolist(), d.T.tolist(), strict=True):
        far = max(range(3), key=dd.__getitem__)  # the first of the farthest in front
        fb = (X[far], Y[far], W[far])
        ex: list[float] = []
        ey: list[float] = []
        for i, j in ((0, 1), (1, 2), (2, 0)):
            di, dj = dd[i], dd[j]
            s = 0.0 if di == dj else di / (di - dj)
            for a, da, db in ((i, di, dj), (j, dj, di)):
                if da >= 0:
                    px, py, pw = X[a], Y[a], W[a]
                elif db >= 0:  # the crossing, interpolated from i to j as numpy did
                    px, py, pw = X[i] + (X[j] - X[i]) * s, Y[i] + (Y[j] - Y[i]) * s, W[i] + (W[j] - W[i]) * s
                else:
                    px, py, pw = fb
                ex.append(min(max((px / pw + 1.0) * sx - 0.5, -1e9), 1e9))
                ey.append(min(max((py / pw + 1.0) * sy - 0.5, -1e9), 1e9))
        xs.append(ex)
        ys.append(ey)
    return np.array(xs).T, np.array(ys).T


#: Triangles across the clip plane up to which :func:`_clipped_ends` works in plain floats.
_FEW_CUT = 8


def _clipped_ends_np(h: NDArray[np.float64], d: NDArray[np.float64], sx: float, sy: float) -> tuple[
        NDArray[np.float64], NDArray[np.float64]]:
    """:func:`_clipped_ends` of many triangles, in numpy (the same operations)."""
    fallback = np.take_along_axis(h, np.argmax(d, axis=0)[None, None, :], axis=1)[:, 0]  # in front
    ends = []
    for i, j in TRIANGLE_EDGES.tolist():
        di, dj = d[i], d[j]
        with np.errstate(divide="ignore", invalid="ignore"):
            s = np.where(di == dj, 0.0, di / (di - dj))
        cross = h[:, i] + (h[:, j] - h[:, i]) * s
        ends += [np.where(di >= 0, h[:, i], np.where(dj >= 0, cross, fallback)),
                 np.where(dj >= 0, h[:, j], np.where(di >= 0, cross, fallback))]
    q = np.stack(ends, axis=1)  # (3, 6, m)
    x = np.clip((q[0] / q[2] + 1.0) * sx - 0.5, -1e9, 1e9)
    y = np.clip((q[1] / q[2] + 1.0) * sy - 0.5, -1e9, 1e9)
    return x, y


def _separated(x: NDArray[np.float64], y: NDArray[np.float64], b0: NDArray[np.float64], b1: NDArray[np.float64],
               b2: NDArray[np.float64], b3: NDArray[np.float64]) -> NDArray[np.bool_]:
    """False where a side's normal separates a clipped triangle's ends ``x``, ``y`` (window
    coordinates, pixel centres at whole numbers, ``(6, n)``: each side's two), grown by
    :data:`~walkstream.shared.screenrects.CENTRE_MARGIN_PX`, from its rectangle of pixel
    centres ``(b0, b1, b2, b3)`` (each ``(n,)``); the three sides at once."""
    nx, ny = y[0::2] - y[1::2], x[1::2] - x[0::2]  # (3, n) the sides' normals
    t = nx[:, None, :] * x + ny[:, None, :] * y  # (3, 6, n) the ends along each
    anx, any_ = np.abs(nx), np.abs(ny)
    grow = CENTRE_MARGIN_PX * (anx + any_)
    lo, hi = t.min(axis=1) - grow, t.max(axis=1) + grow  # (3, n)
    cx = b0 + b2  # (n,) twice the rectangle's centre and half sizes
    cy = b1 + b3
    hx = b2 - b0
    hy = b3 - b1
    c = nx * cx + ny * cy  # (3, n), doubled
    r = anx * hx + any_ * hy
    return np.all((c - r <= 2.0 * hi) & (c + r >= 2.0 * lo), axis=0)
