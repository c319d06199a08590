"""A cut-away picture of an interior storey: its contents cut off above eye height, seen from above."""

from __future__ import annotations

import math
import os
from collections.abc import Sequence

import moderngl
import numpy as np

from walkstream.client.draw.meshes import MeshRenderer
from walkstream.shared.camera import fit_view
from walkstream.shared.errors import InputError
from walkstream.shared.records import Mesh

__all__ = ["CUTAWAY_DIRECTION", "render_cutaway"]

CUTAWAY_DIRECTION: tuple[float, float, float] = (
    -math.cos(math.radians(55.0)) * math.sqrt(0.5),
    -math.cos(math.radians(55.0)) * math.sqrt(0.5),
    math.sin(math.radians(55.0)),
)
"""From the storey towards the eye: south-west, 55 degrees up (into the rooms)."""


def render_cutaway(
    meshes: Sequence[Mesh],
    path: str | os.PathLike[str],
    *,
    title: str = "",
    size: tuple[int, int] = (1400, 1000),
    ctx: moderngl.Context | None = None,
    supersample: int = 2,
) -> int:
    """Draw the (already cut) meshes of a storey into a PNG; returns the triangles drawn.

    The whole storey is framed from :data:`CUTAWAY_DIRECTION`; walls, furniture and
    frames show up to the cut, floors and stairs below it.  Every triangle is drawn
    from both sides: a room holds only the inner face of its walls, and the walls on
    the near side of each room turn that face away from the eye (back-face culled,
    they would vanish).
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    used = [m for m in meshes if m.triangles]
    if not used:
        raise InputError("render_cutaway: nothing to draw (the storey has no contents below the cut)")
    pts = np.concatenate([m.positions for m in used]).astype(np.float64)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    w, h = size
    ss = max(1, int(supersample))
    view, proj = fit_view(lo, hi, CUTAWAY_DIRECTION, 30.0, w / h, margin=1.02)
    with MeshRenderer(ctx) as r:
        img = r.render([_two_sided(m) for m in used], view, proj, (w * ss, h * ss))
    img = np.round(img.reshape(h, ss, w, ss, 3).mean(axis=(1, 3))).astype(np.uint8)
    dpi = 100
    fig = Figure(figsize=(w / dpi, (h + 40) / dpi), dpi=dpi, facecolor="white")
    FigureCanvasAgg(fig)
    ax = fig.add_axes((0.0, 0.0, 1.0, h / (h + 40)))
    ax.imshow(img, interpolation="nearest", aspect="auto")
    ax.set_axis_off()
    tris = sum(m.triangles for m in used)
    fig.suptitle(f"{title}{': ' if title else ''}{tris:,} triangles below the cut", fontsize=12, y=0.99)
    fig.savefig(os.fspath(path), dpi=dpi, format="png")
    return tris


def _two_sided(mesh: Mesh) -> Mesh:
    """The mesh with a reversed copy of every triangle (normals flipped)."""
    n = len(mesh.positions)
    idx = np.asarray(mesh.indices, np.uint32)
    return Mesh(
        np.concatenate([mesh.positions, mesh.positions]),
        np.concatenate([mesh.normals, -np.asarray(mesh.normals)]),
        np.concatenate([idx, idx[:, ::-1] + np.uint32(n)]),
        np.concatenate([mesh.materials, mesh.materials]) if len(mesh.materials) else mesh.materials,
    )
