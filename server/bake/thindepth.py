"""A conservative depth for the thin pass: the fill's depth taken as the farthest over each pixel's neighbours.

The fill's depth buffer holds, per pixel, the depth at the pixel's centre.  An occluder
whose silhouette crosses a pixel but covers its centre claims the whole pixel there,
so an object under a pixel just beside the silhouette (the far street piece in the
row that straddles the horizon, the facade edge at a street's end) fails the depth
test of the thin pass although a viewer sees it.  Taking, per pixel, the farthest depth
of the 3 x 3 pixels around it (a max filter, tile by tile) shrinks every occluder by a
pixel for that test: an occluder then hides only what it covers with a pixel to spare
on every side, never more than it stands for.  The filtered depth is written back into
the depth buffer (a full-screen pass writing ``gl_FragDepth``), so the thin pass's
lines and points are tested against it on the GPU as before; the fill's ids and counts
are not touched.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, cast

import numpy as np
from numpy.typing import NDArray

from walkstream.shared.gl import Releasable

if TYPE_CHECKING:
    import moderngl

__all__ = ["DepthEroder", "farthest_around"]

_VERTEX = """
#version 330
in vec2 in_pos;
void main() {
    gl_Position = vec4(in_pos, 0.0, 1.0);
}
"""

_FRAGMENT = """
#version 330
uniform sampler2D depth;
out uvec4 f_id;
void main() {
    // the framebuffer is used from its origin, so window and texel coordinates agree
    gl_FragDepth = texelFetch(depth, ivec2(gl_FragCoord.xy), 0).r;
    f_id = uvec4(0u);
}
"""


def farthest_around(depth: NDArray[np.float32], tile: int) -> NDArray[np.float32]:
    """Per pixel, the largest depth of the 3 x 3 pixels around it, within its own tile.

    Parameters
    ----------
    depth : (h, w) float32
        A depth image made of ``tile`` x ``tile`` tiles (rows and columns multiples
        of ``tile``); the filter never reaches across a tile's border.
    tile : int
        Side of a tile, pixels.

    Returns
    -------
    (h, w) float32
    """
    h, w = depth.shape
    t = depth.reshape(h // tile, tile, w // tile, tile)
    out = t.copy()
    out[:, 1:] = np.maximum(out[:, 1:], t[:, :-1])
    out[:, :-1] = np.maximum(out[:, :-1], t[:, 1:])
    rows = out.copy()
    out[:, :, :, 1:] = np.maximum(out[:, :, :, 1:], rows[:, :, :, :-1])
    out[:, :, :, :-1] = np.maximum(out[:, :, :, :-1], rows[:, :, :, 1:])
    return out.reshape(h, w)


class DepthEroder(Releasable):
    """Replaces a framebuffer's depth over a viewport by :func:`farthest_around` of it.

    Parameters
    ----------
    ctx : moderngl.Context
    size : (int, int)
        Width and height of the framebuffers it will be used with.
    """

    def __init__(self, ctx: moderngl.Context, size: tuple[int, int]) -> None:
        self.ctx: moderngl.Context | None = ctx
        self._prog = ctx.program(vertex_shader=_VERTEX, fragment_shader=_FRAGMENT)
        quad = np.array([-1, -1, 1, -1, -1, 1, 1, 1], np.float32)
        self._vbo = ctx.buffer(quad.tobytes())
        self._vao = ctx.vertex_array(self._prog, [(self._vbo, "2f", "in_pos")])
        self._tex = ctx.texture(size, 1, dtype="f4")
        self._tex.filter = (ctx.NEAREST, ctx.NEAREST)
        self._depth = np.empty((size[1], size[0]), np.float32)

    def erode(self, fbo: moderngl.Framebuffer, used: tuple[int, int, int, int], tile: int) -> None:
        """Read the depth of ``used`` (x, y, w, h from the origin), filter it, write it back.

        ``used`` starts at the origin.  Leaves the depth function at "always", the
        viewport at ``used`` and the depth mask on (the caller sets its own); the
        colour over ``used`` is written 0.
        """
        import moderngl

        ctx = self.ctx
        assert ctx is not None
        _, _, w, h = used
        d = self._depth[:h, :w]
        fbo.read_into(d, viewport=used, components=1, attachment=-1, dtype="f4", alignment=1)
        self._tex.write(np.ascontiguousarray(farthest_around(d, tile)).tobytes(), viewport=used)
        ctx.viewport = used
        ctx.scissor = None
        ctx.disable(moderngl.CULL_FACE)
        ctx.depth_func = "1"  # always
        fbo.depth_mask = True
        self._tex.use(0)
        cast("moderngl.Uniform", self._prog["depth"]).value = 0
        self._vao.render(moderngl.TRIANGLE_STRIP)

    def release(self) -> None:
        """Release the GL objects; idempotent."""
        for name in ("_vao", "_vbo", "_tex", "_prog"):
            obj = getattr(self, name, None)
            if obj is not None:
                obj.release()
                setattr(self, name, None)
        self.ctx = None
