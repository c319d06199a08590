"""Offscreen mesh renderer for the client and for report figures.

:class:`MeshRenderer` keeps one vertex and index buffer per uploaded mesh and draws
them with a directional + ambient light, coloured by material through
:data:`~walkstream.shared.palette.PALETTE`.  Depth test and back-face culling are on, so a
triangle with the wrong winding shows up as a hole rather than being hidden.

:func:`render_lods_figure` draws several meshes (the LODs of one building) side by
side into a PNG for reports.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable, Sequence

import moderngl
import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.shared import lighting
from walkstream.shared.camera import fit_view, mat4_bytes
from walkstream.shared.errors import InputError, RenderError
from walkstream.shared.gl import Framebuffer, Releasable, check_gl_error, create_context
from walkstream.shared.ground import GROUND_MATERIAL, ground_quad
from walkstream.shared.palette import material_rgb
from walkstream.shared.records import Mesh

__all__ = [
    "AMBIENT",
    "BACKGROUND_RGB",
    "FIGURE_DIRECTION",
    "LIGHT_DIRECTION",
    "MeshRenderer",
    "SHADINGS",
    "pack_vertices",
    "render_lods_figure",
]

#: Clear colour, ambient share and light direction: the one lighting of city objects
#: (:mod:`walkstream.shared.lighting`, which the bake's impostor images use too).
BACKGROUND_RGB: tuple[int, int, int] = lighting.BACKGROUND_RGB
AMBIENT = lighting.AMBIENT
LIGHT_DIRECTION: tuple[float, float, float] = lighting.LIGHT_DIRECTION

#: From the object towards the eye in :func:`render_lods_figure`: south-west, 25 degrees up.
FIGURE_DIRECTION: tuple[float, float, float] = (
    -math.cos(math.radians(25.0)) * math.sqrt(0.5),
    -math.cos(math.radians(25.0)) * math.sqrt(0.5),
    math.sin(math.radians(25.0)),
)

# Two programs share the vertex layout.  Without fog (the city) the lighting is done
# per vertex and the fragment shader only writes the interpolated colour: on llvmpipe
# the fragment shader is most of a frame's cost (the budget's floor is a few hundred
# triangles covering the screen), and a fog branch is paid per fragment even when fog
# is off (llvmpipe runs both sides of a branch under a mask).  Every triangle the client
# builds is flat (its three normals are equal), so per-vertex lighting computes the same
# colour; frames differ from per-fragment lighting by at most one level of 255 in a
# channel (rounding: ``walkstream bench fill`` measures it).  With fog
# (interiors) or ``shading="fragment"`` the per-fragment program below is used.
_VERTEX_SHADER = """
#version 330
uniform mat4 u_view_proj;
uniform vec3 u_light_dir;
uniform float u_ambient;
in vec3 in_position;
in vec3 in_normal;
in vec4 in_color;
out vec3 v_lit;
invariant gl_Position;
void main() {
    gl_Position = u_view_proj * vec4(in_position, 1.0);
    float diffuse = max(dot(normalize(in_normal), u_light_dir), 0.0);
    v_lit = in_color.rgb * (u_ambient + (1.0 - u_ambient) * diffuse);
}
"""

_FRAGMENT_SHADER = """
#version 330
in vec3 v_lit;
out vec4 f_color;
void main() {
    f_color = vec4(v_lit, 1.0);
}
"""

_FOG_VERTEX_SHADER = """
#version 330
uniform mat4 u_view_proj;
in vec3 in_position;
in vec3 in_normal;
in vec4 in_color;
out vec3 v_normal;
out vec3 v_color;
out vec3 v_world;
invariant gl_Position;
void main() {
    gl_Position = u_view_proj * vec4(in_position, 1.0);
    v_normal = in_normal;
    v_color = in_color.rgb;
    v_world = in_position;
}
"""

_FOG_FRAGMENT_SHADER = """
#version 330
uniform vec3 u_light_dir;
uniform float u_ambient;
uniform vec3 u_eye;
uniform float u_fog;
uniform vec3 u_background;
in vec3 v_normal;
in vec3 v_color;
in vec3 v_world;
out vec4 f_color;
void main() {
    // Meshes are in scene-local world space (no model matrix), so the normal needs no
    // transform; renormalise because interpolation shortens it.
    float diffuse = max(dot(normalize(v_normal), u_light_dir), 0.0);
    vec3 lit = v_color * (u_ambient + (1.0 - u_ambient) * diffuse);
    // fog (interiors, u_fog > 0): surfaces fade into the background over the last
    // fifth of the fog distance, so that what the fog culls does not pop
    float fade = u_fog > 0.0 ? smoothstep(0.8 * u_fog, u_fog, distance(v_world, u_eye)) : 0.0;
    f_color = vec4(mix(lit, u_background, fade), 1.0);
}
"""

_PROGRAMS: dict[str, tuple[str, str]] = {
    "plain": (_VERTEX_SHADER, _FRAGMENT_SHADER),
    "fog": (_FOG_VERTEX_SHADER, _FOG_FRAGMENT_SHADER),
}

#: Values of ``MeshRenderer(shading=...)``: where the lighting is computed without fog.
SHADINGS: tuple[str, ...] = ("vertex", "fragment")

# Interleaved vertex: position, normal (float32) and an RGBA8 colour. 28 bytes keeps
# every attribute 4-byte aligned; alpha is padding.
_VERTEX_DTYPE = np.dtype([("p", "<f4", 3), ("n", "<f4", 3), ("c", "u1", 4)])
_VERTEX_FORMAT = "3f 3f 4f1"


def pack_vertices(mesh: Mesh) -> NDArray[np.void]:
    """The interleaved GPU vertices of ``mesh``: 28 bytes each.

    Returns
    -------
    (n_vertices,) structured array
        float32 position ``p`` (3), float32 normal ``n`` (3), RGBA8 colour ``c`` of the
        material (alpha 255, padding), in the layout ``"3f 3f 4f1"``.
    """
    verts = np.empty(len(mesh.positions), _VERTEX_DTYPE)
    verts["p"] = mesh.positions
    verts["n"] = mesh.normals
    verts["c"][:, :3] = material_rgb(mesh.materials)
    verts["c"][:, 3] = 255
    return verts


class _GpuMesh:
    """The GL objects of one uploaded mesh (holds the mesh so its id() stays unique)."""

    __slots__ = ("mesh", "vbo", "ibo", "vaos")

    def __init__(self, mesh: Mesh | None, vbo: moderngl.Buffer, ibo: moderngl.Buffer) -> None:
        self.mesh = mesh
        self.vbo = vbo
        self.ibo = ibo
        # one vertex array per program ("plain", "fog"), made on first use
        self.vaos: dict[str, moderngl.VertexArray] = {}

    def vao(self, name: str, program: moderngl.Program) -> moderngl.VertexArray:
        vao = self.vaos.get(name)
        if vao is None:
            vao = self.vaos[name] = program.ctx.vertex_array(
                program,
                [(self.vbo, _VERTEX_FORMAT, "in_position", "in_normal", "in_color")],
                index_buffer=self.ibo,
                index_element_size=4,
            )
        return vao

    def release(self) -> None:
        for vao in self.vaos.values():
            vao.release()
        self.vaos.clear()
        self.ibo.release()
        self.vbo.release()


class MeshRenderer(Releasable):
    """Uploads :class:`~walkstream.shared.records.Mesh` objects and draws them offscreen.

    Parameters
    ----------
    ctx : moderngl.Context, optional
        Context to draw with.  When omitted the renderer creates one with
        :func:`~walkstream.shared.gl.create_context` and releases it in :meth:`close`; a context
        that is passed in stays the caller's.
    light_dir : (3,) float
        Direction towards the light, world space (normalised here).
    ambient : float
        Share of the base colour lit regardless of the light (0..1).
    background : (3,) int
        Clear colour, sRGB 0-255.
    shading : {"vertex", "fragment"}
        Where the lighting is computed when there is no fog: ``"vertex"`` (default,
        the cheap program) or ``"fragment"`` (the per-fragment program that fog uses;
        the path before, kept for comparison).  With fog the per-fragment program is
        always used.

    Notes
    -----
    Uploaded meshes are keyed by identity (``Mesh`` holds arrays, so it is not
    hashable); the renderer keeps a reference to each so that an id is never reused
    while its buffers live.  Call :meth:`forget` to drop one, :meth:`close` for all.
    """

    def __init__(
        self,
        ctx: moderngl.Context | None = None,
        light_dir: ArrayLike = LIGHT_DIRECTION,
        ambient: float = AMBIENT,
        background: tuple[int, int, int] = BACKGROUND_RGB,
        shading: str = "vertex",
    ) -> None:
        if shading not in SHADINGS:
            raise InputError(f"MeshRenderer.shading: expected one of {SHADINGS}, got {shading!r}")
        self.shading: str = shading
        light = np.asarray(light_dir, dtype=np.float64).reshape(3)
        if not np.linalg.norm(light) > 0:
            raise InputError(
                f"MeshRenderer.light_dir: expected a non-zero vector, got {light_dir!r}"
            )
        if not 0.0 <= ambient <= 1.0:
            raise InputError(f"MeshRenderer.ambient: expected 0..1, got {ambient}")
        r, g, b = (int(c) for c in background)
        self.background: tuple[int, int, int] = (r, g, b)
        self.fog_m: float = 0.0
        """Fog distance (metres) over whose last fifth surfaces fade into the
        background; 0: no fog (the city)."""
        self.ground_z: float | None = None
        """Height of the ground plane drawn under every frame (:mod:`walkstream.shared.ground`:
        after the clear, depth test off, so it hides nothing); None: no plane (an interior,
        a figure)."""
        self._ground: _GpuMesh | None = None
        # Validate before creating a context, so a bad argument leaks nothing.
        self._own_ctx = ctx is None
        self.ctx: moderngl.Context = create_context() if ctx is None else ctx
        self._meshes: dict[int, _GpuMesh] = {}
        self._fb: Framebuffer | None = None
        self._light = tuple(float(v) for v in light / np.linalg.norm(light))
        self._ambient = float(ambient)
        self._progs: dict[str, moderngl.Program] = {}
        self._closed = False
        self._make_program("plain")  # a driver that cannot compile it fails here, early

    def _make_program(self, name: str) -> moderngl.Program:
        prog = self._progs.get(name)
        if prog is not None:
            return prog
        vs, fs = _PROGRAMS[name]
        try:
            prog = self.ctx.program(vertex_shader=vs, fragment_shader=fs)
        except Exception as exc:
            self.release()
            raise RenderError(f"MeshRenderer: shader program failed: {exc}") from exc
        self._progs[name] = prog
        self._set(prog, "u_light_dir", self._light)
        self._set(prog, "u_ambient", self._ambient)
        return prog

    @staticmethod
    def _set(prog: moderngl.Program, name: str, value: object) -> None:
        u = prog[name]
        assert isinstance(u, moderngl.Uniform), f"{name} is not a uniform"
        u.value = value

    @property
    def program_name(self) -> str:
        """Which program a frame is drawn with now: ``"fog"`` (per-fragment lighting and
        fog: fog is on or ``shading="fragment"``) or ``"plain"`` (per-vertex lighting)."""
        return "fog" if self.fog_m > 0.0 or self.shading == "fragment" else "plain"

    # -- buffers -------------------------------------------------------------------

    @property
    def uploaded(self) -> int:
        """Number of meshes with live GPU buffers."""
        return len(self._meshes)

    def upload(self, mesh: Mesh) -> None:
        """Create the vertex and index buffers of ``mesh`` (no-op if already uploaded).

        A mesh without triangles gets no buffers (GL cannot make empty ones) and is
        skipped when drawing.
        """
        if id(mesh) in self._meshes or mesh.triangles == 0:
            return
        if self._closed:
            raise RenderError("MeshRenderer: used after close()")
        vbo = self.ctx.buffer(pack_vertices(mesh).tobytes())
        ibo = self.ctx.buffer(np.ascontiguousarray(mesh.indices, dtype="<u4").tobytes())
        self._meshes[id(mesh)] = _GpuMesh(mesh, vbo, ibo)

    def buffers(self, mesh: Mesh) -> tuple[moderngl.Buffer, moderngl.Buffer] | None:
        """The vertex and index buffers of an uploaded ``mesh`` (None when it has none).

        Vertices are 28 bytes: float32 position, float32 normal, RGBA8 colour; indices
        uint32 triangles.  For other passes over the same buffers (object ids).
        """
        gm = self._meshes.get(id(mesh))
        return None if gm is None else (gm.vbo, gm.ibo)

    def forget(self, mesh: Mesh) -> None:
        """Release the buffers of ``mesh`` (no-op if it was not uploaded)."""
        gm = self._meshes.pop(id(mesh), None)
        if gm is not None:
            gm.release()

    # -- drawing -------------------------------------------------------------------

    def _framebuffer(self, size: tuple[int, int]) -> Framebuffer:
        # Reuse the framebuffer while the size stays the same (the usual case per frame).
        w, h = (int(v) for v in size)
        if self._fb is None or self._fb.size != (w, h):
            if self._fb is not None:
                self._fb.release()
                self._fb = None
            self._fb = Framebuffer(self.ctx, (w, h))
        return self._fb

    def draw(
        self,
        meshes: Iterable[Mesh],
        view: ArrayLike,
        proj: ArrayLike,
        size: tuple[int, int],
        viewport: tuple[int, int, int, int] | None = None,
        clear: bool = True,
    ) -> None:
        """Draw into the internal framebuffer without reading it back.

        Parameters
        ----------
        meshes : iterable of Mesh
            Uploaded on first use.
        view, proj : (4, 4) float
            Camera matrices (see :mod:`walkstream.shared.camera`).
        size : (int, int)
            Framebuffer width and height in pixels.
        viewport : (x, y, w, h), optional
            Sub-rectangle to draw into (GL convention: y from the bottom); default is
            the whole framebuffer.
        clear : bool
            Clear colour and depth of the whole framebuffer first.
        """
        self.begin(view, proj, size, viewport, clear)
        name = self.program_name
        prog = self.program
        for mesh in meshes:
            self.upload(mesh)
            gm = self._meshes.get(id(mesh))
            if gm is not None:
                gm.vao(name, prog).render()
        check_gl_error(self.ctx, "after MeshRenderer.draw")

    @property
    def program(self) -> moderngl.Program:
        """The shader program a frame is drawn with now (:attr:`program_name`; vertex
        layout ``"3f 3f 4f1"``: position, normal, colour)."""
        if self._closed:
            raise RenderError("MeshRenderer: used after close()")
        return self._make_program(self.program_name)

    def begin(
        self,
        view: ArrayLike,
        proj: ArrayLike,
        size: tuple[int, int],
        viewport: tuple[int, int, int, int] | None = None,
        clear: bool = True,
    ) -> None:
        """Bind and clear the framebuffer and set the camera and GL state for a frame.

        What :meth:`draw` does before its draw calls, for callers that issue their own
        (batched) draw calls with :attr:`program`; parameters as for :meth:`draw`.
        """
        prog = self.program
        fb = self._framebuffer(size)
        fb.use()
        if clear:
            r, g, b = (c / 255.0 for c in self.background)
            fb.clear((r, g, b, 1.0))
        if viewport is not None:
            x, y, vw, vh = (int(v) for v in viewport)
            self.ctx.viewport = (x, y, vw, vh)
        vp = np.asarray(proj, dtype=np.float64) @ np.asarray(view, dtype=np.float64)
        u_vp = prog["u_view_proj"]
        assert isinstance(u_vp, moderngl.Uniform)
        u_vp.write(mat4_bytes(vp))
        if self.program_name == "fog":
            eye = np.linalg.inv(np.asarray(view, dtype=np.float64))[:3, 3]
            self._set(prog, "u_eye", tuple(float(v) for v in eye))
            self._set(prog, "u_fog", max(float(self.fog_m), 0.0))
            self._set(prog, "u_background", tuple(c / 255.0 for c in self.background))
        if clear and self.ground_z is not None:
            self._draw_ground(view, proj)
        # Set on every draw: the context may be shared with code that changes state.
        self.ctx.enable(self.ctx.DEPTH_TEST | self.ctx.CULL_FACE)
        self.ctx.front_face = "ccw"
        self.ctx.cull_face = "back"

    def _draw_ground(self, view: ArrayLike, proj: ArrayLike) -> None:
        # The plane under the eye, reaching twice the far plane, drawn with the depth test
        # off: it writes no depth, so whatever is drawn next covers it, and a street or
        # an area lying on it never fights with it.  Seen from below it is left out.
        assert self.ground_z is not None
        eye = np.linalg.inv(np.asarray(view, dtype=np.float64))[:3, 3]
        if eye[2] <= self.ground_z:
            return
        p = np.asarray(proj, dtype=np.float64)
        far = p[2, 3] / (p[2, 2] + 1.0)
        verts = np.empty(4, _VERTEX_DTYPE)
        verts["p"] = ground_quad(eye, 2.0 * far, self.ground_z)
        verts["n"] = (0.0, 0.0, 1.0)
        verts["c"][:, :3] = material_rgb([GROUND_MATERIAL])
        verts["c"][:, 3] = 255
        if self._ground is None:
            quad = np.array([0, 1, 2, 0, 2, 3], "<u4")
            self._ground = _GpuMesh(None, self.ctx.buffer(verts.tobytes()), self.ctx.buffer(quad.tobytes()))
        else:
            self._ground.vbo.write(verts.tobytes())
        self.ctx.disable(self.ctx.DEPTH_TEST | self.ctx.CULL_FACE)
        self._ground.vao(self.program_name, self.program).render()

    def read(self) -> NDArray[np.uint8]:
        """The last drawn image, ``(h, w, 3) uint8``, row 0 at the top."""
        if self._fb is None:
            raise RenderError("MeshRenderer.read: nothing drawn yet")
        return self._fb.read(components=3)

    def render(
        self,
        meshes: Iterable[Mesh],
        view: ArrayLike,
        proj: ArrayLike,
        size: tuple[int, int],
    ) -> NDArray[np.uint8]:
        """Draw ``meshes`` and read the image back.

        Parameters
        ----------
        meshes : iterable of Mesh
        view, proj : (4, 4) float
            Camera matrices (see :mod:`walkstream.shared.camera`).
        size : (int, int)
            Width and height in pixels.

        Returns
        -------
        (h, w, 3) uint8
            sRGB image, row 0 at the top.
        """
        self.draw(meshes, view, proj, size)
        return self.read()

    # -- lifetime ------------------------------------------------------------------

    def release(self) -> None:
        """Release every GL object made here (and the context, if it was made here)."""
        for gm in self._meshes.values():
            gm.release()
        self._meshes.clear()
        if self._ground is not None:
            self._ground.release()
            self._ground = None
        if self._fb is not None:
            self._fb.release()
            self._fb = None
        for prog in self._progs.values():
            prog.release()
        self._progs.clear()
        self._closed = True
        if self._own_ctx:
            self.ctx.release()
            self._own_ctx = False



def _bounds(mesh: Mesh) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
    """Bounding box of the vertices that triangles use, or None for an empty mesh."""
    if mesh.triangles == 0:
        return None
    used = mesh.positions[np.unique(mesh.indices)].astype(np.float64)
    return used.min(axis=0), used.max(axis=0)


def render_lods_figure(
    meshes: Sequence[Mesh],
    path: str | os.PathLike[str],
    size: tuple[int, int] = (1200, 500),
    titles: Sequence[str] = ("LOD0", "LOD1", "LOD2"),
    ctx: moderngl.Context | None = None,
    supersample: int = 2,
) -> None:
    """Draw meshes side by side into a PNG, each framed by its own bounding box.

    All panels use the same 3/4 view direction (:data:`FIGURE_DIRECTION`, from the
    south-west and 25 degrees above), so the LODs of one building compare directly.
    Each panel is titled with its name and triangle count.

    Parameters
    ----------
    meshes : sequence of Mesh
        One panel each, left to right.
    path : path-like
        Output PNG.
    size : (int, int)
        Width and height of the PNG in pixels.
    titles : sequence of str
        Panel names; panels beyond ``len(titles)`` are called ``LOD<i>``.
    ctx : moderngl.Context, optional
        Context to draw with (default: a new one, released afterwards).
    supersample : int
        Render each panel this many times larger and average down (anti-aliasing
        without relying on driver MSAA support).
    """
    # Agg through the object API: no pyplot global state, no GUI backend selection.
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    if not meshes:
        raise InputError("render_lods_figure: expected at least one mesh, got none")
    w, h = (int(v) for v in size)
    n = len(meshes)
    title_px = min(40, h // 4)
    pad = 4
    panel_w = max(1, w // n - 2 * pad)
    panel_h = max(1, h - title_px - 2 * pad)
    ss = max(1, int(supersample))
    fovy = 30.0

    images: list[NDArray[np.uint8]] = []
    with MeshRenderer(ctx) as r:
        for mesh in meshes:
            box = _bounds(mesh)
            if box is None:
                images.append(np.empty((panel_h, panel_w, 3), np.uint8))
                images[-1][:] = r.background
                continue
            view, proj = fit_view(box[0], box[1], FIGURE_DIRECTION, fovy, panel_w / panel_h)
            img = r.render([mesh], view, proj, (panel_w * ss, panel_h * ss))
            img = img.reshape(panel_h, ss, panel_w, ss, 3).mean(axis=(1, 3))
            images.append(np.round(img).astype(np.uint8))

    dpi = 100
    fig = Figure(figsize=(w / dpi, h / dpi), dpi=dpi, facecolor="white")
    FigureCanvasAgg(fig)
    for i, (mesh, img) in enumerate(zip(meshes, images, strict=True)):
        name = titles[i] if i < len(titles) else f"LOD{i}"
        ax = fig.add_axes(
            (
                (i * (w / n) + pad) / w,
                pad / h,
                panel_w / w,
                panel_h / h,
            )
        )
        ax.imshow(img, interpolation="nearest", aspect="auto")
        ax.set_axis_off()
        ax.set_title(f"{name}: {mesh.triangles:,} triangles", fontsize=12, pad=6)
    fig.savefig(os.fspath(path), dpi=dpi, format="png")
