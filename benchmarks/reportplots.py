"""A replay report's plots: axes placed by fixed margins against measured by ``tight_layout``.

Every replay report (and every row of a ``walkstream bench`` that writes one) draws its
plots with :mod:`walkstream.client.report.plots`.  :func:`run_plots_bench` reads a report
folder back and writes its bytes, quality, frame-rate and budget plots both ways, the
two alternating, ``repeat`` times each: CPU seconds per plot, the median of each way.
Run it as ``python -m walkstream.benchmarks.reportplots REPORT_DIR [REPEAT]``.
"""

from __future__ import annotations

import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

__all__ = ["format_plots_table", "run_plots_bench"]


def run_plots_bench(report_dir: str | Path, repeat: int = 5) -> list[dict[str, Any]]:
    """One row per plot: its median CPU seconds measured and by fixed margins, their ratio."""
    from walkstream.client.report import plots
    from walkstream.client.report.files import load_run

    summary, frames, bytes_log = load_run(report_dir)
    run = plots.make_run("report", summary, frames, bytes_log, 0)
    drawers = {
        "bytes": plots.plot_bytes,
        "quality": plots.plot_quality,
        "fps": plots.plot_fps,
        "budget": plots.plot_budget,
    }
    times: dict[tuple[str, bool], list[float]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        try:
            for _ in range(repeat):
                for name, draw in drawers.items():
                    for measured in (True, False):
                        plots.MEASURED_LAYOUT = measured
                        t = time.process_time()
                        draw(Path(tmp) / f"{name}.png", [run], "bench")
                        times.setdefault((name, measured), []).append(time.process_time() - t)
        finally:
            plots.MEASURED_LAYOUT = False
    rows = []
    for name in drawers:
        m, g = statistics.median(times[name, True]), statistics.median(times[name, False])
        rows.append({"plot": name, "measured_s": m, "margins_s": g, "ratio": m / g if g > 0 else float("inf")})
    return rows


def format_plots_table(rows: list[dict[str, Any]]) -> str:
    """The rows of :func:`run_plots_bench` as a text table, with the total."""
    head = f"{'plot':<8} {'tight_layout s':>14} {'fixed margins s':>15} {'ratio':>6}"
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(f"{r['plot']:<8} {r['measured_s']:>14.3f} {r['margins_s']:>15.3f} {r['ratio']:>5.2f}x")
    m, g = sum(r["measured_s"] for r in rows), sum(r["margins_s"] for r in rows)
    lines.append(f"{'all':<8} {m:>14.3f} {g:>15.3f} {m / g if g > 0 else float('inf'):>5.2f}x")
    return "\n".join(lines)


if __name__ == "__main__":
    if not sys.argv[1:]:
        sys.exit("usage: python -m walkstream.benchmarks.reportplots REPORT_DIR [REPEAT]")
    print(format_plots_table(run_plots_bench(sys.argv[1], int(sys.argv[2]) if sys.argv[2:] else 5)))
