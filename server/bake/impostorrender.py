"""The impostor images of the bake: one object alone, orthographic, in the client's palette and light.

:class:`ImpostorRenderer` holds the LOD2 meshes of a city's buildings in one vertex
buffer (one context, made headless through EGL like every renderer of the project)
and renders one object at a time along a bin's direction
(:func:`~walkstream.shared.impostors.bin_direction`) into a square of ``2 R`` metres
(:func:`~walkstream.shared.impostors.image_basis`), over transparent black, at
:data:`SUPERSAMPLE` times the size asked; averaging the supersamples gives
premultiplied colour with soft silhouettes (:mod:`walkstream.shared.codec.image`).
The lighting is the client's per-vertex lighting (:mod:`walkstream.shared.lighting`,
material colours of :mod:`walkstream.shared.palette`), so an image shows an object as
the client draws its LOD2.

:func:`impostor_task` is the chunk task the one chunk runner (:mod:`.chunks`) runs: a
list of images to make in, their encoded bytes out.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from walkstream.server.bake.objectrows import building_box
from walkstream.shared.buildings import build_lod_batch
from walkstream.shared.camera import look_at, mat4_bytes
from walkstream.shared.codec.image import encode_image
from walkstream.shared.errors import InputError
from walkstream.shared.gl import (
    Framebuffer,
    Releasable,
    check_gl_error,
    create_context,
    release_objects,
)
from walkstream.shared.impostors import bin_direction
from walkstream.shared.lighting import AMBIENT, LIGHT_DIRECTION
from walkstream.shared.palette import material_rgb
from walkstream.shared.records import Mesh

__all__ = ["SUPERSAMPLE", "ImageJob", "ImpostorRenderer", "impostor_task", "release_impostor_renderer"]

SUPERSAMPLE = 2
"""Rendered samples per image texel along each axis (averaged: soft silhouettes)."""

ImageJob = tuple[int, int, int, int, int, int]
"""One image to make: ``(image id, object id, level, azimuth bin, elevation bin, size)``."""

_VERTEX_SHADER = """
#version 330
uniform mat4 u_view_proj;
uniform vec3 u_light_dir;
uniform float u_ambient;
in vec3 in_position;
in vec3 in_normal;
in vec3 in_color;
out vec3 v_lit;
void main() {
    gl_Position = u_view_proj * vec4(in_position, 1.0);
    float diffuse = max(dot(normalize(in_normal), u_light_dir), 0.0);
    v_lit = in_color * (u_ambient + (1.0 - u_ambient) * diffuse);
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


def _ortho(radius: float, far: float) -> NDArray[np.float64]:
    """Orthographic projection of a ``2 radius`` square, depth 0.01..``far``."""
    n = 0.01
    m = np.zeros((4, 4))
    m[0, 0] = m[1, 1] = 1.0 / radius
    m[2, 2] = -2.0 / (far - n)
    m[2, 3] = -(far + n) / (far - n)
    m[3, 3] = 1.0
    return m


class ImpostorRenderer(Releasable):
    """Renders impostor images of objects (see the module docstring).

    Parameters
    ----------
    meshes, ids:
        The objects' LOD2 meshes and their object ids.
    boxes:
        Each object's ``(minx, miny, minz, maxx, maxy, maxz)``, whose centre and half
        diagonal an image covers (default: its mesh's box); the bake passes the
        stored boxes (:func:`~.objectrows.building_box`) so the client places the
        quad from the same numbers.
    ctx:
        A context to use (default: a new headless one, released with the renderer).
    """

    def __init__(
        self, meshes: Sequence[Mesh], ids: Sequence[int], boxes: Sequence[Sequence[float]] | None = None,
        ctx: Any = None,
    ) -> None:
        if len(meshes) != len(ids):
            raise InputError(f"ImpostorRenderer: {len(meshes)} meshes but {len(ids)} ids")
        self._own_ctx = ctx is None
        self.ctx = create_context() if ctx is None else ctx
        self._objects: list[Any] = []
        self._fbs: dict[int, Framebuffer] = {}
        pos, nor, col, idx = [], [], [], []
        self._range: dict[int, tuple[int, int]] = {}
        self._bounds: dict[int, tuple[NDArray[np.float64], float]] = {}
        base = first = 0
        for k, (oid, m) in enumerate(zip(ids, meshes, strict=True)):
            pos.append(m.positions)
            nor.append(m.normals)
            col.append(material_rgb(m.materials).astype(np.float32) / 255.0)
            idx.append(m.indices.reshape(-1) + base)
            self._range[int(oid)] = (first, m.indices.size)
            if boxes is not None:
                lo, hi = np.asarray(boxes[k][:3], np.float64), np.asarray(boxes[k][3:], np.float64)
            else:
                lo, hi = m.positions.min(axis=0).astype(np.float64), m.positions.max(axis=0).astype(np.float64)
            self._bounds[int(oid)] = ((lo + hi) / 2.0, float(np.linalg.norm(hi - lo) / 2.0))
            base += len(m.positions)
            first += m.indices.size
        verts = np.hstack([np.vstack(pos), np.vstack(nor), np.vstack(col)]).astype(np.float32)
        light = np.asarray(LIGHT_DIRECTION, np.float64)
        prog: Any = self.ctx.program(vertex_shader=_VERTEX_SHADER, fragment_shader=_FRAGMENT_SHADER)
        self.prog = prog
        self._objects.append(prog)
        prog["u_light_dir"].value = tuple(float(v) for v in light / np.linalg.norm(light))
        prog["u_ambient"].value = float(AMBIENT)
        vbo = self.ctx.buffer(np.ascontiguousarray(verts).tobytes())
        ibo = self.ctx.buffer(np.concatenate(idx).astype(np.uint32).tobytes())
        self._objects += [vbo, ibo]
        self.vao = self.ctx.vertex_array(
            self.prog, [(vbo, "3f 3f 3f", "in_position", "in_normal", "in_color")],
            index_buffer=ibo, index_element_size=4,
        )
        self._objects.append(self.vao)

    def bounds(self, oid: int) -> tuple[NDArray[np.float64], float]:
        """The centre and bounding-sphere radius of object ``oid``'s box."""
        return self._bounds[oid]

    def _framebuffer(self, side: int) -> Framebuffer:
        fb = self._fbs.get(side)
        if fb is None:
            fb = self._fbs[side] = Framebuffer(self.ctx, (side, side))
        return fb

    def render(
        self, oid: int, direction: NDArray[np.float64], size: int,
        centre: NDArray[np.float64] | None = None, radius: float | None = None,
    ) -> NDArray[np.uint8]:
        """The premultiplied ``(size, size, 4) uint8`` image of object ``oid`` seen along
        ``-direction`` (row 0 at the top), centred on ``centre`` over ``2 radius``
        metres (default: the object's own box)."""
        if oid not in self._range:
            raise InputError(f"impostor: no mesh of object {oid}")
        c0, r0 = self._bounds[oid]
        c = c0 if centre is None else np.asarray(centre, np.float64)
        r = max(r0 if radius is None else float(radius), 1e-3)
        u = np.asarray(direction, np.float64)
        u = u / np.linalg.norm(u)
        view = look_at(c + u * (r + 1.0), c).astype(np.float64)
        mvp = _ortho(r, 2.0 * r + 2.0) @ view
        side = int(size) * SUPERSAMPLE
        fb = self._framebuffer(side)
        fb.use()
        fb.clear((0.0, 0.0, 0.0, 0.0))
        self.ctx.enable(self.ctx.DEPTH_TEST | self.ctx.CULL_FACE)
        prog: Any = self.prog
        prog["u_view_proj"].write(mat4_bytes(mvp))
        first, count = self._range[oid]
        self.vao.render(vertices=count, first=first)
        check_gl_error(self.ctx, "impostor image")
        img = fb.read().reshape(size, SUPERSAMPLE, size, SUPERSAMPLE, 4)
        # the mean of the samples, rounded (integer sums: a float mean costs more than the render)
        n = SUPERSAMPLE * SUPERSAMPLE
        total = img.sum(axis=(1, 3), dtype=np.uint16)
        return ((total + n // 2) // n).astype(np.uint8)

    def release(self) -> None:
        """Free the GL objects (and the context when it made it)."""
        for fb in self._fbs.values():
            fb.release()
        self._fbs.clear()
        release_objects(self.ctx, self._objects, self._own_ctx)
        self._objects = []


# ------------------------------------------------------------------ chunk task

_WORKER: dict[str, Any] = {}


def _renderer_for(scene: Any, key: str) -> ImpostorRenderer:
    """One renderer per process (and per scene), built on first use and kept."""
    if _WORKER.get("key") != key:
        release_impostor_renderer()
        meshes = build_lod_batch(scene.buildings, 2)
        boxes = [building_box(b) for b in scene.buildings]
        _WORKER["renderer"] = ImpostorRenderer(meshes, [b.id for b in scene.buildings], boxes)
        _WORKER["key"] = key
    renderer: ImpostorRenderer = _WORKER["renderer"]
    return renderer


def impostor_task(
    jobs: list[ImageJob], scene: Any, key: str, codec: str, quality: int
) -> list[tuple[ImageJob, bytes]]:
    """Render and encode images (:data:`ImageJob` each); ``(job, bytes)`` out, in order.

    Runs wherever the one chunk runner sends it; ``scene`` is the city's
    :class:`~walkstream.server.sources.scene.SourceScene`, ``key`` names it (a worker
    keeps its renderer while the key stays).
    """
    renderer = _renderer_for(scene, key)
    out = []
    for job in jobs:
        _, oid, level, ia, ie, size = job
        img = renderer.render(oid, bin_direction(level, ia, ie), size)
        out.append((job, encode_image(img, codec, quality)))
    return out


def release_impostor_renderer() -> None:
    """Free this process's impostor renderer (its GL context)."""
    r = _WORKER.pop("renderer", None)
    _WORKER.pop("key", None)
    if r is not None:
        r.release()
