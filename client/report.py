"""Replay reports: ``report.json``, the per-frame CSV, plots and an HTML index.

:func:`write_report` turns one replay (its summary from :func:`client.metrics.summarise`,
its :class:`~client.metrics.FrameLog` and the link's bytes log) into a folder::

    report.json   the summary (JSON-safe: numpy types converted, NaN/inf -> null)
    frames.csv    one row per frame, the FrameLog columns
    bytes.csv     the link's (t, cumulative bytes) samples
    bytes.png     bytes downloaded over time (cumulative kB, and rate in kbit/s)
    quality.png   download and rewrite quality per frame over time (paper 001, Figure 1)
    fps.png       displayed frame rate over time, target and +-10 % band, floor-limited
                  frames marked, the uncounted first second shaded
    budget.png    polygon budget and triangles drawn over time
    index.html    a self-contained page: headline table, every plot and snapshot
                  (relative links), the summary JSON

:func:`write_comparison` overlays several runs (with / without prefetch, meshes ...) for
the stream benchmark.  Every file is written to a temporary file in the same folder
and moved into place with :func:`os.replace`, so a reader never sees half a file and
writing over an earlier report replaces it file by file.  Long logs are drawn through a
min/max envelope of at most a few thousand points per line, so 15,000 frames plot as
fast as 1,500 and spikes still show.
"""

from __future__ import annotations

import csv
import dataclasses
import html
import io
import json
import logging
import math
import os
import shutil
import tempfile
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any
from urllib.parse import quote

import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.client.metrics import COLUMNS, FrameLog, first_perfect_index
from walkstream.shared.errors import InputError

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = [
    "BytesLog",
    "PLOT_NAMES",
    "SERIES_COLOURS",
    "format_comparison_table",
    "format_headline",
    "headline_rows",
    "json_safe",
    "load_run",
    "read_bytes_csv",
    "read_frames_csv",
    "write_bytes_csv",
    "write_comparison",
    "write_frames_csv",
    "write_json",
    "write_report",
]

log = logging.getLogger(__name__)

F64 = NDArray[np.float64]

#: ``(t, cumulative bytes)`` samples of the link: two equal-length 1-D arrays.
BytesLog = tuple[ArrayLike, ArrayLike]

#: The plots of one report, in page order.
PLOT_NAMES: tuple[str, ...] = ("bytes.png", "quality.png", "fps.png", "budget.png")

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


# --------------------------------------------------------------------------- JSON, files


def json_safe(obj: Any) -> Any:
    """A copy of ``obj`` that :func:`json.dumps` accepts with ``allow_nan=False``.

    numpy scalars and arrays become Python numbers and lists, NaN and infinities
    become ``None``, tuples and sets become lists, paths become strings, dataclasses
    become dicts and mapping keys become strings.
    """
    if obj is None or isinstance(obj, bool | str):
        return obj
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, int | np.integer):
        return int(obj)
    if isinstance(obj, float | np.floating):
        v = float(obj)
        return v if math.isfinite(v) else None
    if isinstance(obj, np.ndarray):
        return json_safe(obj.tolist())
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return json_safe(dataclasses.asdict(obj))
    if isinstance(obj, Mapping):
        return {str(k): json_safe(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple | set | frozenset):
        return [json_safe(v) for v in obj]
    if isinstance(obj, np.generic):
        return json_safe(obj.item())
    raise InputError(f"cannot write a {type(obj).__name__} to JSON: {obj!r}")


@contextmanager
def _atomic(path: Path, mode: str = "w") -> Iterator[IO[Any]]:
    """Open a temporary file next to ``path``; on success move it over ``path``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        kw: dict[str, Any] = {} if "b" in mode else {"encoding": "utf-8", "newline": ""}
        with os.fdopen(fd, mode, **kw) as f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise


def write_json(path: str | os.PathLike[str], obj: Any) -> Path:
    """Write ``json_safe(obj)`` to ``path`` atomically (indented, keys in given order)."""
    p = Path(path)
    text = json.dumps(json_safe(obj), indent=2, allow_nan=False) + "\n"
    with _atomic(p) as f:
        f.write(text)
    return p


def write_frames_csv(path: str | os.PathLike[str], frames: FrameLog) -> Path:
    """Write the log as CSV (header = column names, flags as 0/1) atomically."""
    p = Path(path)
    cols = []
    for name, dtype in COLUMNS:
        a = getattr(frames, name)
        cols.append(a.astype(np.int64).tolist() if dtype is np.bool_ else a.tolist())
    with _atomic(p) as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow([name for name, _ in COLUMNS])
        w.writerows(zip(*cols, strict=True))
    return p


def read_frames_csv(path: str | os.PathLike[str]) -> FrameLog:
    """Read a log written by :func:`write_frames_csv`.

    Raises
    ------
    InputError
        The file lacks a column or a value does not parse.
    """
    p = Path(path)
    with p.open(encoding="utf-8", newline="") as f:
        rows = list(csv.reader(f))
    if not rows:
        raise InputError(f"{p}: empty file, expected a header row")
    header = rows[0]
    missing = [name for name, _ in COLUMNS if name not in header]
    if missing:
        raise InputError(f"{p}: missing columns {missing}")
    body = rows[1:]
    out: dict[str, Any] = {}
    for name, dtype in COLUMNS:
        j = header.index(name)
        try:
            vals = [r[j] for r in body]
            if dtype is np.bool_:
                out[name] = np.array([int(v) for v in vals], np.int64).astype(np.bool_)
            elif dtype is np.int64:
                out[name] = np.array([int(v) for v in vals], np.int64)
            else:
                out[name] = np.array([float(v) for v in vals], np.float64)
        except (ValueError, IndexError) as exc:
            raise InputError(f"{p}: column {name!r}: {exc}") from exc
    return FrameLog(**out)


def _bytes_arrays(bytes_log: BytesLog | None) -> tuple[F64, F64]:
    if bytes_log is None:
        return np.empty(0), np.empty(0)
    t = np.asarray(bytes_log[0], dtype=np.float64).reshape(-1)
    b = np.asarray(bytes_log[1], dtype=np.float64).reshape(-1)
    if t.shape != b.shape:
        raise InputError(
            f"bytes log: {t.shape[0]} times but {b.shape[0]} byte counts (must be equal)"
        )
    return t, b


def write_bytes_csv(path: str | os.PathLike[str], bytes_log: BytesLog | None) -> Path:
    """Write the link's ``(t, cumulative bytes)`` samples as CSV atomically."""
    p = Path(path)
    t, b = _bytes_arrays(bytes_log)
    with _atomic(p) as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(["t", "bytes"])
        w.writerows(zip(t.tolist(), b.astype(np.int64).tolist(), strict=True))
    return p


def read_bytes_csv(path: str | os.PathLike[str]) -> tuple[F64, NDArray[np.int64]]:
    """Read a bytes log written by :func:`write_bytes_csv`."""
    p = Path(path)
    try:
        data = np.loadtxt(p, delimiter=",", skiprows=1, ndmin=2, dtype=np.float64)
    except ValueError as exc:
        raise InputError(f"{p}: {exc}") from exc
    if data.size == 0:
        return np.empty(0), np.empty(0, np.int64)
    if data.shape[1] != 2:
        raise InputError(f"{p}: expected 2 columns (t, bytes), got {data.shape[1]}")
    return data[:, 0].copy(), data[:, 1].astype(np.int64)


def load_run(
    report_dir: str | os.PathLike[str],
) -> tuple[dict[str, Any], FrameLog, tuple[F64, NDArray[np.int64]]]:
    """Read back ``(summary, frames, bytes_log)`` of a folder written by :func:`write_report`."""
    d = Path(report_dir)
    try:
        summary = json.loads((d / "report.json").read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        raise InputError(f"{d}: cannot read report.json: {exc}") from exc
    bytes_log = (
        read_bytes_csv(d / "bytes.csv")
        if (d / "bytes.csv").exists()
        else (np.empty(0), np.empty(0, np.int64))
    )
    return summary, read_frames_csv(d / "frames.csv"), bytes_log


# --------------------------------------------------------------------------- headline


def _ratio(v: Any) -> str:
    return f"{100.0 * v:.2f} %"


def _fmt_bytes(v: Any) -> str:
    return f"{int(v):,} B ({v / 1000.0:,.1f} kB)"


# (key, label, formatter): what the page and the CLI show first, when present.
_HEADLINE: tuple[tuple[str, str, Callable[[Any], str]], ...] = (
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
    ("recovery_frames", "recovery after cost step", lambda v: f"{int(v)} frames"),
)


def headline_rows(summary: Mapping[str, Any]) -> list[tuple[str, str, str]]:
    """``(key, label, formatted value)`` of the headline figures present in ``summary``.

    A key that is present with value ``None`` shows as ``"n/a"``.
    """
    rows = []
    for key, label, fmt in _HEADLINE:
        if key not in summary:
            continue
        v = summary[key]
        if isinstance(v, float) and not math.isfinite(v):
            v = None
        rows.append((key, label, "n/a" if v is None else fmt(v)))
    return rows


def format_headline(summary: Mapping[str, Any]) -> str:
    """The headline figures as aligned ``label  value`` lines (for the CLI)."""
    rows = headline_rows(summary)
    if not rows:
        return ""
    w = max(len(label) for _, label, _ in rows)
    return "\n".join(f"{label:<{w}}  {value}" for _, label, value in rows)


def format_comparison_table(runs: Sequence[tuple[str, Mapping[str, Any]]]) -> str:
    """A plain-text table: one row per headline figure, one column per run."""
    keys = [k for k, _, _ in _HEADLINE if any(k in s for _, s in runs)]
    labels = {k: label for k, label, _ in _HEADLINE}
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


# --------------------------------------------------------------------------- plotting


@dataclasses.dataclass(frozen=True, slots=True)
class _Run:
    label: str
    summary: Mapping[str, Any]
    frames: FrameLog
    bytes_t: F64
    bytes_b: F64
    t0: float
    colour: str


def _make_run(
    label: str, summary: Mapping[str, Any], frames: FrameLog, bytes_log: BytesLog | None, i: int
) -> _Run:
    bt, bb = _bytes_arrays(bytes_log)
    if bt.size == 0 and len(frames):
        # No link samples: the per-frame cumulative count is the next best thing.
        bt, bb = frames.t.astype(np.float64), frames.bytes_down.astype(np.float64)
    t0 = summary.get("t_start_s")
    if t0 is None or not math.isfinite(float(t0)):
        starts = [a[0] for a in (frames.t, bt) if a.size]
        t0 = float(min(starts)) if starts else 0.0
    return _Run(label, summary, frames, bt, bb, float(t0), SERIES_COLOURS[i % len(SERIES_COLOURS)])


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


def _figure(
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


def _save(fig: Figure, path: Path) -> Path:
    if fig.get_suptitle():  # keep the figure title clear of the top row's titles
        top = 1.0 - 0.35 / fig.get_figheight()
        fig.tight_layout(rect=(0.0, 0.0, 1.0, top))
    else:
        fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    with _atomic(path, "wb") as f:
        f.write(buf.getvalue())
    return path


def _thousands(ax: Axes) -> None:
    from matplotlib.ticker import FuncFormatter

    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _pos: f"{v:,.0f}"))


def _rate_bins(run: _Run) -> tuple[F64, F64, float]:
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


def _plot_bytes(path: Path, runs: Sequence[_Run], title: str) -> Path:
    fig, (ax_cum, ax_rate) = _figure(2)
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
    return _save(fig, path)


def _quality_axes(ax: Axes, r: _Run, column: str, first: int | None, *, note: bool) -> None:
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


def _plot_quality(path: Path, runs: Sequence[_Run], title: str) -> Path:
    # One row per run, download and rewrite quality side by side (the layout of the
    # paper's Figure 1): overlaid lines that all sit at 100 % would hide each other.
    fig, axes = _figure(len(runs), height=2.4 if len(runs) > 1 else 3.4, cols=2)
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
    return _save(fig, path)


def _plot_fps(path: Path, runs: Sequence[_Run], title: str) -> Path:
    fig, (ax,) = _figure(1, height=4.2)
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
    ax.set_title(title + ("\n" + "; ".join(notes) if notes else ""), fontsize=10)
    _legend(ax, loc="lower right")
    return _save(fig, path)


def _plot_budget(path: Path, runs: Sequence[_Run], title: str) -> Path:
    fig, (ax,) = _figure(1, height=4.2)
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
    return _save(fig, path)


# --------------------------------------------------------------------------- HTML

_CSS = """
body { font-family: system-ui, sans-serif; margin: 1.5em auto; max-width: 1150px; color: #222; }
h1 { font-size: 1.4em; } h2 { font-size: 1.15em; margin-top: 1.6em; }
table { border-collapse: collapse; } td, th { padding: 3px 10px; border-bottom: 1px solid #ddd; }
th { text-align: left; } td.v { text-align: right; font-variant-numeric: tabular-nums; }
figure { margin: 1em 0; } figure img { max-width: 100%; border: 1px solid #ccc; }
figcaption { font-size: 0.9em; color: #555; }
.snaps { display: flex; flex-wrap: wrap; gap: 8px; }
.snaps figure { margin: 0; width: 280px; } .snaps img { width: 100%; }
pre { background: #f6f6f6; padding: 0.8em; overflow-x: auto; font-size: 0.85em; }
.missing { color: #b00; }
"""

_CAPTIONS = {
    "bytes.png": "Bytes downloaded over time: cumulative (top) and rate per time bin (bottom).",
    "quality.png": "Download quality and rewrite quality per frame: the share of the current "
    "cell's PVS whose parameters have arrived / whose geometry is built.",
    "fps.png": "Displayed frame rate per frame, with the target and its +-10 % band; red "
    "crosses are floor-limited frames (the LOD0s alone exceed the budget).",
    "budget.png": "Polygon budget set by the controller and triangles drawn per frame.",
}

_DEFINITIONS = (
    ("perfect frame", "cell known, download and rewrite quality both 100 %"),
    (
        "perfect frames",
        "share of the frames from the first perfect one (included) that are perfect",
    ),
    ("quality means", "mean over all frames, in percent"),
    (
        "frames within 10 %",
        "frames after the first second, floor-limited ones left out, whose displayed "
        "frame rate is within 10 % of target, or above it with everything visible at LOD2",
    ),
    ("displayed frame rate", "1 / max(frame time, 1 / tick rate)"),
)


def _url(rel: str) -> str:
    return quote(rel.replace(os.sep, "/"))


def _headline_table(summary: Mapping[str, Any]) -> str:
    rows = "".join(
        f"<tr><th>{html.escape(label)}</th><td class='v'>{html.escape(value)}</td></tr>"
        for _, label, value in headline_rows(summary)
    )
    return f"<table>{rows}</table>"


def _page(title: str, body: str) -> str:
    return (
        "<!doctype html>\n<html lang='en'><head><meta charset='utf-8'>"
        f"<title>{html.escape(title)}</title><style>{_CSS}</style></head>\n"
        f"<body><h1>{html.escape(title)}</h1>\n{body}\n</body></html>\n"
    )


def _figures(names: Sequence[str], captions: Mapping[str, str]) -> str:
    return "\n".join(
        f"<figure><img src='{_url(n)}' alt='{html.escape(n)}'>"
        f"<figcaption>{html.escape(captions.get(n, n))}</figcaption></figure>"
        for n in names
    )


def _place_snapshots(
    out: Path, snapshots: Sequence[str | os.PathLike[str]]
) -> list[tuple[str, bool]]:
    """Relative paths of the snapshots under ``out`` (copied in when they lie outside).

    Returns ``(relative path, exists)``; a missing snapshot is logged and listed, not fatal,
    so that a long replay still gets its report.
    """
    placed: list[tuple[str, bool]] = []
    used: set[str] = set()
    root = out.resolve()
    for s in snapshots:
        p = Path(s)
        if not p.is_file():
            log.warning("snapshot %s does not exist; listed as missing in the report", p)
            placed.append((os.fspath(p), False))
            continue
        rp = p.resolve()
        if rp.is_relative_to(root):
            rel = rp.relative_to(root).as_posix()
        else:
            name = p.name
            stem, k = p.stem, 1
            while f"snapshots/{name}" in used:
                name, k = f"{stem}_{k}{p.suffix}", k + 1
            rel = f"snapshots/{name}"
            with _atomic(out / rel, "wb") as f, rp.open("rb") as src:
                shutil.copyfileobj(src, f)
        used.add(rel)
        placed.append((rel, True))
    return placed


def _snapshot_section(placed: Sequence[tuple[str, bool]]) -> str:
    if not placed:
        return ""
    items = []
    for rel, ok in placed:
        if ok:
            items.append(
                f"<figure><a href='{_url(rel)}'><img src='{_url(rel)}' loading='lazy' "
                f"alt='{html.escape(rel)}'></a><figcaption>{html.escape(Path(rel).name)}"
                "</figcaption></figure>"
            )
        else:
            items.append(f"<p class='missing'>missing snapshot: {html.escape(rel)}</p>")
    return f"<h2>Snapshots ({len(placed)})</h2><div class='snaps'>{''.join(items)}</div>"


# --------------------------------------------------------------------------- entry points


def write_report(
    out_dir: str | os.PathLike[str],
    summary: Mapping[str, Any],
    log: FrameLog,
    bytes_log: BytesLog | None,
    *,
    snapshots: Sequence[str | os.PathLike[str]] = (),
    title: str = "walkstream replay",
) -> Path:
    """Write the report folder of one replay and return the path of its ``index.html``.

    Parameters
    ----------
    out_dir : path
        The report folder; created when missing.  Files of an earlier report there are
        replaced one by one, each atomically.
    summary : mapping
        The figures (:func:`client.metrics.summarise` plus the replay's own keys);
        written as ``report.json``.  ``t_start_s`` sets the origin of the time axes.
    log : FrameLog
        The frames.
    bytes_log : (t, cumulative bytes) arrays, or None
        The link's samples; when missing or empty, the log's ``bytes_down`` is plotted.
    snapshots : sequence of paths
        PNG frames to show.  Those inside ``out_dir`` are linked where they are; others
        are copied into ``out_dir/snapshots/``; missing ones are listed as missing.
    title : str
        Heading of the page and the plots.

    Returns
    -------
    Path
        ``out_dir/index.html``.

    Raises
    ------
    InputError
        The summary holds something that cannot be written as JSON, or the bytes
        log's arrays differ in length.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    safe = json_safe(summary)  # fail before writing anything when it is not serialisable
    run = _make_run(title, safe, log, bytes_log, 0)
    write_frames_csv(out / "frames.csv", log)
    write_bytes_csv(out / "bytes.csv", bytes_log)
    _plot_bytes(out / "bytes.png", [run], f"{title}: bytes downloaded")
    _plot_quality(out / "quality.png", [run], f"{title}: download and rewrite quality per frame")
    _plot_fps(out / "fps.png", [run], f"{title}: frame rate")
    _plot_budget(out / "budget.png", [run], f"{title}: polygon budget")
    placed = _place_snapshots(out, snapshots)
    write_json(out / "report.json", safe)
    summary_json = json.dumps(safe, indent=2, allow_nan=False)
    body = "\n".join(
        [
            _headline_table(safe),
            "<p>Files: <a href='report.json'>report.json</a> · <a href='frames.csv'>frames.csv</a>"
            " (one row per frame) · <a href='bytes.csv'>bytes.csv</a> (link samples)</p>",
            "<h2>Plots</h2>",
            _figures(PLOT_NAMES, _CAPTIONS),
            _snapshot_section(placed),
            "<h2>Definitions</h2><ul>"
            + "".join(
                f"<li><b>{html.escape(k)}</b>: {html.escape(v)}</li>" for k, v in _DEFINITIONS
            )
            + "</ul>",
            f"<h2>Summary (report.json)</h2><pre>{html.escape(summary_json)}</pre>",
        ]
    )
    index = out / "index.html"
    with _atomic(index) as f:
        f.write(_page(title, body))
    return index


def write_comparison(
    out_dir: str | os.PathLike[str],
    runs: Sequence[
        tuple[str, Mapping[str, Any], FrameLog, BytesLog | None]
        | tuple[str, Mapping[str, Any], FrameLog, BytesLog | None, str | os.PathLike[str] | None]
    ],
    title: str = "walkstream stream benchmark",
    *,
    reports: Mapping[str, str | os.PathLike[str]] | None = None,
) -> list[Path]:
    """Overlay several replays (the stream benchmark's Figure 1) in one folder.

    Writes ``compare_bytes.png`` (bytes over time, all runs overlaid),
    ``compare_quality.png`` (download and rewrite quality per frame, one panel per
    run), ``compare_fps.png``, ``compare_budget.png``, ``comparison.json``
    (``{"title", "runs": [{"label", "report", "summary"}]}``) and ``index.html`` (a
    table of the runs' headline figures, the plots, links to each run's own report).

    Parameters
    ----------
    out_dir : path
        Folder to write into (created when missing).
    runs : sequence of (label, summary, FrameLog, bytes log[, report folder])
        The runs, in legend order; labels must be distinct.  An optional fifth item
        is the run's own report folder (``None`` for none), as with ``reports``.
    title : str
        Heading of the page and the plots.
    reports : mapping label -> folder, optional
        Each run's own report folder (from :func:`write_report`), linked from the page;
        overrides a folder given in ``runs``.

    Returns
    -------
    list of Path
        The files written, ``index.html`` last.

    Raises
    ------
    InputError
        No runs, repeated labels, or a report folder for an unknown label.
    """
    if not runs:
        raise InputError("write_comparison needs at least one run")
    for r in runs:
        if len(r) not in (4, 5):
            raise InputError(
                f"a run is (label, summary, log, bytes_log[, report folder]), got {len(r)} items"
            )
    labels = [r[0] for r in runs]
    if len(set(labels)) != len(labels):
        raise InputError(f"run labels must be distinct, got {labels}")
    unknown = sorted(set(reports or {}) - set(labels))
    if unknown:
        raise InputError(f"reports given for unknown run labels {unknown}; runs are {labels}")
    folders: dict[str, str | os.PathLike[str]] = {
        r[0]: r[4] for r in runs if len(r) == 5 and r[4] is not None
    }
    folders.update(reports or {})
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    safe = [json_safe(r[1]) for r in runs]
    prepared = [
        _make_run(r[0], s, r[2], r[3], i) for i, (r, s) in enumerate(zip(runs, safe, strict=True))
    ]
    written = [
        _plot_bytes(out / "compare_bytes.png", prepared, f"{title}: bytes downloaded"),
        _plot_quality(out / "compare_quality.png", prepared, f"{title}: quality per frame"),
        _plot_fps(out / "compare_fps.png", prepared, f"{title}: frame rate"),
        _plot_budget(out / "compare_budget.png", prepared, f"{title}: polygon budget"),
    ]
    links: dict[str, str] = {}
    for label, d in folders.items():
        rel = os.path.relpath(Path(d) / "index.html", out)
        links[label] = rel.replace(os.sep, "/")
    written.append(
        write_json(
            out / "comparison.json",
            {
                "title": title,
                "runs": [
                    {"label": label, "report": links.get(label), "summary": s}
                    for label, s in zip(labels, safe, strict=True)
                ],
            },
        )
    )
    # Table: one row per headline figure, one column per run.
    keys = [k for k, _, _ in _HEADLINE if any(k in s for s in safe)]
    names = {k: label for k, label, _ in _HEADLINE}
    vals = [{k: v for k, _, v in headline_rows(s)} for s in safe]
    head = "".join(
        "<th>"
        + (
            f"<a href='{_url(links[label])}'>{html.escape(label)}</a>"
            if label in links
            else html.escape(label)
        )
        + "</th>"
        for label in labels
    )
    rows = "".join(
        f"<tr><th>{html.escape(names[k])}</th>"
        + "".join(f"<td class='v'>{html.escape(v.get(k, ''))}</td>" for v in vals)
        + "</tr>"
        for k in keys
    )
    captions = {
        "compare_bytes.png": "Bytes downloaded over time, all runs.",
        "compare_quality.png": "Download and rewrite quality per frame, one panel per run.",
        "compare_fps.png": "Displayed frame rate over time, all runs.",
        "compare_budget.png": "Polygon budget (solid) and triangles drawn (dashed), all runs.",
    }
    run_links = (
        "<h2>Run reports</h2><ul>"
        + "".join(
            f"<li><a href='{_url(links[label])}'>{html.escape(label)}</a></li>"
            for label in labels
            if label in links
        )
        + "</ul>"
        if links
        else ""
    )
    body = "\n".join(
        [
            f"<table><tr><th></th>{head}</tr>{rows}</table>",
            "<p>Data: <a href='comparison.json'>comparison.json</a></p>",
            run_links,
            "<h2>Plots</h2>",
            _figures([p.name for p in written[:4]], captions),
        ]
    )
    index = out / "index.html"
    with _atomic(index) as f:
        f.write(_page(title, body))
    written.append(index)
    return written
