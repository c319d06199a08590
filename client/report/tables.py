"""Headline figures of a replay as text: labelled rows, aligned lines, a comparison table."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    pass

__all__ = ["headline_rows", "format_headline", "format_comparison_table", "HEADLINE"]


# --------------------------------------------------------------------------- headline


def _ratio(v: Any) -> str:
    return f"{100.0 * v:.2f} %"


def _fmt_bytes(v: Any) -> str:
    return f"{int(v):,} B ({v / 1000.0:,.1f} kB)"


# (key, label, formatter): what the page and the CLI show first, when present.
HEADLINE: tuple[tuple[str, str, Callable[[Any], str]], ...] = (
    ("frames", "frames", lambda v: f"{int(v):,}"),
    ("duration_s", "duration", lambda v: f"{v:.1f} s"),
    ("path", "path", str),
    ("stream", "stream", str),
    ("prefetch", "prefetch", lambda v: "yes" if v else "no"),
    ("device", "device", str),
    ("bandwidth_bps", "bandwidth", lambda v: f"{v / 1000.0:g} kbit/s"),
    ("rtt_s", "round trip", lambda v: f"{1000.0 * v:.0f} ms"),
    ("bytes_received", "bytes received", _fmt_bytes),
    ("overfetch_ratio", "overfetch ratio", lambda v: f"{v:.3f}"),
    ("link_utilisation", "link utilisation", _ratio),
    ("link_utilisation_busy", "link utilisation, requests in flight", _ratio),
    ("redownloads", "re-downloads", lambda v: f"{int(v):,}"),
    ("rebuilds", "rebuilds", lambda v: f"{int(v):,}"),
    ("time_to_first_perfect_frame_s", "first perfect frame after", lambda v: f"{v:.2f} s"),
    ("perfect_frame_ratio", "perfect frames (from the first)", _ratio),
    ("download_quality_mean", "download quality, mean", lambda v: f"{v:.2f} %"),
    ("rewrite_quality_mean", "rewrite quality, mean", lambda v: f"{v:.2f} %"),
    ("fps_target", "target frame rate", lambda v: f"{v:g} fps"),
    ("fps_mean", "frame rate, mean", lambda v: f"{v:.1f} fps"),
    ("fps_within_10pct_ratio", "frames within 10 % of target", _ratio),
    ("floor_limited_ratio", "floor-limited frames", _ratio),
    ("budget_median", "polygon budget, median", lambda v: f"{v:,.0f} triangles"),
    ("triangles_mean", "triangles drawn, mean", lambda v: f"{v:,.0f}"),
    (
        "frame_phases_median_ms",
        "frame loop, median ms per phase",
        lambda v: ", ".join(f"{k} {float(x):.2f}" for k, x in v.items()),
    ),
    ("frame_period_median_ms", "frame period (start to start), median", lambda v: f"{v:.2f} ms"),
    ("frame_period_within_10pct_ratio", "frame periods within 10 % of target", _ratio),
    ("recovery_frames", "recovery after cost step", lambda v: f"{int(v)} frames"),
    ("rewrite", "rebuilds ran", lambda v: _rewrite_path(v)),
)
"""The headline rows of a report: ``(label, summary key, format)``."""


def _rewrite_path(d: Mapping[str, Any]) -> str:
    """Which path the real clock's rebuilds took (``summary["rewrite"]``), in words."""
    if d.get("mode") != "process":
        out = f"{d.get('mode')}: {d.get('batches', 0)} batches"
    else:
        ready = d.get("workers_ready_s")
        out = (
            f"process: {d.get('shm_batches', 0)} batches through shared memory "
            f"(bound {d.get('shm_bytes', 0) / 2**20:.0f} MB, peak "
            f"{d.get('shm_peak_bytes', 0) / 2**20:.1f} MB), {d.get('pipe_batches', 0)} through "
            f"the pipe, {d.get('thread_batches', 0)} in threads; workers ready after "
            + ("n/a" if ready is None else f"{ready:.2f} s")
        )
        if d.get("shm_error"):
            out += f" ({d['shm_error']})"
    return out + f"; {d.get('dropped_jobs', 0)} queued jobs dropped"


def headline_rows(summary: Mapping[str, Any]) -> list[tuple[str, str, str]]:
    """``(key, label, formatted value)`` of the headline figures present in ``summary``.

    A key that is present with value ``None`` shows as ``"n/a"``.
    """
    rows = []
    for key, label, fmt in HEADLINE:
        if key not in summary:
            continue
        v = summary[key]
        if isinstance(v, float) and not math.isfinite(v):
            v = None
        rows.append((key, label, "n/a" if v is None else fmt(v)))
    return rows


def format_headline(summary: Mapping[str, Any]) -> str:
    """The figures a person looks at first, on five lines (what the CLI prints after a replay)."""

    def pct(key: str) -> str:
        v = summary.get(key)
        return "n/a" if v is None else f"{v:.1f} %"

    def ratio(key: str) -> str:
        v = summary.get(key)
        return "n/a" if v is None else f"{100 * v:.1f} %"

    first = summary.get("time_to_first_perfect_frame_s")
    return "\n".join(
        [
            f"frames {summary.get('frames', 0)}, perfect {ratio('perfect_frame_ratio')}, "
            f"first perfect frame at {'never' if first is None else f'{first:.2f} s'}",
            f"download quality {pct('download_quality_mean')}, rewrite quality "
            f"{pct('rewrite_quality_mean')}",
            f"bytes received {summary.get('bytes_received') or 0:,}, overfetch "
            f"{ratio('overfetch_ratio')}, re-downloads {summary.get('redownloads', 0)}, rebuilds "
            f"{summary.get('rebuilds', 0)}",
            f"link utilisation {ratio('link_utilisation')} ({ratio('link_utilisation_busy')} "
            "while requests were in flight)",
            f"fps mean {summary.get('fps_mean') or 0:.1f} (target {summary.get('fps_target', 0):g}), "
            f"within 10 % {ratio('fps_within_10pct_ratio')}, floor-limited "
            f"{ratio('floor_limited_ratio')}",
        ]
        + _phases_line(summary)
        + ([f"rebuilds ran in {_rewrite_path(summary['rewrite'])}"] if "rewrite" in summary else [])
    )


def _phases_line(summary: Mapping[str, Any]) -> list[str]:
    """The frame loop's median ms per phase (real-clock runs), or nothing."""
    ph = summary.get("frame_phases_median_ms")
    if not ph:
        return []
    parts = ", ".join(f"{k} {float(v):.2f}" for k, v in ph.items())
    period = summary.get("frame_period_median_ms")
    return [
        f"frame loop, median ms: {parts}; period {period or 0:.2f} ms, "
        f"{100 * (summary.get('frame_period_within_10pct_ratio') or 0):.1f} % within 10 %"
    ]


def format_comparison_table(runs: Sequence[tuple[str, Mapping[str, Any]]]) -> str:
    """A plain-text table: one row per headline figure, one column per run."""
    keys = [k for k, _, _ in HEADLINE if any(k in s for _, s in runs)]
    labels = {k: label for k, label, _ in HEADLINE}
    cells = []
    for _, s in runs:
        values = {k: v for k, _, v in headline_rows(s)}
        cells.append([values.get(k, "") for k in keys])
    header = ["", *[label for label, _ in runs]]
    table = [header] + [[labels[k], *[c[i] for c in cells]] for i, k in enumerate(keys)]
    widths = [max(len(row[j]) for row in table) for j in range(len(header))]
    lines = []
    for r, row in enumerate(table):
        lines.append(
            "  ".join(
                (cell.ljust(widths[j]) if j == 0 else cell.rjust(widths[j]))
                for j, cell in enumerate(row)
            ).rstrip()
        )
        if r == 0:
            lines.append("  ".join("-" * w for w in widths))
    return "\n".join(lines)
