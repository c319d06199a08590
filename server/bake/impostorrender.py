"""The impostor images of the bake: one object alone, orthographic, in the client's palette and light.

:class:`ImpostorRenderer` holds the LOD2 meshes of a city's buildings in one vertex
buffer (one context, made headless through EGL like every renderer of the project)
and renders one object at a time along a bin's direction
(:func:`~walkstream.shared.impostors.bin_direction`) into a square of ``2 R`` metres
(:func:`~walkstream.shared.impostors.image_basis`), over transparent black, with
one of two samplings (:data:`IMPOSTOR_SAMPLINGS`, the bake's ``--impostor-sampling``):

``point`` (the default)
    One sample per texel, at its centre: each texel holds the lit surface colour
    under that point, as the ground truth's rasterised LOD2 holds the surface under
    each pixel's centre.  The demo's windows are about a pixel at D 60 m, so a texel
    that mixes a window with its wall matches neither colour the truth's pixel can
    take: with the texels and the pixels on one grid, ``point`` leaves 0.3 % of the
    building's pixels over ΔE00 2.3, area averaging 44 %
    (``walkstream bench impostor-sampling``, docs/benchmarks.md).
``area``
    :data:`~.litimage.SUPERSAMPLE` x :data:`~.litimage.SUPERSAMPLE` samples averaged:
    premultiplied colour with soft silhouettes (:mod:`walkstream.shared.codec.image`).
The lighting is the client's per-vertex lighting (:mod:`walkstream.shared.lighting`,
material colours of :mod:`walkstream.shared.palette`), so an image shows an object as
the client draws its LOD2.

:func:`impostor_task` is the chunk task the one chunk runner (:mod:`.chunks`) runs: a
list of images to make in, their encoded bytes out.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from walkstream.server.bake.objectrows import building_box
from walkstream.shared.buildings import build_lod_batch
from walkstream.shared.camera import mat4_bytes, off_axis, orthographic
from walkstream.shared.codec.image import encode_image
from walkstream.shared.codec.params import stored_form
from walkstream.shared.errors import InputError
from walkstream.shared.gl import (
    Framebuffer,
    Releasable,
    check_gl_error,
    create_context,
    release_objects,
)
from walkstream.shared.impostors import bin_direction, eye_distance, half_side, image_basis
from walkstream.shared.litimage import NUDGE_TEXELS, SUPERSAMPLE, average_samples, lit_program
from walkstream.shared.palette import material_rgb
from walkstream.shared.records import Mesh

__all__ = ["IMPOSTOR_SAMPLINGS", "ImageJob", "ImpostorRenderer", "impostor_task", "release_impostor_renderer", "samples_of"]

_ATLAS_SIDE = 2048
"""Largest side of the framebuffer the images of one read are tiled in, pixels."""

IMPOSTOR_SAMPLINGS: tuple[str, ...] = ("point", "area")
"""How a texel is sampled (module docstring): its centre alone, or the mean over its area."""


def samples_of(sampling: str) -> int:
    """Rendered samples per texel along each axis for ``sampling`` (one of :data:`IMPOSTOR_SAMPLINGS`)."""
    if sampling not in IMPOSTOR_SAMPLINGS:
        raise InputError(f"impostor sampling {sampling!r}: expected one of {', '.join(IMPOSTOR_SAMPLINGS)}")
    return 1 if sampling == "point" else SUPERSAMPLE


ImageJob = tuple[int, int, int, int, int, int]
"""One image to make: ``(image id, object id, level, azimuth bin, elevation bin, size)``."""

_FRAGMENT_SHADER = """
#version 330
in vec3 v_lit;
out vec4 f_color;
void main() {
    f_color = vec4(v_lit, 1.0);
}
"""


_NUDGE: dict[int, NDArray[np.float64]] = {}


def _nudge(size: int) -> NDArray[np.float64]:
    """A shift of the point samples by :data:`~.litimage.NUDGE_TEXELS` of a texel on both axes, kept per size.

    A point sample exactly on an edge of the building (a window's edge on a texel centre,
    which the grammar's round sizes make happen) falls on either side by the last bit of
    the viewport transform, which differs with the tile the image is drawn in: a resumed
    bake, tiling its images otherwise, would store other bytes.  Off the exact centre by
    a fraction no round size meets, the sample falls on one side wherever it is drawn.
    """
    m = np.eye(4)
    m[0, 3] = m[1, 3] = 2.0 * NUDGE_TEXELS / size
    _NUDGE[size] = m
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
        prog = lit_program(self.ctx, _FRAGMENT_SHADER)
        self.prog = prog
        self._objects.append(prog)
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

    def _mvp(self, oid: int, direction: NDArray[np.float64], eye: float = math.inf) -> NDArray[np.float64]:
        """The orthographic view of object ``oid`` along ``-direction`` over its bounding
        square or, for a finite ``eye`` (metres from the centre along ``direction``), the
        off-axis perspective from there onto the square through the centre that holds
        the bounding sphere's silhouette (:func:`~walkstream.shared.impostors.half_side`),
        near plane at the sphere's front."""
        if oid not in self._range:
            raise InputError(f"impostor: no mesh of object {oid}")
        c, r = self._bounds[oid]
        r = max(r, 1e-3)
        u = np.asarray(direction, np.float64)
        u = u / np.linalg.norm(u)
        right, up = image_basis(u)
        if math.isfinite(eye):
            if eye <= r:
                raise InputError(f"impostor: sampling eye {eye:g} m inside object {oid}'s sphere ({r:g} m)")
            s = float(half_side(r, eye))
            return off_axis(c + u * eye, c - (right + up) * s, right, up, 2.0 * s, 2.0 * s,
                            max(eye - r - 1.0, 0.01 * eye), eye + r + 1.0)
        at = c + u * (r + 1.0)
        view = np.eye(4)  # look_at(at, c) written out: numpy's cross costs more than the draw
        view[0, :3], view[1, :3], view[2, :3] = right, up, u
        view[:3, 3] = -view[:3, :3] @ at
        out: NDArray[np.float64] = orthographic(r, 0.01, 2.0 * r + 2.0) @ view
        return out

    def render(
        self, oid: int, direction: NDArray[np.float64], size: int, sampling: str = "point", eye: float = math.inf
    ) -> NDArray[np.uint8]:
        """The premultiplied ``(size, size, 4) uint8`` image of object ``oid`` seen along
        ``-direction`` (row 0 at the top), over its bounding square, each texel sampled
        as ``sampling`` says (:data:`IMPOSTOR_SAMPLINGS`); orthographic, or in perspective
        from ``eye`` metres out along ``direction`` when finite (:meth:`_mvp`)."""
        return self.render_many([(oid, direction, eye)], size, sampling)[0]

    def render_many(
        self, views: Sequence[tuple[int, NDArray[np.float64]] | tuple[int, NDArray[np.float64], float]],
        size: int, sampling: str = "point",
    ) -> list[NDArray[np.uint8]]:
        """:meth:`render` of several ``(object, direction[, eye])`` at one size, drawn as tiles of
        one framebuffer and read back once: llvmpipe's cost is mostly the wait for each
        read (its threads handing a frame over), so one read per tile grid, not per image."""
        samples = samples_of(sampling)
        side = int(size) * samples
        per_row = max(1, min(_ATLAS_SIDE // side, math.ceil(math.sqrt(len(views)))))
        per_fb = per_row * per_row
        out: list[NDArray[np.uint8]] = []
        prog: Any = self.prog
        for k in range(0, len(views), per_fb):
            part = views[k : k + per_fb]
            fb = self._framebuffer(per_row * side)
            fb.use()
            fb.clear((0.0, 0.0, 0.0, 0.0))
            self.ctx.enable(self.ctx.DEPTH_TEST | self.ctx.CULL_FACE)
            for t, view in enumerate(part):
                # tile t: column t % per_row, row t // per_row from the top (GL's y from the bottom)
                col, row = t % per_row, t // per_row
                self.ctx.viewport = (col * side, (per_row - 1 - row) * side, side, side)
                oid = view[0]
                mvp = self._mvp(oid, view[1], float(view[2]) if len(view) > 2 else math.inf)
                if samples == 1:
                    mvp = _NUDGE[size] @ mvp if size in _NUDGE else _nudge(size) @ mvp
                prog["u_view_proj"].write(mat4_bytes(mvp))
                first, count = self._range[oid]
                self.vao.render(vertices=count, first=first)
            check_gl_error(self.ctx, "impostor images")
            atlas = fb.read()
            # the mean of the samples, rounded, over the whole atlas at once (integer sums of
            # contiguous rows: per tile, or in floats, it costs more than the render)
            small = average_samples(atlas, samples)
            for t in range(len(part)):
                col, row = t % per_row, t // per_row
                out.append(small[row * size : (row + 1) * size, col * size : (col + 1) * size].copy())
        return out

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
        # the buildings as the client rebuilds them (on the centimetre): a door on the side it has there
        buildings = [stored_form(b) for b in scene.buildings]
        meshes = build_lod_batch(buildings, 2)
        boxes = [building_box(b) for b in buildings]
        _WORKER["renderer"] = ImpostorRenderer(meshes, [b.id for b in buildings], boxes)
        _WORKER["key"] = key
    renderer: ImpostorRenderer = _WORKER["renderer"]
    return renderer


def impostor_task(
    jobs: list[ImageJob], scene: Any, key: str, codec: str, quality: int, sampling: str = "point",
    projection: tuple[str, float, float] = ("ortho", 0.0, 0.0),
) -> list[tuple[ImageJob, bytes]]:
    """Render and encode images (:data:`ImageJob` each); ``(job, bytes)`` out, in order.

    Runs wherever the one chunk runner sends it; ``scene`` is the city's
    :class:`~walkstream.server.sources.scene.SourceScene`, ``key`` names it (a worker
    keeps its renderer while the key stays).  ``projection`` is ``(kind, A radians,
    D metres)``: ``perspective`` renders each image from its level's sampling eye
    (:func:`~walkstream.shared.impostors.eye_distance`).
    """
    renderer = _renderer_for(scene, key)
    kind, bound, far = projection

    def eye(job: ImageJob) -> float:
        if kind != "perspective":
            return math.inf
        return float(eye_distance(renderer.bounds(job[1])[1], job[2], bound, far))

    out = []
    for size in sorted({job[5] for job in jobs}):
        same = [job for job in jobs if job[5] == size]
        images = renderer.render_many([(job[1], bin_direction(*job[2:5]), eye(job)) for job in same], size, sampling)
        out += [(job, encode_image(img, codec, quality)) for job, img in zip(same, images, strict=True)]
    order = {job[0]: k for k, job in enumerate(jobs)}
    return sorted(out, key=lambda r: order[r[0][0]])


def release_impostor_renderer() -> None:
    """Free this process's impostor renderer (its GL context)."""
    r = _WORKER.pop("renderer", None)
    _WORKER.pop("key", None)
    if r is not None:
        r.release()
