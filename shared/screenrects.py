"""Whole-pixel screen rectangles of point sets, clipped against a plane before projection.

A visible screen area (VSA) is an axis-aligned rectangle of whole pixels ``(x0, y0,
x1, y1)``, inclusive, row 0 at the bottom (GL's window coordinates).  A portal's or a
box's rectangle is the projected bounding rectangle of its points, taken as **the
pixels whose centres it may cover**: a rasteriser draws a pixel only when the pixel's
centre is inside a triangle, so what is seen through a portal, or drawn of what lies
in a box, is drawn at centres inside the projection, and those pixels are all the
rectangle need hold.  The bounds are grown by :data:`CENTRE_MARGIN_PX` first (float32
transforms, sub-pixel snapping).  A rectangle with no centre is empty (``x0 > x1`` or
``y0 > y1``): a door seen edge-on down a corridor, a sliver thinner than the gap
between two centres, shows nothing through it.  (Rounded outward to every pixel the
projection touched, such slivers became a pixel-wide rectangle each, and the rooms
behind them were drawn, twice the triangles the walker saw down a generated office's
corridor.)  The points are clipped against a plane ``clip_m`` in front of the eye
first, so that a vertex behind the eye never projects to a wrong place (see
:mod:`walkstream.shared.portals` for why the plane is not the camera's near plane).
Pure numpy, every set of a batch at once.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "CENTRE_MARGIN_PX",
    "TOUCH_MARGIN_PX",
    "BOX_EDGES",
    "full_vsa",
    "corner_secant",
    "point_rects",
    "clipped_rects",
    "ndc_pixels",
    "box_rects",
]


#: Pixels by which a projected rectangle is grown before its pixel centres are taken:
#: room for the float32 transform and the rasteriser's sub-pixel snapping, so a centre
#: the GPU may find inside an edge is never left out of the rectangle.
CENTRE_MARGIN_PX = 0.125

#: The margin that keeps every pixel a projection touches (the rule before the centres):
#: for a predicted view, which is a guess, so that a door about to open beyond a sliver
#: is fetched before it shows (the prefetch's portal walk, :mod:`walkstream.client.stream.rooms`).
TOUCH_MARGIN_PX = 0.5


def full_vsa(size: tuple[int, int]) -> NDArray[np.int64]:
    """The whole viewport ``(4,)`` as a VSA."""
    return np.array([0, 0, int(size[0]) - 1, int(size[1]) - 1], np.int64)


def corner_secant(proj: NDArray[np.float64]) -> float:
    """Secant of the angle between the view axis and the frustum's corner rays."""
    tx, ty = 1.0 / abs(float(proj[0, 0])), 1.0 / abs(float(proj[1, 1]))
    return math.sqrt(1.0 + tx * tx + ty * ty)


def point_rects(
    pts: NDArray[np.float64],
    edges: NDArray[np.int64],
    view: NDArray[np.float64],
    proj: NDArray[np.float64],
    size: tuple[int, int],
    clip_m: float,
    naive: bool = False,
    margin_px: float = CENTRE_MARGIN_PX,
) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
    """Whole-pixel rectangles of point sets clipped against depth ``clip_m``.

    ``pts`` ``(m, k, 3)`` world points, ``edges`` ``(e, 2)`` the index pairs joining
    them (the polygon's sides or a box's edges).  Returns ``(m, 4)`` inclusive pixel
    rectangles (unclamped) and ``(m,)`` whether anything of each set lies in front;
    ``margin_px`` as in :func:`ndc_pixels`.
    """
    m = len(pts)
    if m == 0:
        return np.zeros((0, 4), np.int64), np.zeros(0, bool)
    # eye space (m, k, 3); one 2-d product (a stack of m small ones is several times slower)
    v = (pts.reshape(-1, 3) @ view[:3, :3].T + view[:3, 3]).reshape(pts.shape)
    if naive:
        # the paper's Figure 4: culled only when every vertex is behind the eye; the
        # others projected as they are, a vertex behind the eye flipped through it
        h = np.concatenate([v, np.ones((*v.shape[:2], 1))], axis=2) @ proj.T
        w = np.where(np.abs(h[..., 3]) < 1e-12, 1e-12, h[..., 3])
        ndc = h[..., :2] / w[..., None]
        front = np.any(-v[..., 2] > 0, axis=1)
        lo, hi = ndc.min(axis=1), ndc.max(axis=1)
    else:
        depth = -v[..., 2]
        near_d, far_d = _kmin(depth), _kmax(depth)
        ahead = near_d >= clip_m
        front = np.ones(m, bool)
        # the common case, nothing to clip: the vertices' projections bound the set;
        # computed for every row (elementwise, so each row's figures are the same as
        # alone) and the others overwritten below
        d = np.where(ahead[:, None], depth, 1.0)
        x = (proj[0, 0] * v[..., 0] + proj[0, 2] * v[..., 2]) / d
        y = (proj[1, 1] * v[..., 1] + proj[1, 2] * v[..., 2]) / d
        rect = ndc_pixels(np.stack([_kmin(x), _kmin(y)], axis=1), np.stack([_kmax(x), _kmax(y)], axis=1), size,
                          margin_px)
        behind = far_d < clip_m
        front[behind] = False
        rect[behind] = (1, 1, 0, 0)
        rest = ~ahead & ~behind
        if rest.any():
            rect[rest], front[rest] = clipped_rects(v[rest], depth[rest], edges, proj, size, clip_m, margin_px)
        return rect, front
    return ndc_pixels(lo, hi, size, margin_px), front


def _kmin(a: NDArray[np.float64]) -> NDArray[np.float64]:
    """``(m,)`` minima over the second axis of ``(m, k)``: ``k - 1`` elementwise minima,
    cheaper than a reduction along a short axis for the few vertices of a portal or box."""
    out = a[:, 0].copy()
    for j in range(1, a.shape[1]):
        np.minimum(out, a[:, j], out=out)
    return out


def _kmax(a: NDArray[np.float64]) -> NDArray[np.float64]:
    """``(m,)`` maxima over the second axis of ``(m, k)`` (see :func:`_kmin`)."""
    out = a[:, 0].copy()
    for j in range(1, a.shape[1]):
        np.maximum(out, a[:, j], out=out)
    return out


def clipped_rects(
    v: NDArray[np.float64],
    depth: NDArray[np.float64],
    edges: NDArray[np.int64],
    proj: NDArray[np.float64],
    size: tuple[int, int],
    clip_m: float,
    margin_px: float = CENTRE_MARGIN_PX,
) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
    """:func:`point_rects` of eye-space point sets ``(m, k, 3)`` that cross the clip plane."""
    a, b = v[:, edges[:, 0]], v[:, edges[:, 1]]  # (m, e, 3)
    da, db = depth[:, edges[:, 0]], depth[:, edges[:, 1]]
    cross = (da - clip_m) * (db - clip_m) < 0
    t = np.where(cross, (clip_m - da) / np.where(cross, db - da, 1.0), 0.0)
    xpts = a + t[..., None] * (b - a)
    allp = np.concatenate([v, xpts], axis=1)  # (m, k + e, 3)
    ok = np.concatenate([depth >= clip_m, cross], axis=1)
    d = np.where(ok, -allp[..., 2], 1.0)
    # a perspective projection: x_ndc = (P00 x + P02 z) / -z, likewise y
    x = (proj[0, 0] * allp[..., 0] + proj[0, 2] * allp[..., 2]) / d
    y = (proj[1, 1] * allp[..., 1] + proj[1, 2] * allp[..., 2]) / d
    front = np.any(ok, axis=1)
    big = 1e30
    lo = np.stack([np.where(ok, x, big).min(axis=1), np.where(ok, y, big).min(axis=1)], axis=1)
    hi = np.stack([np.where(ok, x, -big).max(axis=1), np.where(ok, y, -big).max(axis=1)], axis=1)
    return ndc_pixels(lo, hi, size, margin_px), front


def ndc_pixels(
    lo: NDArray[np.float64], hi: NDArray[np.float64], size: tuple[int, int], margin_px: float = CENTRE_MARGIN_PX
) -> NDArray[np.int64]:
    """NDC bounds ``(m, 2)`` each to inclusive whole-pixel rectangles ``(m, 4)``: the pixels
    whose centre lies within the bounds grown by ``margin_px`` (empty, ``x0 > x1`` or
    ``y0 > y1``, when no centre does; module docstring).  ``margin_px`` 0.5 keeps every
    pixel the bounds touch (a predicted view's, :data:`TOUCH_MARGIN_PX`)."""
    wh = np.array([size[0], size[1]], np.float64)
    plo = np.clip((lo + 1.0) * 0.5 * wh, -1e9, 1e9)
    phi = np.clip((hi + 1.0) * 0.5 * wh, -1e9, 1e9)
    # pixel i's centre is at i + 0.5: the first centre at or after plo, the last at or before phi
    return np.concatenate(
        [np.ceil(plo - 0.5 - margin_px), np.floor(phi - 0.5 + margin_px)], axis=1
    ).astype(np.int64)


BOX_EDGES = np.array(
    [[0, 1], [2, 3], [4, 5], [6, 7], [0, 2], [1, 3], [4, 6], [5, 7], [0, 4], [1, 5], [2, 6], [3, 7]], np.int64
)


def box_rects(
    lo: ArrayLike, hi: ArrayLike, view: ArrayLike, proj: ArrayLike, size: tuple[int, int], clip_m: float = 0.03
) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
    """Whole-pixel rectangles ``(n, 4)`` of boxes ``(n, 3)`` clipped at depth ``clip_m``, and
    ``(n,)`` whether any part of each box lies in front of that plane."""
    lo_ = np.asarray(lo, np.float64).reshape(-1, 3)
    hi_ = np.asarray(hi, np.float64).reshape(-1, 3)
    bits = (np.arange(8)[:, None] >> np.arange(3)[None, :]) & 1  # (8, 3)
    corners = np.where(bits[None, :, :] == 1, hi_[:, None, :], lo_[:, None, :])
    return point_rects(corners, BOX_EDGES, np.asarray(view, np.float64), np.asarray(proj, np.float64), size, clip_m)
