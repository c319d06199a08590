"""Footprint cleaning of a city: whole-array GEOS checks against one polygon at a time.

Loading a city (``load_geojson``, the bake, ``city_summary``) cleans and checks every
footprint ring (:mod:`walkstream.server.sources.rings`).  :func:`run_ring_bench` times,
on generated cities of the given sizes, :func:`~walkstream.server.sources.rings.clean_and_repair`
called once per polygon (a geometry object and a GEOS call per ring and per check)
against :func:`~walkstream.server.sources.rings.clean_and_repair_all` (one GEOS call per
check over every polygon), both on the same polygons (checked to give the same parts),
and the whole :func:`~walkstream.server.sources.citysummary.city_summary` (generation
excluded).  CPU seconds, the best of ``repeat`` runs.  Run it as
``python -m walkstream.benchmarks.ringrepair [SIZE ...]``.
"""

from __future__ import annotations

import copy
import sys
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

__all__ = ["format_ring_table", "run_ring_bench"]


def _city_polygons(fc: dict[str, Any]) -> list[Any]:
    """The buildings of a generated city as the loader's polygons, in metres from the first vertex."""
    from walkstream.server.sources.features import PolyFeature

    polys = []
    origin = None
    for k, f in enumerate(fc["features"]):
        if (f.get("properties") or {}).get("kind") != "building":
            continue
        rings = [np.asarray(r, np.float64) for r in f["geometry"]["coordinates"]]
        if origin is None:
            origin = rings[0][0].copy()
        polys.append(PolyFeature(k, str(f["id"]), str(f["id"]), False, None, {}, rings, [r - origin for r in rings]))
    return polys


def _best(fn: Callable[[], Any], repeat: int) -> tuple[float, Any]:
    """The least CPU seconds of ``repeat`` calls of ``fn`` and the last call's result."""
    best, out = float("inf"), None
    for _ in range(repeat):
        t = time.process_time()
        out = fn()
        best = min(best, time.process_time() - t)
    return best, out


def run_ring_bench(sizes: Sequence[int] = (700, 2000), repeat: int = 3) -> list[dict[str, Any]]:
    """One row per city size: polygons, the two ways' CPU seconds, their ratio, ``city_summary``'s.

    Raises
    ------
    AssertionError
        The two ways gave different parts or issues (the benchmark compares equals only).
    """
    from walkstream.server.sources.citygen import generate_city
    from walkstream.server.sources.citysummary import city_summary
    from walkstream.server.sources.features import IssueLog
    from walkstream.server.sources.rings import clean_and_repair, clean_and_repair_all

    rows = []
    for size in sizes:
        fc = generate_city(size)
        polys = _city_polygons(fc)

        def one_by_one(polys: list[Any] = polys) -> tuple[list[Any], IssueLog]:
            log, mine = IssueLog(), copy.deepcopy(polys)
            return [clean_and_repair(p, log) for p in mine], log

        def batched(polys: list[Any] = polys) -> tuple[list[Any], IssueLog]:
            log, mine = IssueLog(), copy.deepcopy(polys)
            return clean_and_repair_all(mine, log), log

        t_one, (parts_one, log_one) = _best(one_by_one, repeat)
        t_all, (parts_all, log_all) = _best(batched, repeat)
        assert [[(c.source_id, [r.tobytes() for r in c.rings]) for c in p] for p in parts_one] == [
            [(c.source_id, [r.tobytes() for r in c.rings]) for c in p] for p in parts_all
        ] and log_one.sorted() == log_all.sorted()
        def summary(fc: dict[str, Any] = fc) -> dict[str, Any]:
            return city_summary(fc)

        t_sum, _ = _best(summary, repeat)
        rows.append({"size_m": size, "polygons": len(polys), "one_by_one_s": t_one, "batched_s": t_all,
                     "speedup": t_one / t_all if t_all > 0 else float("inf"), "city_summary_s": t_sum})
    return rows


def format_ring_table(rows: Sequence[dict[str, Any]]) -> str:
    """The rows of :func:`run_ring_bench` as a text table."""
    head = f"{'city m':>6} {'polygons':>8} {'one by one s':>12} {'batched s':>9} {'speedup':>7} {'city_summary s':>14}"
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(
            f"{r['size_m']:>6} {r['polygons']:>8,} {r['one_by_one_s']:>12.3f} {r['batched_s']:>9.3f} "
            f"{r['speedup']:>6.2f}x {r['city_summary_s']:>14.3f}"
        )
    return "\n".join(lines)


if __name__ == "__main__":
    sizes = [int(a) for a in sys.argv[1:]] or [700, 2000]
    print(format_ring_table(run_ring_bench(sizes)))
