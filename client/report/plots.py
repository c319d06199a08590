"""The report's figures, one function per PNG: bytes, quality, frame rate, budget over time,
an interior walk's cells and fog, the image error against the truth.

Long logs are drawn through a min/max envelope of at most a few thousand points per
line, so 15,000 frames plot as fast as 1,500 and spikes still show.
"""

from __future__ import annotations

import dataclasses
import io
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.client.report.colour import ColourLog
from walkstream.client.report.framelog import FrameLog
from walkstream.client.report.metrics import first_perfect_index
from walkstream.client.report.truth import OVER_SHARE, TruthLog
from walkstream.client.truth.colour import COLOUR_CAUSE_RGB, COLOUR_CAUSES, VISIBLE_DE
from walkstream.client.truth.compare import CAUSE_RGB, CAUSES

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure
from walkstream.client.report.files import BytesLog, atomic_open, bytes_arrays
from walkstream.shared.arrays import F64

_COLOUR_RGB = {**CAUSE_RGB, **COLOUR_CAUSE_RGB}

__all__ = [
    "BASE_PLOT_NAMES",
    "PLOT_NAMES",
    "SERIES_COLOURS",
    "plot_interior",
    "PlotRun",
    "make_run",
    "grid_figure",
    "save_figure",
    "plot_bytes",
    "plot_quality",
    "plot_fps",
    "plot_budget",
    "plot_error",
    "plot_culled",
]

#: The plots every report holds, in page order.
BASE_PLOT_NAMES: tuple[str, ...] = ("bytes.png", "quality.png", "fps.png", "budget.png")

#: Every plot a report can hold, in page order: the base plots, then ``phases.png``
#: (when the replay timed its phases), ``interior.png`` (an interior walk) and
#: ``error.png`` (frames compared with the ground truth), ``culled.png`` (a walk with
#: rooms compared with the ground truth).
PLOT_NAMES: tuple[str, ...] = (*BASE_PLOT_NAMES, "phases.png", "interior.png", "error.png", "culled.png")

#: Line colours for runs and series (Okabe-Ito, readable for colour-blind readers).
#: ``shared.palette`` holds material colours only, which are meant for buildings.
SERIES_COLOURS: tuple[str, ...] = (
    "#0072B2",  # blue
    "#D55E00",  # vermillion
    "#009E73",  # bluish green
    "#CC79A7",  # reddish purple
    "#E69F00",  # orange
    "#56B4E9",  # sky blue
    "#000000",  # black
    "#F0E442",  # yellow
)

_DPI = 110
_MAX_POINTS = 4000  # per drawn line, after the min/max envelope
_MAX_MARKERS = 2500


# --------------------------------------------------------------------------- plotting


@dataclasses.dataclass(frozen=True, slots=True)
class PlotRun:
    """One run's figures, frames and link samples, as the plots draw them."""
    label: str
    summary: Mapping[str, Any]
    frames: FrameLog
    bytes_t: F64
    bytes_b: F64
    t0: float
    colour: str


def make_run(
    label: str, summary: Mapping[str, Any], frames: FrameLog, bytes_log: BytesLog | None, i: int
) -> PlotRun:
    """The :class:`PlotRun` of one replay (``i``: its place, which picks its colour)."""
    bt, bb = bytes_arrays(bytes_log)
    if bt.size == 0 and len(frames):
        # No link samples: the per-frame cumulative count is the next best thing.
        bt, bb = frames.t.astype(np.float64), frames.bytes_down.astype(np.float64)
    t0 = summary.get("t_start_s")
    if t0 is None or not math.isfinite(float(t0)):
        starts = [a[0] for a in (frames.t, bt) if a.size]
        t0 = float(min(starts)) if starts else 0.0
    return PlotRun(label, summary, frames, bt, bb, float(t0), SERIES_COLOURS[i % len(SERIES_COLOURS)])


def _envelope(x: ArrayLike, y: ArrayLike, max_points: int = _MAX_POINTS) -> tuple[F64, F64]:
    """Thin a line to at most about ``max_points`` points, keeping each bucket's min and max.

    Consecutive samples are grouped into buckets; each bucket contributes its lowest
    and its highest sample in time order, so spikes and dips survive the thinning.
    """
    xa = np.asarray(x, dtype=np.float64)
    ya = np.asarray(y, dtype=np.float64)
    n = xa.size
    if n <= max_points:
        return xa, ya
    size = math.ceil(n / max(1, max_points // 2))
    m = math.ceil(n / size)
    pad = m * size - n
    # Pad with the last sample so every bucket has the same length.
    yp = np.concatenate([ya, np.full(pad, ya[-1])]).reshape(m, size)
    base = np.arange(m) * size
    lo = np.minimum(base + np.argmin(yp, axis=1), n - 1)
    hi = np.minimum(base + np.argmax(yp, axis=1), n - 1)
    idx = np.unique(np.concatenate([lo, hi, [0, n - 1]]))
    return xa[idx], ya[idx]


def _thin(idx: NDArray[np.intp], limit: int = _MAX_MARKERS) -> NDArray[np.intp]:
    if idx.size <= limit:
        return idx
    return idx[np.linspace(0, idx.size - 1, limit).astype(np.intp)]


def grid_figure(
    rows: int = 1, height: float = 3.2, *, cols: int = 1, sharex: bool = True
) -> tuple[Figure, list[Axes]]:
    """A figure of ``rows x cols`` axes (row-major list), gridded, on the Agg backend."""
    import matplotlib

    matplotlib.use("Agg")  # never a display; plots are files
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10.0 if cols == 1 else 12.0, 0.8 + height * rows), dpi=_DPI)
    axes = list(fig.subplots(rows, cols, sharex=sharex, squeeze=False).reshape(-1))
    for ax in axes:
        ax.grid(True, alpha=0.3)
    return fig, axes


def _legend(ax: Axes, **kw: Any) -> None:
    """A legend when something on the axes has a label (an empty log draws nothing)."""
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=8, **kw)


# Margins of the grid layout, inches: tick labels and a y label on the left, tick labels
# and an x label below, a title line of 10 pt above an axes.
_LEFT_IN, _RIGHT_IN, _BOTTOM_IN, _TOP_IN = 0.95, 0.45, 0.6, 0.15
_TITLE_LINE_IN, _XLABELS_IN, _COL_GAP_IN = 0.2, 0.55, 1.05

#: True: every figure is laid out by measuring its labels (:meth:`~Figure.tight_layout`),
#: the grids too: the reference ``python -m walkstream.benchmarks.reportplots`` times
#: the fixed margins against.
MEASURED_LAYOUT = False


def _grid_layout(fig: Figure) -> bool:
    """Place the axes of a :func:`grid_figure` by fixed margins in inches; False when ``fig``
    is not such a grid (a colour bar, an image: :meth:`~Figure.tight_layout` then).

    :meth:`~Figure.tight_layout` measures every tick label and title by drawing them, as
    long again as writing the PNG; a report's plots are grids of line plots whose labels
    fit these margins, so the measuring is skipped for them."""
    axes = fig.axes
    specs = [ax.get_subplotspec() for ax in axes]
    if not axes or any(s is None for s in specs) or any(ax.images for ax in axes):
        return False
    legends = [leg for leg in (ax.get_legend() for ax in axes) if leg is not None]
    if any(leg.get_bbox_to_anchor() is not leg.axes.bbox for leg in legends):
        return False  # a legend placed outside its axes needs its room measured
    rows, cols = specs[0].get_gridspec().get_geometry()  # type: ignore[union-attr]
    w, h = fig.get_size_inches()

    def lines(ax: Axes) -> int:
        titles = [ax.get_title(loc=loc) for loc in ("left", "center", "right")]
        return max((t.count("\n") + 1 for t in titles if t), default=0)

    top_row = [ax for ax, s in zip(axes, specs, strict=True) if s.is_first_row()]  # type: ignore[union-attr]
    below = [ax for ax, s in zip(axes, specs, strict=True) if not s.is_first_row()]  # type: ignore[union-attr]
    shared = all(len(ax.get_shared_x_axes().get_siblings(ax)) > 1 for ax in axes)
    top = _TOP_IN + _TITLE_LINE_IN * max(map(lines, top_row), default=0)
    if fig.get_suptitle():  # keep the figure title clear of the top row's titles
        top += 0.35
    gap = _TITLE_LINE_IN * max(map(lines, below), default=0) + (0.15 if shared else _XLABELS_IN)
    ax_h = (h - top - _BOTTOM_IN - (rows - 1) * gap) / rows
    ax_w = (w - _LEFT_IN - _RIGHT_IN - (cols - 1) * _COL_GAP_IN) / cols
    if ax_h <= 0.5 or ax_w <= 0.5:
        return False
    fig.subplots_adjust(left=_LEFT_IN / w, right=1.0 - _RIGHT_IN / w, bottom=_BOTTOM_IN / h,
                        top=1.0 - top / h, hspace=gap / ax_h, wspace=_COL_GAP_IN / ax_w)  # fmt: skip
    return True


def save_figure(fig: Figure, path: Path) -> Path:
    """Lay ``fig`` out and write it to ``path`` as PNG (atomically); returns ``path``."""
    if not MEASURED_LAYOUT and _grid_layout(fig):
        pass  # placed by fixed margins
    elif fig.get_suptitle():  # keep the figure title clear of the top row's titles
        fig.tight_layout(rect=(0.0, 0.0, 1.0, 1.0 - 0.35 / fig.get_figheight()))
    else:
        fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    with atomic_open(path, "wb") as f:
        f.write(buf.getvalue())
    return path


def _thousands(ax: Axes) -> None:
    from matplotlib.ticker import FuncFormatter

    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _pos: f"{v:,.0f}"))


def _rate_bins(run: PlotRun) -> tuple[F64, F64, float]:
    """Download rate per time bin: (bin starts s, kbit/s, bin width s)."""
    if run.bytes_t.size == 0:
        return np.empty(0), np.empty(0), 1.0
    t = run.bytes_t - run.t0
    inc = np.diff(run.bytes_b, prepend=0.0)
    span = max(float(t.max()), 1e-9)
    width = max(1.0, math.ceil(span / 600.0))  # at most ~600 bins
    k = np.maximum(np.floor(t / width), 0).astype(np.int64)
    sums = np.bincount(k, weights=inc, minlength=int(k.max()) + 1)
    starts: F64 = np.arange(sums.size, dtype=np.float64) * width
    rate: F64 = np.asarray(sums * (8.0 / 1000.0 / width), dtype=np.float64)
    return starts, rate, width


def plot_bytes(path: Path, runs: Sequence[PlotRun], title: str) -> Path:
    """``bytes.png``: the bytes received over time (top) and the rate (bottom), one line per run."""
    fig, (ax_cum, ax_rate) = grid_figure(2)
    top, widths = 1.0, set()
    for r in runs:
        if r.bytes_t.size == 0:
            continue
        x, y = _envelope(r.bytes_t - r.t0, r.bytes_b / 1000.0)
        ax_cum.step(x, y, where="post", color=r.colour, label=r.label, linewidth=1.4)
        bx, rate, width = _rate_bins(r)
        widths.add(width)
        top = max(top, float(rate.max()) if rate.size else 0.0)
        ax_rate.step(
            np.append(bx, bx[-1] + width) if bx.size else bx,
            np.append(rate, rate[-1]) if rate.size else rate,
            where="post",
            color=r.colour,
            label=r.label,
            linewidth=1.1,
        )
    bws = sorted(
        {float(r.summary["bandwidth_bps"]) for r in runs if r.summary.get("bandwidth_bps")}
    )
    for bw in bws:
        top = max(top, bw / 1000.0)
        ax_rate.axhline(bw / 1000.0, color="#555555", linestyle="--", linewidth=1.0)
        ax_rate.annotate(
            f"link {bw / 1000.0:g} kbit/s",
            (0.0, bw / 1000.0),
            xycoords=("axes fraction", "data"),
            xytext=(4, 3),
            textcoords="offset points",
            fontsize=8,
            color="#555555",
        )
    ax_cum.set_ylabel("downloaded (kB, cumulative)")
    _thousands(ax_cum)
    per = f", per {widths.pop():g} s" if len(widths) == 1 else ""
    ax_rate.set_ylabel(f"download rate (kbit/s{per})")
    ax_rate.set_xlabel("time since replay start (s)")
    ax_cum.set_ylim(bottom=0)
    ax_rate.set_ylim(0.0, 1.15 * top)
    if len(runs) > 1:
        _legend(ax_cum, loc="upper left")
    ax_cum.set_title(title, fontsize=10)
    return save_figure(fig, path)


def _quality_axes(ax: Axes, r: PlotRun, column: str, first: int | None, *, note: bool) -> None:
    f = r.frames
    x = f.t - r.t0
    xs, ys = _envelope(x, 100.0 * getattr(f, column))
    ax.step(xs, ys, where="post", color=r.colour, linewidth=1.4)
    if first is not None:
        ax.axvline(x[first], color="#009E73", linestyle=":", linewidth=1.2)
        if note:
            ax.annotate(
                f"first perfect frame {x[first]:.2f} s",
                (x[first], 50.0),
                xytext=(4, 0),
                textcoords="offset points",
                fontsize=8,
                color="#009E73",
            )
    ax.set_ylim(-3.0, 103.0)


def plot_quality(path: Path, runs: Sequence[PlotRun], title: str) -> Path:
    """``quality.png``: download and rewrite quality over time, one row per run."""
    # One row per run, download and rewrite quality side by side (the layout of the
    # paper's Figure 1): overlaid lines that all sit at 100 % would hide each other.
    fig, axes = grid_figure(len(runs), height=2.4 if len(runs) > 1 else 3.4, cols=2)
    columns = (
        ("download_quality", "download quality", "download_quality_mean", "% of PVS received"),
        ("rewrite_quality", "rewrite quality", "rewrite_quality_mean", "% of PVS built"),
    )
    for i, r in enumerate(runs):
        first = first_perfect_index(r.frames) if len(r.frames) else None
        for j, (column, name, mean_key, unit) in enumerate(columns):
            ax = axes[2 * i + j]
            _quality_axes(ax, r, column, first, note=j == 0)
            mean = r.summary.get(mean_key)
            head = f"{r.label}: " if len(runs) > 1 else ""
            tail = f", mean {mean:.1f} %" if mean is not None else ""
            if j == 0 and r.summary.get("perfect_frame_ratio") is not None:
                tail += f"; perfect frames {100.0 * r.summary['perfect_frame_ratio']:.2f} %"
            ax.set_title(head + name + tail, fontsize=9, loc="left")
            ax.set_ylabel(unit)
    for ax in axes[-2:]:
        ax.set_xlabel("time since replay start (s)")
    fig.suptitle(title, fontsize=10)
    return save_figure(fig, path)


def plot_fps(path: Path, runs: Sequence[PlotRun], title: str) -> Path:
    """``fps.png``: the displayed frame rate over time against its target band."""
    fig, (ax,) = grid_figure(1, height=4.2)
    ymax = 1.0
    for tgt in sorted(
        {float(r.summary["fps_target"]) for r in runs if r.summary.get("fps_target")}
    ):
        ax.axhspan(0.9 * tgt, 1.1 * tgt, color="#009E73", alpha=0.15, linewidth=0)
        ax.axhline(tgt, color="#009E73", linestyle="--", linewidth=1.2)
        ax.annotate(
            f"target {tgt:g} fps +-10 %",
            (1.0, tgt),
            xycoords=("axes fraction", "data"),
            xytext=(-4, 4),
            textcoords="offset points",
            ha="right",
            fontsize=8,
            color="#006040",
        )
        ymax = max(ymax, 1.3 * tgt)
    warm = [r for r in runs if len(r.frames)]
    if warm:
        ax.axvspan(
            0.0, 1.0, color="#888888", alpha=0.12, linewidth=0, label="first second (not counted)"
        )
    floor_labelled = False
    for r in runs:
        f = r.frames
        if not len(f):
            continue
        x = f.t - r.t0
        fin = np.isfinite(f.fps)
        xs, ys = _envelope(x[fin], f.fps[fin])
        ax.plot(
            xs,
            ys,
            color=r.colour,
            linewidth=0.9,
            label=r.label if len(runs) > 1 else "displayed fps",
        )
        if fin.any():
            ymax = max(ymax, 1.08 * float(f.fps[fin].max()))
        step = r.summary.get("cost_step_frame")
        if isinstance(step, int) and 0 <= step < len(f):
            ax.axvline(float(x[step]), color="#D55E00", linestyle=":", linewidth=1.2)
            ax.annotate(
                "cost step",
                (float(x[step]), 0.02),
                xycoords=("data", "axes fraction"),
                xytext=(3, 0),
                textcoords="offset points",
                fontsize=8,
                color="#D55E00",
            )
        fl = _thin(np.flatnonzero(f.floor_limited & fin))
        if fl.size:
            ax.plot(
                x[fl],
                f.fps[fl],
                linestyle="none",
                marker="x",
                markersize=4,
                color="#D00000",
                label=None if floor_labelled else "floor-limited frame",
            )
            floor_labelled = True
    ax.set_ylim(0.0, ymax)
    ax.set_ylabel("frame rate (frames/s)")
    ax.set_xlabel("time since replay start (s)")
    notes = []
    for r in runs:
        s = r.summary
        if s.get("fps_within_10pct_ratio") is not None:
            notes.append(
                (f"{r.label}: " if len(runs) > 1 else "")
                + f"{100.0 * s['fps_within_10pct_ratio']:.1f} % of counted frames within 10 %"
                + (f", mean {s['fps_mean']:.1f} fps" if s.get("fps_mean") is not None else "")
            )
    ax.set_title(title + ("\n" + "\n".join(notes) if notes else ""), fontsize=10)
    _legend(ax, loc="lower right")
    return save_figure(fig, path)


def plot_budget(path: Path, runs: Sequence[PlotRun], title: str) -> Path:
    """``budget.png``: the budget controller's triangle budget and what was drawn."""
    fig, (ax,) = grid_figure(1, height=4.2)
    top = 1.0
    for r in runs:
        f = r.frames
        if not len(f):
            continue
        x = f.t - r.t0
        prefix = f"{r.label}: " if len(runs) > 1 else ""
        xs, ys = _envelope(x, f.budget)
        ax.step(
            xs, ys, where="post", color=r.colour, linewidth=1.3, label=prefix + "polygon budget"
        )
        xs, ys = _envelope(x, f.triangles)
        ax.plot(
            xs,
            ys,
            color=r.colour,
            linewidth=0.8,
            alpha=0.6,
            linestyle="--",
            label=prefix + "triangles drawn",
        )
        top = max(top, float(f.budget.max()), float(f.triangles.max()))
    # Headroom above the lines for the legend (two entries per run).
    ax.set_ylim(0.0, top * (1.15 + 0.1 * len(runs)))
    _thousands(ax)
    ax.set_ylabel("triangles per frame")
    ax.set_xlabel("time since replay start (s)")
    ax.set_title(title, fontsize=10)
    _legend(ax, loc="upper right")
    return save_figure(fig, path)


def plot_error(path: Path, run: PlotRun, truth: TruthLog, title: str) -> Path:
    """``error.png``: the frame rate (top) and the image error against the truth (bottom) over time.

    The middle panel stacks the missing pixels of each compared frame by cause (% of
    the frame) and draws the differing pixels as a line; the 0.5 % line is the
    threshold of ``over_half_percent_ratio``.  With colour figures (a city walk) a
    bottom panel shows the colour error of the client's picture against the full
    scene: the mean linear-RGB error (% of full scale) and the pixels over the
    visible ΔE00 threshold stacked by cause (% of the frame), the 0.5 % line theirs.
    """
    colour = truth.colour
    fig, axes = grid_figure(3 if colour is not None else 2, height=3.0)
    ax_fps, ax_err = axes[0], axes[1]
    f = run.frames
    if len(f):
        x = f.t - run.t0
        fin = np.isfinite(f.fps)
        xs, ys = _envelope(x[fin], f.fps[fin])
        ax_fps.plot(xs, ys, color=run.colour, linewidth=0.9, label="displayed fps")
        tgt = run.summary.get("fps_target")
        if tgt:
            ax_fps.axhline(float(tgt), color="#009E73", linestyle="--", linewidth=1.1, label=f"target {float(tgt):g} fps")
        ax_fps.set_ylim(0.0, 1.3 * max(float(tgt or 1.0), float(f.fps[fin].max()) if fin.any() else 1.0))
        first = first_perfect_index(f)
        for ax in axes:
            if first is not None:
                ax.axvline(float(x[first]), color="#009E73", linestyle=":", linewidth=1.1)
    ax_fps.set_ylabel("frame rate (frames/s)")
    _legend(ax_fps, loc="lower right")
    tx = truth.t - run.t0
    if len(truth):
        shares = 100.0 * truth.missing
        colours = ["#{:02x}{:02x}{:02x}".format(*CAUSE_RGB[c]) for c in CAUSES]
        ax_err.stackplot(tx, shares.T, labels=[f"missing: {c}" for c in CAUSES], colors=colours, alpha=0.85, step="post")
        ax_err.plot(tx, 100.0 * truth.differing, color="#333333", linewidth=0.9, drawstyle="steps-post", label="differing pixels")
        top = max(float((100.0 * truth.differing).max()), float(shares.sum(axis=1).max()), 100.0 * OVER_SHARE)
        # linear up to 1 %, logarithmic above: the start-up frames (everything missing)
        # must not flatten the fractions of a percent that matter afterwards
        ax_err.set_yscale("symlog", linthresh=1.0, linscale=2.0)
        ax_err.set_ylim(0.0, max(2.0, 1.5 * top))
    ax_err.axhline(100.0 * OVER_SHARE, color="#D55E00", linestyle="--", linewidth=1.0, label="0.5 % of the frame")
    ax_err.set_ylabel("% of the frame's pixels (log above 1 %)")
    if colour is None:
        ax_err.set_xlabel("time since replay start (s)")
    _legend(ax_err, loc="upper right", ncol=2)
    if colour is not None:
        _colour_panel(axes[2], colour, run.t0)
    s = run.summary.get("truth") or {}
    notes = []
    if s.get("frames"):
        notes.append(f"{s['frames']} frames compared")
        if s.get("differing_pixels_mean") is not None:
            notes.append(f"differing {100.0 * s['differing_pixels_mean']:.2f} % mean")
        if s.get("over_half_percent_ratio") is not None:
            notes.append(f"frames missing > 0.5 %: {100.0 * s['over_half_percent_ratio']:.1f} %")
    c = s.get("colour") or {}
    colour_note = ""
    if c.get("frames") and (c.get("mean_error") or {}).get("median") is not None:
        colour_note = (
            f"\ncolour error median {100.0 * c['mean_error']['median']:.2f} % (p95 {100.0 * c['mean_error']['p95']:.2f} %) "
            f"of full scale; frames with > 0.5 % of pixels over dE00 {c['visible_threshold']:g}: "
            f"{100.0 * c['frames_over_visible_ratio']:.1f} %"
        )
    ax_fps.set_title(title + ("\n" + "; ".join(notes) if notes else "") + colour_note, fontsize=10)
    return save_figure(fig, path)


def _colour_panel(ax: Axes, colour: ColourLog, t0: float) -> None:
    """The colour error of the compared frames over time (the bottom panel of ``error.png``)."""
    if len(colour):
        tx = colour.t - t0
        shares = 100.0 * colour.causes
        some = [k for k in range(len(COLOUR_CAUSES)) if shares[:, k].any()]  # a legend of the causes seen
        if some:
            colours = ["#{:02x}{:02x}{:02x}".format(*_COLOUR_RGB[COLOUR_CAUSES[k]]) for k in some]
            ax.stackplot(tx, shares[:, some].T, labels=[f"over dE00 {VISIBLE_DE:g}: {COLOUR_CAUSES[k]}" for k in some],
                         colors=colours, alpha=0.85, step="post")
        ax.plot(tx, 100.0 * colour.mean_error, color="#000000", linewidth=1.1, drawstyle="steps-post",
                label="mean error, linear RGB (% of full scale)")
        top = max(float(shares.sum(axis=1).max()), float((100.0 * colour.mean_error).max()), 100.0 * OVER_SHARE)
        if colour.visible_scielab is not None:  # beside the per-pixel count, never in its place
            ax.plot(tx, 100.0 * colour.visible_scielab, color="#0072B2", linestyle="--", linewidth=1.1,
                    drawstyle="steps-post", label=f"over dE00 {VISIBLE_DE:g} at the viewer's scale (S-CIELAB)")
            top = max(top, float((100.0 * colour.visible_scielab).max()))
        ax.set_yscale("symlog", linthresh=1.0, linscale=2.0)
        ax.set_ylim(0.0, max(2.0, 1.5 * top))
    ax.axhline(100.0 * OVER_SHARE, color="#D55E00", linestyle="--", linewidth=1.0, label="0.5 % of the frame")
    ax.set_ylabel("colour error, % (log above 1 %)")
    ax.set_xlabel("time since replay start (s)")
    _legend(ax, loc="upper right", ncol=2)


def plot_interior(path: Path, t: ArrayLike, series: dict[str, ArrayLike], title: str) -> Path:
    """An interior walk per frame: visible cells and portals opened, triangles drawn,
    culling milliseconds, and the fog distance in force (one panel each).

    Parameters
    ----------
    path : Path
    t : (n,) float
        Seconds since the walk started.
    series : dict
        ``cells``, ``portals``, ``triangles``, ``cull_ms``, ``fog_m``: ``(n,)`` each.
    title : str
    """
    x = np.asarray(t, np.float64)
    fig, axes = grid_figure(4, 2.2)
    fig.suptitle(title)
    panels = (
        (("cells", "visible cells"), ("portals", "portals opened")),
        (("triangles", "triangles drawn"),),
        (("cull_ms", "culling CPU ms (cells and parts)"),),
        (("fog_m", "fog distance m"),),
    )
    for ax, lines in zip(axes, panels, strict=True):
        for k, (key, label) in enumerate(lines):
            y = np.asarray(series[key], np.float64)
            ax.plot(x[: len(y)], y, lw=0.8, color=SERIES_COLOURS[k], label=label)
        _legend(ax, loc="upper right")
    axes[-1].set_xlabel("walk time, s")
    return save_figure(fig, path)


def plot_culled(path: Path, t: ArrayLike, culled: ArrayLike, pinholes: ArrayLike, refused: ArrayLike,
                title: str) -> Path:
    """``culled.png``: a walk with rooms, per compared frame: the culled pixels (pinholes
    apart, must be 0), the pinholes, and the frames refused as poses in solid geometry.

    Parameters
    ----------
    path : Path
    t : (n,) float
        Each compared frame's walk time, seconds.
    culled, pinholes : (n,) int
        Its culled pixels and pinholes.
    refused : (n,) bool
        Whether it was refused (not compared).
    title : str
    """
    x = np.asarray(t, np.float64)
    c = np.asarray(culled, np.float64)
    p = np.asarray(pinholes, np.float64)
    r = np.asarray(refused, bool)
    fig, (ax,) = grid_figure(1, height=3.2)
    ax.plot(x, c, lw=0.9, color=SERIES_COLOURS[1], marker=".", ms=3, label="culled pixels (must be 0)")
    ax.plot(x, p, lw=0.8, color=SERIES_COLOURS[0], marker=".", ms=2, label="pinholes")
    if r.any():
        ax.plot(x[r], np.zeros(int(r.sum())), "x", color="#333333", ms=5, label="refused: eye in solid geometry")
    ax.set_yscale("symlog", linthresh=1.0)
    ax.set_ylim(0.0, max(10.0, 1.5 * float(max(c.max(initial=0.0), p.max(initial=0.0)))))
    ax.set_xlabel("walk time, s")
    ax.set_ylabel("pixels per compared frame")
    _legend(ax, loc="upper right")
    ax.set_title(f"{title}\n{len(x)} frames compared, {int(c.sum()):,} culled pixels on {int((c > 0).sum())}, "
                 f"{int(p.sum()):,} pinholes, {int(r.sum())} refused", fontsize=10)
    return save_figure(fig, path)
