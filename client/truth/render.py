"""The ground-truth renderer: every city object at LOD2 and every room part, nothing culled.

One renderer for every scene, whatever it holds: city objects (their LOD2 meshes,
lit in their materials' colours) and room parts (each part of each cell's contents,
:class:`~walkstream.shared.codec.cellmesh.CellPart`, in its material's colour, lit with flat
normals as the client lights it).
Each thing drawn has a key: a room part ``(cell, part)``, a city object
``(-1 - id, 0)`` (:func:`object_key`); :attr:`TruthRenderer.keys` lists them in draw
order -- the objects in ascending ids, then the parts by cell and part -- and a
frame gives, per pixel, the index of the key it shows, its eye-space depth and its
colour.

It shares no code with the client's frame path (no culling of
:mod:`walkstream.shared.frustum` or :mod:`walkstream.shared.portals`, no LOD choice of
:mod:`walkstream.client.draw.allocate`, not even its mesh buffers): everything lives in
one vertex buffer and a frame draws the runs of what it is asked to draw in one pass
into three attachments -- colour, key index and depth.  Only the lighting constants
are the client's (:mod:`walkstream.client.draw.meshes`), so that where both frames
show the same object they show the same colour.

What differs by scene kind on purpose is the caller's: the projection (the city's
near plane is 0.5 m, the rooms' and a crossing's 0.1 m), whether back faces are
culled (``two_sided``: a city object is a closed solid and the client culls its back
faces too; room parts clipped to cells are not closed, so interiors and crossings
draw both sides), and the fog (``fog_m`` of :meth:`TruthRenderer.render`: fragments
farther from the eye are not drawn, so what the fog hides on purpose is no miss).

Besides, it draws the coarser forms a client drew (``forms``: an object's LOD0 or LOD1
mesh, key :func:`form_key`), so that the client's picture is drawn by the same shader,
light and palette as the full scene and the two differ only where the client's choice
of forms makes them differ (:mod:`walkstream.client.truth.picture`, the colour error of
:mod:`walkstream.client.truth.colour`).

Anti-aliased colour (``samples`` of :meth:`TruthRenderer.render`, a
:class:`~walkstream.client.truth.antialias.Sampling`): the frame's colour drawn again into
an N x N supersampled or multisampled target and resolved to the frame size
(:mod:`walkstream.client.truth.antialias`); its key indices and depths stay point-sampled.
By default one sample a pixel, at its centre, as always.

Under a scene with outdoor space (``ground_z``) the truth draws the ground plane of
:mod:`walkstream.shared.ground` first, depth test off, key 0 (nothing): it changes the
colour below the horizon from the sky's to the ground's and no key of any pixel.

Why ascending ids: two coplanar surfaces (a street piece meeting a crossroad) tie in
depth, and the depth test ``<`` keeps the one drawn first; the client's ID pass draws
in ascending ids too, so ties resolve the same way in both frames.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.client.draw.meshes import AMBIENT, BACKGROUND_RGB, LIGHT_DIRECTION
from walkstream.client.truth.antialias import Sampling, SmoothTarget
from walkstream.shared.camera import mat4_bytes, perspective
from walkstream.shared.codec.cellmesh import CellMesh, flat_normals
from walkstream.shared.errors import InputError, RenderError
from walkstream.shared.gl import Releasable, check_gl_error, create_context, release_objects
from walkstream.shared.ground import GROUND_MATERIAL, ground_quad
from walkstream.shared.palette import material_rgb
from walkstream.shared.records import Mesh

if TYPE_CHECKING:
    import moderngl

    from walkstream.client.draw.quads import Quad, QuadRenderer

__all__ = ["MAX_BUFFER_BYTES", "TruthRenderer", "form_key", "object_key"]

_VERTEX_SHADER = """
#version 330
uniform mat4 u_view_proj;
in vec3 in_position;
in vec3 in_normal;
in vec4 in_color;
in uint in_id;
out vec3 v_world;
out vec3 v_normal;
out vec3 v_color;
flat out uint v_id;
invariant gl_Position;
void main() {
    gl_Position = u_view_proj * vec4(in_position, 1.0);
    v_world = in_position;
    v_normal = in_normal;
    v_color = in_color.rgb;
    v_id = in_id;
}
"""

_FRAGMENT_SHADER = """
#version 330
uniform vec3 u_light_dir;
uniform float u_ambient;
uniform vec3 u_eye;
uniform float u_fog;
in vec3 v_world;
in vec3 v_normal;
in vec3 v_color;
flat in uint v_id;
layout(location = 0) out vec4 f_color;
layout(location = 1) out uint f_id;
void main() {
    if (distance(v_world, u_eye) > u_fog) discard;
    float diffuse = max(dot(normalize(v_normal), u_light_dir), 0.0);
    f_color = vec4(v_color * (u_ambient + (1.0 - u_ambient) * diffuse), 1.0);
    f_id = v_id;
}
"""

#: The largest vertex or index buffer the truth makes (GL sizes are 32-bit ints in places).
MAX_BUFFER_BYTES = 2**31

_VERTEX = np.dtype([("p", "<f4", 3), ("n", "<f4", 3), ("c", "u1", 4), ("id", "<u4")])


def object_key(oid: int) -> tuple[int, int]:
    """The key of city object ``oid`` among the truth's keys (room parts are ``(cell, part)``, cells >= 0)."""
    return (-1 - int(oid), 0)


def form_key(oid: int, lod: int) -> tuple[int, int]:
    """The key of city object ``oid`` drawn at a coarser ``lod`` (0 or 1) than LOD2, as a client drew it.

    ``(-1 - id, 1 + lod)``: the object's own key is ``(-1 - id, 0)`` (:func:`object_key`).
    """
    if not 0 <= int(lod) < 2:
        raise InputError(f"form_key: expected a LOD coarser than LOD2 (0 or 1), got {lod}")
    return (-1 - int(oid), 1 + int(lod))


class TruthRenderer(Releasable):
    """Draws ground-truth frames of a fixed set of city objects and room parts.

    Parameters
    ----------
    objects : mapping id -> Mesh
        Every city object that may be drawn, at LOD2, scene-local metres.
    size : (int, int)
        Frame width and height in pixels.
    rooms : mapping cell id -> CellMesh
        Every room cell's contents whose parts may be drawn (parts without a
        triangle are left out).
    fov_deg, near, far : float
        The projection (the client's: the city's 0.5 m to 2000 m by default).
    view_distance : float
        :meth:`within` and :meth:`colour_frame` take the objects whose bounding box
        comes this close to the eye.
    two_sided : bool
        Draw back faces too (room parts are not closed solids); by default they are
        culled, as the client culls a city object's.
    ground_z : float, optional
        Height of the ground plane drawn under every frame (a scene with outdoor
        space: :data:`~walkstream.shared.ground.GROUND_Z`); None: no plane.
    ctx : moderngl.Context, optional
        Context to draw with; by default one is made (and released by :meth:`release`).
    forms : mapping (object id, lod) -> Mesh
        Coarser forms (LOD0, LOD1) of objects, as the client drew them: drawn with the
        same shader, light and palette, so that a picture of what the client drew
        (:mod:`walkstream.client.truth.picture`) and the full scene differ only where
        the client's picture does.  Their keys (:func:`form_key`) come after the room
        parts; a frame that draws any of them draws everything in ascending object
        id, as the client's id pass does (ties in depth resolve alike).
    facade_filter : {"point", "anisotropic"}
        How :meth:`paint_quads` reads facade pictures where they are minified, as the
        client did (:data:`~walkstream.client.draw.quads.FACADE_FILTERS`).
    """

    def __init__(
        self,
        objects: Mapping[int, Mesh] | None = None,
        size: tuple[int, int] = (640, 480),
        *,
        rooms: Mapping[int, CellMesh] | None = None,
        fov_deg: float = 60.0,
        near: float = 0.5,
        far: float = 2000.0,
        view_distance: float = 800.0,
        two_sided: bool = False,
        ground_z: float | None = None,
        ctx: moderngl.Context | None = None,
        forms: Mapping[tuple[int, int], Mesh] | None = None,
        facade_filter: str = "point",
    ) -> None:
        objects = objects or {}
        rooms = rooms or {}
        forms = forms or {}
        w, h = (int(v) for v in size)
        if w <= 0 or h <= 0:
            raise InputError(f"TruthRenderer.size: expected positive width and height, got {size}")
        if not float(view_distance) > 0:
            raise InputError(f"TruthRenderer.view_distance: expected > 0, got {view_distance}")
        self.size = (w, h)
        self._quads: QuadRenderer | None = None
        self.facade_filter = facade_filter
        self._smooth: dict[Sampling, SmoothTarget] = {}
        self._shown: SmoothTarget | None = None  # where the last frame's colour is (None: the point-sampled one)
        self.near, self.far = float(near), float(far)
        self.proj = perspective(fov_deg, w / h, near, far).astype(np.float64)
        self.view_distance = float(view_distance)
        self.two_sided = bool(two_sided)
        self.ground_z = None if ground_z is None else float(ground_z)
        """Height of the ground plane under every frame; None: none."""
        ids = np.array(sorted(int(i) for i in objects), np.int64)
        if len(ids) and ids[0] < 0:
            raise InputError(f"TruthRenderer: object ids must be >= 0, got {ids[0]}")
        self.ids = ids
        """The objects' ids, ascending: key index ``k < len(ids)`` is object ``ids[k]``."""
        meshes = [objects[int(i)] for i in ids]
        self._lo = np.array([m.positions.min(axis=0) if len(m.positions) else np.full(3, np.inf) for m in meshes], np.float64).reshape(-1, 3)
        self._hi = np.array([m.positions.max(axis=0) if len(m.positions) else np.full(3, -np.inf) for m in meshes], np.float64).reshape(-1, 3)
        self.keys: list[tuple[int, int]] = [object_key(i) for i in ids.tolist()]
        """What each key index draws, in draw order (:func:`object_key`, ``(cell, part)``)."""
        parts: list[Any] = []
        for cid in sorted(rooms):
            if int(cid) < 0:
                raise InputError(f"TruthRenderer: room cell ids must be >= 0, got {cid}")
            for k, part in enumerate(rooms[cid].parts):
                if part.triangles:
                    self.keys.append((int(cid), k))
                    parts.append(part)
        self._forms0 = len(self.keys)
        form_ids = sorted((int(i), int(lod)) for i, lod in forms)
        oid = [*ids.tolist(), *([-1] * len(parts))]
        lods = [*([2] * len(ids)), *([-1] * len(parts))]
        for i, lod in form_ids:
            if i < 0:
                raise InputError(f"TruthRenderer: object ids must be >= 0, got {i}")
            self.keys.append(form_key(i, lod))
            oid.append(i)
            lods.append(lod)
        form_meshes = [forms[k] for k in form_ids]
        self._key_oid = np.array(oid, np.int64)
        self._key_lod = np.array(lods, np.int64)
        # the order of a frame with forms: objects and forms by id, room parts after
        self._order_key = np.where(self._key_oid >= 0, self._key_oid, np.iinfo(np.int64).max)
        self.index = {key: i for i, key in enumerate(self.keys)}
        self.triangles = np.array(
            [len(m.indices) for m in meshes] + [p.triangles for p in parts] + [len(m.indices) for m in form_meshes],
            np.int64,
        )
        """Triangles of each key."""
        nv = np.array(
            [len(m.positions) for m in meshes] + [len(p.positions) for p in parts] + [len(m.positions) for m in form_meshes],
            np.int64,
        )
        ni = np.array(
            [m.indices.size for m in meshes] + [p.indices.size for p in parts] + [m.indices.size for m in form_meshes],
            np.int64,
        )
        v0 = np.concatenate([[0], np.cumsum(nv)]).astype(np.int64)
        i0 = np.concatenate([[0], np.cumsum(ni)]).astype(np.int64)
        self._first, self._stop = i0[:-1], i0[1:]
        nbytes = max(int(v0[-1]) * _VERTEX.itemsize, int(i0[-1]) * 4)
        if nbytes >= MAX_BUFFER_BYTES:
            # drivers take buffer sizes and offsets as 32-bit ints: past this they crash
            also = f" and {len(parts)} room parts" if parts else ""
            raise RenderError(
                f"TruthRenderer: {len(ids)} objects at LOD2{also} need a {nbytes / 2**30:.1f} GiB buffer "
                f"(at most {MAX_BUFFER_BYTES / 2**30:.0f} GiB): give it the objects near the camera only"
            )
        verts = np.empty(int(v0[-1]), _VERTEX)
        index = np.empty(int(i0[-1]), np.uint32)
        lit = [*enumerate(meshes), *((self._forms0 + j, m) for j, m in enumerate(form_meshes))]
        for k, m in lit:
            s, e = int(v0[k]), int(v0[k + 1])
            verts["p"][s:e] = m.positions
            verts["n"][s:e] = m.normals
            verts["c"][s:e, :3] = material_rgb(m.materials)
            index[i0[k] : i0[k + 1]] = m.indices.reshape(-1) + np.uint32(s)
        for j, p in enumerate(parts):
            k = len(ids) + j
            s, e = int(v0[k]), int(v0[k + 1])
            verts["p"][s:e] = p.positions
            # lit as the client lights a room part (flat normals: Part.mesh()), so that a
            # virtual wall's texture, rendered so by the bake, compares with what it carries
            verts["n"][s:e] = flat_normals(p.positions, p.indices)
            verts["c"][s:e, :3] = material_rgb(np.full(e - s, p.material))
            index[i0[k] : i0[k + 1]] = p.indices.reshape(-1) + np.uint32(s)
        verts["c"][:, 3] = 255
        verts["id"] = np.repeat(np.arange(1, len(nv) + 1, dtype=np.uint32), nv)  # 0 is the clear value: nothing
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
        self._depth = ctx.depth_texture((w, h))
        self._fbo = ctx.framebuffer(color_attachments=[self._colour, self._idbuf], depth_attachment=self._depth)
        # an integer attachment must not be cleared with the float sky colour: each is
        # cleared through a framebuffer of its own
        self._fbo_colour = ctx.framebuffer(color_attachments=[self._colour], depth_attachment=self._depth)
        self._fbo_ids = ctx.framebuffer(color_attachments=[self._idbuf])
        # the ground plane: four vertices rewritten per frame around the eye, key 0
        self._ground_vbo = ctx.buffer(reserve=4 * _VERTEX.itemsize)
        self._ground_ibo = ctx.buffer(np.array([0, 1, 2, 0, 2, 3], "<u4").tobytes())
        self._ground_vao = ctx.vertex_array(
            self._prog,
            [(self._ground_vbo, "3f 3f 4f1 u4", "in_position", "in_normal", "in_color", "in_id")],
            index_buffer=self._ground_ibo,
            index_element_size=4,
        )
        self._gl += [self._ground_vao, self._ground_ibo, self._ground_vbo]
        self._gl += [self._vao, self._ibo, self._vbo, self._fbo, self._fbo_colour, self._fbo_ids]
        self._gl += [self._colour, self._idbuf, self._depth]
        check_gl_error(ctx, "after creating the truth renderer")

    # -- what to draw ---------------------------------------------------------------

    def within(self, eye: ArrayLike) -> NDArray[np.int64]:
        """Ids of the objects whose bounding box comes within the view distance of ``eye``."""
        out: NDArray[np.int64] = self.ids[self._near(eye)]
        return out

    def _near(self, eye: ArrayLike) -> NDArray[np.bool_]:
        e = np.asarray(eye, np.float64).reshape(3)
        gap = np.maximum(np.maximum(self._lo - e, e - self._hi), 0.0)
        out: NDArray[np.bool_] = np.einsum("nk,nk->n", gap, gap) <= self.view_distance**2
        return out

    def flags(self, keys: Iterable[tuple[int, int]]) -> NDArray[np.bool_]:
        """``(len(keys),)`` which of :attr:`keys` ``keys`` names (unknown keys are ignored)."""
        out = np.zeros(len(self.keys), bool)
        for key in keys:
            i = self.index.get((int(key[0]), int(key[1])))
            if i is not None:
                out[i] = True
        return out

    def object_ids(self, index: ArrayLike) -> NDArray[np.uint32]:
        """A frame's key indices as object id + 1 per pixel (0 where no object shows), forms included."""
        k = np.asarray(index, np.int64)
        oid = np.where(k >= 0, self._key_oid[np.clip(k, 0, None)] if len(self._key_oid) else -1, -1)
        out: NDArray[np.uint32] = (np.maximum(oid, -1) + 1).astype(np.uint32)
        return out

    def lods(self, index: ArrayLike) -> NDArray[np.int64]:
        """A frame's key indices as the LOD each pixel's object is drawn at (2: the object's
        own key, 0 or 1: a form), -1 where no object shows."""
        k = np.asarray(index, np.int64)
        out: NDArray[np.int64] = np.where(k >= 0, self._key_lod[np.clip(k, 0, None)] if len(self._key_lod) else -1, -1)
        return out

    # -- frames ---------------------------------------------------------------------

    def render(
        self,
        eye: ArrayLike,
        view: ArrayLike,
        only: NDArray[np.bool_] | None = None,
        fog_m: float = math.inf,
        *,
        proj: ArrayLike | None = None,
        samples: Sampling | None = None,
    ) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        """Draw the keys (all, or those flagged in ``only``) from one camera.

        Parameters
        ----------
        eye : (3,) float
            The camera position (for the fog).
        view : (4, 4) float
            The camera.
        only : (len(keys),) bool, optional
            What to draw (default: the full scene, every object at LOD2 and every room
            part; the coarser ``forms`` only when flagged).
        fog_m : float
            Fragments farther from the eye are not drawn.
        proj : (4, 4) float, optional
            The projection (default: the renderer's).
        samples : Sampling, optional
            The colour's sampling (:mod:`walkstream.client.truth.antialias`); None or
            one sample: point-sampled.  Anti-aliased, the frame is drawn a second time
            into its target, and :meth:`colour` and :meth:`paint_quads` use that one.

        Returns
        -------
        ids : (h, w) int64
            Index into :attr:`keys` of what each pixel shows, -1 for nothing; row 0 at the top.
        depth : (h, w) float64
            Eye-space depth, metres (``inf`` where nothing shows).

        The colour of the same frame is :meth:`colour`.
        """
        if self.ctx is None:
            raise RenderError("TruthRenderer: used after release()")

        ctx = self.ctx
        p = self.proj if proj is None else np.asarray(proj, np.float64)
        vp = p @ np.asarray(view, np.float64)
        self._prog["u_view_proj"].write(mat4_bytes(vp))
        self._prog["u_eye"].value = tuple(float(v) for v in np.asarray(eye, np.float64).reshape(3))
        self._prog["u_fog"].value = float(min(fog_m, 1e30))
        w, h = self.size
        r, g, b = (c / 255.0 for c in BACKGROUND_RGB)
        self._fbo_colour.clear(r, g, b, 1.0, depth=1.0)
        self._fbo_ids.clear(0.0, 0.0, 0.0, 0.0)
        self._fbo.use()
        ctx.viewport = (0, 0, w, h)
        if only is None:  # the full scene: every object at LOD2 and every room part, no coarser form
            flags = np.zeros(len(self.keys), bool)
            flags[: self._forms0] = True
        else:
            flags = np.asarray(only, bool)
        runs = self._runs(flags)
        self._draw(eye, p, runs)
        self._shown = None
        if samples is not None and not samples.point:
            target = self._smooth.get(samples)
            if target is None:
                target = self._smooth[samples] = SmoothTarget(ctx, self.size, samples)
            target.clear((r, g, b))
            self._draw(eye, p, runs)
            self._shown = target
        check_gl_error(ctx, "after drawing a truth frame")
        raw = self._fbo.read(components=1, attachment=1, dtype="u4", alignment=1)
        ids = np.frombuffer(raw, np.uint32).reshape(h, w)[::-1].astype(np.int64) - 1
        d = np.frombuffer(self._depth.read(alignment=1), np.float32).astype(np.float64)
        n, f = self.near, self.far
        if proj is not None:  # the depth range of the projection drawn with
            n, f = p[2, 3] / (p[2, 2] - 1.0), p[2, 3] / (p[2, 2] + 1.0)
        ndc = 2.0 * d - 1.0
        lin = np.where(d >= 1.0, np.inf, 2.0 * n * f / (f + n - ndc * (f - n)))
        return ids, lin.reshape(h, w)[::-1]

    def _draw(self, eye: ArrayLike, proj: NDArray[np.float64], runs: list[tuple[int, int]]) -> None:
        """Draw the ground and the key runs ``runs`` into the bound framebuffer."""
        import moderngl

        ctx = self.ctx
        ctx.disable(moderngl.BLEND)
        if self.ground_z is not None:
            self._draw_ground(eye, proj)
        if self.two_sided:
            ctx.enable(moderngl.DEPTH_TEST)
            ctx.disable(moderngl.CULL_FACE)
        else:
            ctx.enable(moderngl.DEPTH_TEST | moderngl.CULL_FACE)
            ctx.front_face = "ccw"
            ctx.cull_face = "back"
        ctx.depth_func = "<"
        for s, t in runs:
            first, last = int(self._first[s]), int(self._stop[t - 1])
            if last > first:
                self._vao.render(moderngl.TRIANGLES, vertices=last - first, first=first)

    def _runs(self, flags: NDArray[np.bool_]) -> list[tuple[int, int]]:
        """``(start, stop)`` runs of key indices to draw, in draw order."""
        if not flags[self._forms0 :].any():  # key order: objects by id, then room parts
            padded = np.concatenate([[False], flags, [False]]).astype(np.int8)
            step = np.diff(padded)
            starts, stops = np.flatnonzero(step == 1), np.flatnonzero(step == -1)
            return list(zip(starts.tolist(), stops.tolist(), strict=True))
        keys = np.flatnonzero(flags)
        keys = keys[np.argsort(self._order_key[keys], kind="stable")]
        cut = np.flatnonzero(np.diff(keys) != 1) + 1
        return [(int(r[0]), int(r[-1]) + 1) for r in np.split(keys, cut)]

    def _draw_ground(self, eye: ArrayLike, proj: NDArray[np.float64]) -> None:
        # depth test off: the plane writes no depth and whatever is drawn next covers it;
        # its key is 0 (nothing), so no pixel's key changes.  Seen from below it is left out.
        import moderngl

        assert self.ground_z is not None
        e = np.asarray(eye, np.float64).reshape(3)
        if e[2] <= self.ground_z:
            return
        far = proj[2, 3] / (proj[2, 2] + 1.0)
        v = np.zeros(4, _VERTEX)
        v["p"] = ground_quad(e, 2.0 * far, self.ground_z)
        v["n"] = (0.0, 0.0, 1.0)
        v["c"][:, :3] = material_rgb([GROUND_MATERIAL])
        v["c"][:, 3] = 255
        self._ground_vbo.write(v.tobytes())
        self.ctx.disable(moderngl.DEPTH_TEST | moderngl.CULL_FACE)
        self._ground_vao.render(moderngl.TRIANGLES)

    def colour(self, *, smooth: bool = True) -> NDArray[np.uint8]:
        """``(h, w, 3)`` the lit colour of the last frame drawn, row 0 at the top: anti-aliased
        when it was drawn so, unless ``smooth`` is False (its point-sampled colour, as
        drawn before any :meth:`paint_quads`)."""
        if self.ctx is None:
            raise RenderError("TruthRenderer: used after release()")
        if self._shown is not None and smooth:
            return self._shown.colour()
        w, h = self.size
        raw = self._fbo.read(components=3, attachment=0, alignment=1)
        return np.frombuffer(raw, np.uint8).reshape(h, w, 3)[::-1].copy()

    def colour_frame(
        self, eye: ArrayLike, view: ArrayLike, proj: ArrayLike | None = None, *, also: Iterable[int] = (),
        samples: Sampling | None = None,
    ) -> tuple[NDArray[np.uint8], NDArray[np.uint32]]:
        """The city's truth of one camera: every object within the view distance, and ``also``.

        Parameters
        ----------
        eye : (3,) float
            The camera position (for the view distance).
        view, proj : (4, 4) float
            The camera; ``proj`` defaults to the renderer's projection.
        also : ints
            Objects to draw wherever they are (those the client drew), so that the
            truth never lacks a surface the client's frame shows.
        samples : Sampling, optional
            The colour's sampling (:meth:`render`); the ids stay point-sampled.

        Returns
        -------
        rgb : (h, w, 3) uint8
            The lit colour frame, row 0 at the top.
        ids : (h, w) uint32
            Object id + 1 per pixel, 0 where none shows.
        """
        draw = np.zeros(len(self.keys), bool)
        draw[: len(self.ids)] = self._near(eye)
        extra = np.fromiter((int(i) for i in also), np.int64)
        if len(extra) and len(self.ids):
            pos = np.clip(np.searchsorted(self.ids, extra), 0, len(self.ids) - 1)
            draw[pos[self.ids[pos] == extra]] = True
        ids, _ = self.render(eye, view, draw, proj=proj, samples=samples)
        return self.colour(), self.object_ids(ids)

    def paint_quads(
        self, quads: Sequence[Quad], view: ArrayLike, proj: ArrayLike | None = None, image_filter: int | None = None
    ) -> NDArray[np.uint8]:
        """Draw textured ``quads`` over the last frame drawn (its depth tested, not written;
        premultiplied blend, as the client draws impostors) and return the colour, row 0 at the top
        (into the anti-aliased target when the last frame was drawn anti-aliased).
        ``image_filter`` overrides the client's minifying filter of impostor images
        (:class:`~walkstream.client.draw.quads.QuadRenderer`; benchmarks compare them)."""
        if self.ctx is None:
            raise RenderError("TruthRenderer: used after release()")
        from walkstream.client.draw.quads import QuadRenderer

        if self._quads is not None and image_filter is not None and self._quads.image_filter != image_filter:
            self._quads.release()
            self._quads = None
        if self._quads is None:
            self._quads = QuadRenderer(self.ctx, image_filter, self.facade_filter)
        if self._shown is not None:
            self._shown.use()
        else:
            self._fbo_colour.use()
        p = self.proj if proj is None else proj
        self._quads.draw(quads, np.asarray(p, np.float64) @ np.asarray(view, np.float64))
        return self.colour()

    def release(self) -> None:
        """Release every GL object (and the context if it was made here); idempotent."""
        if self._quads is not None:
            self._quads.release()
            self._quads = None
        for target in self._smooth.values():
            target.release()
        self._smooth.clear()
        self._shown = None
        release_objects(self.ctx, self._gl, self._own_ctx)
        self.ctx = None
