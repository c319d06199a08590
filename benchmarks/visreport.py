"""The figures of ``walkstream bench visibility``: its table and its plot."""

from __future__ import annotations

import math
import os
from typing import Any

import numpy as np

from walkstream.benchmarks.vissettings import PREVIOUS, TARGETS, TODAY

__all__ = ["format_table", "plot_visibility_benchmark"]


def _pct(v: float | None, digits: int = 2) -> str:
    return "n/a" if v is None else f"{100.0 * v:.{digits}f}"


def _ratio(v: float | None) -> str:
    return "n/a" if v is None else f"{v:.2f}"


def format_table(result: dict[str, Any]) -> str:
    """The rows of :func:`visibility_benchmark` as text, with the reference and the targets."""
    ref = result["reference"]
    lines = [
        f"reference: {len(result['cells'])} cells ({ref['cells_scored']} see something), "
        f"{ref['points_per_cell']:.0f} random points/cell over the cell and its height range, "
        f"{ref['resolution']} px, LOD{ref['lod']}, no frustum culling: PVS {ref['pvs_mean']:.1f} "
        f"of {result['objects']} objects, {ref['sec_per_cell']:.1f} s/cell"
        + (f" ({ref['cached']} cells from the cache)" if ref.get("cached") else ""),
        f"image error: {result['views']} random eye points ({result['view_size'][0]}x{result['view_size'][1]}, "
        "random heading) compared with their ground truth",
        "",
        f"{'setting':<20} {'pts':>4} {'ms/cell':>8} {'time x':>6} {'x dflt':>6} {'x prev':>6} {'PVS':>6} {'PVS x':>5} {'x prev':>6} "
        f"{'culled%':>7} {'missed':>6} {'miss#%':>6} {'miss px%':>8} {'max obj%':>8} {'view px%':>8} {'view #%':>7} {'v>0.5%':>6} "
        f"{'v>0.01%':>7}",
    ]
    for r in result["rows"]:
        mark = "  <- bake default" if r["name"] == result.get("default") else ""
        sec, tr = r.get("sec_per_cell"), r["time_ratio"]
        lines.append(
            f"{r['name']:<20} {r.get('points_per_cell', float('nan')):>4.0f} "
            f"{'n/a' if sec is None else f'{1e3 * sec:.1f}':>8} "
            f"{'n/a' if tr is None else f'{tr:.2f}':>6} {_ratio(r.get('time_ratio_default')):>6} "
            f"{_ratio(r.get('time_ratio_previous')):>6} {r['pvs_mean']:>6.1f} "
            f"{r['pvs_ratio']:>5.2f} {_ratio(r.get('pvs_ratio_previous')):>6} {_pct(r['culled'], 1):>7} {r['missed']:>6d} "
            f"{_pct(r['miss_count'], 1):>6} "
            f"{_pct(r['miss_px'], 4):>8} {_pct(r['miss_max'], 4):>8} {_pct(r.get('view_miss_px'), 3):>8} "
            f"{_pct(r.get('view_miss_count'), 1):>7} {_pct(r.get('view_over_half'), 1):>6} "
            f"{_pct(r.get('view_over_hundredth'), 1):>7}{mark}"
        )
    t = TARGETS
    lines += [
        "",
        f"targets: miss px <= {100 * t['miss_px']:g} %, max obj <= {100 * t['miss_max']:g} % of a cell's "
        f"reference pixels, PVS x <= {t['pvs_ratio']:g}, x dflt <= {t['time_ratio_default']:g}, culled >= 90 % "
        "(missed, miss#%: objects missed over the cells and their mean share, reported, not a goal)",
        f"time x, PVS x: against {TODAY.name} (the first bake); x dflt: against the bake's default; "
        f"x prev: against {PREVIOUS.name} (the default before region sampling), when it is a row",
        "view px%: truth pixels showing an object missing from the cell's PVS; view #%: objects "
        "shown that are missing; v>0.5%, v>0.01%: views whose missing pixels exceed 0.5 % (0.01 %) of the frame",
        "least PVS: the fewest objects a PVS can hold and still meet both miss targets against this "
        "reference (the least-seen objects left out first): no sampling stays under its PVS x",
    ]
    vn = result.get("view_need")
    if vn:
        lines.append(
            f"view need: {vn['pvs_mean']:.1f} objects a cell keep each of its views within 0.01 % of the frame "
            f"(each view less its least-seen objects within it): {_ratio(vn['pvs_ratio'])} x {TODAY.name}'s PVS, "
            f"the per-frame figure's need at these eye points; of them {vn['must_mean']:.1f} "
            f"({_ratio(vn['must_ratio'])} x) alone cover over 0.01 % of some view: no PVS that keeps every view "
            "within 0.01 % holds fewer"
        )
    for r in result["rows"]:
        if r.get("bake_sec_per_cell") is not None:
            lines.append(
                f"{r['name']}: the bench renders a cell's {r['points_per_cell']:.1f} field points alone; the bake "
                f"renders each of the {r['field_points']} field points once for the {result['cells_total']} cells "
                f"({r['field_points_per_cell']:.1f} per cell): {1e3 * r['bake_sec_per_cell']:.1f} ms/cell, "
                f"{r['bake_time_ratio_default']:.2f} x the default"
            )
    for r in result["rows"]:
        sh = r.get("missed_ref_shares")
        if sh:
            a = 100.0 * np.array(sh)
            lines.append(
                f"missed objects against the reference, {r['name']}: {len(a)} misses, median "
                f"{np.median(a):.5f} %, p90 {np.percentile(a, 90):.5f} % of the cell's reference pixels"
            )
    for r in result["rows"]:
        s = r.get("missed_sizes")
        if s is not None and not s:
            lines.append(f"missed objects' sizes in the views, {r['name']}: nothing missed")
        elif s:
            a = 100.0 * np.array(s)
            lines.append(
                f"missed objects' sizes in the views, {r['name']}: {len(a)} misses, median "
                f"{np.median(a):.4f} %, p95 {np.percentile(a, 95):.4f} %, max {a.max():.4f} % of the frame"
            )
    return "\n".join(lines)


def _nice_ticks(lo: float, hi: float) -> list[float]:
    """A few 1-2-5 tick values covering ``lo .. hi`` (> 0) on a log axis."""
    e0, e1 = math.floor(math.log10(lo)) - 1, math.ceil(math.log10(hi)) + 1
    cand = [m * 10.0**e for e in range(e0, e1) for m in (1, 2, 5)]
    return [v for v in cand if lo / 2.5 <= v <= hi * 2.5]


def plot_visibility_benchmark(result: dict[str, Any], path: str | os.PathLike[str], *, dpi: int = 120) -> None:
    """A PNG of three panels: misses against bake time, misses against PVS size, missed objects' sizes.

    Left: pixel-weighted misses and the largest single miss (%, log) against seconds
    per cell (log) for every setting, the targets as dashed lines.  Middle: misses by
    pixels against the PVS size relative to the first default, the targets dashed.  Right:
    the distribution of the missed objects' sizes at the random eye points (share of
    the frame, log bins) for the first default, the bake default and the baked PVS.
    """
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure
    from matplotlib.ticker import FuncFormatter, NullFormatter

    rows = result["rows"]
    timed = [r for r in rows if r.get("sec_per_cell")]
    fig = Figure(figsize=(17, 6.0), dpi=dpi)
    ax1, ax2, ax3 = fig.subplots(1, 3)
    floor = 1e-5
    for r in timed:
        x = r["sec_per_cell"]
        special = r["name"] in (TODAY.name, result.get("default"))
        colour = "#D55E00" if r["name"] == TODAY.name else ("#009E73" if r["name"] == result.get("default") else "#0072B2")
        ax1.plot([x], [max(100 * r["miss_px"], floor)], "o", color=colour, markersize=8 if special else 6)
        ax1.plot([x], [max(100 * r["miss_max"], floor)], "^", color=colour, markersize=8 if special else 6, markerfacecolor="white")
        ax1.annotate(r["name"], (x, max(100 * r["miss_px"], floor)), xytext=(4, 3), textcoords="offset points", fontsize=7)
        ax2.plot([r["pvs_ratio"]], [max(100 * r["miss_px"], floor)], "o", color=colour, markersize=8 if special else 6)
        ax2.annotate(r["name"], (r["pvs_ratio"], max(100 * r["miss_px"], floor)), xytext=(4, 3), textcoords="offset points", fontsize=7)
    dflt = next((r for r in timed if r["name"] == result.get("default")), None)
    if dflt is not None:
        lim = TARGETS["time_ratio_default"] * dflt["sec_per_cell"]
        ax1.axvline(lim, color="#888888", linestyle=":", linewidth=1.0)
        ax1.annotate(f"{TARGETS['time_ratio_default']:g} x the bake default's time", (lim, 0.98), xycoords=("data", "axes fraction"), fontsize=7, rotation=90, va="top", ha="right", color="#555555")
    ax1.axhline(100 * TARGETS["miss_px"], color="#0072B2", linestyle="--", linewidth=1.0, label="target: misses by pixels")
    ax1.axhline(100 * TARGETS["miss_max"], color="#555555", linestyle="-.", linewidth=1.0, label="target: largest single miss")
    ax1.plot([], [], "o", color="#555555", label="misses by pixels (pooled)")
    ax1.plot([], [], "^", color="#555555", markerfacecolor="white", label="largest missed object (one cell)")
    ax1.set_xscale("log")
    ax1.set_yscale("log")
    # seconds per cell span less than a decade: labelled minor ticks would overlap
    ax1.xaxis.set_minor_formatter(NullFormatter())
    ax1.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    ax1.set_xticks(_nice_ticks(min(r["sec_per_cell"] for r in timed), max(r["sec_per_cell"] for r in timed)) if timed else [])
    ax1.set_xlabel("bake seconds per cell (median, log)")
    ax1.set_ylabel("% of a cell's reference pixels (log)")
    ax1.set_title("misses against bake time (red: first default, green: bake default)", fontsize=9)
    ax1.legend(fontsize=7, loc="lower left")
    ax2.axvline(TARGETS["pvs_ratio"], color="#888888", linestyle=":", linewidth=1.0)
    base = next((r for r in timed if r["name"] == TODAY.name), None)
    if base is not None and base["pvs_mean"]:
        # the reference's own PVS against the first default's: no sampling that holds
        # every reference-visible object stays left of this line
        need = result["reference"]["pvs_mean"] / base["pvs_mean"]
        ax2.axvline(need, color="#CC79A7", linestyle="-.", linewidth=1.0)
        ax2.annotate(
            "the reference PVS", (need, 0.98), xycoords=("data", "axes fraction"),
            fontsize=7, rotation=90, va="top", ha="right", color="#CC79A7",
        )
        # the floors: no PVS left of them meets the miss targets (the reference) or keeps
        # every random view within 0.01 % of the frame (the per-frame figure)
        least = next((r for r in rows if r["name"] == "least PVS"), None)
        vn = result.get("view_need")
        for x, label, colour in (
            (least["pvs_mean"] / base["pvs_mean"] if least else None, "the least PVS within the miss targets", "#E69F00"),
            (vn["pvs_ratio"] if vn else None, "what the views need (per frame)", "#56B4E9"),
        ):
            if x is not None:
                ax2.axvline(x, color=colour, linestyle="-.", linewidth=1.0)
                ax2.annotate(label, (x, 0.98), xycoords=("data", "axes fraction"), fontsize=7, rotation=90,
                             va="top", ha="right", color=colour)
    ax2.axhline(100 * TARGETS["miss_px"], color="#0072B2", linestyle="--", linewidth=1.0)
    ax2.set_yscale("log")
    ax2.set_xlabel("mean PVS size / the first default's")
    ax2.set_ylabel("reference pixels missed (%, pooled, log)")
    ax2.set_title("misses by pixels against PVS growth (targets dashed, the PVS bound dotted, the floors dash-dotted)", fontsize=9)
    bins = np.logspace(-6, 0, 37)
    for name, colour in ((TODAY.name, "#D55E00"), (result.get("default"), "#009E73"), ("baked", "#555555")):
        r = next((x for x in rows if x["name"] == name), None)
        if r is None or not r.get("missed_sizes"):
            continue
        ax3.hist(
            np.clip(r["missed_sizes"], 1e-6, 1.0), bins=bins, histtype="step", linewidth=1.6, color=colour,
            linestyle="--" if name == "baked" else "-",
            label=f"{name}: {len(r['missed_sizes'])} misses in {result['views']} views",
        )
    ax3.set_xscale("log")
    ax3.set_xlabel("missed object's pixels / the frame's pixels (log)")
    ax3.set_ylabel("missed objects")
    ax3.set_title("sizes of the objects a PVS misses at random eye points", fontsize=9)
    if ax3.get_legend_handles_labels()[0]:
        ax3.legend(fontsize=7)
    elif not result["views"]:
        # an empty panel would read as "nothing missed"
        ax3.text(0.5, 0.5, "no random eye points\n(--views 0)", ha="center", va="center",
                 transform=ax3.transAxes, fontsize=9, color="0.4")
    for ax in (ax1, ax2, ax3):
        ax.grid(True, which="both", alpha=0.25)
    ref = result["reference"]
    fig.suptitle(
        f"Visibility bake against a dense reference: {len(result['cells'])} cells, "
        f"{ref['points_per_cell']:.0f} random points/cell at {ref['resolution']} px, LOD2, no culling",
        fontsize=10,
    )
    fig.tight_layout(rect=(0, 0, 1, 0.95))
    fig.savefig(os.fspath(path))
