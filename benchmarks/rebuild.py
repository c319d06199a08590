"""What rebuilding buildings from parameters costs and saves: ``walkstream bench rebuild``.

:func:`building_stats` rebuilds every building of a scene at every LOD on one core,
timing each LOD, and counts the parameter bytes against the LOD2 geometry bytes;
``walkstream buildings stats`` and the demo print it for one run, :func:`rebuild_table`
summarises several runs (medians) for the benchmark.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable, Sequence
from typing import Any

from walkstream.shared.buildings import LODS, build_lod
from walkstream.shared.codec import encode_building
from walkstream.shared.lsystem.grammar import Grammar
from walkstream.shared.records import BuildingParams

__all__ = ["REBUILD_GOALS", "building_stats", "rebuild_table"]

REBUILD_GOALS: tuple[int | None, int | None, int | None] = (2000, None, 200)
"""Buildings per second per LOD to reach (issue 2), on one core, derivation included."""


def building_stats(
    buildings: Sequence[BuildingParams],
    grammar: Grammar | None = None,
    *,
    skipped: int = 0,
    progress: Callable[[int], None] | None = None,
) -> dict[str, Any]:
    """Rebuild every building at every LOD, timing each LOD on this one core.

    Parameters
    ----------
    buildings: the buildings to rebuild.
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
        param_bytes += len(encode_building(b))
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



def rebuild_table(runs: Sequence[dict[str, Any]], source: str) -> str:
    """Several runs of :func:`building_stats` on one scene: median, min and max per LOD."""
    first = runs[0]
    lines = [
        f"rebuild benchmark: {source} ({first['buildings']} buildings, {len(runs)} runs, one core)",
        f"{'LOD':<6}{'median b/s':>12}{'min':>10}{'max':>10}{'triangles':>14}{'goal b/s':>10}",
    ]
    for lod in LODS:
        rates = [float(r["rebuild_per_s"][lod]) for r in runs]
        goal = REBUILD_GOALS[lod]
        lines.append(
            f"LOD{lod:<3}{statistics.median(rates):>12,.0f}{min(rates):>10,.0f}{max(rates):>10,.0f}"
            f"{first['triangles'][lod]:>14,}{goal if goal else '-':>10}"
        )
    ratio = float(first["ratio"])
    lines.append(
        f"parameters {first['param_bytes']:,} B, LOD2 geometry {first['lod2_bytes']:,} B, "
        f"ratio {100 * ratio:.4f} % (goal <= 0.1 %)"
    )
    return "\n".join(lines)
