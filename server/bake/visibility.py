"""Visibility and average coverage hints (ACH) of a view cell, by rendering ID buffers.

This is the bake step of Marvie et al. (2003), section 2.1: for each view cell, six
90-degree cameras (the faces of a cube) at a few sample points near the corners of the
cell render every object with a unique id; the PVS is the set of ids that cover at
least one pixel of the 48 images and ``ACH_j = N_j / sum(N)`` where ``N_j`` is the
number of pixels object ``j`` covers over all images.  The sampling is not
conservative (an object seen only from the inside of the cell is missed);
:func:`~walkstream.server.bake.samples.dense_points` gives a denser set of viewpoints to
measure what it misses.

How it is made fast enough on a software rasteriser (Mesa llvmpipe):

* all objects live in ONE vertex buffer and ONE index buffer, in Hilbert-curve order of their
  bounding-box centres, so objects close to each other are contiguous and a
  frustum-culled set of objects becomes a few contiguous index ranges;
* each vertex carries the object's local index + 1 and the fragment shader writes it
  to an ``R32UI`` colour attachment (0 = nothing);
* all images of a cell are tiles of one framebuffer (a row of 6 faces per sample
  point, or of the 4 faces of a horizon band, :mod:`~walkstream.server.bake.faceset`),
  cleared once, read back once and counted with one ``np.bincount``;
* culling is vectorised numpy: per cell the distance to every bounding box, per cube
  face a 6-plane frustum test of every bounding box; the ranges of each face are drawn
  with one ``glMultiDrawElementsIndirect`` call (OpenGL 4.3; older contexts fall back
  to one draw per range)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.server.bake.draworder import frustum_planes, runs
from walkstream.server.bake.faceset import FaceSet
from walkstream.server.bake.idpack import pack_meshes
from walkstream.server.bake.thindepth import DepthEroder
from walkstream.server.bake.thinpass import draw_thin_pass
from walkstream.shared.errors import InputError, RenderError
from walkstream.shared.gl import (
    VERTEX_ID_FRAGMENT_SHADER,
    Framebuffer,
    Releasable,
    check_gl_error,
    create_context,
)
from walkstream.shared.records import Mesh

if TYPE_CHECKING:
    import moderngl


from walkstream.shared.arrays import F64, I64

__all__ = ["VisibilityRenderer", "pvs_from_counts"]


_VERTEX_SHADER = """
#version 330
uniform mat4 mvp;
in vec3 in_pos;
in uint in_id;
flat out uint v_id;
void main() {
    gl_Position = mvp * vec4(in_pos, 1.0);
    v_id = in_id;
}
"""

#: Bytes of one DrawElementsIndirectCommand (count, instanceCount, firstIndex,
#: baseVertex, baseInstance), the stride moderngl uses for render_indirect.
_INDIRECT_STRIDE = 20


# ------------------------------------------------------------------------ renderer


class VisibilityRenderer(Releasable):
    """Counts the pixels each object covers in cube-face ID images at sample points.

    Parameters
    ----------
    meshes : sequence of Mesh
        The objects, in scene-local metres (float32 positions near the origin).
    object_ids : sequence of int
        One non-negative id per mesh.  Several meshes may share an id (their pixels
        add up).
    resolution : int
        Width and height in pixels of each cube-face image.
    view_distance : float
        Far plane of every camera, metres; an object whose bounding box is farther
        than this from a sample point is not drawn for that point.
    near : float
        Near plane, metres (sample points must keep at least this far from walls).
    ctx : moderngl.Context, optional
        Context to render with; by default one is created (and released by
        :meth:`release`).  A context passed in is not released.
    max_points_per_pass : int
        Sample points rendered into one framebuffer (one clear and one read-back); the
        framebuffer is ``6 * resolution`` by ``max_points_per_pass * resolution``.
    cull_back_faces : bool
        Skip back-facing triangles (front faces are counter-clockwise, as
        :class:`~walkstream.shared.records.Mesh` winds them seen from outside).  For closed meshes
        seen from outside this changes nothing but halves the triangles the
        rasteriser sets up (2-3 times faster on llvmpipe); turn it off for meshes that
        are open or wound the other way.  Counts may differ by a few pixels where
        adjacent meshes leave sub-pixel cracks (a back face behind the crack is seen
        without culling).
    merge_gap : int
        Two visible index ranges of one face separated by at most this many indices of
        culled objects are drawn as one range.  On llvmpipe a draw costs about as much
        as 170 triangles, so bridging short gaps is cheaper; on a GPU it hardly matters.
    frustum_cull : bool
        Draw in each cube face only the objects whose bounding box meets its frustum
        (conservative: the counts are the same either way).  A reference that must
        not depend on any culling turns it off and draws every object within the view
        distance in every face.
    edge_pass : bool
        After the filled triangles of a face, draw their edges again as one-pixel
        lines (depth test ``<=``), so that an object thinner than a pixel still marks
        the pixels it crosses instead of falling between pixel centres: a street seen
        edge-on 60 m away is a band a third of a 128 px pixel high, caught or not by
        the row centres depending on the eye height.  A cheap stand-in for
        conservative rasterisation: it adds objects within about half a pixel of
        being visible (it does not open gaps narrower than a pixel between
        occluders).
    thin_pass : float
        After the fill, draw again the objects each face did not show whose bounding
        box projects at most this many pixels across in its narrower screen direction,
        as one-pixel lines (their edges) and points (their vertices), depth-tested
        against the fill without writing depth: an object under a pixel is added
        when it is not behind the fill at some pixel it touches
        (:mod:`~walkstream.server.bake.thinpass`).  Only the tested objects are
        drawn thicker, never the occluders, so the pass only adds.  0: off.
    thin_depth : bool
        Test the thin pass against the fill's depth taken as the farthest over each
        pixel's 3 x 3 neighbours (:mod:`~walkstream.server.bake.thindepth`): every
        occluder shrunk by a pixel for that test, so what a pixel centre on an
        occluder's silhouette hides is not taken as hidden.
    band : float
        0 (default): the six faces of a cube, ``resolution`` pixels square.  Otherwise
        a horizon band (:meth:`~walkstream.server.bake.faceset.FaceSet.band`): the four
        sideways faces, ``resolution`` pixels across, cut to this many degrees above
        and below the horizon (the far field at a client's pixel size, :mod:`~.farband`).

    Raises
    ------
    InputError
        On inconsistent arguments.
    RenderError
        When no OpenGL context can be made or a GL object cannot be created.

    Notes
    -----
    The renderer is deterministic: the same meshes and points give the same counts
    (the rasteriser's coverage rules do not depend on draw order and the depth test
    is ``<``, so ties keep the object drawn first, and objects are always drawn in
    the same order).
    """

    def __init__(
        self,
        meshes: Sequence[Mesh],
        object_ids: Sequence[int] | NDArray[np.integer[Any]],
        *,
        resolution: int = 128,
        view_distance: float = 800.0,
        near: float = 0.1,
        ctx: moderngl.Context | None = None,
        max_points_per_pass: int = 16,
        cull_back_faces: bool = True,
        merge_gap: int = 512,
        frustum_cull: bool = True,
        edge_pass: bool = False,
        thin_pass: float = 0.0,
        thin_depth: bool = False,
        band: float = 0.0,
    ) -> None:
        ids = np.asarray(object_ids, dtype=np.int64).reshape(-1)
        if len(ids) != len(meshes):
            raise InputError(
                f"VisibilityRenderer.object_ids: expected {len(meshes)} ids (one per mesh), "
                f"got {len(ids)}"
            )
        if len(ids) and ids.min() < 0:
            raise InputError(f"VisibilityRenderer.object_ids: expected ids >= 0, got {ids.min()}")
        if int(resolution) < 1:
            raise InputError(f"VisibilityRenderer.resolution: expected >= 1, got {resolution}")
        if not 0.0 < float(near) < float(view_distance) < math.inf:
            raise InputError(
                "VisibilityRenderer: expected 0 < near < view_distance < inf, got "
                f"near={near}, view_distance={view_distance}"
            )
        if int(max_points_per_pass) < 1:
            raise InputError(
                f"VisibilityRenderer.max_points_per_pass: expected >= 1, got {max_points_per_pass}"
            )
        if not 0.0 <= float(thin_pass) < math.inf:
            raise InputError(f"VisibilityRenderer.thin_pass: expected >= 0 pixels, got {thin_pass}")
        if int(merge_gap) < 0:
            raise InputError(f"VisibilityRenderer.merge_gap: expected >= 0, got {merge_gap}")
        if not 0.0 <= float(band) < 45.0:
            raise InputError(f"VisibilityRenderer.band: expected 0 <= degrees < 45, got {band}")
        if band and thin_pass:
            raise InputError("VisibilityRenderer: the thin pass works on cube faces, not on a horizon band")
        self.resolution = int(resolution)
        self.view_distance = float(view_distance)
        self.near = float(near)
        self.cull_back_faces = bool(cull_back_faces)
        self.merge_gap = int(merge_gap)
        self.frustum_cull = bool(frustum_cull)
        self.edge_pass = bool(edge_pass)
        self.thin_pass = float(thin_pass)
        self.thin_depth = bool(thin_depth)
        self.band = float(band)
        self._faces = FaceSet.band(self.resolution, self.band) if self.band else FaceSet.cube(self.resolution)
        self._eroder: DepthEroder | None = None
        self._prepare_geometry(meshes, ids)

        self._own_ctx = ctx is None
        self.ctx: moderngl.Context | None = None
        self._prog: moderngl.Program | None = None
        self._vbo: moderngl.Buffer | None = None
        self._ibo: moderngl.Buffer | None = None
        self._vao: moderngl.VertexArray | None = None
        self._indirect: moderngl.Buffer | None = None
        self._fb: Framebuffer | None = None
        try:
            self.ctx = create_context() if ctx is None else ctx
            limit = int(self.ctx.info["GL_MAX_RENDERBUFFER_SIZE"])
            nf, (tw, th) = len(self._faces), self._faces.tile
            if nf * tw > limit:
                raise InputError(
                    f"VisibilityRenderer.resolution: {nf} * {tw} exceeds the "
                    f"driver's maximum framebuffer size {limit}"
                )
            self.points_per_pass = max(1, min(int(max_points_per_pass), limit // th))
            # glMultiDrawElementsIndirect is core in OpenGL 4.3; older contexts (e.g. macOS
            # 4.1) draw range by range instead.
            self._multi_draw = self.ctx.version_code >= 430
            self._create_gl_objects()
            check_gl_error(self.ctx, "after creating the visibility renderer")
        except BaseException:
            self.release()
            raise
        self._w_pos, self._w_neg, self._t = frustum_planes(self.near, self.view_distance)
        self._proj = self._faces.projection(self.near, self.view_distance)
        # The face rotations are the same at every point; only the translation
        # (-R @ eye) changes, so the per-point matrices are one vectorised product.
        self._face_rot = self._faces.rotations

    # -- setup ---------------------------------------------------------------------

    def _prepare_geometry(self, meshes: Sequence[Mesh], ids: I64) -> None:
        """Pack the meshes in Hilbert-curve order (:func:`~.idpack.pack_meshes`) and keep the result."""
        packed = pack_meshes(meshes, ids)
        #: object id of each drawn object, in draw (Hilbert-curve) order
        self._ids = packed.ids
        self._lo, self._hi = packed.lo, packed.hi
        self.object_ids = ids.copy()
        self.object_ids.flags.writeable = False
        self._index_first, self._index_stop = packed.index_first, packed.index_stop
        self._verts, self._index = packed.verts, packed.index

    def _create_gl_objects(self) -> None:
        ctx = self.ctx
        assert ctx is not None
        self._prog = ctx.program(vertex_shader=_VERTEX_SHADER, fragment_shader=VERTEX_ID_FRAGMENT_SHADER)
        self._mvp = cast("moderngl.Uniform", self._prog["mvp"])
        # Empty buffers are not allowed; a 16-byte placeholder keeps an empty scene valid.
        self._vbo = ctx.buffer(self._verts.tobytes() if len(self._verts) else bytes(16))
        self._ibo = ctx.buffer(self._index.tobytes() if len(self._index) else bytes(12))
        self._vao = ctx.vertex_array(
            self._prog,
            [(self._vbo, "3f4 u4", "in_pos", "in_id")],
            index_buffer=self._ibo,
            index_element_size=4,
        )
        self._indirect = ctx.buffer(reserve=_INDIRECT_STRIDE * 1024, dynamic=True)
        nf, (tw, th) = len(self._faces), self._faces.tile
        self._fb = Framebuffer(ctx, (nf * tw, self.points_per_pass * th), 1, "u4")
        self._pixels = np.empty((self.points_per_pass * th, nf * tw), np.uint32)
        # The CPU copies are not needed once uploaded.
        del self._verts, self._index

    # -- culling -------------------------------------------------------------------

    def _face_masks(self, points: F64) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
        """Which objects to draw in each cube face of each point.

        Returns
        -------
        draw : (p * 6, n) bool
            The object's box meets the face's frustum and is within the view distance
            of the point.
        unsafe : (p * 6, n) bool
            Not drawn but could show pixels if it were: its box meets the frustum (the
            far plane is a depth, so a box farther than the view distance can still be
            in front of it).  Merged draw ranges must not include these.
        """
        p, nf = len(points), len(self._faces)
        draw = np.zeros((p, nf, len(self._ids)), bool)
        unsafe = np.zeros_like(draw)
        # Per cell, one O(n) box-to-box test first: in a 90-degree face the distance to
        # a visible point is at most sqrt(3) times its depth, so boxes farther than
        # sqrt(3) * view_distance from the points' bounding box are clipped by the far
        # plane in every face; they skip the per-point tests (cheap in big scenes).
        gap = np.maximum(
            np.maximum(self._lo - points.max(axis=0), points.min(axis=0) - self._hi), 0.0
        )
        reach2 = self.view_distance**2
        cand = np.flatnonzero(np.einsum("nk,nk->n", gap, gap) <= 3.0 * reach2)
        if len(cand) == 0:
            return draw.reshape(p * nf, -1), unsafe.reshape(p * nf, -1)
        lo_c, hi_c = self._lo[cand], self._hi[cand]
        for i, eye in enumerate(points):  # a loop over points bounds memory to (c, 36)
            lo, hi = lo_c - eye, hi_c - eye  # boxes relative to the eye
            d = np.maximum(np.maximum(lo, -hi), 0.0)
            near_enough = np.einsum("ck,ck->c", d, d) <= reach2
            if self.frustum_cull:
                best = hi @ self._w_pos.T + lo @ self._w_neg.T  # (c, 36): box maxima per plane
                # (c, 6) per cube face; a band's faces are the cube's sideways ones, cut
                # short: culled by the cube face's frustum (conservative)
                inside = (best >= self._t).reshape(len(cand), 6, 6).all(axis=2)[:, self._faces.cube_faces]
            else:
                inside = np.ones((len(cand), nf), bool)
            draw[i][:, cand] = (inside & near_enough[:, None]).T
            unsafe[i][:, cand] = (inside & ~near_enough[:, None]).T
        return draw.reshape(p * nf, -1), unsafe.reshape(p * nf, -1)

    def _draw_commands(
        self, draw: NDArray[np.bool_], unsafe: NDArray[np.bool_]
    ) -> tuple[NDArray[np.uint32], I64]:
        """Indirect draw commands for every face and each face's first command.

        Parameters
        ----------
        draw, unsafe : (faces, n) bool
            As returned by :meth:`_face_masks`.

        Returns
        -------
        commands : (m, 5) uint32
            DrawElementsIndirectCommand rows, face by face.
        offsets : (faces + 1,) int64
            Face ``f`` uses commands ``offsets[f]:offsets[f + 1]``.
        """
        rows, starts, stops = runs(draw)
        first = self._index_first[starts]
        stop = self._index_stop[stops - 1]
        if self.merge_gap and len(rows) > 1:
            # Bridge short gaps of culled objects (one range costs less than two draws),
            # but only gaps whose objects all lie outside the frustum, so that the
            # extra triangles are clipped away and the counts do not change.
            n_unsafe = np.zeros((len(draw), draw.shape[1] + 1), np.int64)
            np.cumsum(unsafe, axis=1, out=n_unsafe[:, 1:])
            same = rows[1:] == rows[:-1]
            row = rows[1:]
            blocked = n_unsafe[row, starts[1:]] - n_unsafe[row, stops[:-1]] > 0
            join = same & ~blocked & (first[1:] - stop[:-1] <= self.merge_gap)
            head = np.concatenate([[True], ~join])
            rows, first = rows[head], first[head]
            stop = np.maximum.reduceat(stop, np.flatnonzero(head))
        commands = np.zeros((len(rows), 5), np.uint32)
        commands[:, 0] = stop - first
        commands[:, 1] = 1
        commands[:, 2] = first
        offsets = np.concatenate([[0], np.cumsum(np.bincount(rows, minlength=len(draw)))])
        return commands, offsets.astype(np.int64)

    # -- rendering -----------------------------------------------------------------

    def _prepare_pass(self, points: F64) -> tuple[NDArray[np.bool_], NDArray[np.uint32], I64, NDArray[np.float32]]:
        """Cull one pass's faces, upload its draw commands and build its face matrices.

        Returns the faces' draw masks ``(p * 6, n)``, the commands and their per-face
        offsets (as :meth:`_draw_commands`) and the ``(p * 6, 4, 4)`` column-major
        float32 model-view-projection matrices the shader takes.
        """
        indirect = self._indirect
        assert indirect is not None
        p = len(points)
        draw, unsafe = self._face_masks(points)
        commands, offsets = self._draw_commands(draw, unsafe)
        if self._multi_draw and len(commands):
            need = commands.nbytes
            if need > indirect.size:
                indirect.orphan(max(need, 2 * indirect.size))
            indirect.write(commands.tobytes())
        nf = len(self._faces)
        views = np.zeros((p, nf, 4, 4))
        views[:, :, :3, :3] = self._face_rot
        views[:, :, :3, 3] = -np.einsum("fij,pj->pfi", self._face_rot, points)
        views[:, :, 3, 3] = 1.0
        # float64 product, transposed to column-major for GLSL, float32 on upload
        mvps = np.ascontiguousarray(
            np.transpose(self._proj @ views, (0, 1, 3, 2)).reshape(p * nf, 4, 4), np.float32
        )
        return draw, commands, offsets, mvps

    def _begin_pass(self, fb: Framebuffer, used: tuple[int, int, int, int] | None) -> None:
        """Bind ``fb`` with the GL state every pass draws with; clear ``used`` (x, y, w, h) if given."""
        import moderngl

        ctx = self.ctx
        assert ctx is not None
        fb.fbo.use()
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.disable(moderngl.BLEND)
        ctx.depth_func = "<"
        if self.cull_back_faces:
            ctx.front_face = "ccw"
            ctx.cull_face = "back"
            ctx.enable(moderngl.CULL_FACE)
        else:
            ctx.disable(moderngl.CULL_FACE)
        ctx.scissor = None
        if used is not None:
            fb.fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0, viewport=used)

    def _render_pass(
        self, points: F64, counts: I64, seen: list[I64] | None = None, each: list[I64] | None = None
    ) -> None:
        """Render up to ``points_per_pass`` points and add each object's pixels to ``counts``.

        With ``seen``, also append per point the local indices + 1 it sees (0 dropped);
        with ``each``, per point its own pixel counts (indexed as ``counts``).
        """
        ctx, fb = self.ctx, self._fb
        assert ctx is not None and fb is not None
        import moderngl

        (tw, res), p = self._faces.tile, len(points)  # res: a point's rows
        draw, commands, offsets, mvps = self._prepare_pass(points)
        used = (0, 0, len(self._faces) * tw, p * res)
        self._begin_pass(fb, used)
        try:
            self._draw_faces(commands, offsets, mvps)
            rows = self._pixels[: p * res]
            fb.fbo.read_into(rows, viewport=used, components=1, dtype="u4", alignment=1)
            filled = np.bincount(rows.reshape(-1), minlength=len(counts))[: len(counts)]
            counts += filled
            # presence by bincount: several times faster than np.unique on a row of tiles
            n = len(counts)
            per = [np.bincount(rows[i * res : (i + 1) * res].reshape(-1), minlength=n)[:n] > 0 for i in range(p)] if seen is not None else []
            own = [np.bincount(rows[i * res : (i + 1) * res].reshape(-1), minlength=n)[:n] for i in range(p)] if each is not None else []
            if self.edge_pass:
                # Edges over the finished fill, tested against its depth but writing
                # none: a second image whose ids only ever ADD to the fill's (an edge
                # written over the fill would also grow every occluder by half a
                # pixel and hide the very slivers it is meant to catch).
                ctx.wireframe = True
                ctx.depth_func = "<="
                fb.fbo.depth_mask = False
                try:
                    self._draw_faces(commands, offsets, mvps)
                finally:
                    ctx.wireframe = False
                    ctx.depth_func = "<"
                    fb.fbo.depth_mask = True
                fb.fbo.read_into(rows, viewport=used, components=1, dtype="u4", alignment=1)
                edges = np.bincount(rows.reshape(-1), minlength=len(counts))[: len(counts)]
                counts += np.where(filled == 0, edges, 0)
                if seen is not None:
                    per = [a | (np.bincount(rows[i * res : (i + 1) * res].reshape(-1), minlength=n)[:n] > 0) for i, a in enumerate(per)]
                if each is not None:
                    own = [np.where(a == 0, np.bincount(rows[i * res : (i + 1) * res].reshape(-1), minlength=n)[:n], a)
                           for i, a in enumerate(own)]
            if self.thin_pass > 0:
                thin = self._thin_pass(points, draw, rows, used, mvps)
                counts += thin
                for i in range(p):
                    extra = np.bincount(rows[i * res : (i + 1) * res].reshape(-1), minlength=n)[:n]
                    if seen is not None:
                        per[i] = per[i] | (extra > 0)
                    if each is not None:
                        own[i] = own[i] + extra
        finally:
            ctx.scissor = None
            if self.cull_back_faces:
                ctx.disable(moderngl.CULL_FACE)
        if seen is not None:
            seen.extend(np.flatnonzero(a[1:]).astype(np.int64) + 1 for a in per)
        if each is not None:
            each.extend(own)

    def _thin_pass(
        self, points: F64, draw: NDArray[np.bool_], rows: NDArray[np.uint32], used: tuple[int, int, int, int],
        mvps: NDArray[np.float32],
    ) -> I64:
        """The thin pass over the finished fill (:func:`~.thinpass.draw_thin_pass`); its pixels per object."""
        return draw_thin_pass(self, points, draw, rows, used, mvps)

    def _unmerged_commands(self, mask: NDArray[np.bool_]) -> tuple[NDArray[np.uint32], I64]:
        """:meth:`_draw_commands` of ``mask`` with no gap bridged (each run its own range)."""
        gap, self.merge_gap = self.merge_gap, 0
        try:
            return self._draw_commands(mask, mask)
        finally:
            self.merge_gap = gap

    def _draw_faces(
        self, commands: NDArray[np.uint32], offsets: I64, mvps: NDArray[np.float32], mode: int | None = None
    ) -> None:
        """Draw every face's commands into its own tile (faces of point ``i`` in row ``i``).

        ``mode``: the primitive (triangles by default; points for the thin pass).
        """
        import moderngl

        mode = moderngl.TRIANGLES if mode is None else mode

        ctx, vao, indirect = self.ctx, self._vao, self._indirect
        assert ctx is not None and vao is not None and indirect is not None
        nf, (tw, th) = len(self._faces), self._faces.tile
        for face in range(len(offsets) - 1):
            c0, c1 = int(offsets[face]), int(offsets[face + 1])
            if c1 == c0:
                continue
            i, f = divmod(face, nf)
            tile = (f * tw, i * th, tw, th)
            ctx.viewport = tile
            # Guard-band clipping may rasterise outside the viewport; the scissor keeps
            # every face inside its own tile on every driver.
            ctx.scissor = tile
            self._mvp.write(mvps[face].tobytes())
            if self._multi_draw:
                vao.render_indirect(indirect, mode, count=c1 - c0, first=c0)
            else:
                for cmd in commands[c0:c1]:
                    vao.render(mode, vertices=int(cmd[0]), first=int(cmd[2]))

    def cell_counts(self, points: ArrayLike) -> tuple[I64, I64]:
        """Pixels each object covers in the six cube faces of every sample point.

        Parameters
        ----------
        points : (p, 3) float
            Sample points (camera centres), scene-local metres.

        Returns
        -------
        ids : (k,) int64
            Ids of the objects seen (covering at least one pixel), ascending.
        pixels : (k,) int64
            Pixels each covers, summed over the ``6 * p`` images.

        Raises
        ------
        InputError
            When ``points`` is not ``(p, 3)`` finite numbers.
        RenderError
            When the renderer was released or OpenGL reports an error.
        """
        pts = self._check_points(points)
        counts = self._counts(pts, None)
        return self._ids_pixels(counts)

    def point_counts(self, points: ArrayLike) -> tuple[I64, I64, list[I64]]:
        """:meth:`cell_counts`, plus the ids each point sees on its own (same render).

        Returns
        -------
        ids, pixels : (k,) int64
            As :meth:`cell_counts`.
        seen : list of (k_i,) int64
            Per point, the ids of the objects covering a pixel of its six faces,
            ascending (for :func:`~walkstream.server.bake.samples.split_points`).
        """
        pts = self._check_points(points)
        per: list[I64] = []
        counts = self._counts(pts, per)
        seen = [np.unique(self._ids[a - 1]) for a in per] if len(self._ids) else [np.zeros(0, np.int64) for _ in pts]
        return *self._ids_pixels(counts), seen

    def each_point_counts(self, points: ArrayLike) -> list[tuple[I64, I64]]:
        """Per sample point, the pixels each object covers in that point's six cube faces.

        The same render as :meth:`cell_counts`, kept apart by point (the dense
        visibility field of :mod:`~walkstream.server.bake.field` keeps every point's
        visible set with its pixel counts).

        Returns
        -------
        list of (ids, pixels)
            Per point, as :meth:`cell_counts` returns for that point alone.
        """
        pts = self._check_points(points)
        own: list[I64] = []
        if len(pts) and len(self._ids):
            counts = np.zeros(len(self._ids) + 1, np.int64)
            for s in range(0, len(pts), self.points_per_pass):
                self._render_pass(pts[s : s + self.points_per_pass], counts, None, own)
            assert self.ctx is not None
            check_gl_error(self.ctx, f"after rendering {len(pts)} visibility sample points")
            return [self._ids_pixels(c.astype(np.int64)) for c in own]
        return [(np.zeros(0, np.int64), np.zeros(0, np.int64)) for _ in pts]

    def _check_points(self, points: ArrayLike) -> F64:
        pts = np.asarray(points, dtype=np.float64)
        if pts.size == 0:
            pts = pts.reshape(0, 3)
        if pts.ndim != 2 or pts.shape[1] != 3 or not np.all(np.isfinite(pts)):
            raise InputError(
                f"cell_counts.points: expected (p, 3) finite numbers, got shape {pts.shape}"
            )
        if self._fb is None or self.ctx is None:
            raise RenderError("VisibilityRenderer: used after release()")
        return pts

    def _counts(self, pts: F64, seen: list[I64] | None) -> I64:
        counts = np.zeros(len(self._ids) + 1, np.int64)
        if len(pts) and len(self._ids):
            for s in range(0, len(pts), self.points_per_pass):
                self._render_pass(pts[s : s + self.points_per_pass], counts, seen)
            assert self.ctx is not None
            check_gl_error(self.ctx, f"after rendering {len(pts)} visibility sample points")
        return counts

    def _ids_pixels(self, counts: I64) -> tuple[I64, I64]:
        seen = np.flatnonzero(counts[1:])
        ids, inverse = np.unique(self._ids[seen], return_inverse=True)
        # Several meshes may carry one id; their pixels add up.
        pixels = np.bincount(inverse.reshape(-1), weights=counts[1:][seen], minlength=len(ids))
        return ids.astype(np.int64), pixels.astype(np.int64)

    # -- lifetime ------------------------------------------------------------------

    def release(self) -> None:
        """Release every GL object (and the context if this renderer made it); idempotent."""
        if getattr(self, "_eroder", None) is not None:
            self._eroder.release()  # type: ignore[union-attr]
            self._eroder = None
        if self._fb is not None:
            self._fb.release()
            self._fb = None
        for name in ("_vao", "_indirect", "_ibo", "_vbo", "_prog"):
            obj = getattr(self, name, None)
            if obj is not None:
                obj.release()
                setattr(self, name, None)
        if self._own_ctx and self.ctx is not None:
            self.ctx.release()
        self.ctx = None



# ------------------------------------------------------------------ PVS and ACH


def pvs_from_counts(ids: ArrayLike, pixels: ArrayLike, *, threshold: int = 0) -> tuple[I64, F64]:
    """The PVS and ACH of a cell from per-object pixel counts.

    Parameters
    ----------
    ids : (k,) int
        Object ids (as returned by :meth:`VisibilityRenderer.cell_counts`).
    pixels : (k,) int
        Pixels each object covers over all the cell's images.
    threshold : int
        An object is potentially visible when it covers more than this many pixels
        (0: any pixel at all; larger values drop hardly visible objects).

    Returns
    -------
    pvs : (m,) int64
        The ids kept, in input order.
    ach : (m,) float64
        ``ACH_j = N_j / sum(N)`` over the kept objects; sums to 1 unless the cell
        sees nothing (then both arrays are empty).
    """
    i = np.asarray(ids, dtype=np.int64).reshape(-1)
    n = np.asarray(pixels, dtype=np.int64).reshape(-1)
    if len(i) != len(n):
        raise InputError(
            f"pvs_from_counts: expected as many pixels as ids ({len(i)}), got {len(n)}"
        )
    keep = n > int(threshold)
    i, n = i[keep], n[keep]
    total = int(n.sum())
    if total == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.float64)
    return i, n.astype(np.float64) / float(total)
