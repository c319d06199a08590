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
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.shared.partcull import near_far
from walkstream.shared.screenrects import CENTRE_MARGIN_PX, box_rects

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

#: Each side's two ends in turn, as vertex indices (the sides of :data:`TRIANGLE_EDGES`).
_SIDE_ENDS = TRIANGLE_EDGES.reshape(-1)


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


def _eligible(mesh: _Mesh, min_triangles: int) -> NDArray[np.bool_]:
    """The parts of ``mesh`` that may be tested: at least ``min_triangles`` triangles, not a
    stand-in (made once per mesh and count)."""
    key = f"eligible {min_triangles}"
    got = mesh._cache.get(key)
    if got is None:
        got = np.diff(_packed(mesh)[1]) >= min_triangles
        if mesh.missing:
            got[np.asarray(mesh.missing, np.int64)] = False
        mesh._cache[key] = got
    return np.asarray(got, bool)


def _packed(mesh: _Mesh) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]:
    """:func:`cell_triangles` and the parts' boxes ``(parts, 3)`` (lower, upper), made once per mesh."""
    got = mesh._cache.get("triangles_ckm")
    if got is not None:
        return got
    per = [np.asarray(p.positions, np.float64)[np.asarray(p.indices, np.int64)].reshape(-1, 3, 3) for p in mesh.parts]
    counts = np.array([len(t) for t in per], np.int64)
    start = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    tri = np.concatenate(per) if per else np.zeros((0, 3, 3))
    box = [(t.reshape(-1, 3).min(axis=0), t.reshape(-1, 3).max(axis=0)) if len(t) else (np.zeros(3), np.zeros(3))
           for t in per]
    lo = np.array([b[0] for b in box]).reshape(-1, 3)
    hi = np.array([b[1] for b in box]).reshape(-1, 3)
    out = (np.ascontiguousarray(tri.transpose(2, 1, 0)), start, lo, hi)
    mesh._cache["triangles_ckm"] = out
    return out


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

    Returns
    -------
    int
        The number of parts dropped.
    """
    V, P = np.asarray(view, np.float64), np.asarray(proj, np.float64)
    planes = near_far(P)
    if planes is None:  # not a perspective projection (depth is not w): left as the boxes decided
        return 0
    # the candidates: kept parts of enough triangles, not stand-ins, of cells with VSAs
    cells: list[int] = []
    picks: list[NDArray[np.int64]] = []
    for c, m in masks.items():
        if c not in vsas or c not in meshes or not vsas[c]:
            continue
        able = _eligible(meshes[c], min_triangles)
        if len(able) != len(m):
            continue  # not the mesh the mask was made for: left as it is
        idx = np.flatnonzero(m & able)
        if len(idx):
            cells.append(c)
            picks.append(idx)
    if not cells:
        return 0
    lists = [vsas[c] for c in cells]
    kmax = max(map(len, lists))
    table = np.array([list(v) + [(1, 1, 0, 0)] * (kmax - len(v)) for v in lists], np.int64)  # (cells, kmax, 4)
    # only the parts whose box is not wholly inside a VSA, or is thin there: a box well
    # inside one mostly holds triangles that draw there, and testing them cost 3 times
    # the rest of the culling on the duplex's tour
    lo = np.concatenate([_packed(meshes[c])[2][i] for c, i in zip(cells, picks, strict=True)])
    hi = np.concatenate([_packed(meshes[c])[3][i] for c, i in zip(cells, picks, strict=True)])
    powner = np.repeat(np.arange(len(cells)), [len(i) for i in picks])
    brect, _front = box_rects(lo, hi, V, P, size, clip_m)
    v = table[powner]  # (parts, kmax, 4)
    b = brect[:, None, :]
    within = ((b[..., 0] >= v[..., 0]) & (b[..., 1] >= v[..., 1]) & (b[..., 2] <= v[..., 2]) & (b[..., 3] <= v[..., 3])
              & (b[..., 2] - b[..., 0] >= WIDE_PX - 1) & (b[..., 3] - b[..., 1] >= WIDE_PX - 1))
    inside = np.any(within, axis=1)
    tris: list[NDArray[np.float64]] = []
    part_of: list[NDArray[np.int64]] = []
    runs: list[NDArray[np.int64]] = []  # the tested parts' triangle counts, in order
    at = 0
    keep_cells = []
    for k, (c, idx) in enumerate(zip(cells, picks, strict=True)):
        idx = idx[~inside[at:at + len(idx)]]
        at += len(picks[k])
        if not len(idx):
            continue
        tri, start, _lo, _hi = _packed(meshes[c])
        # each candidate triangle's index into the cell's packed triangles, in order: the
        # parts' runs (not a pass over all the cell's triangles)
        first, counts = start[idx], start[idx + 1] - start[idx]
        ends = np.cumsum(counts)
        t = np.arange(int(ends[-1])) + np.repeat(first - (ends - counts), counts)
        tris.append(tri[:, :, t])
        part_of.append(np.repeat(idx, counts))
        runs.append(counts)
        keep_cells.append(k)
    if not keep_cells:
        return 0
    table = table[keep_cells]
    cells = [cells[k] for k in keep_cells]
    owner = np.repeat(np.arange(len(cells)), [len(p) for p in part_of])
    pts = np.concatenate(tris, axis=2)
    # a part shows when any of its triangles does (parts numbered across the cells)
    base = np.concatenate([[0], np.cumsum([len(masks[c]) for c in cells])])
    gid = np.concatenate([p + base[k] for k, p in enumerate(part_of)])
    vsa = table[owner]
    if len(gid) <= _ONE_ROUND:
        got = _shows(pts, vsa, V, P, size, clip_m, planes)
    else:
        # two rounds: each part's first triangles, then the rest of the parts none of whose
        # first showed (a part shows when any of its triangles does: the parts are the same)
        got = np.zeros(len(gid), bool)
        run = np.concatenate(runs)
        rank = np.arange(len(gid)) - np.repeat(np.cumsum(run) - run, run)  # each triangle's place in its part
        one = np.flatnonzero(rank < _FIRST_ROUND)
        got[one] = _shows(pts[:, :, one], vsa[one], V, P, size, clip_m, planes)
        settled = np.zeros(int(base[-1]), bool)
        settled[gid[one[got[one]]]] = True
        two = np.flatnonzero(~settled[gid])
        two = two[rank[two] >= _FIRST_ROUND]
        if len(two):
            got[two] = _shows(pts[:, :, two], vsa[two], V, P, size, clip_m, planes)
    shows = np.bincount(gid[got], minlength=int(base[-1])) > 0
    tested = np.zeros(int(base[-1]), bool)
    tested[gid] = True
    gone = tested & ~shows
    dropped = int(gone.sum())
    if dropped:
        for k, c in enumerate(cells):
            g = gone[base[k]:base[k + 1]]
            if g.any():
                masks[c][g] = False
    return dropped


def _shows(
    pts: NDArray[np.float64],
    vsa: NDArray[np.int64],
    view: NDArray[np.float64],
    proj: NDArray[np.float64],
    size: tuple[int, int],
    clip_m: float,
    planes: tuple[float, float],
) -> NDArray[np.bool_]:
    """Whether each triangle ``pts`` ``(3, 3, n)`` may draw a pixel centre inside one of its
    VSAs ``vsa`` ``(n, k, 4)`` (padded with empty rectangles).

    The triangle is clipped at depth ``clip_m`` (each side's part in front of that plane:
    a side's line projects to a line) and projected; it may draw there when its rectangle
    of pixel centres (:func:`~walkstream.shared.screenrects.ndc_pixels`' rule and margin)
    meets the VSA, no side's normal separates the two (a separating axis proves them
    apart: a triangle across a corner of a door's rectangle, or a long beam's face
    passing beside the view, whose screen box reaches into it while the triangle does
    not), and its depths reach between the near and far planes (``planes``).

    Cost: the same figures as testing every triangle's six side ends against every padded
    VSA, with less work: a triangle wholly in front of the plane (most) is its three
    vertices (its sides' ends are those, twice), the few across it are clipped in plain
    floats (:func:`_clipped_ends`), and only the triangles whose rectangle meets a VSA
    within the depths get their sides' test, against those VSAs alone.
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
    sx, sy = 0.5 * size[0], 0.5 * size[1]
    # window coordinates with pixel i's centre at i, of the three vertices; a triangle
    # across the plane or wholly behind it is overwritten below (its divisions unseen)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        x = np.clip((h[0] / depth + 1.0) * sx - 0.5, -1e9, 1e9)
        y = np.clip((h[1] / depth + 1.0) * sy - 0.5, -1e9, 1e9)
    xlo, xhi, ylo, yhi = x.min(axis=0), x.max(axis=0), y.min(axis=0), y.max(axis=0)
    ends = None
    if len(cut):
        ends = _clipped_ends(h[:, :, cut], depth[:, cut] - clip_m, size)
        ex, ey = ends
        xlo[cut], xhi[cut] = ex.min(axis=0), ex.max(axis=0)
        ylo[cut], yhi[cut] = ey.min(axis=0), ey.max(axis=0)
    r0 = np.ceil(xlo - CENTRE_MARGIN_PX)
    r1 = np.ceil(ylo - CENTRE_MARGIN_PX)
    r2 = np.floor(xhi + CENTRE_MARGIN_PX)
    r3 = np.floor(yhi + CENTRE_MARGIN_PX)
    # each triangle's rectangle cut to each of its VSAs: the pixel centres it may draw there
    b0 = np.maximum(r0[:, None], vsa[..., 0])
    b1 = np.maximum(r1[:, None], vsa[..., 1])
    b2 = np.minimum(r2[:, None], vsa[..., 2])
    b3 = np.minimum(r3[:, None], vsa[..., 3])
    meet = (b0 <= b2) & (b1 <= b3)  # (n, k)
    on = front & meet.any(axis=1) & (far_d >= planes[0]) & (near_d <= planes[1])
    ti, vi = np.nonzero(meet & on[:, None])  # the (triangle, VSA) pairs left to the sides' test
    if not len(ti):
        return on
    # each tested triangle's side ends (6, pairs): its vertices twice, or its clipped ends
    tri = np.flatnonzero(on)
    ex6 = x[_SIDE_ENDS][:, tri]
    ey6 = y[_SIDE_ENDS][:, tri]
    if ends is not None:
        where = np.searchsorted(tri, cut)
        hit = (where < len(tri))
        hit[hit] = tri[where[hit]] == cut[hit]
        ex6[:, where[hit]] = ends[0][:, hit]
        ey6[:, where[hit]] = ends[1][:, hit]
    k = np.searchsorted(tri, ti)
    ok = _separated(ex6[:, k], ey6[:, k], b0[ti, vi], b1[ti, vi], b2[ti, vi], b3[ti, vi])
    out = np.zeros(n, bool)
    out[ti[ok]] = True
    return out


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
