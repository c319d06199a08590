"""What rebuilding buildings from parameters costs and saves: ``walkstream bench rebuild``.

:func:`building_stats` rebuilds every building of a scene at every LOD on one core,
one building per call, timing each LOD, and counts the parameter bytes against the
LOD2 geometry bytes; ``walkstream buildings stats`` and the demo print it for one run.
:func:`rebuild_run` adds, in the same run, the batched path
(:func:`~walkstream.shared.buildings.build_lod_batch`, many buildings per call) at
some batch sizes and :func:`trimesh.creation.extrude_polygon` per footprint (what a
plain LOD0 prism costs elsewhere); :func:`rebuild_table` summarises several runs
(medians, and ratios of the medians) for ``walkstream bench rebuild``.
:func:`beside_loop` (``--beside-loop``) rebuilds a whole scene with the client's rewrite
pool in threads or in worker processes while a frame-loop stand-in runs at 60 Hz on the
same event loop, timing the stand-in: what rebuilding does to the frame loop.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from walkstream.shared.buildings import LODS, build_lod, build_lod_batch
from walkstream.shared.codec import encode_building
from walkstream.shared.lsystem.grammar import Grammar
from walkstream.shared.records import BuildingParams

__all__ = [
    "REBUILD_GOALS",
    "BATCH_GOALS",
    "EXTRUDE_GOAL",
    "building_stats",
    "batched_rates",
    "extrude_rate",
    "rebuild_run",
    "rebuild_table",
    "beside_loop",
    "beside_loop_table",
]

REBUILD_GOALS: tuple[int | None, int | None, int | None] = (2000, None, 200)
"""Buildings per second per LOD to reach (issue 2), on one core, derivation included."""

BATCH_GOALS: tuple[float | None, float | None, float | None] = (5.0, None, 3.0)
"""Batched over one-by-one throughput per LOD to reach (issue 15), in the same run."""

EXTRUDE_GOAL = 5.0
"""Batched LOD0 over ``trimesh.creation.extrude_polygon`` per footprint (issue 15)."""


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



def batched_rates(
    buildings: Sequence[BuildingParams],
    batch: int,
    grammar: Grammar | None = None,
    *,
    progress: Callable[[int], None] | None = None,
) -> list[float]:
    """Buildings per second per LOD through :func:`build_lod_batch`, ``batch`` buildings per call."""
    if batch < 1:
        raise ValueError(f"batch: expected >= 1, got {batch}")
    rates = []
    n = len(buildings)
    for lod in LODS:
        t0 = time.perf_counter()
        for i in range(0, n, batch):
            build_lod_batch(buildings[i : i + batch], lod, grammar)
            if progress is not None and lod == LODS[-1]:
                progress(min(batch, n - i))
        dt = time.perf_counter() - t0
        rates.append(round(n / dt, 1) if dt > 0 else 0.0)
    return rates


def extrude_rate(buildings: Sequence[BuildingParams]) -> float:
    """Footprints per second through ``trimesh.creation.extrude_polygon`` (a closed prism of the
    building's height, like LOD0; the shapely polygons are made before the clock starts)."""
    import trimesh
    from shapely.geometry import Polygon

    polys = [(Polygon(b.rings[0], b.rings[1:]), b.height) for b in buildings]
    t0 = time.perf_counter()
    for poly, h in polys:
        trimesh.creation.extrude_polygon(poly, h)
    dt = time.perf_counter() - t0
    return round(len(polys) / dt, 1) if dt > 0 else 0.0


def rebuild_run(
    buildings: Sequence[BuildingParams],
    batches: Sequence[int],
    grammar: Grammar | None = None,
    *,
    progress: Callable[[int], None] | None = None,
) -> dict[str, Any]:
    """One run of everything ``walkstream bench rebuild`` compares, one after the other.

    Returns
    -------
    :func:`building_stats`'s dict, plus ``batched`` (batch size -> buildings per second
    per LOD) and ``extrude_per_s`` (footprints per second through trimesh).
    """
    stats = building_stats(buildings, grammar, progress=progress)
    stats["batched"] = {int(b): batched_rates(buildings, b, grammar) for b in batches}
    stats["extrude_per_s"] = extrude_rate(buildings)
    return stats


def rebuild_table(runs: Sequence[dict[str, Any]], source: str) -> str:
    """Several runs of :func:`building_stats` (or :func:`rebuild_run`) on one scene.

    Median, min and max per LOD and path; ``x one-by-one`` is the batched median over
    the one-by-one median of the same runs.
    """
    med = statistics.median
    first = runs[0]
    n = first["buildings"]
    lines = [
        f"rebuild benchmark: {source} ({n} buildings, {len(runs)} runs, one core; all rows in the same runs)",
        f"{'path':<26}{'LOD':<6}{'median b/s':>12}{'min':>10}{'max':>10}{'x one-by-one':>14}"
        f"{'triangles':>14}{'goal':>10}",
    ]
    single = [med(float(r["rebuild_per_s"][lod]) for r in runs) for lod in LODS]

    def row(path: str, lod: int, rates: list[float], ratio: str, goal: str) -> str:
        return (
            f"{path:<26}LOD{lod:<3}{med(rates):>12,.0f}{min(rates):>10,.0f}{max(rates):>10,.0f}{ratio:>14}"
            f"{first['triangles'][lod]:>14,}{goal:>10}"
        )

    for lod in LODS:
        goal = REBUILD_GOALS[lod]
        lines.append(row("one by one", lod, [float(r["rebuild_per_s"][lod]) for r in runs], "1.0x", f"{goal} b/s" if goal else "-"))
    batches = sorted(first.get("batched", {}))
    for b in batches:
        label = f"batch {b}" if b < n else f"batch {b} (all)"
        for lod in LODS:
            rates = [float(r["batched"][b][lod]) for r in runs]
            ratio = med(rates) / single[lod] if single[lod] else 0.0
            times = BATCH_GOALS[lod]
            lines.append(row(label, lod, rates, f"{ratio:.1f}x", f">= {times:g}x" if times else "-"))
    if "extrude_per_s" in first:
        ext = [float(r["extrude_per_s"]) for r in runs]
        lines.append(
            f"{'trimesh extrude_polygon':<26}{'LOD0':<6}{med(ext):>12,.0f}{min(ext):>10,.0f}{max(ext):>10,.0f}"
            f"{med(ext) / single[0] if single[0] else 0.0:>13.1f}x{'':>14}{'-':>10}"
        )
        for b in batches:
            ratio = med(float(r["batched"][b][0]) for r in runs) / med(ext) if med(ext) else 0.0
            lines.append(f"LOD0 batch {b} vs trimesh extrude_polygon: {ratio:.1f}x (goal >= {EXTRUDE_GOAL:g}x)")
    ratio = float(first["ratio"])
    lines.append(
        f"parameters {first['param_bytes']:,} B, LOD2 geometry {first['lod2_bytes']:,} B, "
        f"ratio {100 * ratio:.4f} % (goal <= 0.1 %)"
    )
    return "\n".join(lines)


def _loop_work(centres: NDArray[np.float64], eye: NDArray[np.float64]) -> int:
    """A stand-in for one pass of the frame loop's Python (about 1-2 ms alone): a numpy
    distance sort over the objects, then per-object interpreter work on each."""
    d = np.linalg.norm(centres - eye, axis=1)
    total = 0
    for k in np.argsort(d).tolist():
        total += (k * 31 + 7) % 13
    return total


def beside_loop(
    buildings: Sequence[BuildingParams],
    mode: str,
    workers: int,
    hz: float = 60.0,
    shm_bytes: int = 16 << 20,
    passes: int = 3,
) -> dict[str, Any]:
    """Rebuild every building (three LODs) ``passes`` times with the client's rewrite pool
    under the real clock while a frame-loop stand-in runs at ``hz`` on the same event loop.

    ``mode`` is ``"none"`` (the loop alone, no rebuilding), ``"thread"`` or
    ``"process"``; worker processes are started (and ready) before the clock starts.

    Returns
    -------
    dict
        ``mode``, ``workers``, ``rebuild_s`` (wall seconds to rebuild all), ``per_s``
        (buildings per second), ``loop_ms`` and ``loop_p95_ms`` (median and 95th
        percentile of the stand-in's wall time per pass while rebuilding).
    """
    import asyncio

    from walkstream.client.clock import RealClock
    from walkstream.client.rewrite.pool import RewriteOptions, RewritePool
    from walkstream.shared.buildings import default_grammar

    # a fixed stand-in, whatever the scene: 8,000 objects
    centres = np.random.default_rng(0).random((8000, 2)) * 700.0
    eye = np.array([350.0, 350.0])
    n = len(buildings) * passes
    built = [0]
    pool = RewritePool(
        RealClock(), None, lambda g: built.__setitem__(0, built[0] + 1), workers=workers,
        options=RewriteOptions("thread" if mode == "none" else mode, shm_bytes),
    )  # fmt: skip
    times: list[float] = []

    async def main() -> float:
        pool.start()
        try:
            if pool._procs is not None:
                await pool._procs.wait_ready()
            t0 = time.perf_counter()
            if mode != "none":
                for k in range(n):
                    pool.submit(k, buildings[k % len(buildings)], (float(k), 0.0))
                pool.set_grammar(default_grammar())
            while (built[0] < n if mode != "none" else time.perf_counter() - t0 < 2.0):
                t = time.perf_counter()
                _loop_work(centres, eye)
                times.append(time.perf_counter() - t)
                await asyncio.sleep(max(0.0, 1.0 / hz - (time.perf_counter() - t)))
            return time.perf_counter() - t0
        finally:
            await pool.close()

    wall = asyncio.run(main())
    ms = np.asarray(times) * 1e3
    return {
        "mode": mode,
        "workers": workers,
        "rebuild_s": wall if mode != "none" else None,
        "per_s": n / wall if mode != "none" else None,
        "loop_ms": float(np.median(ms)),
        "loop_p95_ms": float(np.percentile(ms, 95)),
    }


def beside_loop_table(runs: Sequence[dict[str, Any]], buildings: int) -> str:
    """Medians per (mode, workers) of several :func:`beside_loop` runs."""
    med = statistics.median
    keys = list(dict.fromkeys((r["mode"], r["workers"]) for r in runs))
    lines = [
        f"rebuilding {buildings} buildings (3 LODs) 3 times beside a 60 Hz frame-loop stand-in "
        "(8,000 objects sorted and visited), real clock, medians of the runs (interleaved); "
        "loop: wall ms per pass of the stand-in while rebuilding",
        f"{'rebuild in':<12}{'workers':>8}{'rebuild s':>11}{'b/s':>8}{'loop ms':>9}{'loop p95':>10}",
    ]
    for mode, w in keys:
        rs = [r for r in runs if (r["mode"], r["workers"]) == (mode, w)]
        reb = [r["rebuild_s"] for r in rs if r["rebuild_s"] is not None]
        rate = [r["per_s"] for r in rs if r["per_s"] is not None]
        lines.append(
            f"{mode:<12}{w:>8}{(f'{med(reb):.2f}' if reb else '-'):>11}"
            f"{(f'{med(rate):,.0f}' if rate else '-'):>8}{med(r['loop_ms'] for r in rs):>9.2f}"
            f"{med(r['loop_p95_ms'] for r in rs):>10.2f}"
        )
    return "\n".join(lines)
