"""Impostor quads on the GPU: each image a texture, each impostor a textured quad blended premultiplied.

The frame's impostors (:class:`~walkstream.client.walk.impostors.DrawnImpostor`) are
drawn after its meshes, into the framebuffer they left bound: depth tested against
the geometry, depth not written (an image is a stand-in with no depth of its own, and
a building fading from its image to its geometry draws both), blended with
premultiplied alpha (``ONE, ONE_MINUS_SRC_ALPHA``: the bake stores premultiplied
texels, so a silhouette's half-covered texels add their share of colour over what is
behind and no dark fringe appears; the blend's opacity scales all four channels),
farthest first (:func:`back_to_front`: with no depth written, overlapping images
compose in the order drawn).
Textures live while a frame draws them: the frame's images are already within the
texture budget (:func:`~walkstream.client.draw.impostors.fit_textures`), and one no
frame drew is released at the next draw.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import moderngl
import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.shared.camera import mat4_bytes
from walkstream.shared.errors import InputError, RenderError
from walkstream.shared.walls import NO_WARP, WallWarp

__all__ = ["ANISOTROPY", "FACADE_FILTERS", "FACADE_IDS", "IMPOSTOR_MIN_FILTER", "WALL_MIN_FILTER", "Quad",
           "QuadRenderer", "back_to_front", "cross_fade", "quads_of", "warped", "with_mesh"]

IMPOSTOR_MIN_FILTER: int = moderngl.LINEAR
"""How an impostor image's texels are read when it is drawn smaller than baked: bilinear.
Nearest (the texel under the pixel's centre, as the truth's rasterised LOD2 takes the
surface under it) is closer to the truth pixel by pixel (``walkstream bench
impostor-sampling``; on the D 60 m walk it takes the visibly wrong share's median from
1.00 to 0.82 % of the frame) but the images shimmer as they move: the switch's
frame-to-frame change over plain motion's rose from 1.02 to 1.13 there, so bilinear stays."""

WALL_MIN_FILTER: int = moderngl.NEAREST
"""How a wall texture's texels are read when it is drawn smaller than baked: the texel
under the pixel's centre, as the truth's rasterised geometry takes the surface under it
(read anisotropically, with the facade pictures, the village's walk on ``pda`` was worse
against the point-sampled truth and against the 4 x 4 one: docs/benchmarks.md, "Facade
pictures read anisotropically")."""

FACADE_IDS: int = 1 << 40
"""The quads' image ids by kind: 0 and up an impostor image, -1 down to ``-FACADE_IDS + 1``
a wall texture (``-1 - texture id``), ``-FACADE_IDS`` and below a facade picture
(:func:`~walkstream.client.draw.facades.facade_image_id`).  The renderer keeps one texture
an id, so the ranges never meet."""

FACADE_FILTERS: tuple[str, ...] = ("point", "anisotropic")
"""How a facade picture is read when drawn smaller than baked (``--facade-filter``):
``point``, the texel under the pixel's centre, as one sample a pixel of LOD2 geometry takes
the surface under it (the closest to the point-sampled truth); ``anisotropic``, the mean of
the texels under the pixel's footprint (trilinear mipmaps, :data:`ANISOTROPY` samples along
a face seen obliquely), as an anti-aliased drawing of the geometry would show them."""

ANISOTROPY: float = 16.0
"""The largest anisotropy of an ``anisotropic`` facade picture (the driver clamps it to its own)."""

Quad = tuple[NDArray[np.float64], int, NDArray[np.uint8], float]
"""``(corners (4, 3), image id, premultiplied RGBA (h, w, 4), opacity)``; corners bottom-left,
bottom-right, top-right, top-left of the image (its row 0 is the top).  Corners ``(4, 5)``
carry each corner's texture coordinates ``u, v`` too (a virtual wall's texture slid along
the wall, :func:`cross_fade`; outside 0..1 the image's edge texels).  Corners ``(3 m, 6)``
are ``m`` triangles with projective texture coordinates ``u q, v q, q`` (a wall texture's
depth mesh, :mod:`walkstream.shared.walldepth`, its warped quad as the first two
triangles: :func:`with_mesh`)."""

_VS = """
#version 330
uniform mat4 u_view_proj;
uniform float u_push;
in vec3 in_pos;
in vec3 in_uvq;
out vec3 v_uvq;
void main() {
    v_uvq = in_uvq;
    gl_Position = u_view_proj * vec4(in_pos, 1.0);
    // a depth mesh's quad: just before the far plane, so it shows only where neither its
    // mesh (depth written) nor geometry drew (z = c w stays linear: clipping agrees)
    if (u_push > 0.5) gl_Position.z = 0.99999 * gl_Position.w;
}
"""

_FS = """
#version 330
uniform sampler2D u_image;
uniform float u_alpha;
in vec3 v_uvq;
out vec4 f_colour;
void main() {
    // projective: a depth mesh's triangle shows what the sampling point saw (q = 1 on a quad)
    f_colour = texture(u_image, v_uvq.xy / v_uvq.z) * u_alpha;  // premultiplied: every channel scales
}
"""

# texture v: row 0 of the array (the image's top) is at v = 0
_UV = np.array([[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]], np.float32)

_MESH_VERTICES = 3 * 2 * (2 + 16 * 16)
"""Vertices the buffer holds from the start: a 16 x 16 depth mesh and its quad (more grows it)."""


def _uvq(corners: NDArray[np.floating]) -> NDArray[np.float32]:
    """``(4, 6)`` a quad's corners ``(4, 3)`` or ``(4, 5)`` with ``u, v, q = 1``."""
    c = np.asarray(corners, np.float32)
    uv = c[:, 3:5] if c.shape[1] >= 5 else _UV
    return np.hstack([c[:, :3], uv, np.ones((4, 1), np.float32)])


def with_mesh(quad: NDArray[np.floating], mesh: NDArray[np.float32]) -> NDArray[np.float64]:
    """``(6 + n, 6)`` triangles: the quad ``(4, 3)`` or ``(4, 5)`` (a wall's warped quad)
    as two triangles first, then the depth mesh ``(n, 6)``; the renderer draws the mesh
    and fills its holes with the quad (:meth:`QuadRenderer._mesh`; :func:`back_to_front`
    sorts the item by the quad)."""
    q = _uvq(quad)
    out: NDArray[np.float64] = np.vstack([q[[0, 1, 2, 0, 2, 3]], np.asarray(mesh, np.float32)]).astype(np.float64)
    return out


class QuadRenderer:
    """Textures and draws impostor quads on ``ctx`` (see the module docstring)."""

    def __init__(self, ctx: moderngl.Context, image_filter: int | None = None, facade_filter: str = "point") -> None:
        if facade_filter not in FACADE_FILTERS:
            raise InputError(f"--facade-filter {facade_filter!r}: expected one of {', '.join(FACADE_FILTERS)}")
        self.ctx = ctx
        self.image_filter = IMPOSTOR_MIN_FILTER if image_filter is None else int(image_filter)
        """Minifying filter of impostor images (moderngl ``NEAREST`` or ``LINEAR``)."""
        self.facade_filter = facade_filter
        """How facade pictures are read when minified (one of :data:`FACADE_FILTERS`)."""
        try:
            self._prog = ctx.program(vertex_shader=_VS, fragment_shader=_FS)
        except Exception as exc:
            raise RenderError(f"QuadRenderer: shader program failed: {exc}") from exc
        self._vbo = ctx.buffer(reserve=_MESH_VERTICES * 6 * 4)
        self._vao = ctx.vertex_array(self._prog, [(self._vbo, "3f 3f", "in_pos", "in_uvq")])
        self._textures: dict[int, moderngl.Texture] = {}
        self._bytes: dict[int, int] = {}
        self.texture_bytes = 0
        """Bytes of the textures held."""
        self.last_quads = 0
        """Quads the last :meth:`draw` drew."""
        self.last_triangles = 0
        """Triangles the last :meth:`draw` drew (two a quad, a depth mesh's own)."""

    def _texture(self, image: int, rgba: NDArray[np.uint8]) -> moderngl.Texture:
        tex = self._textures.get(image)
        if tex is None:
            a = np.ascontiguousarray(rgba, np.uint8)
            tex = self.ctx.texture((a.shape[1], a.shape[0]), 4, a.tobytes())
            # magnified, bilinear; minified, by kind (FACADE_FILTERS, WALL_MIN_FILTER,
            # IMPOSTOR_MIN_FILTER: why each)
            if image <= -FACADE_IDS and self.facade_filter == "anisotropic":
                tex.build_mipmaps()
                tex.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
                tex.anisotropy = ANISOTROPY
            else:
                tex.filter = (moderngl.NEAREST if image <= -FACADE_IDS else WALL_MIN_FILTER if image < 0
                              else self.image_filter, moderngl.LINEAR)
            tex.repeat_x = tex.repeat_y = False
            self._textures[image] = tex
            # a mipmapped texture's levels hold a third more
            self._bytes[image] = a.nbytes * 4 // 3 if tex.filter[0] == moderngl.LINEAR_MIPMAP_LINEAR else a.nbytes
            self.texture_bytes += self._bytes[image]
        return tex

    def draw(self, quads: Sequence[Quad], view_proj: ArrayLike) -> None:
        """Draw ``quads`` into the bound framebuffer with the camera ``view_proj``; release
        the textures of images not among them."""
        used = {q[1] for q in quads}
        for image in [i for i in self._textures if i not in used]:
            tex = self._textures.pop(image)
            self.texture_bytes -= self._bytes.pop(image)
            tex.release()
        self.last_quads = len(quads)
        self.last_triangles = sum(2 if len(q[0]) == 4 else len(q[0]) // 3 for q in quads)
        if not quads:
            return
        ctx = self.ctx
        u = self._prog["u_view_proj"]
        assert isinstance(u, moderngl.Uniform)
        u.write(mat4_bytes(view_proj))
        ua = self._prog["u_alpha"]
        assert isinstance(ua, moderngl.Uniform)
        ctx.enable(moderngl.DEPTH_TEST | moderngl.BLEND)
        ctx.disable(moderngl.CULL_FACE)  # a quad is seen from its baking side only, but either winding
        ctx.blend_func = moderngl.ONE, moderngl.ONE_MINUS_SRC_ALPHA
        fbo = ctx.fbo  # the bound framebuffer (the meshes' own): its depth is tested, not written
        fbo.depth_mask = False
        try:
            for corners, image, rgba, alpha in back_to_front(quads, view_proj):
                self._texture(image, rgba).use(0)
                ua.value = float(alpha)
                c = np.asarray(corners, np.float32)
                if len(c) != 4:  # a depth mesh, then its quad where the mesh left holes
                    self._mesh(c, fbo)
                    continue
                verts = _uvq(c)
                self._vbo.write(verts.astype("f4").tobytes())
                self._vao.render(moderngl.TRIANGLE_FAN, vertices=4)
        finally:
            fbo.depth_mask = True
            ctx.disable(moderngl.BLEND)
            ctx.blend_func = moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA

    def _mesh(self, tris: NDArray[np.floating], fbo: Any) -> None:
        """Draw a :func:`with_mesh` item: the mesh (its rows after the first six) with its
        depth written, then the quad (the first six) pushed to the far plane, so it fills
        only the mesh's holes (what a viewer nearer than the sampling point sees past the
        texture's edges), as ``benchmarks/walldepth.py`` measured "mesh + warp"."""
        data = np.ascontiguousarray(tris, "f4").tobytes()
        if len(data) > self._vbo.size:
            self._vbo.orphan(len(data))
        self._vbo.write(data)
        push = self._prog["u_push"]
        assert isinstance(push, moderngl.Uniform)
        fbo.depth_mask = True
        self._vao.render(moderngl.TRIANGLES, vertices=len(tris) - 6, first=6)
        fbo.depth_mask = False
        push.value = 1.0
        self._vao.render(moderngl.TRIANGLES, vertices=6, first=0)
        push.value = 0.0

    def release(self) -> None:
        """Release the textures and buffers."""
        for tex in self._textures.values():
            tex.release()
        self._textures.clear()
        self._bytes.clear()
        self.texture_bytes = 0
        self._vao.release()
        self._vbo.release()
        self._prog.release()


def back_to_front(quads: Sequence[Quad], view_proj: ArrayLike) -> list[Quad]:
    """``quads`` farthest first (by the clip-space ``w``, the depth along the view, of each
    quad's centre under ``view_proj`` ``(4, 4)``), ties in their given order.

    Depth is not written, so two images overlapping on the screen compose in the order
    drawn: in the order given (by object id) a farther building's image was painted over
    a nearer one's wherever they overlap, as along a street of impostors at a short
    ``D``.  Farthest first, each nearer image covers the farther ones; the two images of
    one building cross-fading share a centre and keep their order (the old under the new).
    """
    m = np.asarray(view_proj, np.float64).reshape(4, 4)
    # a depth mesh by its quad (its first two triangles, :func:`with_mesh`)
    depth = [float(m[3, :3] @ np.asarray(q[0], np.float64)[:6 if len(q[0]) != 4 else 4, :3].mean(axis=0) + m[3, 3])
             for q in quads]
    order = sorted(range(len(quads)), key=lambda k: -depth[k])  # stable: ties keep their order
    return [quads[k] for k in order]


def quads_of(drawn: Sequence[Any], image: Any) -> list[Quad]:
    """The quads of a frame's impostors (:class:`~walkstream.client.walk.impostors.DrawnImpostor`),
    ``image(id)`` giving each one's decoded RGBA (those it has none for left out)."""
    out: list[Quad] = []
    for d in drawn:
        rgba = image(d.image)
        if rgba is not None:
            out.append((d.corners, d.image, rgba, float(d.alpha)))
    return out


def warped(corners: NDArray[np.float64], warp: WallWarp) -> NDArray[np.float64]:
    """``(4, 5)`` a virtual wall's ``corners`` ``(4, 3)`` (bottom-left, bottom-right,
    top-right, top-left, vertical) with texture coordinates that lay its texture by
    ``warp`` (:data:`~walkstream.shared.walls.WallWarp`: the texture's point at
    ``(along + scale s, up + scale z)`` shown at the wall's ``(s, z)``); the corners as
    given for :data:`~walkstream.shared.walls.NO_WARP`.  The map is affine on the quad's
    plane, so the corners' coordinates interpolated across it are exact."""
    if tuple(warp) == NO_WARP:
        return corners
    k, along, up = (float(v) for v in warp)
    c = np.asarray(corners, np.float64).reshape(4, 3)
    length = max(float(np.linalg.norm(c[1, :2] - c[0, :2])), 1e-9)
    z0, z1 = float(c[0, 2]), float(c[3, 2])
    height = z1 - z0 if abs(z1 - z0) > 1e-9 else 1e-9
    s = np.array([0.0, length, length, 0.0])
    uv = np.stack([(along + k * s) / length, (z1 - (up + k * c[:, 2])) / height], axis=1)
    return np.hstack([c, uv])


def cross_fade(
    corners: NDArray[np.float64], key: int, rgba: NDArray[np.uint8], other_key: int,
    other: NDArray[np.uint8] | None, alpha: float, mix: float, warps: tuple[WallWarp, WallWarp] = (NO_WARP, NO_WARP),
) -> list[Quad]:
    """One quad showing ``(1 - mix)`` of ``rgba`` and ``mix`` of ``other`` at opacity
    ``alpha``, as the renderer composes it: ``rgba`` at ``a (1 - m) / (1 - a m)`` and
    ``other`` over it at ``a m``; drawn "over" (premultiplied) that is exactly
    ``a ((1 - m) rgba + m other) + (1 - a) behind`` for opaque images.  One quad when
    ``other`` is None or ``mix`` is 0.  ``corners`` ``(4, 3)``, images ``(h, w, 4)``;
    ``warps`` how each image is laid on the quad (:func:`warped`)."""
    own = warped(corners, warps[0])
    if other is None or mix <= 0.0:
        return [(own, key, rgba, float(alpha))]
    a, m = float(alpha), float(mix)
    return [(own, key, rgba, a * (1.0 - m) / max(1.0 - a * m, 1e-9)),
            (warped(corners, warps[1]), other_key, other, a * m)]
