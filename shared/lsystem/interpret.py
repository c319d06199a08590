"""Turn the terminal modules of a derivation into a triangle mesh.

The terminals are generic operations placed in the frame of a footprint edge
(``u`` along the edge, ``z`` up, ``n`` outward): ``Quad`` (a rectangle), ``Box`` (a
rectangle extruded outward) and ``Cap`` (the footprint polygon at a height).  Each
kind is built for all its modules at once by instancing a unit template with numpy:
``(k modules, v template vertices, 3)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from walkstream.shared.records import Mesh

__all__ = [
    "EdgeFrames",
    "interpret",
    "count_triangles",
    "TEMPLATE_TRIANGLES",
    "QUAD",
    "BOX",
    "valid_rows",
    "instance",
]


@dataclass(frozen=True, slots=True)
class EdgeFrames:
    """Local frames of a footprint's edges and its cap triangulation.

    ``origin (E, 2)`` edge start points, ``direction (E, 2)`` unit vectors along the
    edges, ``normal (E, 2)`` outward unit normals, ``length (E,)``; ``cap_xy (n, 2)``
    the footprint's vertices and ``cap_tris (t, 3)`` their triangles, CCW from above.
    """

    origin: NDArray[np.float64]
    direction: NDArray[np.float64]
    normal: NDArray[np.float64]
    length: NDArray[np.float64]
    cap_xy: NDArray[np.float64]
    cap_tris: NDArray[np.int64]


def _template(faces: list[tuple[list[tuple[int, int, int]], tuple[int, int, int]]]) -> tuple[
    NDArray[np.float64], NDArray[np.float64], NDArray[np.int64]
]:
    corners: list[tuple[int, int, int]] = []
    normals: list[tuple[int, int, int]] = []
    tris: list[tuple[int, int, int]] = []
    for quad, nrm in faces:
        base = len(corners)
        corners.extend(quad)
        normals.extend([nrm] * 4)
        tris.extend([(base, base + 1, base + 2), (base, base + 2, base + 3)])
    return np.array(corners, np.float64), np.array(normals, np.float64), np.array(tris, np.int64)


# Unit templates in right-handed (a along u, b along z, c along n) coordinates,
# faces counter-clockwise seen from outside.
QUAD = _template([([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], (0, 0, 1))])
"""The unit quad template: one face, normal +z in template space."""
BOX = _template(
    [
        ([(0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)], (0, 0, 1)),  # front
        ([(0, 1, 0), (0, 1, 1), (1, 1, 1), (1, 1, 0)], (0, 1, 0)),  # top
        ([(0, 0, 0), (1, 0, 0), (1, 0, 1), (0, 0, 1)], (0, -1, 0)),  # bottom
        ([(1, 0, 0), (1, 1, 0), (1, 1, 1), (1, 0, 1)], (1, 0, 0)),  # right end
        ([(0, 0, 0), (0, 0, 1), (0, 1, 1), (0, 1, 0)], (-1, 0, 0)),  # left end
    ]
)
"""The unit box template: front, top, bottom and the two ends (no back face)."""

#: triangles one module of each terminal makes (Cap depends on the footprint)
TEMPLATE_TRIANGLES = {"Quad": len(QUAD[2]), "Box": len(BOX[2])}


def valid_rows(sym: str, p: NDArray[np.float64], n_edges: int) -> NDArray[np.bool_]:
    """Rows that make real geometry: finite, on an existing edge, positive extent."""
    ok = np.isfinite(p).all(axis=1)
    if sym in ("Quad", "Box"):
        e = p[:, 0]
        ok &= (e >= 0) & (e < n_edges) & (p[:, 3] > p[:, 1]) & (p[:, 4] > p[:, 2])
        if sym == "Box":
            ok &= p[:, 6] > 0
    return np.asarray(ok, dtype=bool)


def count_triangles(modules: dict[str, NDArray[np.float64]], frames: EdgeFrames) -> int:
    """Triangles :func:`interpret` would make, without making them."""
    n_edges = len(frames.length)
    total = 0
    for sym, per in TEMPLATE_TRIANGLES.items():
        p = modules.get(sym)
        if p is not None and len(p):
            total += per * int(valid_rows(sym, p, n_edges).sum())
    caps = modules.get("Cap")
    if caps is not None and len(caps):
        total += len(frames.cap_tris) * int(valid_rows("Cap", caps, n_edges).sum())
    return total


def instance(
    template: tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.int64]],
    frames: EdgeFrames,
    e: NDArray[np.int64],
    u0: NDArray[np.float64],
    z0: NDArray[np.float64],
    du: NDArray[np.float64],
    dz: NDArray[np.float64],
    c0: NDArray[np.float64],
    dc: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.int64]]:
    """``k`` copies of ``template`` placed on edges ``e`` of ``frames``: positions and
    normals ``(k * v, 3)`` and triangles ``(k * t, 3)``.

    Copy ``i`` spans ``u0[i] .. u0[i] + du[i]`` along its edge, ``z0[i] .. z0[i] + dz[i]``
    up and ``c0[i] .. c0[i] + dc[i]`` out along the edge's normal (all ``(k,)``).
    """
    corners, tnormals, ttris = template
    d = frames.direction[e]  # (k, 2)
    nrm = frames.normal[e]
    org = frames.origin[e]
    a = u0[:, None] + corners[None, :, 0] * du[:, None]  # (k, v)
    b = z0[:, None] + corners[None, :, 1] * dz[:, None]
    c = c0[:, None] + corners[None, :, 2] * dc[:, None]
    k, v = a.shape
    pos = np.empty((k, v, 3))
    pos[..., 0] = org[:, None, 0] + a * d[:, None, 0] + c * nrm[:, None, 0]
    pos[..., 1] = org[:, None, 1] + a * d[:, None, 1] + c * nrm[:, None, 1]
    pos[..., 2] = b
    nor = np.empty((k, v, 3))
    ta, tb, tc = tnormals[:, 0], tnormals[:, 1], tnormals[:, 2]
    nor[..., 0] = ta[None, :] * d[:, None, 0] + tc[None, :] * nrm[:, None, 0]
    nor[..., 1] = ta[None, :] * d[:, None, 1] + tc[None, :] * nrm[:, None, 1]
    nor[..., 2] = np.broadcast_to(tb[None, :], (k, v))
    tris = (ttris[None, :, :] + (np.arange(k) * v)[:, None, None]).reshape(-1, 3)
    return pos.reshape(-1, 3), nor.reshape(-1, 3), tris


def interpret(modules: dict[str, NDArray[np.float64]], frames: EdgeFrames) -> Mesh:
    """Build the mesh of a derivation's terminal modules (non-terminals are ignored)."""
    n_edges = len(frames.length)
    parts_p, parts_n, parts_t, parts_m = [], [], [], []
    base = 0

    def add(pos: NDArray, nor: NDArray, tris: NDArray, mats: NDArray) -> None:
        nonlocal base
        parts_p.append(pos)
        parts_n.append(nor)
        parts_t.append(tris + base)
        parts_m.append(mats)
        base += len(pos)

    caps = modules.get("Cap")
    if caps is not None and len(caps) and len(frames.cap_tris):
        caps = caps[valid_rows("Cap", caps, n_edges)]
        nv = len(frames.cap_xy)
        for z, direction, mat in caps:
            pos = np.column_stack([frames.cap_xy, np.full(nv, z)])
            up = 1.0 if direction >= 0 else -1.0
            nor = np.zeros((nv, 3))
            nor[:, 2] = up
            tris = frames.cap_tris if up > 0 else frames.cap_tris[:, ::-1]
            add(pos, nor, tris, np.full(nv, mat))

    for sym, template in (("Quad", QUAD), ("Box", BOX)):
        p = modules.get(sym)
        if p is None or len(p) == 0:
            continue
        p = p[valid_rows(sym, p, n_edges)]
        if len(p) == 0:
            continue
        e = p[:, 0].astype(np.int64)
        u0, z0, u1, z1, off = p[:, 1], p[:, 2], p[:, 3], p[:, 4], p[:, 5]
        if sym == "Quad":
            depth, mat = np.zeros(len(p)), p[:, 6]
        else:
            depth, mat = p[:, 6], p[:, 7]
        pos, nor, tris = instance(template, frames, e, u0, z0, u1 - u0, z1 - z0, off, depth)
        add(pos, nor, tris, np.repeat(mat, len(template[0])))

    if not parts_p:
        return Mesh(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)))
    return Mesh(
        np.concatenate(parts_p),
        np.concatenate(parts_n),
        np.concatenate(parts_t),
        np.clip(np.concatenate(parts_m), 0, 255).astype(np.uint8),
    )
