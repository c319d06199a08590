"""Ground truth of an interior: every part of every cell drawn with its id, no culling.

Each part of each cell's contents (:class:`~walkstream.shared.codec.cellmesh.CellPart`)
is one object, drawn from both sides (interiors are not all closed solids once
clipped to cells) into an object-id image with depth.  What a culling kept is checked
pixel by pixel against a second frame of the kept parts alone: a pixel is **missed**
when the whole building shows a culled part there and the kept parts alone show
something more than :data:`TIE_M` farther (or nothing).  The tolerance is for
coincident surfaces, not for culling: the bake gives the outside cell whole triangles
that also lie, clipped, in the rooms (a ground-floor slab's top face under every
room's floor, a few micrometres apart after quantisation), and which of two such
surfaces wins a pixel is the depth buffer's coin toss.  The parts that show anywhere
are the **truly visible** ones, against which the triangles drawn are compared
(tightness).

``fog_m``: fragments farther from the eye than the fog distance in force are not
drawn (the truth's far distance is the client's), so what the fog hides on purpose
is not a miss.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.shared.camera import mat4_bytes, perspective
from walkstream.shared.codec.cellmesh import CellMesh
from walkstream.shared.errors import RenderError
from walkstream.shared.gl import Releasable, check_gl_error, create_context, release_objects

__all__ = ["TIE_M", "InteriorTruth", "TruthCheck", "interior_truth"]

#: Depth difference (metres) below which two surfaces count as the same surface.
TIE_M = 0.005

_VS = """
#version 330
uniform mat4 u_view_proj;
in vec3 in_position;
in uint in_id;
out vec3 v_world;
flat out uint v_id;
invariant gl_Position;
void main() {
    gl_Position = u_view_proj * vec4(in_position, 1.0);
    v_world = in_position;
    v_id = in_id;
}
"""

_FS = """
#version 330
uniform vec3 u_eye;
uniform float u_fog;
in vec3 v_world;
flat in uint v_id;
out uint f_id;
void main() {
    if (distance(v_world, u_eye) > u_fog) discard;
    f_id = v_id;
}
"""


@dataclass(frozen=True)
class TruthCheck:
    """One frame checked against the truth.

    ``missed_pixels`` show a culled part (see the module docstring); ``missed``
    names those parts as ``(cell, part)``; ``visible`` are the parts that show at all
    and ``visible_triangles`` their triangles.
    """

    missed_pixels: int
    missed: frozenset[tuple[int, int]]
    visible: frozenset[tuple[int, int]]
    visible_triangles: int
    pinholes: int = 0
    """Missed pixels that are single pixels (no missed neighbour) where the eight
    neighbours all show a kept part nearer, or one of them a kept part at the same
    depth (within 1 %): a crack between two pieces of a wall seen through at one
    pixel, or a piece of the outside cell lying on a kept surface's edge; not a cell
    culled (that shows through a portal's whole area)."""
    mask: NDArray[np.bool_] | None = None
    """``(h, w)`` the missed pixels (row 0 at the top)."""
    depth: NDArray[np.float64] | None = None
    """``(h, w)`` the truth's depth, metres."""


class InteriorTruth(Releasable):
    """Object-id frames of a whole interior (see the module docstring).

    Parameters
    ----------
    meshes : mapping of cell id -> CellMesh
        Every cell's contents.
    size : (int, int)
        Frame size, pixels.
    fov_deg, near, far : float
        The projection (the client's).
    ctx : moderngl.Context, optional
        Context to draw with (default: a new one, released by :meth:`release`).
    """

    def __init__(
        self,
        meshes: Mapping[int, CellMesh],
        size: tuple[int, int] = (160, 120),
        *,
        fov_deg: float = 60.0,
        near: float = 0.1,
        far: float = 100.0,
        ctx: Any = None,
    ) -> None:
        self.keys: list[tuple[int, int]] = []
        pos: list[NDArray[np.float32]] = []
        idx: list[NDArray[np.uint32]] = []
        tris: list[int] = []
        nv = 0
        for cid in sorted(meshes):
            for k, part in enumerate(meshes[cid].parts):
                if part.triangles == 0:
                    continue
                self.keys.append((int(cid), k))
                pos.append(part.positions)
                idx.append(part.indices.reshape(-1) + np.uint32(nv))
                nv += len(part.positions)
                tris.append(part.triangles)
        self.index = {key: i for i, key in enumerate(self.keys)}
        self.triangles = np.array(tris, np.int64)
        stop = np.cumsum([len(i) for i in idx]).astype(np.int64)
        self._first = np.concatenate([[0], stop[:-1]]).astype(np.int64)
        self._stop = stop
        verts = np.empty(nv, [("p", "<f4", 3), ("id", "<u4")])
        if nv:
            verts["p"] = np.concatenate(pos)
            verts["id"] = np.repeat(np.arange(1, len(pos) + 1, dtype=np.uint32), [len(p) for p in pos])
        index = np.concatenate(idx) if idx else np.zeros(3, np.uint32)
        self.size = (int(size[0]), int(size[1]))
        self.near, self.far = float(near), float(far)
        self.proj = perspective(fov_deg, self.size[0] / self.size[1], near, far).astype(np.float64)
        self._own = ctx is None
        self.ctx: Any = create_context() if ctx is None else ctx
        self._gl: list[Any] = []
        try:
            c = self.ctx
            self._prog: Any = c.program(vertex_shader=_VS, fragment_shader=_FS)
            self._vbo = c.buffer(verts.tobytes() if nv else bytes(16))
            self._ibo = c.buffer(index.astype(np.uint32).tobytes())
            self._vao = c.vertex_array(self._prog, [(self._vbo, "3f u4", "in_position", "in_id")],
                                       index_buffer=self._ibo, index_element_size=4)
            w, h = self.size
            self._ids = c.renderbuffer((w, h), components=1, dtype="u4")
            self._depth = c.depth_texture((w, h))
            self._fbo = c.framebuffer(color_attachments=[self._ids], depth_attachment=self._depth)
            self._gl = [self._vao, self._ibo, self._vbo, self._prog, self._fbo, self._ids, self._depth]
            check_gl_error(c, "after creating the interior truth")
        except Exception as exc:
            self.release()
            raise RenderError(f"InteriorTruth: {exc}") from exc

    def render(
        self, eye: ArrayLike, view: ArrayLike, only: NDArray[np.bool_] | None = None, fog_m: float = math.inf
    ) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        """Draw the parts (all, or those flagged in ``only``) from one camera.

        Returns
        -------
        ids : (h, w) int64
            Index into :attr:`keys` of the part each pixel shows, -1 for none; row 0 at the top.
        depth : (h, w) float64
            Eye-space depth, metres (``inf`` where nothing shows).
        """
        import moderngl

        c = self.ctx
        vp = self.proj @ np.asarray(view, np.float64)
        self._prog["u_view_proj"].write(mat4_bytes(vp))
        self._prog["u_eye"].value = tuple(float(v) for v in np.asarray(eye, np.float64).reshape(3))
        self._prog["u_fog"].value = float(min(fog_m, 1e30))
        self._fbo.use()
        w, h = self.size
        c.viewport = (0, 0, w, h)
        self._fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        c.enable(moderngl.DEPTH_TEST)
        c.disable(moderngl.CULL_FACE | moderngl.BLEND)
        c.depth_func = "<"
        flags = np.ones(len(self.keys), bool) if only is None else only
        padded = np.concatenate([[False], flags, [False]]).astype(np.int8)
        step = np.diff(padded)
        for s, t in zip(np.flatnonzero(step == 1).tolist(), np.flatnonzero(step == -1).tolist(), strict=True):
            first, last = int(self._first[s]), int(self._stop[t - 1])
            if last > first:
                self._vao.render(moderngl.TRIANGLES, vertices=last - first, first=first)
        check_gl_error(c, "after drawing an interior truth frame")
        ids = np.frombuffer(self._fbo.read(components=1, attachment=0, dtype="u4", alignment=1), np.uint32)
        d = np.frombuffer(self._depth.read(alignment=1), np.float32).astype(np.float64)
        ndc = 2.0 * d - 1.0
        n, f = self.near, self.far
        lin = np.where(d >= 1.0, np.inf, 2.0 * n * f / (f + n - ndc * (f - n)))
        return ids.reshape(h, w)[::-1].astype(np.int64) - 1, lin.reshape(h, w)[::-1]

    def flags(self, kept: Iterable[tuple[int, int]]) -> NDArray[np.bool_]:
        """``(len(keys),)`` which parts ``kept`` names."""
        out = np.zeros(len(self.keys), bool)
        for key in kept:
            i = self.index.get((int(key[0]), int(key[1])))
            if i is not None:
                out[i] = True
        return out

    def check(
        self, kept: Iterable[tuple[int, int]], eye: ArrayLike, view: ArrayLike, fog_m: float = math.inf
    ) -> TruthCheck:
        """Compare the parts a culling kept with the truth of one camera (module docstring)."""
        keep = self.flags(kept)
        ids, depth = self.render(eye, view, None, fog_m)
        shown = ids >= 0
        culled = shown & ~keep[np.maximum(ids, 0)]
        pinholes = 0
        if culled.any():
            _, kdepth = self.render(eye, view, keep, fog_m)
            culled &= kdepth > depth + TIE_M
            # a pinhole: no missed neighbour, and every neighbour nearer than the miss
            pad = np.pad(culled, 1)
            dpad = np.pad(depth, 1, constant_values=np.inf)
            h, w = culled.shape
            alone = culled.copy()
            nearer = np.ones_like(culled)
            same = np.zeros_like(culled)
            for dy in (-1, 0, 1):
                for dx in (-1, 0, 1):
                    if dy or dx:
                        nb = (slice(1 + dy, 1 + dy + h), slice(1 + dx, 1 + dx + w))
                        alone &= ~pad[nb]
                        nearer &= dpad[nb] < depth
                        with np.errstate(invalid="ignore"):
                            same |= np.abs(dpad[nb] - depth) <= 0.01 * depth
            pinholes = int(np.count_nonzero(alone & (nearer | same)))
        seen = np.unique(ids[shown])
        return TruthCheck(
            missed_pixels=int(np.count_nonzero(culled)),
            missed=frozenset(self.keys[i] for i in np.unique(ids[culled]).tolist()),
            visible=frozenset(self.keys[i] for i in seen.tolist()),
            visible_triangles=int(self.triangles[seen].sum()),
            pinholes=pinholes,
            mask=culled,
            depth=depth,
        )

    def release(self) -> None:
        """Release the GL objects (and the context if made here); idempotent."""
        release_objects(self.ctx, self._gl, self._own)
        self.ctx = None


async def interior_truth(
    transport: Any,
    base_url: str,
    scene: str,
    cells: Iterable[int],
    notes: Iterable[tuple[int, Any, Any, list[tuple[int, int]], float]],
    size: tuple[int, int],
    fov_deg: float,
    clock: Any,
) -> dict[str, Any]:
    """The replay's ground-truth comparison of an interior walk (``--truth-every``).

    Every cell's contents are fetched on the unshaped ``transport`` (nothing counted
    on the walk's link); each noted frame ``(index, eye, view, parts drawn, fog)`` is
    checked against the whole building's id frame with the truth's far distance at
    the fog in force.  A noted part ``(cell, -1)`` stands for a visible cell not yet
    received (all its parts count as kept: not culled, only late).  Returns: frames
    compared, ``culled`` pixels (a part culled that shows: must be 0) and frames with any, the pinholes apart, the share of the
    pixels the fog hides on purpose (shown without fog, not with it), and the
    tightness (triangles drawn over truly visible), mean and p95.
    """
    import httpx

    from walkstream.client.net.api import SceneClient
    from walkstream.client.truth.scene import UnshapedTransport

    notes = list(notes)
    async with httpx.AsyncClient(transport=UnshapedTransport(transport), base_url=base_url,
                                 timeout=httpx.Timeout(120.0)) as http:
        api = SceneClient(http, clock, scene)
        meshes = {int(c): await api.contents(int(c)) for c in cells}
    truth = InteriorTruth(meshes, size, fov_deg=fov_deg)
    culled = frames_culled = pinholes = 0
    fog_share: list[float] = []
    tight: list[float] = []
    try:
        for _, eye, view, noted, fog in notes:
            drawn = [k for k in noted if k[1] >= 0]
            waiting = {k[0] for k in noted if k[1] < 0}
            kept = drawn + [k for k in truth.keys if k[0] in waiting]
            chk = truth.check(kept, eye, view, fog)
            culled += chk.missed_pixels - chk.pinholes
            frames_culled += chk.missed_pixels - chk.pinholes > 0
            pinholes += chk.pinholes
            if math.isfinite(fog):
                ids_all, _ = truth.render(eye, view)
                ids_fog, _ = truth.render(eye, view, None, fog)
                fog_share.append(float(np.mean((ids_all >= 0) & (ids_fog < 0))))
            drawn_tris = sum(truth.triangles[truth.index[k]] for k in drawn if k in truth.index)
            if chk.visible_triangles:
                tight.append(drawn_tris / chk.visible_triangles)
    finally:
        truth.release()
    return {
        "frames": len(notes),
        "culled_pixels": int(culled),
        "culled_frames": int(frames_culled),
        "pinholes": int(pinholes),
        "fog_hidden_pct": 100.0 * float(np.mean(fog_share)) if fog_share else 0.0,
        "tightness_mean": float(np.mean(tight)) if tight else 0.0,
        "tightness_p95": float(np.percentile(tight, 95)) if tight else 0.0,
    }
