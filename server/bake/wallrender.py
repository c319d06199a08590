"""Wall textures: what lies behind a virtual wall, seen off-axis from a zone's sampling point.

:class:`WallRenderer` holds every triangle of a scene in one vertex buffer (an
interior's elements, or a city's objects with buildings at LOD2, as
:func:`wall_elements` lists them) (flat normals, the palette's material colours, the client's lighting of
:mod:`walkstream.shared.lighting`; one headless context as every renderer of the
project) and renders a wall side's zone with an **off-axis perspective** whose
near plane is the wall itself (:func:`off_axis`): the frustum from the sampling
point through the wall's rectangle, so what is in front of the wall is clipped and
the image lands on the wall's quad exactly as the sampling point sees it.  Elements
crossing the wall are not on the texture: they are drawn as transparent holes (depth
written, colour and alpha 0), so the client's quad, drawn over the geometry at the
wall's depth, lets the object's geometry behind the wall's plane show through instead
of covering it (the paper's treatment of the geometry that stays geometry).  Samples are averaged
(:data:`~.litimage.SUPERSAMPLE`) into premultiplied RGBA over transparent black
(:mod:`walkstream.shared.codec.image`).

:func:`wall_task` is the chunk task of the one chunk runner (:mod:`.chunks`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from walkstream.server.bake.wallplan import WallJob, texture_height
from walkstream.server.sources.interior import InteriorScene
from walkstream.server.sources.scene import SourceScene
from walkstream.shared.camera import mat4_bytes
from walkstream.shared.camera import off_axis as camera_off_axis
from walkstream.shared.codec.image import encode_image
from walkstream.shared.gl import (
    Framebuffer,
    Releasable,
    check_gl_error,
    create_context,
    release_objects,
)
from walkstream.shared.litimage import SUPERSAMPLE, average_samples, lit_program
from walkstream.shared.palette import material_rgb
from walkstream.shared.walldepth import attach_depth, encode_depth, vertex_depths
from walkstream.shared.walls import WallSide

__all__ = ["WallElement", "WallRenderer", "off_axis", "release_wall_renderer", "wall_elements", "wall_task"]

_FAR = 2000.0
"""Far plane of a texture's view, metres (as far as the client draws the streets; an
interior ends long before)."""

_FRAGMENT_SHADER = """
#version 330
uniform float u_hole;
in vec3 v_lit;
out vec4 f_color;
void main() {
    // an object crossing the wall: a transparent hole, so its geometry shows through the quad
    f_color = u_hole > 0.5 ? vec4(0.0) : vec4(v_lit, 1.0);
}
"""


WallElement = tuple[int, NDArray[np.float64], NDArray[np.uint8]]
"""One object a wall texture may show: ``(id, triangles (m, 3, 3), materials (m,))``."""


def wall_elements(scene: InteriorScene | SourceScene) -> list[WallElement]:
    """What wall textures of ``scene`` show: an interior's elements, or a city's objects
    as the bake renders them (:func:`~.visibility.meshes_for_scene`, buildings at LOD2,
    the detail the client draws near) built from their stored form
    (:func:`~.objectrows.stored_scene`: the centimetre the client rebuilds from, so a
    door lands on the side the client's own building has it)."""
    if isinstance(scene, InteriorScene):
        return [(int(e.id), e.soup.astype(np.float64), np.asarray(e.materials, np.uint8))
                for e in scene.elements if len(e.triangles)]
    from walkstream.server.bake.idpack import meshes_for_scene
    from walkstream.server.bake.objectrows import stored_scene

    meshes, ids = meshes_for_scene(stored_scene(scene), 2)
    out: list[WallElement] = []
    for oid, m in zip(ids.tolist(), meshes, strict=True):
        idx = np.asarray(m.indices, np.int64).reshape(-1, 3)
        if len(idx) == 0:
            continue
        mats = np.asarray(m.materials, np.uint8)
        tri_mats = mats[idx[:, 0]] if len(mats) == len(m.positions) else np.zeros(len(idx), np.uint8)
        out.append((int(oid), np.asarray(m.positions, np.float64)[idx], tri_mats))
    return out


def off_axis(eye: NDArray[np.float64], side: WallSide, far: float = _FAR) -> NDArray[np.float64]:
    """``(4, 4)`` view-projection from ``eye`` ``(3,)`` through the side's quad: the
    quad fills the image (``p0`` on the left, ``z1`` at the top), the near plane is
    the wall's plane (what is in front of it is clipped); the one off-axis projection
    (:func:`~walkstream.shared.camera.off_axis`)."""
    return camera_off_axis(eye, (side.p0[0], side.p0[1], side.z0), (*side.along, 0.0), (0.0, 0.0, 1.0),
                           side.length, side.z1 - side.z0, None, far)


class WallRenderer(Releasable):
    """Renders wall textures of one scene (see the module docstring); ``scene`` an
    interior or a city, or the elements themselves (:func:`wall_elements`)."""

    def __init__(self, scene: InteriorScene | SourceScene | Sequence[WallElement], ctx: Any = None) -> None:
        self._own_ctx = ctx is None
        self.ctx = create_context() if ctx is None else ctx
        self._objects: list[Any] = []
        self._fbs: dict[tuple[int, int], Framebuffer] = {}
        self._range: list[tuple[int, int, int]] = []  # (element id, first vertex, count)
        pos, nor, col = [], [], []
        first = 0
        elements = scene if isinstance(scene, Sequence) else wall_elements(scene)
        for eid, tri, mats in elements:
            nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
            nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-12)
            pos.append(tri.reshape(-1, 3))
            nor.append(np.repeat(nrm, 3, axis=0))
            col.append(np.repeat(material_rgb(mats).astype(np.float32) / 255.0, 3, axis=0))
            self._range.append((eid, first, 3 * len(tri)))
            first += 3 * len(tri)
        verts = np.hstack([np.vstack(pos), np.vstack(nor), np.vstack(col)]).astype(np.float32) if pos else \
            np.zeros((3, 9), np.float32)
        prog = lit_program(self.ctx, _FRAGMENT_SHADER)
        self.prog = prog
        self._objects.append(prog)
        vbo = self.ctx.buffer(np.ascontiguousarray(verts).tobytes())
        self._objects.append(vbo)
        self.vao = self.ctx.vertex_array(prog, [(vbo, "3f 3f 3f", "in_position", "in_normal", "in_color")])
        self._objects.append(self.vao)

    def render(self, side: WallSide, zone: int, width: int, exclude: Sequence[int] = (),
               eye: NDArray[np.float64] | None = None) -> NDArray[np.uint8]:
        """The premultiplied ``(height, width, 4) uint8`` texture of ``side``'s zone ``zone``
        (row 0 at the top), the elements ``exclude`` as transparent holes; with ``eye``
        ``(3,)`` what that eye sees through the wall's quad instead of the zone's sampling
        point (what a viewer there should see on the wall: tests and benchmarks hold the
        texture against it)."""
        height = texture_height(side, width)
        size = (width * SUPERSAMPLE, height * SUPERSAMPLE)
        fb = self._fbs.get(size)
        if fb is None:
            fb = self._fbs[size] = Framebuffer(self.ctx, size)
        fb.use()
        fb.clear((0.0, 0.0, 0.0, 0.0))
        self.ctx.enable(self.ctx.DEPTH_TEST)
        self.ctx.disable(self.ctx.CULL_FACE)
        at = side.sample_point(zone) if eye is None else np.asarray(eye, np.float64).reshape(3)
        self.prog["u_view_proj"].write(mat4_bytes(off_axis(at, side)))
        skip = set(int(e) for e in exclude)
        self.prog["u_hole"].value = 0.0
        run_first = run_count = 0
        for eid, first, count in self._range:
            if eid in skip:
                if run_count:
                    self.vao.render(vertices=run_count, first=run_first)
                run_first, run_count = first + count, 0
                continue
            if run_count == 0:
                run_first = first
            run_count += count
        if run_count:
            self.vao.render(vertices=run_count, first=run_first)
        if skip:  # the crossing objects: holes in the texture
            self.prog["u_hole"].value = 1.0
            for eid, first, count in self._range:
                if eid in skip:
                    self.vao.render(vertices=count, first=first)
        check_gl_error(self.ctx, "wall textures")
        return average_samples(fb.read())

    def depth_behind(self, side: WallSide, zone: int, width: int,
                     eye: NDArray[np.float64] | None = None) -> NDArray[np.float32]:
        """``(height * SUPERSAMPLE, width * SUPERSAMPLE) float32`` how far behind the wall's
        plane (metres along its normal) each sample of the last :meth:`render` of the same
        arguments lies, ``inf`` where nothing was drawn (row 0 at the top): the depth a
        textured depth mesh would carry (``benchmarks/walldepth.py`` measures one)."""
        fb = self._fbs[(width * SUPERSAMPLE, texture_height(side, width) * SUPERSAMPLE)]
        d = fb.read_depth().astype(np.float64)
        at = side.sample_point(zone) if eye is None else np.asarray(eye, np.float64).reshape(3)
        near = float((np.asarray(side.p0, np.float64) - at[:2]) @ side.normal)
        ndc = 2.0 * d - 1.0
        view = 2.0 * near * _FAR / (_FAR + near - ndc * (_FAR - near))
        out: NDArray[np.float32] = np.where(d >= 1.0, np.inf, np.maximum(view - near, 0.0)).astype(np.float32)
        return out

    def release(self) -> None:
        """Free the GL objects (and the context when it made it)."""
        for fb in self._fbs.values():
            fb.release()
        self._fbs.clear()
        release_objects(self.ctx, self._objects, self._own_ctx)
        self._objects = []


_WORKER: dict[str, Any] = {}


def wall_task(jobs: list[WallJob], scene: InteriorScene | SourceScene, key: str, codec: str,
              quality: int = 90, depth_grid: int = 0) -> list[tuple[WallJob, tuple[int, bytes]]]:
    """Render and encode textures (:data:`~.wallplan.WallJob` each): ``(job, (height, bytes))``
    in order, lossy codecs at ``quality``; with ``depth_grid`` ``G`` > 0 each image followed
    by its ``G`` x ``G`` depth grid (:mod:`walkstream.shared.walldepth`, from the render's
    own depth buffer).  A worker keeps its renderer while ``key`` (the scene's) stays."""
    if _WORKER.get("key") != key:
        release_wall_renderer()
        _WORKER["renderer"] = WallRenderer(scene)
        _WORKER["key"] = key
    r: WallRenderer = _WORKER["renderer"]
    out = []
    for job in jobs:
        tid, row, zone, width, exclude = job
        side = WallSide.from_row(list(row), f"texture {tid}")
        img = r.render(side, zone, width, exclude)
        data = encode_image(img, codec, quality)
        if depth_grid:
            inv = vertex_depths(r.depth_behind(side, zone, width), side.depth, depth_grid)
            data = attach_depth(data, encode_depth(inv))
        out.append((job, (img.shape[0], data)))
    return out


def release_wall_renderer() -> None:
    """Free this process's wall renderer (its GL context)."""
    r = _WORKER.pop("renderer", None)
    _WORKER.pop("key", None)
    if r is not None:
        r.release()
