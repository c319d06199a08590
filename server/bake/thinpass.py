"""Which objects the ID render may miss for being under a pixel: the thin pass's candidates.

A cube face of 128 pixels over 90 degrees has 1.4 pixels a degree where a client's
640-pixel, 60-degree view has 10.7, so an object that projects below a bake pixel in
one direction (a street piece seen edge-on near the horizon, a low building hundreds
of metres off) falls between the pixel centres of every sample and is missed, while a
viewer sees it.  The thin pass of
:class:`~walkstream.server.bake.visibility.VisibilityRenderer` draws such objects
again after the fill, as their triangles' edges (one-pixel lines) and vertices
(one-pixel points), depth-tested against the fill without writing depth: a line or a
point marks every pixel it crosses however thin the object, so an object under a
pixel that is not behind the fill's depth at some pixel it touches is added.  The
occluders stay what the fill drew (nothing is grown but the object tested), so the
pass only ever adds objects.

This module picks the candidates, per sample point and cube face: objects drawn in the
face, not seen in the face by the fill, whose bounding box projects at most ``pixels``
pixels across in its narrower screen direction (small on screen from that point).
Restricting the pass to them keeps it cheap (most objects of a face are either seen
or large) and keeps the half-pixel growth of lines away from the large objects whose
edges merely touch an occluder's silhouette.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from walkstream.shared.arrays import F64, I64

__all__ = ["draw_thin_pass", "face_presence", "thin_candidates"]


def face_presence(rows: NDArray[np.uint32], resolution: int, points: int, n: int) -> NDArray[np.bool_]:
    """Which local ids (``1..n``) cover a pixel of each cube-face tile of an ID image.

    Parameters
    ----------
    rows : (points * resolution, 6 * resolution) uint32
        The ID image: face ``f`` of point ``i`` is the tile at rows ``i * res``,
        columns ``f * res``; 0 is "nothing".
    resolution : int
        Tile side, pixels.
    points : int
        Sample points in the image.
    n : int
        Number of objects (local ids ``1..n``).

    Returns
    -------
    (points * 6, n) bool
        Point-major, face-minor: row ``6 * i + f``.
    """
    res = int(resolution)
    tiles = rows[: points * res].reshape(points, res, 6, res).transpose(0, 2, 1, 3).reshape(points * 6, res * res)
    # one bincount over tile-offset ids: tile t's id k lands in bin t * (n + 1) + k
    offset = (np.arange(points * 6, dtype=np.int64) * (n + 1))[:, None]
    hits = np.bincount((tiles.astype(np.int64) + offset).reshape(-1), minlength=points * 6 * (n + 1))
    return (hits.reshape(points * 6, n + 1) > 0)[:, 1:]


def thin_candidates(
    points: F64,
    lo: F64,
    hi: F64,
    draw: NDArray[np.bool_],
    seen: NDArray[np.bool_],
    *,
    resolution: int,
    near: float,
    pixels: float,
) -> NDArray[np.bool_]:
    """The objects of each face that the thin pass draws again.

    Parameters
    ----------
    points : (p, 3) float64
        Sample points (eyes), scene-local metres.
    lo, hi : (n, 3) float64
        Bounding boxes of the objects, in the renderer's local order.
    draw : (p * 6, n) bool
        Objects drawn in each face (within the view distance and the face's frustum).
    seen : (p * 6, n) bool
        Objects that covered a pixel of the face in the fill (:func:`face_presence`).
    resolution : int
        Face side, pixels (the face spans 90 degrees: ``[-1, 1]`` in both screen axes).
    near : float
        Near plane, metres: a box reaching nearer than this is not small on screen.
    pixels : float
        Largest extent, in pixels, of a box's projection in its narrower screen
        direction (clipped to the face) for it to count as small.

    Returns
    -------
    (p * 6, n) bool
        Drawn, not seen by the fill, and small on screen in that face.

    Notes
    -----
    Face ``f`` looks along axis ``f // 2`` with sign ``+`` for even ``f`` (the order
    ``+x -x +y -y +z -z`` of the renderer's frusta); a point's screen coordinates in
    it are the two other axes over the depth, so the box's screen extent is the
    spread of its eight corners' ratios (the signs and the order of the two screen
    axes do not change an extent).
    """
    p, n = len(points), len(lo)
    out = np.zeros((p * 6, n), bool)
    want = draw & ~seen
    if not want.any():
        return out
    corners = _corners(lo, hi)  # (n, 8, 3)
    half = 0.5 * float(resolution)
    for i in range(p):
        rows = want[6 * i : 6 * i + 6]
        cand = np.flatnonzero(rows.any(axis=0))
        if len(cand) == 0:
            continue
        rel = corners[cand] - points[i]  # (c, 8, 3)
        for f in range(6):
            ci = cand[rows[f, cand]]
            if len(ci) == 0:
                continue
            a, s = f // 2, (1.0 if f % 2 == 0 else -1.0)
            b, c = [k for k in range(3) if k != a]
            r = rel[rows[f, cand]]
            depth = s * r[..., a]  # (k, 8)
            front = depth.min(axis=1) >= near
            d = np.maximum(depth, near)
            u = np.clip(r[..., b] / d, -1.0, 1.0)
            v = np.clip(r[..., c] / d, -1.0, 1.0)
            narrow = np.minimum(u.max(axis=1) - u.min(axis=1), v.max(axis=1) - v.min(axis=1)) * half
            out[6 * i + f, ci[front & (narrow <= pixels)]] = True
    return out


def _corners(lo: F64, hi: F64) -> F64:
    """The eight corners ``(n, 8, 3)`` of boxes ``lo, hi`` ``(n, 3)``."""
    pick = np.array([[(k >> a) & 1 for a in range(3)] for k in range(8)], bool)  # (8, 3)
    return np.where(pick[None, :, :], hi[:, None, :], lo[:, None, :])


def draw_thin_pass(
    r: Any, points: F64, draw: NDArray[np.bool_], rows: NDArray[np.uint32],
    used: tuple[int, int, int, int], mvps: NDArray[np.float32],
) -> I64:
    """Draw the thin pass's candidates over the finished fill of ``r``; their pixels per object (local index + 1).

    ``r`` is the :class:`~walkstream.server.bake.visibility.VisibilityRenderer` whose
    pass it is (not imported here: it imports this module).

    ``rows`` is read in (the fill's image) and overwritten with the pass's own
    image: only the candidates' ids, 0 elsewhere.
    """
    import moderngl

    from walkstream.server.bake.thindepth import DepthEroder

    ctx, fb = r.ctx, r._fb
    assert ctx is not None and fb is not None
    n = len(r._ids)
    seen = face_presence(rows, r.resolution, len(points), n)
    cand = thin_candidates(
        points, r._lo, r._hi, draw, seen, resolution=r.resolution, near=r.near, pixels=r.thin_pass
    )
    commands, offsets = r._unmerged_commands(cand)
    if r.thin_depth and len(commands):
        if r._eroder is None:
            r._eroder = DepthEroder(ctx, fb.size)
        r._eroder.erode(fb.fbo, used, r.resolution)
    # Colour only: with the depth mask off the clear keeps the fill's depth.
    fb.fbo.depth_mask = False
    ctx.depth_func = "<="
    ctx.disable(moderngl.CULL_FACE)  # an edge-on sliver may show only its back
    try:
        fb.fbo.clear(0.0, 0.0, 0.0, 0.0, viewport=used)
        if len(commands):
            if r._multi_draw:
                if commands.nbytes > r._indirect.size:
                    r._indirect.orphan(max(commands.nbytes, 2 * r._indirect.size))
                r._indirect.write(commands.tobytes())
            ctx.wireframe = True
            try:
                r._draw_faces(commands, offsets, mvps)
            finally:
                ctx.wireframe = False
            r._draw_faces(commands, offsets, mvps, moderngl.POINTS)
    finally:
        ctx.depth_func = "<"
        fb.fbo.depth_mask = True
        if r.cull_back_faces:
            ctx.enable(moderngl.CULL_FACE)
    fb.fbo.read_into(rows, viewport=used, components=1, dtype="u4", alignment=1)
    return np.bincount(rows.reshape(-1), minlength=n + 1)[: n + 1].astype(np.int64)
