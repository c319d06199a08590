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
Pure numpy, every set of a batch at once, coordinate-major (a handful of sets that
straddle the clip plane in plain floats, the same operations).  A caller may take an
unclipped superset for the sets that straddle the plane instead (:func:`crossing_rects`,
``clip_rest=False``): the parts culling does, a conservative rectangle at a quarter of
the calls.  A caller that tests the
rectangles against VSAs may take an unclipped superset for the sets that straddle the
plane (:func:`crossing_rects`) and clip exactly only those whose superset still meets
one (the parts culling, the portal walk's table).
"""

from __future__ import annotations

import functools
import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "CENTRE_MARGIN_PX",
    "TOUCH_MARGIN_PX",
    "BOX_EDGES",
    "full_vsa",
    "corner_secant",
    "point_rects",
    "coord_rects",
    "rects_ckm",
    "box_rects_ckm",
    "camera_rows",
    "crossing_rects",
    "clipped_box_rects",
    "RectBuffers",
    "box_corners_ckm",
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
    if not naive:
        return coord_rects(np.ascontiguousarray(pts.transpose(2, 1, 0)), edges, view, proj, size, clip_m, margin_px)
    # eye space (m, k, 3); one 2-d product (a stack of m small ones is several times slower)
    v = (pts.reshape(-1, 3) @ view[:3, :3].T + view[:3, 3]).reshape(pts.shape)
    # the paper's Figure 4: culled only when every vertex is behind the eye; the
    # others projected as they are, a vertex behind the eye flipped through it
    h = np.concatenate([v, np.ones((*v.shape[:2], 1))], axis=2) @ proj.T
    w = np.where(np.abs(h[..., 3]) < 1e-12, 1e-12, h[..., 3])
    ndc = h[..., :2] / w[..., None]
    front = np.any(-v[..., 2] > 0, axis=1)
    return ndc_pixels(ndc.min(axis=1), ndc.max(axis=1), size, margin_px), front


#: The empty rectangle (no pixel centre) of a set wholly behind the clip plane, as a column.
_EMPTY_COL = np.array([[1], [1], [0], [0]], np.int64)


def coord_rects(
    pts: NDArray[np.float64],
    edges: NDArray[np.int64],
    view: NDArray[np.float64],
    proj: NDArray[np.float64],
    size: tuple[int, int],
    clip_m: float,
    margin_px: float = CENTRE_MARGIN_PX,
) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
    """:func:`point_rects` (not naive) of point sets given coordinate-major, ``pts`` ``(3, k, m)``.

    The same figures as :func:`point_rects` at about two thirds of its cost: every
    array the frame's batch makes is a run of ``m`` (a coordinate of a vertex of every
    set), so each numpy call is one pass over long rows; the vertices' minima and
    maxima are reductions over the leading axis.
    """
    rect, front, _near, _far = rects_ckm(pts, edges, view, proj, size, clip_m, margin_px)
    return np.ascontiguousarray(rect.T), front


def rects_ckm(
    pts: NDArray[np.float64],
    edges: NDArray[np.int64],
    view: NDArray[np.float64],
    proj: NDArray[np.float64],
    size: tuple[int, int],
    clip_m: float,
    margin_px: float = CENTRE_MARGIN_PX,
    clip_rest: bool = True,
) -> tuple[NDArray[np.int64], NDArray[np.bool_], NDArray[np.float64], NDArray[np.float64]]:
    """:func:`coord_rects` with the rectangles coordinate-major too, ``(4, m)`` (rows ``x0, y0,
    x1, y1``), and each set's nearest and farthest vertex depth ``(m,)`` (``-z`` in eye space).

    Without ``clip_rest`` a set that crosses the clip plane (nearest depth below ``clip_m``,
    farthest at or beyond it) gets :func:`crossing_rects`' rectangle, a superset of its
    clipped one (conservative, not the same)."""
    m = pts.shape[2]
    if m == 0:
        z = np.zeros(0)
        return np.zeros((4, 0), np.int64), np.zeros(0, bool), z, z
    # the projection's numerators and the depth straight from world points: one 3 x 3
    # product (the camera's rows combined with the projection's) instead of the eye
    # space and four passes more over every vertex
    R = view[:3, :3]
    rows, shift = camera_rows(view, proj)
    shift = shift[:, None]
    q = (rows @ pts.reshape(3, -1) + shift).reshape(pts.shape)  # (3, k, m): x and y numerators, depth
    depth = q[2]
    near_d, far_d = depth.min(axis=0), depth.max(axis=0)
    ahead = near_d >= clip_m
    front = far_d >= clip_m
    # the common case, nothing to clip: the vertices' projections bound the set;
    # computed for every set (elementwise, so each set's figures are the same as
    # alone) and the others overwritten below
    # a set not wholly ahead divides by depths <= clip_m (0 or negative too): its figures
    # are overwritten below, so its infinities and NaNs are let through unseen
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        xy = q[:2] / depth
        rect = _pixels4(np.concatenate([xy.min(axis=1), xy.max(axis=1)]), size, margin_px, inplace=True)
    rect[:, ~front] = _EMPTY_COL
    rest = ~ahead & front
    if rest.any() and not clip_rest:
        rect[:, rest] = crossing_rects(q[:, :, rest], size, clip_m, margin_px)
    elif rest.any():
        # the sets that cross the clip plane, clipped in eye space
        part = pts[:, :, rest]
        v = (R @ part.reshape(3, -1) + view[:3, 3:4]).reshape(part.shape)
        rect[:, rest], front[rest] = _clipped(v, -v[2], edges, proj, size, clip_m, margin_px)
    return rect, front, near_d, far_d


def camera_rows(view: NDArray[np.float64], proj: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The camera's rows combined with the projection's, ``(3, 3)``, and their shift ``(3,)``:
    a world point ``p`` has x and y numerators and depth ``rows @ p + shift``.  Nine values,
    worked out in plain floats (the same IEEE products and sums as numpy's, without a
    numpy call per row: a frame makes this a few times)."""
    (r0, r1, r2), t = view[:3, :3].tolist(), view[:3, 3].tolist()
    p00, p02, p11, p12 = float(proj[0, 0]), float(proj[0, 2]), float(proj[1, 1]), float(proj[1, 2])
    rows = [[p00 * a + p02 * c for a, c in zip(r0, r2, strict=True)],
            [p11 * b + p12 * c for b, c in zip(r1, r2, strict=True)],
            [-c for c in r2]]
    shift = [p00 * t[0] + p02 * t[2], p11 * t[1] + p12 * t[2], -t[2]]
    return np.array(rows), np.array(shift)


def box_rects_ckm(
    lohi: NDArray[np.float64],
    view: NDArray[np.float64],
    proj: NDArray[np.float64],
    size: tuple[int, int],
    clip_m: float,
    margin_px: float = CENTRE_MARGIN_PX,
    work: RectBuffers | None = None,
    clip_rest: bool = True,
) -> tuple[NDArray[np.int64], NDArray[np.bool_], NDArray[np.float64], NDArray[np.float64]]:
    """:func:`rects_ckm` of boxes given by their two corners coordinate-major, ``lohi`` ``(3, 2, n)``
    (``lohi[j, 0]`` the lower, ``lohi[j, 1]`` the upper bound of coordinate ``j``).

    The same rectangles and depths as ``rects_ckm(box_corners_ckm(lo, hi), BOX_EDGES, ...)``
    (but for the order of three additions in a corner's sums; tests/test_partcull.py finds
    no rectangle that differs), with less work: a box's eight corners take their x, y and
    z from two values each, so the camera's rows are multiplied with the two bounds of each
    coordinate (18 products a box, not 72) and the corners are the 8 sums of one of each;
    no corner array is made but for the few boxes that cross the clip plane.  With
    ``work`` the temporaries are views of its buffers, made once and reused (the depths
    returned too: valid until ``work`` is used again): a fresh array of a few hundred kB
    per step costs more than the step (the allocator maps and faults its pages in anew).
    ``clip_rest`` as in :func:`rects_ckm`.
    """
    n = lohi.shape[2]
    if n == 0:
        z = np.zeros(0)
        return np.zeros((4, 0), np.int64), np.zeros(0, bool), z, z
    w = work if work is not None else RectBuffers()
    rows, shift = camera_rows(view, proj)
    prod = np.multiply(rows[:, :, None, None], lohi, out=w.take("prod", (3, 3, 2, n)))  # row, coordinate, bound
    prod[:, 0] += shift[:, None, None]
    # (3, 2, 2, 2, n): row, then the bound taken of x, y and z
    q = np.add(prod[:, 0, :, None, None], prod[:, 1, None, :, None], out=w.take("q1", (3, 2, 2, 1, n)))
    q = np.add(q, prod[:, 2, None, None, :], out=w.take("q", (3, 2, 2, 2, n))).reshape(3, 8, n)
    depth = q[2]
    near_d = np.minimum.reduce(depth, axis=0, out=w.take("near", (n,)))
    far_d = np.maximum.reduce(depth, axis=0, out=w.take("far", (n,)))
    ahead = near_d >= clip_m
    front = far_d >= clip_m
    b = w.take("bounds", (4, n))
    # as in rects_ckm, the boxes not wholly ahead are overwritten below
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        xy = np.divide(q[:2], depth, out=w.take("xy", (2, 8, n)))
        np.minimum.reduce(xy, axis=1, out=b[:2])
        np.maximum.reduce(xy, axis=1, out=b[2:])
        rect = _pixels4(b, size, margin_px, inplace=True)
    if not front.all():
        rect[:, ~front] = _EMPTY_COL
    rest = ~ahead & front
    if rest.any() and not clip_rest:
        rect[:, rest] = crossing_rects(q[:, :, rest], size, clip_m, margin_px)
    elif rest.any():
        # the boxes that cross the clip plane: their corners, clipped in eye space
        rect[:, rest], front[rest] = clipped_box_rects(lohi[:, 0, rest].T, lohi[:, 1, rest].T, view, proj, size,
                                                       clip_m, margin_px)
    return rect, front, near_d, far_d


def clipped_box_rects(
    lo: NDArray[np.float64],
    hi: NDArray[np.float64],
    view: NDArray[np.float64],
    proj: NDArray[np.float64],
    size: tuple[int, int],
    clip_m: float,
    margin_px: float = CENTRE_MARGIN_PX,
) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
    """The exact rectangles ``(4, m)`` of boxes ``(m, 3)`` that cross the clip plane, clipped
    in eye space (as :func:`box_rects_ckm` clips them), and ``(m,)`` whether any part is in front."""
    part = box_corners_ckm(lo, hi)
    v = (view[:3, :3] @ part.reshape(3, -1) + view[:3, 3:4]).reshape(part.shape)
    return _clipped(v, -v[2], BOX_EDGES, proj, size, clip_m, margin_px)


def crossing_rects(q: NDArray[np.float64], size: tuple[int, int], clip_m: float,
                   margin_px: float = CENTRE_MARGIN_PX) -> NDArray[np.int64]:
    """Rectangles ``(4, m)`` holding the clipped ones of point sets that cross the clip plane,
    without clipping: ``q`` ``(3, k, m)`` each point's x and y numerators and depth (as
    :func:`rects_ckm` makes them: ``x_ndc = q_0 / q_2``).

    The clipped set's projection is bounded by its vertices': the points in front
    (``q / depth``) and the points where its sides meet the plane.  The numerators are
    linear in the point, so such a point's lie between the set's least and greatest
    numerators, and its depth is ``clip_m``: the bounds of ``q / max(depth, clip_m)`` and
    of ``min q / clip_m``, ``max q / clip_m`` hold both (a point behind the plane adds a
    value within the latter).  Grown by a millionth of a pixel more than ``margin_px``
    for the roundings of the exact clip's own arithmetic.  About ten numpy calls for all
    the sets, against some forty (or a Python loop per set) for the exact clip.  Loose
    for a set reaching past the eye's sides (the numerators over ``clip_m`` are large),
    tight enough for the parts culling: on the generated offices' tours 4 of 70 crossing
    boxes (median) meet a VSA by it, and 1.5 % more boxes are kept than by the exact clip.
    """
    xy = q[:2] / np.maximum(q[2], clip_m)
    lo = np.minimum(xy.min(axis=1), q[:2].min(axis=1) / clip_m)
    hi = np.maximum(xy.max(axis=1), q[:2].max(axis=1) / clip_m)
    return _pixels4(np.concatenate([lo, hi]), size, margin_px + 1e-6, inplace=True)


class RectBuffers:
    """Reusable buffers for a batch's temporaries (:func:`box_rects_ckm`): one flat buffer per
    name, grown when a batch needs more, handed out as contiguous views.

    Not shared between threads.
    """

    def __init__(self) -> None:
        self._bufs: dict[tuple[str, str], NDArray[np.generic]] = {}

    def take(self, name: str, shape: tuple[int, ...], dtype: type = np.float64) -> NDArray[Any]:
        """A view ``shape`` of the buffer ``name`` (its contents are whatever it last held)."""
        need = math.prod(shape)
        key = (name, np.dtype(dtype).str)
        buf = self._bufs.get(key)
        if buf is None or len(buf) < need:
            buf = np.empty(max(need, 1024, 0 if buf is None else len(buf) * 3 // 2), dtype)
            self._bufs[key] = buf
        return buf[:need].reshape(shape)


def _pixels4(b: NDArray[np.float64], size: tuple[int, int], margin_px: float, inplace: bool = False) -> NDArray[np.int64]:
    """:func:`ndc_pixels` of bounds ``(4, m)`` (rows ``lo x, lo y, hi x, hi y``) in one pass,
    the rectangles ``(4, m)``: the same figures (``(b + 1) * 0.5 * w`` as ``(b + 1) * (w / 2)``:
    a halving is exact, so both are the one rounding of the exact product; a ceiling and a
    floor of the two halves); ``inplace`` works in ``b`` itself."""
    half_wh, margin = _columns(int(size[0]), int(size[1]), float(margin_px))
    p = b if inplace else b + 1.0
    if inplace:
        p += 1.0
    p *= half_wh
    np.minimum(p, 1e9, out=p)  # np.clip's bounds, without its per-call cost
    np.maximum(p, -1e9, out=p)
    p -= 0.5
    p += margin
    # the first centre at or after the low side, the last at or before the high one
    np.ceil(p[:2], out=p[:2])
    np.floor(p[2:], out=p[2:])
    return p.astype(np.int64)


@functools.lru_cache(maxsize=16)
def _columns(w: int, h: int, margin_px: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Half the viewport's size and the margin as ``(4, 1)`` columns for :func:`_pixels4`
    (made once per size and margin; read only)."""
    half_wh = np.array([[w], [h], [w], [h]], np.float64) * 0.5
    margin = np.array([[-margin_px], [-margin_px], [margin_px], [margin_px]])
    half_wh.flags.writeable = margin.flags.writeable = False
    return half_wh, margin


def clipped_rects(
    v: NDArray[np.float64],
    depth: NDArray[np.float64],
    edges: NDArray[np.int64],
    proj: NDArray[np.float64],
    size: tuple[int, int],
    clip_m: float,
    margin_px: float = CENTRE_MARGIN_PX,
) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
    """:func:`point_rects` of eye-space point sets ``(m, k, 3)`` that cross the clip plane
    (``depth`` ``(m, k)``, their depths ``-z``)."""
    rect, front = _clipped(np.ascontiguousarray(v.transpose(2, 1, 0)), np.ascontiguousarray(depth.T), edges, proj,
                           size, clip_m, margin_px)
    return np.ascontiguousarray(rect.T), front


def _clipped(
    v: NDArray[np.float64],
    depth: NDArray[np.float64],
    edges: NDArray[np.int64],
    proj: NDArray[np.float64],
    size: tuple[int, int],
    clip_m: float,
    margin_px: float,
) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
    """:func:`clipped_rects` of eye-space sets coordinate-major, ``v`` ``(3, k, m)``, ``depth``
    ``(k, m)``: the vertices in front and the points where the sides cross the plane,
    projected; x and y side by side, so each step is one numpy call for both.  The
    rectangles come coordinate-major, ``(4, m)``."""
    if v.shape[2] <= _FEW:
        return _clipped_few(v, depth, edges, proj, size, clip_m, margin_px)
    a, b = v[:, edges[:, 0]], v[:, edges[:, 1]]  # (3, e, m)
    da, db = depth[edges[:, 0]], depth[edges[:, 1]]
    cross = (da - clip_m) * (db - clip_m) < 0
    t = np.where(cross, (clip_m - da) / np.where(cross, db - da, 1.0), 0.0)
    allp = np.concatenate([v, a + t * (b - a)], axis=1)  # (3, k + e, m)
    ok = np.concatenate([depth >= clip_m, cross], axis=0)
    d = np.where(ok, -allp[2], 1.0)
    # a perspective projection: x_ndc = (P00 x + P02 z) / -z, likewise y
    xy = (np.array([[[proj[0, 0]]], [[proj[1, 1]]]]) * allp[:2]
          + np.array([[[proj[0, 2]]], [[proj[1, 2]]]]) * allp[2]) / d
    big = 1e30
    lo = np.where(ok, xy, big).min(axis=1)
    hi = np.where(ok, xy, -big).max(axis=1)
    return _pixels4(np.concatenate([lo, hi]), size, margin_px), np.any(ok, axis=0)


#: Sets up to which :func:`_clipped` works in plain floats (a frame clips a handful or two:
#: the portals and boxes that straddle the eye's plane; some forty numpy calls cost more).
_FEW = 16


def _clipped_few(
    v: NDArray[np.float64],
    depth: NDArray[np.float64],
    edges: NDArray[np.int64],
    proj: NDArray[np.float64],
    size: tuple[int, int],
    clip_m: float,
    margin_px: float,
) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
    """:func:`_clipped` of a few sets in plain Python floats: the same operations in the
    same order (IEEE doubles either way), so the same rectangles."""
    p00, p02, p11, p12 = float(proj[0, 0]), float(proj[0, 2]), float(proj[1, 1]), float(proj[1, 2])
    w, h = float(size[0]), float(size[1])
    pairs = edges.tolist()
    big = 1e30
    out: list[list[int]] = [[], [], [], []]
    fronts = []
    for pts, dep in zip(v.transpose(2, 1, 0).tolist(), depth.T.tolist(), strict=True):
        xlo = ylo = big
        xhi = yhi = -big
        front = False
        for (x, y, z), d in zip(pts, dep, strict=True):
            if d >= clip_m:
                front = True
                px, py = (p00 * x + p02 * z) / d, (p11 * y + p12 * z) / d
                if px < xlo:
                    xlo = px
                if px > xhi:
                    xhi = px
                if py < ylo:
                    ylo = py
                if py > yhi:
                    yhi = py
        for i, j in pairs:
            da, db = dep[i], dep[j]
            if (da - clip_m) * (db - clip_m) < 0:
                t = (clip_m - da) / (db - da)
                a, b = pts[i], pts[j]
                x, y, z = a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]), a[2] + t * (b[2] - a[2])
                px, py = (p00 * x + p02 * z) / -z, (p11 * y + p12 * z) / -z
                if px < xlo:
                    xlo = px
                if px > xhi:
                    xhi = px
                if py < ylo:
                    ylo = py
                if py > yhi:
                    yhi = py
        fronts.append(front)
        for row, ndc, wh, sign in ((0, xlo, w, -1.0), (1, ylo, h, -1.0), (2, xhi, w, 1.0), (3, yhi, h, 1.0)):
            q = min(max((ndc + 1.0) * 0.5 * wh, -1e9), 1e9) - 0.5 + sign * margin_px
            out[row].append(math.ceil(q) if sign < 0 else math.floor(q))
    return np.array(out, np.int64).reshape(4, -1), np.array(fronts, bool)


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
    return coord_rects(box_corners_ckm(lo_, hi_), BOX_EDGES, np.asarray(view, np.float64),
                       np.asarray(proj, np.float64), size, clip_m)


def box_corners_ckm(lo: NDArray[np.float64], hi: NDArray[np.float64]) -> NDArray[np.float64]:
    """The corners of boxes ``(n, 3)`` coordinate-major, ``(3, 8, n)`` (as :func:`coord_rects`
    takes them), in the order :data:`BOX_EDGES` joins."""
    return np.where(_CORNER_BITS[:, :, None], hi.T[:, None, :], lo.T[:, None, :])


#: ``(3, 8)`` whether corner ``c`` of a box takes coordinate ``j`` from its upper corner
#: (bit ``j`` of ``c``), the order :data:`BOX_EDGES` joins.
_CORNER_BITS = ((np.arange(8)[None, :] >> np.arange(3)[:, None]) & 1).astype(bool)
