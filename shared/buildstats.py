"""Measure what rebuilding buildings from parameters costs and saves."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence

from walkstream.shared.buildings import LODS, build_lod
from walkstream.shared.lsystem.grammar import Grammar
from walkstream.shared.records import BuildingParams

__all__ = ["building_stats"]


def building_stats(
    buildings: Sequence[BuildingParams],
    encode: Callable[[BuildingParams], bytes],
    grammar: Grammar | None = None,
    *,
    skipped: int = 0,
    progress: Callable[[int], None] | None = None,
) -> dict[str, object]:
    """Rebuild every building at every LOD, timing each LOD on this one core.

    Parameters
    ----------
    buildings: the buildings to rebuild.
    encode: the wire encoding of one building's parameters (its length is counted).
    grammar: the building grammar (the built-in one by default).
    skipped: input features that did not become buildings (reported as given).
    progress: called with the number of buildings just done, for a progress bar.

    Returns
    -------
    dict with ``buildings``, ``skipped``, ``triangles`` (per LOD, summed),
    ``rebuild_per_s`` (per LOD, buildings per second, derivation included),
    ``param_bytes``, ``lod2_bytes`` (float32 positions and normals, uint32 indices),
    ``ratio`` (param_bytes / lod2_bytes).
    """
    triangles = [0, 0, 0]
    seconds = [0.0, 0.0, 0.0]
    lod2_bytes = 0
    param_bytes = 0
    for b in buildings:
        param_bytes += len(encode(b))
        for lod in LODS:
            t0 = time.perf_counter()
            m = build_lod(b, lod, grammar)
            seconds[lod] += time.perf_counter() - t0
            triangles[lod] += m.triangles
            if lod == 2:
                lod2_bytes += m.gpu_bytes
        if progress is not None:
            progress(1)
    n = len(buildings)
    return {
        "buildings": n,
        "skipped": int(skipped),
        "triangles": triangles,
        "rebuild_per_s": [round(n / s, 1) if s > 0 else 0.0 for s in seconds],
        "param_bytes": param_bytes,
        "lod2_bytes": lod2_bytes,
        "ratio": param_bytes / lod2_bytes if lod2_bytes else 0.0,
    }

