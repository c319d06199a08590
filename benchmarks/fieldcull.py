"""The dense visibility field's points rendered with exact occlusion culling: tried, measured, not the bake's.

``walkstream bench field`` times it against the bake's ID renderer
(:class:`~walkstream.server.bake.visibility.VisibilityRenderer`, whose
``each_point_counts`` renders the field) on the same points and compares the counts.
It is kept here, beside its benchmark, because on Mesa's llvmpipe it does not pay:
it sets up 60 % fewer triangles but the fill of the near objects, the redrawn faces,
the depth read-back and the tests in numpy cost as much (docs/benchmarks.md).

A field point's twelve cube faces see a few dozen objects, but every face draws
every object whose box meets its frustum within the view distance (on the demo city
about 2,300 triangles a face, of which a tenth show).  :class:`CulledRenderer` draws
each pass of points in two steps and leaves out what cannot show:

1. **Likely occluders first.**  In each face it draws the objects whose box lies
   within :data:`NEAR_RADIUS` of the eye and the objects the points already rendered
   within :data:`HINT_RADIUS` saw in that face direction; the other objects of the
   face are *candidates*.  Then it reads back the ids and the depth.
2. **A conservative test of every candidate** against that depth (a max-depth
   pyramid of each face, as a hierarchical Z-buffer; groups of objects first, then
   boxes, then the prism of an object's outline): a candidate strictly behind the
   drawn depth, by a margin, at every pixel its projection could touch is *hidden*.
   A face with a candidate that is not hidden gets it drawn over step 1's image, or,
   where it could tie in depth with an object drawn first that comes later in the
   draw order, is cleared and drawn again with both, in the one draw order.

Why the counts are the plain render's: the depth drawn in step 1 is never nearer
than the full image's, so a hidden candidate is strictly behind the full image at
every pixel it could cover; it wins no pixel and ties with none, and the objects
drawn keep their order where ties are possible.  What remains is the rasteriser's
own: llvmpipe fills a sliver seen edge-on at the horizon by one pixel more or less
depending on how the same triangles are split into draw calls (the plain renderer
with ``merge_gap=0`` and ``512`` differs the same way), so a culled pass may differ by
a pixel on such an object; the bench counts the points that differ.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.server.bake.visibility import VisibilityRenderer
from walkstream.shared.arrays import F64, I64
from walkstream.shared.gl import check_gl_error
from walkstream.shared.records import Mesh

__all__ = ["DEPTH_MARGIN", "HINT_RADIUS", "MIN_TRIANGLES", "NEAR_RADIUS", "PIXEL_MARGIN", "CulledRenderer"]

NEAR_RADIUS = 30.0
"""Metres: an object whose box is this close to the eye is drawn in the first step."""

MIN_TRIANGLES = 1000
"""A pass whose faces would draw fewer triangles than this each (on average) is drawn
plain: with little to leave out the two steps cost more than they save (a small
scene such as West Oakland's 1,580 triangles)."""

GROUP = 8
"""Objects (one after another in the draw order) tested first by their common box."""

HINT_RADIUS = 6.0
"""Metres: a point draws first what the points already rendered this close saw."""

DEPTH_MARGIN = 2e-6
"""Window depth (0..1) a candidate's box must be behind the drawn depth to be hidden:
about 30 steps of a 24-bit depth buffer, far more than the rounding of a fragment's
depth (at 10 m it is 2 mm; at 300 m 1.8 m)."""

PIXEL_MARGIN = 1
"""Pixels a candidate's projected hull is grown by before the test.  A rasteriser
fills a pixel whose centre is inside a triangle, so the pixels whose index is the
floor of the hull's bounds already hold every pixel it fills; the margin covers the
rounding of the projection in float32 on the GPU."""

HULL_VERTICES = 12
"""An object's outline with more corners than this is tested by its smallest turned
rectangle instead (fewer points to project, still around it)."""

WINDOW = 4
"""Texels per side of the window of the pyramid a candidate is tested on: the level
whose texels cover the candidate's pixels in at most this many per side."""


class CulledRenderer(VisibilityRenderer):
    """A :class:`~.visibility.VisibilityRenderer` that renders many nearby points faster.

    The same constructor (``near_radius``, ``occlusion`` and ``min_triangles`` besides); :meth:`field_counts`
    returns what :meth:`~.visibility.VisibilityRenderer.each_point_counts` returns, by the
    two steps of the module docstring.  With ``occlusion=False``, or with the edge pass
    on (its lines are not drawn by the two steps), it is ``each_point_counts``.

    Attributes
    ----------
    stats : dict
        Running totals: ``passes``, ``faces``, ``faces_redrawn``, ``triangles`` (set
        up by the two steps) and ``triangles_plain`` (what the plain render would set
        up), ``candidates`` and ``hidden`` (candidate tests and how many passed).
    """

    def __init__(
        self,
        meshes: Sequence[Mesh],
        object_ids: Sequence[int] | NDArray[np.integer[Any]],
        *,
        near_radius: float = NEAR_RADIUS,
        occlusion: bool = True,
        min_triangles: float = MIN_TRIANGLES,
        **options: Any,
    ) -> None:
        super().__init__(meshes, object_ids, **options)
        self.near_radius = float(near_radius)
        self.min_triangles = float(min_triangles)
        self.occlusion = bool(occlusion)
        # each face's view axes (right, up, backwards) as world axes and signs, (6, 3) each:
        # the cube's view rotations only permute the axes and flip signs
        rot = np.rint(self._face_rot).astype(np.int64)
        axes = np.abs(rot).argmax(axis=2)
        self._face_axes = (axes, np.take_along_axis(rot, axes[:, :, None], axis=2)[:, :, 0].astype(np.float64))
        self._tris = ((self._index_stop - self._index_first) // 3).astype(np.int64)
        self.stats: dict[str, int] = dict.fromkeys(
            ("passes", "passes_plain", "faces", "faces_redrawn", "faces_appended", "triangles", "triangles_plain", "candidates", "hidden"), 0)

    def _prepare_geometry(self, meshes: Sequence[Mesh], ids: I64) -> None:
        super()._prepare_geometry(meshes, ids)
        # before the vertices leave for the GPU: each object's points to project
        verts = self._verts
        # every object's later objects (in the draw order) whose boxes come within the
        # depth buffer's step at the view distance (4 steps of 2^-24: 1.5 m at 800 m)
        self.tie_gap = max(0.05, 4.0 * 2.0**-24 * self.view_distance**2 / self.near)
        self._later_touching = _later_touching(self._lo, self._hi, self.tie_gap)
        # the boxes of every GROUP objects in the draw order
        n = len(self._lo)
        ng = -(-n // GROUP)
        pad = ng * GROUP - n
        self._glo = np.concatenate([self._lo, np.repeat(self._lo[-1:], pad, axis=0)]).reshape(ng, GROUP, 3).min(axis=1) if n else np.zeros((0, 3))
        self._ghi = np.concatenate([self._hi, np.repeat(self._hi[-1:], pad, axis=0)]).reshape(ng, GROUP, 3).max(axis=1) if n else np.zeros((0, 3))
        self._corners = _prism_corners(
            verts[:, :3].view(np.float32).astype(np.float64), verts[:, 3].astype(np.int64) - 1, self._lo, self._hi)

    def _face_masks(self, points: F64) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
        """:meth:`~.visibility.VisibilityRenderer._face_masks`, every point at once.

        The same tests in the same float64 products (a loop of numpy calls per point
        was a fifth of a field point's time).
        """
        p, n = len(points), len(self._ids)
        draw = np.zeros((p, 6, n), bool)
        unsafe = np.zeros_like(draw)
        gap = np.maximum(np.maximum(self._lo - points.max(axis=0), points.min(axis=0) - self._hi), 0.0)
        reach2 = self.view_distance**2
        cand = np.flatnonzero(np.einsum("nk,nk->n", gap, gap) <= 3.0 * reach2)
        if len(cand) and p:
            lo = self._lo[cand][None] - points[:, None]  # (p, c, 3) boxes relative to each eye
            hi = self._hi[cand][None] - points[:, None]
            d = np.maximum(np.maximum(lo, -hi), 0.0)
            near_enough = np.einsum("pck,pck->pc", d, d) <= reach2
            if self.frustum_cull:
                best = hi @ self._w_pos.T + lo @ self._w_neg.T  # (p, c, 36)
                inside = (best >= self._t).reshape(p, len(cand), 6, 6).all(axis=3)  # (p, c, 6)
            else:
                inside = np.ones((p, len(cand), 6), bool)
            draw[:, :, cand] = (inside & near_enough[..., None]).transpose(0, 2, 1)
            unsafe[:, :, cand] = (inside & ~near_enough[..., None]).transpose(0, 2, 1)
        return draw.reshape(p * 6, n), unsafe.reshape(p * 6, n)

    # -- the public call -------------------------------------------------------------

    def field_counts(self, points: ArrayLike) -> list[tuple[I64, I64]]:
        """Per sample point, the pixels each object covers in its six cube faces.

        Parameters
        ----------
        points : (p, 3) float
            Sample points, scene-local metres; nearby points one after the other make
            the guesses good (the field gives each point at both heights in turn).

        Returns
        -------
        list of (ids, pixels)
            As :meth:`~.visibility.VisibilityRenderer.each_point_counts`.
        """
        if not self.occlusion or self.edge_pass or float(getattr(self, "thin_pass", 0)):
            return self.each_point_counts(points)
        pts = self._check_points(points)
        if not (len(pts) and len(self._ids)):
            return [(np.zeros(0, np.int64), np.zeros(0, np.int64)) for _ in pts]
        out: list[tuple[I64, I64]] = []
        seen = np.zeros((len(pts), 6, len(self._ids)), bool)  # what each point saw, per face
        last: NDArray[np.bool_] | None = None
        for s in range(0, len(pts), self.points_per_pass):
            batch = pts[s : s + self.points_per_pass]
            hint = None
            if s:
                # what the points rendered within HINT_RADIUS saw in each face direction,
                # else what the last pass saw
                d = np.hypot(*(batch[:, None, :2] - pts[None, :s, :2]).transpose(2, 0, 1))
                close = d <= HINT_RADIUS
                by_point = np.empty((len(batch), 6, len(self._ids)), bool)
                for i in range(len(batch)):
                    near_pts = np.flatnonzero(close[i])
                    by_point[i] = seen[near_pts].any(axis=0) if len(near_pts) else last
                hint = by_point.reshape(len(batch) * 6, -1)
            draw, unsafe = self._face_masks(batch)
            tris = int((draw @ self._tris).sum())
            if tris < self.min_triangles * len(draw):
                # too little to leave out: the plain pass (the same draws as ever)
                counts = np.zeros(len(self._ids) + 1, np.int64)
                plain: list[I64] = []
                self._render_pass(batch, counts, None, plain)
                own = np.array(plain, np.int64).reshape(len(batch), -1)
                faces = np.repeat(own[:, None, 1:] > 0, 6, axis=1).reshape(len(batch) * 6, -1)
                for name, v in (("passes", 1), ("passes_plain", 1), ("faces", len(draw)), ("triangles", tris),
                                ("triangles_plain", tris)):
                    self.stats[name] += v
            else:
                own, faces = self._culled_pass(batch, hint, (draw, unsafe))
            seen[s : s + len(batch)] = faces.reshape(len(batch), 6, -1)
            last = np.asarray(faces.reshape(len(batch), 6, -1).any(axis=0), bool)
            out.extend(self._ids_pixels(c) for c in own)
        assert self.ctx is not None
        check_gl_error(self.ctx, f"after rendering {len(pts)} field points")
        return out

    # -- one pass --------------------------------------------------------------------

    def _culled_pass(
        self, points: F64, hint: NDArray[np.bool_] | None, masks: tuple[NDArray[np.bool_], NDArray[np.bool_]]
    ) -> tuple[I64, NDArray[np.bool_]]:
        """Render up to ``points_per_pass`` points by the two steps.

        ``hint`` ``(p * 6, n)``: the objects to draw first in each face besides the
        near ones (None: every object).  Returns each point's counts ``(p, n + 1)``
        (index 0: nothing) and the objects each face shows ``(p * 6, n)``.
        """
        import moderngl

        ctx, fb = self.ctx, self._fb
        assert ctx is not None and fb is not None
        res, p, n = self.resolution, len(points), len(self._ids)
        draw, unsafe = masks
        if hint is None:
            first = draw
        else:
            gap = np.maximum(np.maximum(self._lo[None] - points[:, None], points[:, None] - self._hi[None]), 0.0)
            near = np.einsum("pnk,pnk->pn", gap, gap) <= self.near_radius**2
            first = draw & (np.repeat(near, 6, axis=0) | hint)
        cand = draw & ~first
        mvps = np.ascontiguousarray(np.transpose(self._face_mvps(points), (0, 2, 1)), np.float32)
        used = (0, 0, 6 * res, p * res)
        ids_img = self._pixels[: p * res]
        self._begin_pass(fb, None)
        try:
            # step 1; a merged range never bridges a candidate (it would be drawn)
            commands, offsets = self._upload(first, unsafe | cand)
            fb.fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0, viewport=used)
            self._draw_faces(commands, offsets, mvps)
            fb.fbo.read_into(ids_img, viewport=used, components=1, dtype="u4", alignment=1)
            drawn = int(commands[:, 0].sum()) // 3 if len(commands) else 0
            redraw = np.zeros(len(draw), bool)
            if cand.any():
                depth = np.empty((p * res, 6 * res), np.float32)
                fb.fbo.read_into(depth, viewport=used, components=1, attachment=-1, dtype="f4", alignment=1)
                hidden = self._hidden(cand, points, depth)
                fi, oj = np.nonzero(cand & ~hidden)
                self.stats["candidates"] += int(cand.sum())
                self.stats["hidden"] += int(hidden.sum())
                add = cand & ~hidden
                more = add.any(axis=1)
                # a face whose shown candidate could tie in depth with an object drawn
                # first that comes later in the draw order is drawn again in order; the
                # others get their shown candidates drawn over step 1's image
                redraw = self._may_tie(fi, oj, first, len(draw))
                append = more & ~redraw
                if more.any():
                    final = np.where(redraw[:, None], first | add, add & append[:, None])
                    commands, offsets = self._upload(final, unsafe | (draw & ~(first | add)))
                    for face in np.flatnonzero(redraw).tolist():
                        i, f = divmod(face, 6)
                        fb.fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0, viewport=(f * res, i * res, res, res))
                    self._draw_faces(commands, offsets, mvps)
                    fb.fbo.read_into(ids_img, viewport=used, components=1, dtype="u4", alignment=1)
                    drawn += int(commands[:, 0].sum()) // 3 if len(commands) else 0
                    self.stats["faces_appended"] += int(append.sum())
        finally:
            ctx.scissor = None
            if self.cull_back_faces:
                ctx.disable(moderngl.CULL_FACE)
        # one bincount over every tile: (face, id) pairs
        per_face = np.bincount((self._tile_keys(p) + ids_img).reshape(-1), minlength=p * 6 * (n + 1))
        per_face = per_face.reshape(p, 6, n + 1)
        self.stats["passes"] += 1
        self.stats["faces"] += p * 6
        self.stats["faces_redrawn"] += int(redraw.sum())
        self.stats["triangles"] += drawn
        self.stats["triangles_plain"] += int((draw @ self._tris).sum())
        own: I64 = per_face.sum(axis=1).astype(np.int64)
        return own, (per_face[:, :, 1:] > 0).reshape(p * 6, n)

    def _may_tie(self, fi: I64, oj: I64, first: NDArray[np.bool_], faces: int) -> NDArray[np.bool_]:
        """``(faces,)``: the faces where a shown candidate ``(fi, oj)`` comes before an
        object drawn first whose box is within :attr:`tie_gap` of its own.

        Two fragments at one pixel tie only where their surfaces are that close along
        the ray (the depth buffer's step at the view distance), so a candidate away
        from every later object of step 1 can be drawn after them.
        """
        out = np.zeros(faces, bool)
        if len(fi) == 0:
            return out
        offs, later = self._later_touching
        a, b = offs[oj], offs[oj + 1]
        lens = b - a
        if lens.sum() == 0:
            return out
        rows = np.repeat(fi, lens)
        take = np.repeat(a - np.cumsum(lens) + lens, lens) + np.arange(int(lens.sum()))
        hit = first[rows, later[take]]
        out[rows[hit]] = True
        return out

    def _tile_keys(self, p: int) -> I64:
        """``(p * res, 6 * res)``: each pixel's face times ``n + 1`` (a face and an id make one bin)."""
        keys: I64 | None = getattr(self, "_keys", None)
        if keys is None or keys.shape[0] < p * self.resolution:
            res, n = self.resolution, len(self._ids)
            rows = np.arange(self.points_per_pass * res)[:, None] // res
            keys = ((rows * 6 + np.arange(6 * res)[None, :] // res) * (n + 1)).astype(np.int64)
            self._keys = keys
        out: I64 = keys[: p * self.resolution]
        return out

    def _upload(self, mask: NDArray[np.bool_], unsafe: NDArray[np.bool_]) -> tuple[NDArray[np.uint32], I64]:
        """The draw commands of ``mask`` (never bridging ``unsafe``), written to the indirect buffer."""
        indirect = self._indirect
        assert indirect is not None
        commands, offsets = self._draw_commands(mask, unsafe)
        if self._multi_draw and len(commands):
            if commands.nbytes > indirect.size:
                indirect.orphan(max(commands.nbytes, 2 * indirect.size))
            indirect.write(commands.tobytes())
        return commands, offsets

    def _face_mvps(self, points: F64) -> F64:
        """``(p * 6, 4, 4)`` float64 projection-view matrix of every face (row-major)."""
        p = len(points)
        views = np.zeros((p, 6, 4, 4))
        views[:, :, :3, :3] = self._face_rot
        views[:, :, :3, 3] = -np.einsum("fij,pj->pfi", self._face_rot, points)
        views[:, :, 3, 3] = 1.0
        out: F64 = (self._proj @ views).reshape(p * 6, 4, 4)
        return out

    # -- the occlusion test ----------------------------------------------------------

    def _hidden(self, cand: NDArray[np.bool_], points: F64, depth: NDArray[np.float32]) -> NDArray[np.bool_]:
        """Which candidates ``(faces, n)`` are strictly behind the drawn depth.

        ``depth`` ``(p * res, 6 * res)`` is the window depth read back (face ``i * 6 + f``
        in the tile at row ``i``, column ``f``).  Hierarchically: the box of every
        :data:`GROUP` objects following one another in the draw order (near one another
        on the curve) first, then each object of a group not hidden whole by its box,
        then the objects their boxes leave by the prism of their outlines
        (:func:`_prism_corners`).  An object reaching the near plane is never hidden.
        """
        out = np.zeros_like(cand)
        faces = np.flatnonzero(cand.any(axis=1))
        if len(faces) == 0:
            return out
        pyramid = _max_pyramid(depth, self.resolution, faces)
        n = cand.shape[1]
        ng = -(-n // GROUP)
        padded = np.zeros((len(cand), ng * GROUP), bool)
        padded[:, :n] = cand
        gfi, gj = np.nonzero(padded.reshape(len(cand), ng, GROUP).any(axis=2))
        ghidden = self._boxes_behind(pyramid, faces, gfi, self._glo[gj], self._ghi[gj], points)
        whole = np.zeros((len(cand), ng), bool)
        whole[gfi[ghidden], gj[ghidden]] = True
        out[:] = cand & np.repeat(whole, GROUP, axis=1)[:, :n]
        fi, oj = np.nonzero(cand & ~out)
        if len(fi) == 0:
            return out
        hid = self._boxes_behind(pyramid, faces, fi, self._lo[oj], self._hi[oj], points)
        out[fi[hid], oj[hid]] = True
        rest = np.flatnonzero(~hid)
        if len(rest):
            fr, orr = fi[rest], oj[rest]
            axes, signs = self._face_axes
            ax, sg = axes[fr % 6], signs[fr % 6]
            rel = self._corners[orr] - points[fr // 6][:, None, :]  # (k, v, 3)
            view = np.take_along_axis(rel, np.broadcast_to(ax[:, None, :], rel.shape), axis=2)
            view *= sg[:, None, :]
            w = -view[..., 2]
            wmin = w.min(axis=1)
            ok = wmin > self.near * 1.001
            w = np.where(ok[:, None], w, 1.0)
            x, y = view[..., 0] / w, view[..., 1] / w
            hid2 = ok & self._behind(pyramid, np.searchsorted(faces, fr), x.min(axis=1), y.min(axis=1),
                                     x.max(axis=1), y.max(axis=1), np.where(ok, wmin, 1.0))
            out[fr[hid2], orr[hid2]] = True
        return out

    def _boxes_behind(
        self, pyramid: list[NDArray[np.float32]], faces: I64, fi: I64, lo: F64, hi: F64, points: F64
    ) -> NDArray[np.bool_]:
        """Whether each box ``lo, hi`` ``(m, 3)`` is strictly behind the depth of face ``fi``."""
        axes, signs = self._face_axes
        face = fi % 6
        ax, sg = axes[face], signs[face]  # (m, 3): right, up, backwards
        e = points[fi // 6]
        rows = np.arange(len(fi))[:, None]
        a = (lo - e)[rows, ax] * sg
        b = (hi - e)[rows, ax] * sg
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        # the distance along the face is minus the backwards axis
        wlo, whi = -hi[:, 2], -lo[:, 2]
        front = wlo > self.near * 1.001
        wl, wh = np.where(front, wlo, 1.0), np.where(front, whi, 1.0)
        bounds = [np.where(lo[:, k] <= 0, lo[:, k] / wl, lo[:, k] / wh) for k in (0, 1)]
        bounds += [np.where(hi[:, k] >= 0, hi[:, k] / wl, hi[:, k] / wh) for k in (0, 1)]
        x0, y0, x1, y1 = bounds
        out: NDArray[np.bool_] = front & self._behind(pyramid, np.searchsorted(faces, fi), x0, y0, x1, y1, wl)
        return out

    def _behind(
        self, pyramid: list[NDArray[np.float32]], slot: I64, xlo: F64, ylo: F64, xhi: F64, yhi: F64, wmin: F64
    ) -> NDArray[np.bool_]:
        """Whether a screen rectangle (tangents ``xlo..xhi``, ``ylo..yhi`` of a face) whose
        nearest point is ``wmin`` along the face is strictly behind every pixel's depth."""
        res = self.resolution
        proj = self._proj
        half = res / 2.0
        sx, sy = proj[0, 0], proj[1, 1]
        x0 = np.floor((sx * xlo + 1.0) * half).astype(np.int64) - PIXEL_MARGIN
        x1 = np.floor((sx * xhi + 1.0) * half).astype(np.int64) + PIXEL_MARGIN
        y0 = np.floor((sy * ylo + 1.0) * half).astype(np.int64) - PIXEL_MARGIN
        y1 = np.floor((sy * yhi + 1.0) * half).astype(np.int64) + PIXEL_MARGIN
        # window depth grows with the distance along the face: the nearest point is the least
        dmin = ((-proj[2, 2] * wmin + proj[2, 3]) / wmin + 1.0) / 2.0
        off = (x1 < 0) | (y1 < 0) | (x0 > res - 1) | (y0 > res - 1)  # no pixel of the tile
        x0, y0 = np.clip(x0, 0, res - 1), np.clip(y0, 0, res - 1)
        x1, y1 = np.clip(x1, 0, res - 1), np.clip(y1, 0, res - 1)
        far = np.zeros(len(slot), np.float32)
        level = np.full(len(slot), -1, np.int64)
        for lv in range(len(pyramid)):
            fits = (level < 0) & ((x1 >> lv) - (x0 >> lv) < WINDOW) & ((y1 >> lv) - (y0 >> lv) < WINDOW)
            level[fits] = lv
        for lv, img in enumerate(pyramid):
            sel = np.flatnonzero(level == lv)
            if len(sel) == 0:
                continue
            s = slot[sel]
            ax0, ax1, ay0, ay1 = x0[sel] >> lv, x1[sel] >> lv, y0[sel] >> lv, y1[sel] >> lv
            best = np.zeros(len(sel), np.float32)
            for dy in range(WINDOW):
                yy = np.minimum(ay0 + dy, ay1)
                for dx in range(WINDOW):
                    best = np.maximum(best, img[s, yy, np.minimum(ax0 + dx, ax1)])
            far[sel] = best
        out: NDArray[np.bool_] = off | (dmin > far + DEPTH_MARGIN)
        return out


def _later_touching(lo: F64, hi: F64, gap: float) -> tuple[I64, I64]:
    """For every box ``k``, the boxes after it that come within ``gap`` of it, as
    compressed rows ``(offsets (n + 1,), others)``."""
    import shapely

    n = len(lo)
    if n == 0:
        return np.zeros(1, np.int64), np.zeros(0, np.int64)
    boxes = shapely.box(lo[:, 0] - gap, lo[:, 1] - gap, hi[:, 0] + gap, hi[:, 1] + gap)
    a, b = shapely.STRtree(boxes).query(boxes, predicate="intersects")
    keep = (b > a) & (lo[b, 2] <= hi[a, 2] + 2 * gap) & (lo[a, 2] <= hi[b, 2] + 2 * gap)
    a, b = a[keep], b[keep]
    order = np.lexsort((b, a))
    a, b = a[order], b[order]
    offsets = np.searchsorted(a, np.arange(n + 1)).astype(np.int64)
    return offsets, b.astype(np.int64)


def _prism_corners(xyz: F64, obj: I64, lo: F64, hi: F64) -> F64:
    """``(n, v, 3)`` points around each object: its outline's convex hull in plan (or the
    hull's smallest turned rectangle, past :data:`HULL_VERTICES` corners) at the bottom
    and the top of its box, padded by repeating the first.

    ``xyz`` ``(m, 3)`` are the vertices, ``obj`` ``(m,)`` the object each belongs to;
    an object is inside the prism of its points, so its projection is inside theirs.
    """
    import shapely

    n = len(lo)
    order = np.argsort(obj, kind="stable")
    cuts = np.searchsorted(obj[order], np.arange(n + 1))
    rings: list[F64] = []
    for j in range(n):
        pts = xyz[order[cuts[j] : cuts[j + 1]], :2]
        hull = shapely.convex_hull(shapely.multipoints(pts)) if len(pts) else None
        if hull is None or hull.geom_type != "Polygon":
            ring = np.array([[lo[j, 0], lo[j, 1]], [hi[j, 0], lo[j, 1]], [hi[j, 0], hi[j, 1]], [lo[j, 0], hi[j, 1]]])
        else:
            if len(hull.exterior.coords) - 1 > HULL_VERTICES:
                hull = shapely.oriented_envelope(hull)
            ring = np.asarray(hull.exterior.coords)[:-1]
        rings.append(ring)
    v = max((len(r) for r in rings), default=1)
    out = np.empty((n, 2 * v, 3))
    for j, ring in enumerate(rings):
        full = np.concatenate([ring, np.repeat(ring[:1], v - len(ring), axis=0)])
        out[j, :v, :2] = full
        out[j, v:, :2] = full
        out[j, :v, 2] = lo[j, 2]
        out[j, v:, 2] = hi[j, 2]
    return out


def _max_pyramid(depth: NDArray[np.float32], res: int, faces: I64) -> list[NDArray[np.float32]]:
    """Max-depth pyramids of some faces' tiles: level ``L`` texel ``(y, x)`` holds the
    farthest depth of the tile's pixels ``(y >> L, x >> L)``; ``[level](faces, y, x)``."""
    p6 = depth.shape[0] // res * 6
    tiles = depth.reshape(p6 // 6, res, 6, res).transpose(0, 2, 1, 3).reshape(p6, res, res)[faces]
    size = 1 << max(0, (res - 1).bit_length())
    if size != res:
        # a power of two; the padding (depth 0) never raises a maximum
        padded = np.zeros((len(faces), size, size), np.float32)
        padded[:, :res, :res] = tiles
        tiles = padded
    levels = [np.ascontiguousarray(tiles)]
    while levels[-1].shape[1] > 1:
        t = levels[-1]
        rows = np.maximum(t[:, 0::2], t[:, 1::2])
        levels.append(np.maximum(rows[:, :, 0::2], rows[:, :, 1::2]))
    return levels
