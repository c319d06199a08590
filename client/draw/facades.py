"""Facade textures: a building drawn as its box carries a picture of its LOD2 facades.

On a device whose triangle budget leaves most buildings at their LOD0 box (``pda``:
about 650 triangles a frame against 1,200 for one building's LOD2), the near boxes
are the colour error: walls without a window.  A facade texture puts the windows,
storeys and colours back on the cheap geometry.  The client rebuilds every building's
LOD2 from its parameters anyway (:mod:`walkstream.client.rewrite`), so it renders the
textures itself: nothing more crosses the link.

Each wall face of the coarse mesh (:func:`wall_faces`: its vertical triangles grouped
by plane, one rectangle each) gets one image: the LOD2 mesh drawn orthographically
along the face's inward normal (:class:`FacadeBaker`), framed on the face's
rectangle grown by :data:`MARGIN_M` (LOD2's ledges and parapet stand out of the box),
depth from :data:`FRONT_M` in front of the face to :data:`BACK_M` behind it (recessed
windows, not the far side of the building), lit as the client and the truth light a
surface (:mod:`walkstream.shared.lighting`: a fixed directional light, so the lit
colour does not depend on where the viewer stands), one sample a texel at its centre
(:data:`~walkstream.shared.litimage.NUDGE_TEXELS` off it), premultiplied RGBA.  A texel holds the surface under one
point, as the ground truth's pixel holds the surface under its centre: a texel
averaging a window with its wall (``samples=``:data:`~walkstream.shared.litimage.SUPERSAMPLE`,
the former default) matches neither colour a pixel of the truth can take; the impostors
sample so for the same reason (:mod:`walkstream.server.bake.impostorrender`).  Texels
LOD2 leaves empty are transparent: the box shows through them.

The image is drawn as a textured quad (:data:`~walkstream.client.draw.quads.Quad`)
standing :data:`LIFT_M` outside the face, over the box, by the impostors' own quad
renderer (:mod:`walkstream.client.draw.quads`): depth tested against the frame's
geometry, so nearer buildings hide it, premultiplied blend.  Only the faces turned
to the eye are drawn (:func:`facing`): a quad seen from behind would show its margins
past the box's silhouette.

Cost: a face's quad is two triangles more in the frame; its bake draws the LOD2
triangles that face it (:attr:`FacadeImage.bake_triangles`), charged by the caller to
the frame that bakes it (:mod:`walkstream.client.walk.facades`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from walkstream.client.draw.quads import FACADE_IDS, Quad
from walkstream.shared.camera import mat4_bytes
from walkstream.shared.errors import InputError, RenderError
from walkstream.shared.gl import check_gl_error, create_context, release_objects
from walkstream.shared.litimage import NUDGE_TEXELS, SUPERSAMPLE, average_samples, set_lighting
from walkstream.shared.palette import material_rgb
from walkstream.shared.records import Mesh

__all__ = [
    "BACK_M",
    "FRONT_M",
    "LIFT_M",
    "MARGIN_M",
    "MAX_FACES",
    "FacadeBaker",
    "FacadeImage",
    "FacadeJob",
    "FacadeSet",
    "WallFace",
    "facade_image_id",
    "facing",
    "texture_size",
    "wall_faces",
]

FRONT_M = 0.6
"""Metres in front of a face that its image still shows (ledges, cornices, balconies)."""
BACK_M = 3.0
"""Metres behind a face that its image still shows (recessed windows and doors)."""
MARGIN_M = 0.3
"""Metres a face's rectangle grows on each side and at the bottom (LOD2 stands out of the box)."""
TOP_M = 1.0
"""Metres a face's rectangle grows at the top (LOD2's parapet above the box's roof)."""
LIFT_M = 0.02
"""Metres the quad stands outside its face: in front of the box's own wall, so it wins the depth test."""
MAX_FACES = 64
"""Wall faces a building's images are counted to (image ids: :func:`facade_image_id`)."""

_VS = """
#version 330
uniform mat4 u_view_proj;
in vec3 in_position;
in vec3 in_normal;
in vec3 in_color;
out vec3 v_normal;
out vec3 v_color;
void main() {
    gl_Position = u_view_proj * vec4(in_position, 1.0);
    v_normal = in_normal;
    v_color = in_color;
}
"""

# lit per fragment as the truth lights it (client/truth/render.py): the same colour where both show a surface
_FS = """
#version 330
uniform vec3 u_light_dir;
uniform float u_ambient;
in vec3 v_normal;
in vec3 v_color;
out vec4 f_color;
void main() {
    float diffuse = max(dot(normalize(v_normal), u_light_dir), 0.0);
    f_color = vec4(v_color * (u_ambient + (1.0 - u_ambient) * diffuse), 1.0);
}
"""


@dataclass(frozen=True)
class WallFace:
    """One vertical face of a coarse mesh as a rectangle (see :func:`wall_faces`)."""

    origin: NDArray[np.float64]
    """``(3,)`` the rectangle's bottom-left corner seen from outside."""
    right: NDArray[np.float64]
    """``(3,)`` unit horizontal axis along the face, to the right seen from outside."""
    normal: NDArray[np.float64]
    """``(3,)`` unit outward normal (horizontal)."""
    width: float
    """Metres along :attr:`right`."""
    height: float
    """Metres up."""

    def corners(self, lift: float = 0.0) -> NDArray[np.float64]:
        """``(4, 3)`` bottom-left, bottom-right, top-right, top-left, ``lift`` metres outward."""
        o = self.origin + lift * self.normal
        r, up = self.right * self.width, np.array([0.0, 0.0, self.height])
        return np.stack([o, o + r, o + r + up, o + up])


def wall_faces(mesh: Mesh, top: float | None = None) -> list[WallFace]:
    """The vertical faces of ``mesh`` (a building's LOD0 box or any coarse form) as rectangles.

    Triangles whose normal is within about 6° of horizontal are grouped by plane
    (direction to 0.5°, offset to 5 cm); each group's extent along the plane, grown by
    :data:`MARGIN_M` on the sides and bottom and up to ``top`` (LOD2's highest point,
    at most :data:`TOP_M` above the face), is one face.  At most :data:`MAX_FACES`,
    the widest first.
    """
    p = np.asarray(mesh.positions, np.float64)
    idx = np.asarray(mesh.indices, np.int64).reshape(-1, 3)
    if not len(idx):
        return []
    a, b, c = p[idx[:, 0]], p[idx[:, 1]], p[idx[:, 2]]
    n = np.cross(b - a, c - a)
    length = np.linalg.norm(n, axis=1)
    ok = length > 1e-9
    n = np.where(ok[:, None], n / np.maximum(length, 1e-12)[:, None], 0.0)
    wall = ok & (np.abs(n[:, 2]) < 0.1)
    if not wall.any():
        return []
    nh = n[wall, :2] / np.linalg.norm(n[wall, :2], axis=1, keepdims=True)
    ang = np.round(np.degrees(np.arctan2(nh[:, 1], nh[:, 0])) * 2.0).astype(np.int64)  # 0.5° bins
    off = np.round(np.einsum("ij,ij->i", nh, a[wall, :2]) * 20.0).astype(np.int64)  # 5 cm bins
    tri = np.flatnonzero(wall)
    faces: list[WallFace] = []
    groups: dict[tuple[int, int], list[int]] = {}
    for k, key in enumerate(zip(ang.tolist(), off.tolist(), strict=True)):
        groups.setdefault(key, []).append(k)
    for ks in groups.values():
        normal2 = nh[ks].mean(axis=0)
        normal2 /= np.linalg.norm(normal2)
        normal = np.array([normal2[0], normal2[1], 0.0])
        right = np.array([-normal2[1], normal2[0], 0.0])
        pts = p[idx[tri[ks]].reshape(-1)]
        u = pts @ right
        d = float(np.mean(pts[:, :2] @ normal2))
        z0, z1 = float(pts[:, 2].min()), float(pts[:, 2].max())
        hi = z1 if top is None else min(max(float(top), z1), z1 + TOP_M)
        u0, u1 = float(u.min()) - MARGIN_M, float(u.max()) + MARGIN_M
        base = d * normal + u0 * right
        origin = np.array([base[0], base[1], z0 - MARGIN_M])
        faces.append(WallFace(origin, right, normal, u1 - u0, hi - z0 + MARGIN_M))
    faces.sort(key=lambda f: -f.width * f.height)
    return faces[:MAX_FACES]


def texture_size(face: WallFace, texels_per_m: float, max_size: int) -> tuple[int, int]:
    """``(width, height)`` texels of ``face``'s image: ``texels_per_m`` along each side, each in [4, ``max_size``]."""
    w = int(min(max(4, math.ceil(face.width * texels_per_m)), max_size))
    h = int(min(max(4, math.ceil(face.height * texels_per_m)), max_size))
    return w, h


def facade_image_id(oid: int, face: int) -> int:
    """The image id of building ``oid``'s face ``face``: at most ``-FACADE_IDS``
    (:data:`~walkstream.client.draw.quads.FACADE_IDS`), never an impostor's (0 and up) or
    a wall texture's (-1 down to ``-FACADE_IDS + 1``): the quad renderer keeps one texture
    an id, so a shared id would draw one image in the other's place."""
    return -FACADE_IDS - (int(oid) * MAX_FACES + int(face))


def facing(faces: NDArray[np.float64], normals: NDArray[np.float64], eye: NDArray[np.float64]) -> NDArray[np.bool_]:
    """``(n,)`` which faces (a point of each ``(n, 3)``, their ``(n, 3)`` normals) turn to ``eye``."""
    out: NDArray[np.bool_] = np.einsum("ij,ij->i", np.asarray(eye, np.float64)[None, :] - faces, normals) > 0.0
    return out


@dataclass(frozen=True)
class FacadeImage:
    """One face's image."""

    face: WallFace
    rgba: NDArray[np.uint8]
    """``(h, w, 4)`` premultiplied, row 0 at the top."""
    bake_triangles: int
    """LOD2 triangles drawn to make it (those facing the face within its depth range)."""
    relief: float = 0.0
    """Metres LOD2's surfaces in the image stand in front of or behind the face's plane
    (the larger; ``inf`` where LOD2 rises above the image's top): what parallax the flat
    picture misses (:mod:`walkstream.client.draw.lookalike`)."""


@dataclass(frozen=True)
class FacadeSet:
    """A building's facade images, ready to draw over its box."""

    id: int
    images: tuple[FacadeImage, ...]
    nbytes: int
    """Texture bytes of all its images."""
    bake_triangles: int
    """LOD2 triangles drawn to make all of them."""

    def quads(self, eye: NDArray[np.float64] | None = None) -> list[Quad]:
        """The quads to draw (those turned to ``eye``; all without one)."""
        out: list[Quad] = []
        for k, im in enumerate(self.images):
            f = im.face
            if eye is not None and float(np.dot(np.asarray(eye, np.float64) - f.origin, f.normal)) <= 0.0:
                continue
            out.append((f.corners(LIFT_M), facade_image_id(self.id, k), im.rgba, 1.0))
        return out


@dataclass
class FacadeJob:
    """A building's facade images being made, one face at a time (:meth:`FacadeBaker.bake_face`)."""

    id: int
    faces: tuple[WallFace, ...]
    vertices: NDArray[Any]
    """LOD2's vertices as the baker draws them (position, normal, colour)."""
    selections: tuple[NDArray[np.int64], ...]
    """Per face, the ``(k, 3)`` LOD2 triangles its camera can see."""
    reliefs: tuple[float, ...] = ()
    """Per face, :attr:`FacadeImage.relief`."""
    images: list[FacadeImage] = field(default_factory=list)
    drawn: int = 0
    """Triangles of the current face drawn so far (its image is under way)."""

    @property
    def done(self) -> bool:
        """Every face has its image."""
        return len(self.images) >= len(self.faces)

    def result(self) -> FacadeSet:
        """The images made, as a set to draw."""
        nbytes = sum(im.rgba.nbytes for im in self.images)
        return FacadeSet(self.id, tuple(self.images), int(nbytes), sum(im.bake_triangles for im in self.images))


class FacadeBaker:
    """Renders facade images of buildings (see the module docstring).

    Parameters
    ----------
    ctx : moderngl.Context, optional
        Context to draw with (by default one is made and released by :meth:`release`).
    texels_per_m : float
        Texels per metre of wall.
    max_size : int
        Largest side of an image in texels.
    samples : int
        Samples per texel along each axis: 1 (the default) samples each texel at its
        centre, :data:`~walkstream.shared.litimage.SUPERSAMPLE` averages that many squared.
    """

    def __init__(self, ctx: Any = None, texels_per_m: float = 8.0, max_size: int = 256, samples: int = 1) -> None:
        if not (math.isfinite(texels_per_m) and texels_per_m > 0):
            raise InputError(f"facade texels per metre: expected > 0, got {texels_per_m}")
        if int(max_size) < 4:
            raise InputError(f"facade texture size: expected >= 4 texels, got {max_size}")
        if int(samples) not in (1, SUPERSAMPLE):
            raise InputError(f"facade samples per texel: expected 1 or {SUPERSAMPLE}, got {samples}")
        self.samples = int(samples)
        self.texels_per_m = float(texels_per_m)
        self.max_size = int(max_size)
        self._own = ctx is None
        self._gl: list[Any] = []
        self._fbos: dict[tuple[int, int], Any] = {}
        self.ctx: Any = create_context() if ctx is None else ctx
        try:
            self._prog: Any = self.ctx.program(vertex_shader=_VS, fragment_shader=_FS)
        except Exception as exc:
            release_objects(self.ctx, [], self._own)
            raise RenderError(f"FacadeBaker: shader program failed: {exc}") from exc
        set_lighting(self._prog)
        self._gl.append(self._prog)

    def _fbo(self, w: int, h: int) -> Any:
        fbo = self._fbos.get((w, h))
        if fbo is None:
            col = self.ctx.renderbuffer((w, h), components=4)
            dep = self.ctx.depth_renderbuffer((w, h))
            fbo = self.ctx.framebuffer(color_attachments=[col], depth_attachment=dep)
            self._gl += [fbo, col, dep]
            self._fbos[(w, h)] = fbo
        return fbo

    def job(self, oid: int, coarse: Mesh, lod2: Mesh) -> FacadeJob:
        """Building ``oid``'s images to make, one face at a time (:meth:`bake_face`): each
        wall face of ``coarse`` showing ``lod2``."""
        top = float(np.asarray(lod2.positions)[:, 2].max()) if len(lod2.positions) else None
        faces = wall_faces(coarse, top)
        p = np.asarray(lod2.positions, np.float64)
        idx = np.asarray(lod2.indices, np.int64).reshape(-1, 3)
        normals = np.asarray(lod2.normals, np.float64)[idx].mean(axis=1) if len(idx) else np.zeros((0, 3))
        centres = p[idx].mean(axis=1) if len(idx) else np.zeros((0, 3))
        verts = np.zeros(len(p), [("p", "<f4", 3), ("n", "<f4", 3), ("c", "<f4", 3)])
        verts["p"], verts["n"] = lod2.positions, lod2.normals
        verts["c"] = material_rgb(lod2.materials).astype(np.float32) / 255.0
        sels, reliefs = [], []
        for face in faces:
            # the LOD2 triangles this face's camera can see: facing it, within its depth range
            depth = (centres - face.origin) @ face.normal
            keep = (normals @ face.normal > 0.05) & (depth <= FRONT_M + 0.5) & (depth >= -BACK_M - 0.5)
            sels.append(idx[keep])
            reliefs.append(_relief(face, p, idx[keep], top))
        return FacadeJob(int(oid), tuple(faces), verts, tuple(sels), tuple(reliefs))

    def bake_face(self, job: FacadeJob, max_triangles: int | None = None) -> int:
        """Draw the next triangles of ``job``'s current face, at most ``max_triangles``
        (all by default), into its image; once the face's last are drawn its image is
        read and kept.  Returns the LOD2 triangles drawn.

        A face drawn over several calls keeps its framebuffer between them (one face of
        one job is under way at a time), so the depth test composes the pieces as one draw.
        """
        import moderngl

        if self.ctx is None:
            raise RenderError("FacadeBaker: used after release()")
        k = len(job.images)
        face, sel = job.faces[k], job.selections[k]
        ctx = self.ctx
        w, h = texture_size(face, self.texels_per_m, self.max_size)
        ss = self.samples
        fbo = self._fbo(w * ss, h * ss)
        fbo.use()
        ctx.viewport = (0, 0, w * ss, h * ss)
        if job.drawn == 0:
            fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        stop = len(sel) if max_triangles is None else min(len(sel), job.drawn + max(int(max_triangles), 0))
        part = sel[job.drawn : stop]
        if len(part):
            vbo = ctx.buffer(job.vertices.tobytes())
            ibo = ctx.buffer(part.astype("<u4").tobytes())
            vao = ctx.vertex_array(self._prog, [(vbo, "3f 3f 3f", "in_position", "in_normal", "in_color")],
                                   index_buffer=ibo, index_element_size=4)
            try:
                cam = _face_camera(face)
                if ss == 1:
                    # off the exact texel centres: a window's edge there (the grammar's
                    # round sizes put some there) falls on one side wherever it is drawn
                    cam[0, 3] += 2.0 * NUDGE_TEXELS / w
                    cam[1, 3] += 2.0 * NUDGE_TEXELS / h
                self._prog["u_view_proj"].write(mat4_bytes(cam))
                ctx.enable(moderngl.DEPTH_TEST | moderngl.CULL_FACE)
                ctx.disable(moderngl.BLEND)
                ctx.front_face, ctx.cull_face = "ccw", "back"
                ctx.depth_func = "<"
                vao.render(moderngl.TRIANGLES)
            finally:
                vao.release()
                ibo.release()
                vbo.release()
        job.drawn = stop
        if stop >= len(sel):
            raw = np.frombuffer(fbo.read(components=4, alignment=1), np.uint8)
            img = raw.reshape(h * ss, w * ss, 4)[::-1]
            relief = job.reliefs[k] if k < len(job.reliefs) else 0.0
            job.images.append(FacadeImage(face, average_samples(img, ss), int(len(sel)), relief))
            job.drawn = 0
        check_gl_error(ctx, "after baking a facade image")
        return int(len(part))

    def bake(self, oid: int, coarse: Mesh, lod2: Mesh) -> FacadeSet:
        """Every facade image of building ``oid`` at once (:meth:`job`, then each face)."""
        job = self.job(oid, coarse, lod2)
        while not job.done:
            self.bake_face(job)
        return job.result()

    def release(self) -> None:
        """Release the GL objects (and the context if it was made here); idempotent."""
        release_objects(self.ctx, self._gl, self._own)
        self._fbos.clear()
        self.ctx = None


def _relief(face: WallFace, positions: NDArray[np.float64], tris: NDArray[np.int64], top: float | None) -> float:
    """:attr:`FacadeImage.relief` of ``face``: the largest depth from its plane, clipped to
    the image's depth range, of LOD2's triangles ``tris`` ``(k, 3)`` it shows over the
    wall itself (a centre within the face less its side margins: a sill on the next wall,
    seen edge-on past the corner, is that wall's relief); ``inf`` where LOD2 (its highest
    point ``top``) rises above the image."""
    if top is not None and top > float(face.origin[2]) + face.height + 1e-6:
        return math.inf
    if not len(tris):
        return 0.0
    u = (positions[tris].mean(axis=1) - face.origin) @ face.right
    on = tris[(u >= MARGIN_M) & (u <= face.width - MARGIN_M)]
    if not len(on):
        return 0.0
    depth = (positions[np.unique(on)] - face.origin) @ face.normal
    return float(np.abs(np.clip(depth, -BACK_M, FRONT_M)).max())


def _face_camera(face: WallFace) -> NDArray[np.float64]:
    """``(4, 4)`` orthographic view-projection framing ``face`` from outside: x along
    :attr:`WallFace.right`, y up, depth from :data:`FRONT_M` in front to :data:`BACK_M` behind."""
    r, n = face.right, face.normal
    c = face.origin + r * face.width / 2.0 + np.array([0.0, 0.0, face.height / 2.0])
    span = FRONT_M + BACK_M
    m = np.zeros((4, 4))
    m[0, :3], m[0, 3] = r / (face.width / 2.0), -float(r @ c) / (face.width / 2.0)
    m[1, :3], m[1, 3] = np.array([0.0, 0.0, 1.0]) / (face.height / 2.0), -float(c[2]) / (face.height / 2.0)
    # depth s = FRONT_M - (p - c).n runs 0 -> span: NDC z = 2 s / span - 1
    m[2, :3], m[2, 3] = -2.0 * n / span, 2.0 * (FRONT_M + float(n @ c)) / span - 1.0
    m[3, 3] = 1.0
    return m
