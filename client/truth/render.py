"""The ground-truth renderer: every object within the view distance at LOD2, colour and object id.

It shares no code with the client's frame path (no culling of :mod:`walkstream.shared.frustum`,
no LOD choice of :mod:`walkstream.client.draw.allocate`, not even its mesh buffers): all
objects live in one vertex buffer in ascending id order, each vertex carrying its
object's id, and a frame draws every object whose bounding box comes within the view
distance of the eye (plus any objects named in ``also``), in one pass into two colour
attachments -- the lit colour and the object id.  Only the lighting constants are the
client's (:mod:`walkstream.client.draw.meshes`), so that where both frames show the same
surface they show the same colour.

Why ascending ids: two coplanar surfaces (a street piece meeting a crossroad) tie in
depth, and the depth test ``<`` keeps the one drawn first; the client's ID pass draws
in ascending ids too, so ties resolve the same way in both frames.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.client.draw.meshes import AMBIENT, BACKGROUND_RGB, LIGHT_DIRECTION
from walkstream.shared.camera import mat4_bytes, perspective
from walkstream.shared.errors import InputError, RenderError
from walkstream.shared.gl import Releasable, check_gl_error, create_context, release_objects
from walkstream.shared.palette import material_rgb
from walkstream.shared.records import Mesh

if TYPE_CHECKING:
    import moderngl

__all__ = ["MAX_BUFFER_BYTES", "TruthRenderer"]

_VERTEX_SHADER = """
#version 330
uniform mat4 u_view_proj;
in vec3 in_position;
in vec3 in_normal;
in vec4 in_color;
in uint in_id;
out vec3 v_normal;
out vec3 v_color;
flat out uint v_id;
invariant gl_Position;
void main() {
    gl_Position = u_view_proj * vec4(in_position, 1.0);
    v_normal = in_normal;
    v_color = in_color.rgb;
    v_id = in_id;
}
"""

_FRAGMENT_SHADER = """
#version 330
uniform vec3 u_light_dir;
uniform float u_ambient;
in vec3 v_normal;
in vec3 v_color;
flat in uint v_id;
layout(location = 0) out vec4 f_color;
layout(location = 1) out uint f_id;
void main() {
    float diffuse = max(dot(normalize(v_normal), u_light_dir), 0.0);
    f_color = vec4(v_color * (u_ambient + (1.0 - u_ambient) * diffuse), 1.0);
    f_id = v_id;
}
"""

#: The largest vertex or index buffer the truth makes (GL sizes are 32-bit ints in places).
MAX_BUFFER_BYTES = 2**31

_VERTEX = np.dtype([("p", "<f4", 3), ("n", "<f4", 3), ("c", "u1", 4), ("id", "<u4")])


class TruthRenderer(Releasable):
    """Draws ground-truth frames of a fixed set of objects (their LOD2 meshes).

    Parameters
    ----------
    meshes : mapping id -> Mesh
        Every object that may be drawn, at LOD2, scene-local metres.
    size : (int, int)
        Frame width and height in pixels.
    fov_deg, near, far : float
        The default projection (the client's: 60 degrees, 0.5 m, 2000 m).
    view_distance : float
        An object is drawn when its bounding box comes this close to the eye.
    ctx : moderngl.Context, optional
        Context to draw with; by default one is made (and released by :meth:`release`).
    """

    def __init__(
        self,
        meshes: Mapping[int, Mesh],
        size: tuple[int, int] = (640, 480),
        *,
        fov_deg: float = 60.0,
        near: float = 0.5,
        far: float = 2000.0,
        view_distance: float = 800.0,
        ctx: moderngl.Context | None = None,
    ) -> None:
        w, h = (int(v) for v in size)
        if w <= 0 or h <= 0:
            raise InputError(f"TruthRenderer.size: expected positive width and height, got {size}")
        if not float(view_distance) > 0:
            raise InputError(f"TruthRenderer.view_distance: expected > 0, got {view_distance}")
        self.size = (w, h)
        self.proj = perspective(fov_deg, w / h, near, far)
        self.view_distance = float(view_distance)
        ids = np.array(sorted(int(i) for i in meshes), np.int64)
        if len(ids) and ids[0] < 0:
            raise InputError(f"TruthRenderer: object ids must be >= 0, got {ids[0]}")
        self.ids = ids
        parts = [meshes[int(i)] for i in ids]
        self._lo = np.array([m.positions.min(axis=0) if len(m.positions) else np.full(3, np.inf) for m in parts], np.float64).reshape(-1, 3)
        self._hi = np.array([m.positions.max(axis=0) if len(m.positions) else np.full(3, -np.inf) for m in parts], np.float64).reshape(-1, 3)
        nv = np.array([len(m.positions) for m in parts], np.int64)
        ni = np.array([m.indices.size for m in parts], np.int64)
        v0 = np.concatenate([[0], np.cumsum(nv)]).astype(np.int64)
        i0 = np.concatenate([[0], np.cumsum(ni)]).astype(np.int64)
        self._first, self._stop = i0[:-1], i0[1:]
        nbytes = max(int(v0[-1]) * _VERTEX.itemsize, int(i0[-1]) * 4)
        if nbytes >= MAX_BUFFER_BYTES:
            # drivers take buffer sizes and offsets as 32-bit ints: past this they crash
            raise RenderError(
                f"TruthRenderer: {len(ids)} objects at LOD2 need a {nbytes / 2**30:.1f} GiB buffer "
                f"(at most {MAX_BUFFER_BYTES / 2**30:.0f} GiB): give it the objects near the camera only"
            )
        verts = np.empty(int(v0[-1]), _VERTEX)
        index = np.empty(int(i0[-1]), np.uint32)
        for k, m in enumerate(parts):
            s, e = int(v0[k]), int(v0[k + 1])
            verts["p"][s:e] = m.positions
            verts["n"][s:e] = m.normals
            verts["c"][s:e, :3] = material_rgb(m.materials)
            verts["c"][s:e, 3] = 255
            verts["id"][s:e] = ids[k] + 1  # 0 is the clear value: no object
            index[i0[k] : i0[k + 1]] = m.indices.reshape(-1) + np.uint32(s)
        self._own_ctx = ctx is None
        self.ctx: Any = None
        self._gl: list[Any] = []
        try:
            self.ctx = create_context() if ctx is None else ctx
            self._setup(verts, index)
        except BaseException:
            self.release()
            raise

    def _setup(self, verts: NDArray[Any], index: NDArray[np.uint32]) -> None:
        ctx = self.ctx
        try:
            self._prog = ctx.program(vertex_shader=_VERTEX_SHADER, fragment_shader=_FRAGMENT_SHADER)
        except Exception as exc:
            raise RenderError(f"TruthRenderer: shader program failed: {exc}") from exc
        self._gl.append(self._prog)
        light = np.asarray(LIGHT_DIRECTION, np.float64)
        self._prog["u_light_dir"].value = tuple(light / np.linalg.norm(light))
        self._prog["u_ambient"].value = float(AMBIENT)
        # empty buffers are not allowed: a placeholder keeps an empty scene valid
        self._vbo = ctx.buffer(verts.tobytes() if len(verts) else bytes(_VERTEX.itemsize))
        self._ibo = ctx.buffer(index.tobytes() if len(index) else bytes(12))
        self._vao = ctx.vertex_array(
            self._prog,
            [(self._vbo, "3f 3f 4f1 u4", "in_position", "in_normal", "in_color", "in_id")],
            index_buffer=self._ibo,
            index_element_size=4,
        )
        w, h = self.size
        self._colour = ctx.renderbuffer((w, h), components=4)
        self._idbuf = ctx.renderbuffer((w, h), components=1, dtype="u4")
        self._depth = ctx.depth_renderbuffer((w, h))
        self._fbo = ctx.framebuffer(color_attachments=[self._colour, self._idbuf], depth_attachment=self._depth)
        # an integer attachment must not be cleared with the float sky colour: each is
        # cleared through a framebuffer of its own
        self._fbo_colour = ctx.framebuffer(color_attachments=[self._colour], depth_attachment=self._depth)
        self._fbo_ids = ctx.framebuffer(color_attachments=[self._idbuf])
        self._gl += [self._vao, self._ibo, self._vbo, self._fbo, self._fbo_colour, self._fbo_ids]
        self._gl += [self._colour, self._idbuf, self._depth]
        check_gl_error(ctx, "after creating the truth renderer")

    def within(self, eye: ArrayLike) -> NDArray[np.int64]:
        """Ids of the objects whose bounding box comes within the view distance of ``eye``."""
        e = np.asarray(eye, np.float64).reshape(3)
        gap = np.maximum(np.maximum(self._lo - e, e - self._hi), 0.0)
        near = np.einsum("nk,nk->n", gap, gap) <= self.view_distance**2
        out: NDArray[np.int64] = self.ids[near]
        return out

    def render(
        self,
        eye: ArrayLike,
        view: ArrayLike,
        proj: ArrayLike | None = None,
        *,
        also: Iterable[int] = (),
    ) -> tuple[NDArray[np.uint8], NDArray[np.uint32]]:
        """Draw the truth of one camera.

        Parameters
        ----------
        eye : (3,) float
            The camera position (for the view distance).
        view, proj : (4, 4) float
            The camera; ``proj`` defaults to the renderer's projection.
        also : ints
            Objects to draw wherever they are (those the client drew), so that the
            truth never lacks a surface the client's frame shows.

        Returns
        -------
        rgb : (h, w, 3) uint8
            The lit colour frame, row 0 at the top.
        ids : (h, w) uint32
            Object id + 1 per pixel, 0 where none shows.
        """
        if self.ctx is None:
            raise RenderError("TruthRenderer: used after release()")
        import moderngl

        ctx = self.ctx
        e = np.asarray(eye, np.float64).reshape(3)
        gap = np.maximum(np.maximum(self._lo - e, e - self._hi), 0.0)
        draw = np.einsum("nk,nk->n", gap, gap) <= self.view_distance**2
        extra = np.fromiter((int(i) for i in also), np.int64)
        if len(extra) and len(self.ids):
            pos = np.clip(np.searchsorted(self.ids, extra), 0, len(self.ids) - 1)
            draw[pos[self.ids[pos] == extra]] = True
        p = self.proj if proj is None else np.asarray(proj)
        vp = np.asarray(p, np.float64) @ np.asarray(view, np.float64)
        self._prog["u_view_proj"].write(mat4_bytes(vp))
        w, h = self.size
        r, g, b = (c / 255.0 for c in BACKGROUND_RGB)
        self._fbo_colour.clear(r, g, b, 1.0, depth=1.0)
        self._fbo_ids.clear(0.0, 0.0, 0.0, 0.0)
        self._fbo.use()
        ctx.viewport = (0, 0, w, h)
        ctx.enable(moderngl.DEPTH_TEST | moderngl.CULL_FACE)
        ctx.disable(moderngl.BLEND)
        ctx.depth_func = "<"
        ctx.front_face = "ccw"
        ctx.cull_face = "back"
        padded = np.concatenate([[False], draw, [False]]).astype(np.int8)
        step = np.diff(padded)
        starts, stops = np.flatnonzero(step == 1), np.flatnonzero(step == -1)
        for s, t in zip(starts.tolist(), stops.tolist(), strict=True):
            first, last = int(self._first[s]), int(self._stop[t - 1])
            if last > first:
                self._vao.render(moderngl.TRIANGLES, vertices=last - first, first=first)
        check_gl_error(ctx, "after drawing a truth frame")
        raw = self._fbo.read(components=3, attachment=0, alignment=1)
        rgb = np.frombuffer(raw, np.uint8).reshape(h, w, 3)[::-1].copy()
        raw = self._fbo.read(components=1, attachment=1, dtype="u4", alignment=1)
        ids = np.frombuffer(raw, np.uint32).reshape(h, w)[::-1].copy()
        return rgb, ids

    def release(self) -> None:
        """Release every GL object (and the context if it was made here); idempotent."""
        release_objects(self.ctx, self._gl, self._own_ctx)
        self.ctx = None

