"""An object's geometry per LOD, and how a batch of objects is rebuilt from parameters.

:func:`rebuild_batch` is the job every rewrite worker runs, in the frame loop's process
(:mod:`walkstream.client.rewrite.pool`) or in a worker process
(:mod:`walkstream.client.rewrite.procpool`); :class:`ObjectGeometry` is what it hands
back, and what the cache holds and the renderer draws.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from walkstream.shared.areas import build_flat
from walkstream.shared.buildings import build_lods, build_lods_batch
from walkstream.shared.lsystem.grammar import Grammar
from walkstream.shared.records import AreaParams, BuildingParams, Mesh, StreetParams, readonly

__all__ = ["ObjectGeometry", "geometry_of", "rebuild", "rebuild_batch"]


@dataclass(frozen=True)
class ObjectGeometry:
    """An object's rebuilt (or downloaded) geometry per LOD, with what the renderer needs."""

    id: int
    meshes: tuple[Mesh | None, Mesh | None, Mesh | None]
    triangles: NDArray[np.int64]
    """(3,) triangles per LOD; 0 where the LOD is missing."""
    available: NDArray[np.bool_]
    """(3,) whether each LOD is there."""
    bbox_min: NDArray[np.float64]
    bbox_max: NDArray[np.float64]
    nbytes: int
    """Memory the meshes take (what the cache counts)."""
    cpu_s: float = 0.0

    def __post_init__(self) -> None:
        # the cache hands this record to every frame: nothing in it may change
        for name in ("triangles", "available", "bbox_min", "bbox_max"):
            object.__setattr__(self, name, readonly(np.asarray(getattr(self, name))))


def geometry_of(
    oid: int, meshes: tuple[Mesh | None, Mesh | None, Mesh | None], cpu_s: float = 0.0
) -> ObjectGeometry:
    """Wrap meshes (``None`` for a missing LOD) with triangle counts, bounds and size."""
    tri = np.array([0 if m is None else m.triangles for m in meshes], dtype=np.int64)
    avail = np.array([m is not None for m in meshes], dtype=bool)
    present = [m for m in meshes if m is not None and len(m.positions)]
    if present:
        pos = np.concatenate([m.positions for m in present])
        lo, hi = pos.min(axis=0).astype(np.float64), pos.max(axis=0).astype(np.float64)
    else:
        lo = hi = np.zeros(3)
    # a street shares one mesh across LODs: count it once
    nbytes = sum(m.gpu_bytes for m in {id(m): m for m in meshes if m is not None}.values())
    return ObjectGeometry(oid, meshes, tri, avail, lo, hi, int(nbytes), cpu_s)


def rebuild(oid: int, params: BuildingParams | StreetParams | AreaParams, grammar: Grammar) -> ObjectGeometry:
    """The three LODs of one object, timed in CPU seconds of this thread."""
    t0 = time.thread_time()
    if not isinstance(params, BuildingParams):
        m = build_flat(params)
        meshes: tuple[Mesh | None, Mesh | None, Mesh | None] = (m, m, m)
    else:
        meshes = build_lods(params, grammar)
    return geometry_of(oid, meshes, time.thread_time() - t0)


def rebuild_batch(
    jobs: Sequence[tuple[int, BuildingParams | StreetParams | AreaParams]], grammar: Grammar
) -> list[ObjectGeometry]:
    """The three LODs of several objects, buildings in one batched call; same order as ``jobs``.

    Each object is charged an equal share of the CPU seconds (of this thread) the whole
    call took.
    """
    t0 = time.thread_time()
    buildings = [(k, p) for k, (_, p) in enumerate(jobs) if isinstance(p, BuildingParams)]
    meshes: list[tuple[Mesh | None, Mesh | None, Mesh | None]] = [(None, None, None)] * len(jobs)
    for (k, _), lods in zip(buildings, build_lods_batch([p for _, p in buildings], grammar), strict=True):
        meshes[k] = lods
    for k, (_, p) in enumerate(jobs):
        if not isinstance(p, BuildingParams):
            m = build_flat(p)
            meshes[k] = (m, m, m)
    geoms = [geometry_of(oid, ms) for (oid, _), ms in zip(jobs, meshes, strict=True)]
    share = (time.thread_time() - t0) / max(1, len(jobs))
    return [replace(g, cpu_s=share) for g in geoms]
