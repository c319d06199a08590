"""The scene as the ID renderer draws it: every object's mesh in one buffer, in curve order.

:class:`~walkstream.server.bake.visibility.VisibilityRenderer` keeps all objects in ONE
vertex buffer and ONE index buffer, in Hilbert-curve order of their bounding-box
centres, so that objects close to each other are contiguous and a frustum-culled set of
objects becomes a few contiguous index ranges; each vertex carries the object's local
index + 1, which the fragment shader writes (0 = nothing).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from walkstream.server.bake.draworder import curve_order
from walkstream.shared.areas import build_area
from walkstream.shared.arrays import F64, I64
from walkstream.shared.buildings import build_lod
from walkstream.shared.errors import InputError
from walkstream.shared.records import Mesh
from walkstream.shared.streets import build_street

if TYPE_CHECKING:
    from walkstream.server.sources.scene import SourceScene

__all__ = ["PackedMeshes", "meshes_for_scene", "pack_meshes"]


def meshes_for_scene(scene: SourceScene, lod: int) -> tuple[list[Mesh], I64]:
    """The meshes and object ids of every object of a scene, as the bake renders them.

    Parameters
    ----------
    scene : SourceScene
        Buildings and street pieces in scene-local metres.
    lod : int
        Level of detail of the buildings (0, 1 or 2); street pieces are the same at
        every level.

    Returns
    -------
    meshes : list of Mesh
        Buildings first (``build_lod``), then street pieces (``build_street``), then
        areas (``build_area``).
    ids : (n,) int64
        The object id of each mesh.
    """
    meshes = [build_lod(b, lod) for b in scene.buildings]
    meshes += [build_street(s, lod) for s in scene.streets]
    meshes += [build_area(a, lod) for a in scene.areas]
    ids = np.array([b.id for b in scene.buildings] + [s.id for s in scene.streets] + [a.id for a in scene.areas], dtype=np.int64)
    return meshes, ids


@dataclass(frozen=True, slots=True)
class PackedMeshes:
    """Non-empty meshes packed in draw order (``k`` of them)."""

    ids: I64
    """(k,) object id of each, in draw order."""
    lo: F64
    """(k, 3) bounding-box minima."""
    hi: F64
    """(k, 3) bounding-box maxima."""
    index_first: I64
    """(k,) each object's first index in :attr:`index`."""
    index_stop: I64
    """(k,) one past its last index."""
    verts: NDArray[np.uint32]
    """(v, 4) interleaved ``x, y, z`` (float32 bits) and local index + 1."""
    index: NDArray[np.uint32]
    """(i,) triangle indices into :attr:`verts`."""


def pack_meshes(meshes: Sequence[Mesh], ids: I64) -> PackedMeshes:
    """Concatenate the non-empty meshes in Hilbert-curve order of their boxes' centres.

    Raises
    ------
    InputError
        When the scene has too many vertices for 32-bit indices.
    """
    n = len(meshes)
    lo = np.zeros((n, 3))
    hi = np.zeros((n, 3))
    nonempty = np.zeros(n, bool)
    for i, m in enumerate(meshes):
        if len(m.positions) and len(m.indices):
            p = m.positions.astype(np.float64)
            lo[i], hi[i] = p.min(axis=0), p.max(axis=0)
            nonempty[i] = True
    keep = np.flatnonzero(nonempty)
    order = keep[curve_order((lo[keep, :2] + hi[keep, :2]) / 2.0)]
    nv = np.array([len(meshes[i].positions) for i in order], np.int64)
    ni = np.array([meshes[i].indices.size for i in order], np.int64)
    v_first = np.concatenate([[0], np.cumsum(nv)[:-1]]).astype(np.int64)
    i_first = np.concatenate([[0], np.cumsum(ni)]).astype(np.int64)
    total_v = int(nv.sum())
    if total_v >= 2**32 - 1:
        raise InputError(f"VisibilityRenderer: too many vertices for uint32 indices ({total_v})")
    # Interleaved (x, y, z, id) of 4-byte words: float32 positions as uint32 bits.
    verts = np.empty((total_v, 4), np.uint32)
    index = np.empty(int(i_first[-1]), np.uint32)
    for k, i in enumerate(order):
        m = meshes[i]
        s, e = int(v_first[k]), int(v_first[k] + nv[k])
        verts[s:e, :3] = np.ascontiguousarray(m.positions, np.float32).view(np.uint32)
        verts[s:e, 3] = k + 1  # 0 is the clear value: "nothing here"
        index[i_first[k] : i_first[k + 1]] = m.indices.reshape(-1) + np.uint32(s)
    return PackedMeshes(ids[order], lo[order], hi[order], i_first[:-1], i_first[1:], verts, index)
