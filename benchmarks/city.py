"""Real cities, street cells against grid cells: ``walkstream bench city``.

For each OpenStreetMap extract of ``../shared/data/osm/`` (Kouvola, West Oakland, the
village) the bench bakes two databases, one with street cells and one with grid cells
(same source, same settings otherwise; ``kinds`` adds sections, :mod:`.sections`), and replays one walk in both at 56 kbit/s,
200 ms round trip, under the simulated clock: the recorded ``SE`` of the street
database on Kouvola; on the small extracts, whose networks are too small for a
three-minute walk, the longest walk that does not repeat itself
(:func:`~walkstream.server.bake.walks.longest_walk`).  The very same walk is written
into both databases (path ``bench``), so bytes per km compare the cells, not the
walks.  Each row gives cells, mean PVS, the share of objects the PVS culls, bake
seconds, database bytes, perfect frames, the first perfect frame and bytes per km.
A replay is run by the ``replay`` callable the command line hands in.
"""

from __future__ import annotations

import json
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

from walkstream.server.bake import BakeSettings, bake
from walkstream.server.bake.walks import SE_SPEED_KMH, longest_walk
from walkstream.server.store import SceneReader, write_path
from walkstream.shared.errors import WalkstreamError
from walkstream.shared.paths import RecordedPath

__all__ = ["EXTRACTS", "KINDS", "run_city_bench", "format_city_table"]

Replayer = Callable[[str, Mapping[str, Any], str], Any]

#: The extracts: (label, file in the data folder, which walk is replayed).
EXTRACTS: tuple[tuple[str, str, str], ...] = (
    ("kouvola", "kouvola.osm.pbf", "SE"),
    ("west-oakland", "west-oakland.osm", "longest"),
    ("village", "village-10.068_48.135.osm", "longest"),
)
_BENCH_PATH = "bench"


#: the cell kinds a row can bake (``--kinds``): street cells always (their walk is replayed)
KINDS = ("street", "grid", "sections")


def _bake(src: Path, db: Path, cells: str, reuse: bool, workers: int) -> dict[str, Any]:
    if reuse and db.exists():
        reader = SceneReader.open(db)
        try:
            return reader.summary()
        finally:
            reader.close()
    print(f"  baking {db.name} ({cells} cells) ...", file=sys.stderr, flush=True)
    t0 = time.perf_counter()
    summary = bake(src, db, settings=BakeSettings(cells=cells), workers=workers)
    summary["bake_seconds"] = time.perf_counter() - t0
    return summary


def _walk(street_db: Path, which: str) -> RecordedPath:
    reader = SceneReader.open(street_db)
    try:
        if which == "SE":
            return RecordedPath.from_msgpack(reader.path_blob("SE"), f"{street_db}: SE")
        path = longest_walk(reader.cells(), SE_SPEED_KMH, _BENCH_PATH)
    finally:
        reader.close()
    if path is None:
        raise WalkstreamError(f"{street_db}: no walk of two cells or more in its street cells")
    return path


def run_city_bench(
    replay: Replayer,
    *,
    data: Path,
    out: Path,
    only: Sequence[str] = (),
    reuse: bool = False,
    workers: int = 1,
    truth_every: int = 0,
    kinds: Sequence[str] = ("street", "grid"),
) -> list[dict[str, Any]]:
    """Bake and replay every extract (those whose label contains one of ``only``).

    ``kinds`` are the cell kinds baked and replayed (:data:`KINDS`; street cells are
    always baked: the walk is theirs); ``sections`` bakes sections with their defaults
    (the dense field is kept beside the database, ``--reuse`` reuses it too).

    Returns one row per extract and cell kind; writes ``bench_city.json`` and the
    replay reports into ``out``.  With ``truth_every`` each replay compares every Nth
    frame with the ground truth, and the rows gain what its frames show below the
    horizon (:mod:`walkstream.client.truth.horizon`): the largest share in the sky's
    colour and the mean share with no object.
    """
    bad = [k for k in kinds if k not in KINDS]
    if bad or not kinds:
        raise WalkstreamError(f"--kinds: expected some of {', '.join(KINDS)}, got {', '.join(kinds) or 'none'}")
    kinds = ["street"] + [k for k in KINDS[1:] if k in kinds]
    out.mkdir(parents=True, exist_ok=True)
    rows: list[dict[str, Any]] = []
    for label, file, which in EXTRACTS:
        if only and not any(k.lower() in label for k in only):
            continue
        src = data / file
        if not src.exists():
            raise WalkstreamError(f"{src}: extract not found (see {data / 'README.md'})")
        print(f"{label}:", file=sys.stderr, flush=True)
        dbs = {kind: out / f"{label}-{kind}.db" for kind in kinds}
        summaries = {kind: _bake(src, db, kind, reuse, workers) for kind, db in dbs.items()}
        walk = _walk(dbs["street"], which)
        blob = replace(walk, name=_BENCH_PATH).to_msgpack()
        km = walk.length_m() / 1000.0
        for kind, db in dbs.items():
            write_path(db, _BENCH_PATH, blob)
            options = {
                "path": _BENCH_PATH,
                "bandwidth": "56kbit",
                "rtt": "200ms",
                "clock": "sim",
                "device": "desktop2003",
                "report": str(out / f"{label}-{kind}-report"),
            } | ({"truth_every": truth_every} if truth_every else {})
            print(f"  replaying {which} in {db.name} ...", file=sys.stderr, flush=True)
            result = replay(str(db), options, f"{label} {kind} cells, {which}")
            s = summaries[kind]
            r = result.summary
            rows.append(
                {
                    "extract": label,
                    "cells_kind": kind,
                    "walk": which,
                    "walk_m": walk.length_m(),
                    "walk_s": walk.duration,
                    "cells": s["cells"],
                    "pvs_mean": s["pvs_mean"],
                    "culled_ratio": s["culled_ratio"],
                    "bake_seconds": s["bake_seconds"],
                    "db_bytes": db.stat().st_size,
                    "perfect_frame_ratio": r["perfect_frame_ratio"],
                    "first_perfect_s": r.get("time_to_first_perfect_frame_s"),
                    "bytes_received": r["bytes_received"],
                    "bytes_per_km": r["bytes_received"] / km if km > 0 else None,
                }
                | _below_horizon(r.get("truth"))
            )
    (out / "bench_city.json").write_text(json.dumps(rows, indent=2, default=str))
    return rows


def _below_horizon(truth: Any) -> dict[str, float]:
    """``sky_max`` and ``no_object_mean`` of a replay's truth figures (none without a truth)."""
    below = (truth or {}).get("below_horizon") or {}
    if not below or below["sky"]["max"] is None:
        return {}
    return {"sky_max": below["sky"]["max"], "no_object_mean": below["no_object"]["mean"]}


def format_city_table(rows: list[dict[str, Any]]) -> str:
    """One line per extract and cell kind (with the truth: two more columns, the sky below the horizon)."""
    truth = any("sky_max" in r for r in rows)
    head = (
        f"{'extract':<13} {'cells':<8} {'n cells':>7} {'PVS mean':>8} {'culled%':>7} "
        f"{'bake s':>7} {'db bytes':>10} {'walk':>12} {'perfect%':>8} {'first s':>7} {'bytes/km':>9}"
    ) + (f" {'sky% max':>8} {'no obj%':>7}" if truth else "")
    lines = [head, "-" * len(head)]
    for r in rows:
        first = r["first_perfect_s"]
        walk = f"{r['walk']} {r['walk_m']:.0f}m"
        per_km = "-" if r["bytes_per_km"] is None else f"{r['bytes_per_km']:,.0f}"
        lines.append(
            f"{r['extract']:<13} {r['cells_kind']:<8} {r['cells']:>7,} {r['pvs_mean']:>8.1f} "
            f"{100 * r['culled_ratio']:>7.1f} {r['bake_seconds']:>7.1f} {r['db_bytes']:>10,} "
            f"{walk:>12} {100 * r['perfect_frame_ratio']:>8.2f} "
            f"{'never' if first is None else f'{first:.2f}':>7} "
            f"{per_km:>9}"
            + (
                f" {100 * r['sky_max']:>8.2f} {100 * r['no_object_mean']:>7.1f}"
                if "sky_max" in r
                else (f" {'-':>8} {'-':>7}" if truth else "")
            )
        )
    return "\n".join(lines)
