"""Per-frame headless drawing for the replay and the LOD benchmark, with honest timing.

:class:`FrameRenderer` keeps GPU buffers per key (usually ``(object id, lod)``) and
draws a list of keys per frame with :class:`~walkstream.client.draw.meshes.MeshRenderer`'s shaders
and lighting, so frames look like the LOD figures: a pale sky background, lit
buildings, streets as flat ground, back faces culled; with :attr:`FrameRenderer.ground_z`
set, the ground plane of :mod:`walkstream.shared.ground` under everything.

:meth:`FrameRenderer.draw_ids` is a separate path over the same buffers: the same
keys drawn into an integer image of object ids (which object each pixel shows), for
comparing the client's frame with the ground truth (:mod:`walkstream.client.truth`).
It has its own shader program and framebuffer and is never timed: the frame the user
sees is :meth:`FrameRenderer.draw`.

Draws are batched by default (``batched=True``): every mesh lives in one shared vertex
and index buffer (:class:`~walkstream.client.draw.arena.MeshArena`) and a frame is one
multi-draw call, the object-id pass too; ``batched=False`` keeps one buffer pair and
one draw call per mesh (the path before batching, kept for comparison).

Timing is honest: the clock starts before the clear and stops after
``ctx.finish()``, so the time includes all the GPU work of the frame, not only the
time to queue it (on llvmpipe the CPU rasterises; on a real GPU ``finish`` waits for
it).  The same code runs on both.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Hashable, Iterable

import moderngl
import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.client.draw.arena import MeshArena
from walkstream.client.draw.meshes import MeshRenderer
from walkstream.client.draw.quads import Quad, QuadRenderer
from walkstream.shared.camera import mat4_bytes, perspective
from walkstream.shared.errors import InputError, RenderError
from walkstream.shared.gl import VERTEX_ID_FRAGMENT_SHADER, Framebuffer, Releasable, check_gl_error
from walkstream.shared.records import Mesh

__all__ = ["FrameRenderer", "VERTEX_BYTES", "INDEX_BYTES"]

# The id pass: position only (the first 12 of the 28 bytes of a vertex), one id per
# draw.  ``invariant`` makes its coverage match the truth renderer's exactly.
_ID_VERTEX_SHADER = """
#version 330
uniform mat4 u_view_proj;
in vec3 in_position;
invariant gl_Position;
void main() {
    gl_Position = u_view_proj * vec4(in_position, 1.0);
}
"""

# The batched id pass: the id comes per draw through baseInstance.
_ID_BATCH_VERTEX_SHADER = """
#version 330
uniform mat4 u_view_proj;
in vec3 in_position;
in uint in_id;
flat out uint v_id;
invariant gl_Position;
void main() {
    gl_Position = u_view_proj * vec4(in_position, 1.0);
    v_id = in_id;
}
"""

_ID_FRAGMENT_SHADER = """
#version 330
uniform uint u_id;
out uint f_id;
void main() {
    f_id = u_id;
}
"""

#: Bytes per vertex in the GPU buffers MeshRenderer makes (float32 position and
#: normal, RGBA8 colour).
VERTEX_BYTES = 28
#: Bytes per triangle of the index buffer (three uint32).
INDEX_BYTES = 12
class FrameRenderer(Releasable):
    """Draws frames of keyed meshes offscreen and times them.

    Parameters
    ----------
    size : (int, int)
        Width and height of the frame in pixels.
    fov_deg : float
        Vertical field of view of the default projection.
    near, far : float
        Clip distances of the default projection, metres.
    ctx : moderngl.Context, optional
        Context to draw with; default: a new headless one (released in :meth:`close`).
    batched : bool
        One shared buffer pair and one multi-draw call per frame (default); False:
        one buffer pair and one draw call per mesh.
    shading : {"vertex", "fragment"}
        Lighting per vertex (default, cheap on llvmpipe) or per fragment (the path
        before, for comparison) when there is no fog; see
        :class:`~walkstream.client.draw.meshes.MeshRenderer`.
    facade_filter : {"point", "anisotropic"}
        How facade pictures are read where drawn smaller than baked
        (:data:`~walkstream.client.draw.quads.FACADE_FILTERS`).

    Notes
    -----
    Several keys may hold the same :class:`~walkstream.shared.records.Mesh` object (a street
    piece is one mesh at every LOD); its buffers are made once and released when the
    last key holding it is forgotten.
    """

    def __init__(
        self,
        size: tuple[int, int] = (640, 480),
        fov_deg: float = 60.0,
        near: float = 0.5,
        far: float = 2000.0,
        ctx: moderngl.Context | None = None,
        batched: bool = True,
        shading: str = "vertex",
        facade_filter: str = "point",
    ) -> None:
        w, h = (int(v) for v in size)
        if w <= 0 or h <= 0:
            raise InputError(f"FrameRenderer.size: expected positive width and height, got {size}")
        self.size: tuple[int, int] = (w, h)
        # validates fov, near and far before any GL object exists
        self.proj: NDArray[np.float32] = perspective(fov_deg, w / h, near, far)
        self.fov_deg = float(fov_deg)
        self.near, self.far = float(near), float(far)
        self._r = MeshRenderer(ctx, shading=shading)
        self.ctx: moderngl.Context = self._r.ctx
        self._keys: dict[Hashable, Mesh] = {}
        self._refs: dict[int, int] = {}  # id(mesh) -> number of keys holding it
        self._triangles = 0
        self._bytes = 0
        self._drawn = False
        #: Triangles drawn by the last :meth:`draw`.
        self.last_triangles = 0
        #: Keys drawn by the last :meth:`draw` (the ones that were uploaded).
        self.last_drawn = 0
        # the object-id pass (made on first use)
        self._id_prog: moderngl.Program | None = None
        self._id_fb: Framebuffer | None = None
        self._id_vaos: dict[int, moderngl.VertexArray] = {}
        self.batched = bool(batched)
        self._arena = MeshArena(self.ctx, self._r.program) if self.batched else None
        #: Seconds the last :meth:`draw` spent issuing (clear, uniforms, draw calls)
        #: and waiting in ``ctx.finish()`` for the device.
        self.last_issue_s = 0.0
        self.last_finish_s = 0.0
        self._quads: QuadRenderer | None = None
        self.facade_filter = facade_filter
        """How facade pictures are read when minified (:data:`~walkstream.client.draw.quads.FACADE_FILTERS`)."""
        #: The impostor quads the next :meth:`draw` draws over its meshes (the frame's
        #: ``upload`` step sets them; :mod:`walkstream.client.draw.quads`).
        self.impostors: list[Quad] = []

    # -- buffers ---------------------------------------------------------------

    def upload(self, key: Hashable, mesh: Mesh) -> None:
        """Make the GPU buffers of ``mesh`` and file them under ``key``.

        A key that already holds another mesh is replaced; uploading the same mesh
        again is a no-op.
        """
        old = self._keys.get(key)
        if old is mesh:
            return
        if old is not None:
            self.forget(key)
        mid = id(mesh)
        if self._refs.get(mid, 0) == 0:
            if self._arena is not None:
                self._arena.add(mesh)
            else:
                self._r.upload(mesh)
            self._triangles += mesh.triangles
            self._bytes += len(mesh.positions) * VERTEX_BYTES + mesh.triangles * INDEX_BYTES
        self._refs[mid] = self._refs.get(mid, 0) + 1
        self._keys[key] = mesh

    @property
    def fog_m(self) -> float:
        """Fog distance of the drawn frames: surfaces fade into the background over its
        last fifth (interiors, ``--fog``); 0: none."""
        return self._r.fog_m

    @fog_m.setter
    def fog_m(self, value: float) -> None:
        self._r.fog_m = float(value) if math.isfinite(value) else 0.0

    @property
    def ground_z(self) -> float | None:
        """Height of the ground plane under the drawn frames (:mod:`walkstream.shared.ground`);
        None (the default): no plane.  The id pass never draws it."""
        return self._r.ground_z

    @ground_z.setter
    def ground_z(self, value: float | None) -> None:
        self._r.ground_z = None if value is None else float(value)

    def has(self, key: Hashable) -> bool:
        """Whether ``key`` has been uploaded (and not forgotten)."""
        return key in self._keys

    def forget(self, key: Hashable) -> None:
        """Release the buffers of ``key`` (no-op for an unknown key).

        Buffers shared with another key stay until that key goes too.
        """
        mesh = self._keys.pop(key, None)
        if mesh is None:
            return
        mid = id(mesh)
        n = self._refs.get(mid, 0) - 1
        if n > 0:
            self._refs[mid] = n
            return
        self._refs.pop(mid, None)
        vao = self._id_vaos.pop(mid, None)
        if vao is not None:
            vao.release()
        if self._arena is not None:
            self._arena.remove(mesh)
        else:
            self._r.forget(mesh)
        self._triangles -= mesh.triangles
        self._bytes -= len(mesh.positions) * VERTEX_BYTES + mesh.triangles * INDEX_BYTES

    def forget_object(self, object_id: int) -> None:
        """Forget every key ``(object_id, lod)`` (any tuple key whose first item matches)."""
        for key in [k for k in self._keys if isinstance(k, tuple) and k and k[0] == object_id]:
            self.forget(key)

    def keys(self) -> list[Hashable]:
        """The uploaded keys, in upload order."""
        return list(self._keys)

    @property
    def triangles_uploaded(self) -> int:
        """Triangles in GPU buffers (a mesh shared by several keys counts once)."""
        return self._triangles

    @property
    def gpu_bytes(self) -> int:
        """Bytes of the vertex and index buffers held."""
        return self._bytes

    # -- frames ----------------------------------------------------------------

    def draw(
        self,
        keys: Iterable[Hashable],
        view: ArrayLike,
        proj: ArrayLike | None = None,
    ) -> float:
        """Draw one frame of the given keys and return its time in seconds.

        Keys that are not uploaded are skipped (the frame never waits for geometry).
        The clock starts before the clear and stops after ``ctx.finish()``: the frame
        is complete on the device when the time is taken.

        Parameters
        ----------
        keys : iterable of keys
        view : (4, 4) float
            View matrix (e.g. from :func:`camera`).
        proj : (4, 4) float, optional
            Projection; default: the one made from ``size``, ``fov_deg``, ``near``
            and ``far``.

        Returns
        -------
        float
            Seconds from the clear to the finished frame.
        """
        meshes = [m for m in (self._keys.get(k) for k in keys) if m is not None]
        p = self.proj if proj is None else proj
        t0 = time.perf_counter()
        if self._arena is not None:
            self._r.begin(view, p, self.size)
            self._arena.draw(meshes, self._r.program)
            check_gl_error(self.ctx, "after FrameRenderer.draw")
        else:
            self._r.draw(meshes, view, p, self.size)
        if self.impostors or self._quads is not None:
            if self._quads is None:
                self._quads = QuadRenderer(self.ctx, facade_filter=self.facade_filter)
            self._quads.draw(self.impostors, np.asarray(p, np.float64) @ np.asarray(view, np.float64))
        t1 = time.perf_counter()
        self.ctx.finish()
        dt = time.perf_counter() - t0
        self.last_issue_s, self.last_finish_s = t1 - t0, dt - (t1 - t0)
        self._drawn = True
        self.last_drawn = len(meshes)
        self.last_triangles = sum(m.triangles for m in meshes)
        return dt

    # -- object ids ------------------------------------------------------------

    def draw_ids(
        self,
        keys: Iterable[tuple[int, int]],
        view: ArrayLike,
        proj: ArrayLike | None = None,
    ) -> NDArray[np.uint32]:
        """The object-id image of a frame of the given keys (not timed).

        The same meshes and camera as :meth:`draw`, back faces culled, drawn in
        ascending object id (so that surfaces tied in depth resolve the same way in
        every frame that draws them in that order) into an integer framebuffer of its
        own.

        Parameters
        ----------
        keys : iterable of (object id, lod)
            Uploaded keys; others are skipped.
        view, proj : (4, 4) float
            As for :meth:`draw`.

        Returns
        -------
        (h, w) uint32
            Object id + 1 per pixel, 0 where no object shows; row 0 at the top.
        """
        import moderngl

        ctx = self.ctx
        if self._id_prog is None:
            vs, fs = (
                (_ID_BATCH_VERTEX_SHADER, VERTEX_ID_FRAGMENT_SHADER)
                if self._arena is not None
                else (_ID_VERTEX_SHADER, _ID_FRAGMENT_SHADER)
            )
            try:
                self._id_prog = ctx.program(vertex_shader=vs, fragment_shader=fs)
            except Exception as exc:
                raise RenderError(f"FrameRenderer.draw_ids: shader program failed: {exc}") from exc
        if self._id_fb is None:
            self._id_fb = Framebuffer(ctx, self.size, 1, "u4")
        prog = self._id_prog
        fb = self._id_fb
        fb.use()
        fb.clear((0.0, 0.0, 0.0, 0.0))
        p = self.proj if proj is None else proj
        vp = np.asarray(p, dtype=np.float64) @ np.asarray(view, dtype=np.float64)
        u_vp = prog["u_view_proj"]
        assert isinstance(u_vp, moderngl.Uniform)
        u_vp.write(mat4_bytes(vp))
        ctx.enable(moderngl.DEPTH_TEST | moderngl.CULL_FACE)
        ctx.depth_func = "<"
        ctx.front_face = "ccw"
        ctx.cull_face = "back"
        ordered = sorted(keys, key=lambda k: int(k[0]))
        if self._arena is not None:
            found = [(k, self._keys.get(k)) for k in ordered]
            meshes = [m for _, m in found if m is not None]
            ids = np.array([int(k[0]) + 1 for k, m in found if m is not None], dtype=np.uint32)
            self._arena.draw_ids(meshes, ids, prog)
            check_gl_error(ctx, "after FrameRenderer.draw_ids")
            img_b: NDArray[np.uint32] = fb.read(components=1)[:, :, 0]
            return img_b
        u_id = prog["u_id"]
        assert isinstance(u_id, moderngl.Uniform)
        for key in ordered:
            mesh = self._keys.get(key)
            bufs = None if mesh is None else self._r.buffers(mesh)
            if mesh is None or bufs is None:
                continue
            vao = self._id_vaos.get(id(mesh))
            if vao is None:
                vbo, ibo = bufs
                vao = ctx.vertex_array(
                    prog,
                    [(vbo, f"3f {VERTEX_BYTES - 12}x", "in_position")],
                    index_buffer=ibo,
                    index_element_size=4,
                )
                self._id_vaos[id(mesh)] = vao
            u_id.value = int(key[0]) + 1
            vao.render()
        check_gl_error(ctx, "after FrameRenderer.draw_ids")
        img: NDArray[np.uint32] = fb.read(components=1)[:, :, 0]
        return img

    def snapshot(self) -> NDArray[np.uint8]:
        """The last frame, ``(h, w, 3) uint8``, row 0 at the top."""
        if not self._drawn:
            raise RenderError("FrameRenderer.snapshot: nothing drawn yet")
        return self._r.read()

    def save_png(self, path: str | os.PathLike[str]) -> None:
        """Write the last frame to a PNG file."""
        from PIL import Image

        Image.fromarray(self.snapshot(), "RGB").save(os.fspath(path), format="PNG")

    # -- lifetime --------------------------------------------------------------

    def release(self) -> None:
        """Release every buffer (and the context, if it was made here); idempotent."""
        if self._quads is not None:
            self._quads.release()
            self._quads = None
        for vao in self._id_vaos.values():
            vao.release()
        self._id_vaos.clear()
        if self._id_fb is not None:
            self._id_fb.release()
            self._id_fb = None
        if self._id_prog is not None:
            self._id_prog.release()
            self._id_prog = None
        if self._arena is not None:
            self._arena.release()
        self._keys.clear()
        self._refs.clear()
        self._triangles = 0
        self._bytes = 0
        self._r.release()

