"""Frame rate and polygon budget per device and target: ``walkstream bench budget``.

Each row replays the recorded ``SE`` walk through the whole client on the simulated
clock over a fast link (the budget, not the link, is measured) on one device at one
target frame rate; on the simulated devices the per-triangle cost steps tenfold at
``step_at`` seconds of the walk.  The figures (within 10 %, floor-limited share,
recovery after the step, the worst slowdown after it, budget statistics) are those of
``report.json`` (:mod:`walkstream.client.report.metrics`, one definition for every
report and benchmark).  The ``gl`` rows draw for real.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

from walkstream.benchmarks.stream import Replayer

__all__ = ["BUDGET_GOAL", "budget_cases", "run_budget_bench", "format_budget_table"]

BUDGET_GOAL = "within >= 95 %, recover <= 8 frames, never > 20 % slow"
"""The figures to reach on the simulated devices (issue 6)."""


def budget_cases(gl: bool = True) -> list[tuple[str, float, str]]:
    """``(device, target fps, goal)`` of every row."""
    cases = [
        ("desktop2003", 25.0, BUDGET_GOAL),
        ("desktop2003", 40.0, "(reported)"),
        ("pda", 10.0, BUDGET_GOAL),
    ]
    if gl:
        cases += [("gl", t, "(reported)") for t in (25.0, 40.0, 100.0)]
    return cases


def run_budget_bench(
    db: str,
    replay: Replayer,
    *,
    out: Path,
    duration: str = "180s",
    gl_duration: str = "20s",
    step_at: float = 60.0,
    gl: bool = True,
    seed: int = 0,
) -> list[dict[str, Any]]:
    """One replay per row of :func:`budget_cases`; rows also go to ``bench_budget.json``."""
    cases = budget_cases(gl)
    rows = []
    for k, (device, target, goal) in enumerate(cases, 1):
        options: dict[str, Any] = {
            "device": device,
            "fps": target,
            "bandwidth": "1Mbit",  # the budget, not the link, is measured here
            "rtt": "50ms",
            "seed": seed,
            "duration": gl_duration if device == "gl" else duration,
            "report": str(out / f"{k:02d}-{device}-{target:g}fps"),
        }
        if device != "gl":
            options["cost_step_at_s"] = step_at
        print(f"[{k}/{len(cases)}] {device} at {target:g} fps ...", file=sys.stderr, flush=True)
        result = replay(db, options, f"budget {device} {target:g} fps")
        s = result.summary
        rec, worst = s.get("recovery_frames"), s.get("recovery_worst_slowdown_after")
        rows.append({"device": device, "target": target, "goal": goal, "recover": rec, "worst": worst, **s})
    out.mkdir(parents=True, exist_ok=True)
    (out / "bench_budget.json").write_text(json.dumps(rows, indent=2, default=str))
    return rows


def format_budget_table(rows: list[dict[str, Any]]) -> str:
    """One line per device and target."""
    head = (
        f"{'device':<12} {'target':>6} {'fps mean':>8} {'within10%':>9} {'floor%':>7} "
        f"{'recover':>7} {'worst':>6} {'budget med':>10} {'min':>7} {'max':>8}  goal"
    )
    lines = [head, "-" * len(head)]
    for r in rows:
        within = r.get("fps_within_10pct_ratio")
        worst = r.get("worst")
        lines.append(
            f"{r['device']:<12} {r['target']:>6g} {r.get('fps_mean') or 0:>8.1f} "
            f"{'n/a' if within is None else f'{100 * within:.1f}':>9} "
            f"{100 * (r.get('floor_limited_ratio') or 0):>7.1f} "
            f"{'-' if r['recover'] is None else r['recover']:>7} "
            f"{'-' if worst is None else f'{100 * worst:.0f}%':>6} "
            f"{r.get('budget_median') or 0:>10,.0f} {r.get('budget_min') or 0:>7,.0f} "
            f"{r.get('budget_max') or 0:>8,.0f}  {r['goal']}"
        )
    return "\n".join(lines)
