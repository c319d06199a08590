"""What every image renderer shares: the client's lighting on a GL program, and supersample averaging.

The bake's impostor images (:mod:`walkstream.server.bake.impostorrender`) and wall
textures (:mod:`walkstream.server.bake.wallrender`), and the client's facade textures
(:mod:`walkstream.client.draw.facades`, lit per fragment as the truth lights), all draw meshes of ``(position, normal, colour)`` vertices lit as the client lights
them (:mod:`walkstream.shared.lighting`), at :data:`SUPERSAMPLE` times the size asked,
and average the samples into premultiplied RGBA (:mod:`walkstream.shared.codec.image`).
Each keeps its own fragment shader and its own way of drawing.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from walkstream.shared.lighting import AMBIENT, LIGHT_DIRECTION

__all__ = ["LIT_VERTEX_SHADER", "NUDGE_TEXELS", "SUPERSAMPLE", "average_samples", "lit_program", "set_lighting"]

SUPERSAMPLE = 2
"""Rendered samples per image texel along each axis (averaged: soft edges)."""

NUDGE_TEXELS = 0.0023
"""How far (texels, on both axes) a point-sampled image's samples sit off the texel
centres.  A sample exactly on an edge (a window's edge on a texel centre, which the
grammar's round sizes make happen) falls on either side by the last bit of the viewport
transform, which differs with where the image is drawn; off the centre by a fraction
no round size meets, it falls on one side wherever it is drawn.  Far above the viewport
transform's rounding (about 1e-4 of a pixel in a 2,048-pixel atlas), far below a texel
(an edge this near a centre moves a texel's side on about 0.3 % of a windowed facade's
texels), and no round fraction."""

LIT_VERTEX_SHADER = """
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
"""Vertex shader of the client's per-vertex lighting (``v_lit`` out; ``u_view_proj`` to set per view)."""


def lit_program(ctx: Any, fragment_shader: str) -> Any:
    """A program of :data:`LIT_VERTEX_SHADER` and ``fragment_shader`` (which reads
    ``in vec3 v_lit``), its light direction and ambient already set.

    Parameters
    ----------
    ctx:
        The moderngl context.
    fragment_shader:
        GLSL 330 source of the fragment shader.

    Returns
    -------
    moderngl.Program
        The caller releases it with its other GL objects.
    """
    prog: Any = ctx.program(vertex_shader=LIT_VERTEX_SHADER, fragment_shader=fragment_shader)
    set_lighting(prog)
    return prog


def set_lighting(prog: Any) -> None:
    """Set ``prog``'s ``u_light_dir`` (the unit :data:`~walkstream.shared.lighting.LIGHT_DIRECTION`)
    and ``u_ambient`` (:data:`~walkstream.shared.lighting.AMBIENT`)."""
    light = np.asarray(LIGHT_DIRECTION, np.float64)
    prog["u_light_dir"].value = tuple(float(v) for v in light / np.linalg.norm(light))
    prog["u_ambient"].value = float(AMBIENT)


def average_samples(img: NDArray[np.uint8], factor: int = SUPERSAMPLE) -> NDArray[np.uint8]:
    """The rounded mean of each ``factor`` x ``factor`` block.

    Parameters
    ----------
    img:
        ``(h * factor, w * factor, 4) uint8`` as read from the framebuffer.
    factor:
        Samples per texel along each axis (default :data:`SUPERSAMPLE`; 1 returns ``img``).

    Returns
    -------
    NDArray[np.uint8]
        ``(h, w, 4)``: integer sums of strided views (cheaper than per tile or in floats).
    """
    if factor == 1:
        return img
    wide = img.astype(np.uint16)
    n = factor * factor
    total = np.full_like(wide[::factor, ::factor], n // 2)
    for i in range(factor):
        for j in range(factor):
            total += wide[i::factor, j::factor]
    out: NDArray[np.uint8] = (total // n).astype(np.uint8)
    return out
