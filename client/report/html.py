"""The report folder of a replay (and the overlay of several) with its self-contained index page."""

from __future__ import annotations

import html
import json
import logging
import os
import shutil
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any
from urllib.parse import quote

from walkstream.client.report.framelog import FrameLog
from walkstream.shared.errors import InputError

if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import NDArray

    from walkstream.client.truth.recorder import TruthResult
from walkstream.client.report.colourview import write_colour_worst
from walkstream.client.report.files import (
    BytesLog,
    atomic_open,
    json_safe,
    write_bytes_csv,
    write_frames_csv,
    write_json,
)
from walkstream.client.report.phases import plot_phases, write_phases_csv
from walkstream.client.report.plots import (
    BASE_PLOT_NAMES,
    make_run,
    plot_budget,
    plot_bytes,
    plot_error,
    plot_fps,
    plot_quality,
)
from walkstream.client.report.tables import HEADLINE, headline_rows
from walkstream.client.report.truth import write_truth_csv
from walkstream.client.truth.compare import CAUSE_RGB, CAUSES

__all__ = ["log", "write_report", "write_comparison"]

log = logging.getLogger(__name__)


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
    "phases.png": "Where the frame loop's wall time goes, per frame (top, mean per time bin, "
    "stacked) and its median (bottom): streaming tick, culling, LOD allocation, buffer "
    "uploads, draw calls, finish (waiting for the device to draw), the rest of the loop, and "
    "other (event loop, rebuilding threads, waiting for the tick).",
    "interior.png": "An interior walk per frame: visible cells and portals opened, triangles "
    "drawn, culling CPU milliseconds (cells and parts), and the fog distance in force (set by "
    "the budget controller, tightened when the visible cells exceed the memory budget).",
    "error.png": "The frame rate (top) and, for every compared frame, the share of its pixels "
    "that differ from the ground truth (line) and the pixels where the truth shows an object "
    "the client's frame does not, stacked by cause (middle); on a city walk the colour error of "
    "the client's picture against the full scene (bottom): the mean linear-RGB error per pixel "
    "(line, % of full scale) and the pixels over the visible CIEDE2000 threshold, stacked by cause "
    "(per pixel; with replay --viewer-ppd also at the viewer's scale, as a dashed line).",
    "culled.png": "A walk with rooms: for every compared frame, the pixels where the truth shows "
    "a part the frame culled (must be 0; pinholes apart) and the pinholes; crosses mark poses "
    "refused as in solid geometry.",
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


_NO_PLOTS = "<p class='missing'>Plots not drawn (<code>--no-plots</code>): the figures are in the CSV files.</p>"


def _figures(names: Sequence[str], captions: Mapping[str, str], plots: bool = True) -> str:
    if not plots:
        return _NO_PLOTS
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
            with atomic_open(out / rel, "wb") as f, rp.open("rb") as src:
                shutil.copyfileobj(src, f)
        used.add(rel)
        placed.append((rel, True))
    return placed


def _save_png(path: Path, rgb: Any) -> None:
    from PIL import Image

    with atomic_open(path, "wb") as f:
        Image.fromarray(rgb, "RGB").save(f, format="PNG")


def _truth_section(out: Path, summary: Mapping[str, Any], truth: TruthResult | None, plots: bool = True) -> str:
    """The ground-truth part of the page: figures, error.png, the worst frame; files written here."""
    if truth is None:
        return ""
    s = summary.get("truth") or {}
    parts = ["<h2>Ground truth</h2>"]
    if truth.error:
        parts.append(f"<p class='missing'>no ground truth: {html.escape(truth.error)}</p>")
    if truth.culled:
        parts.append(_culled_section(out, s, truth, plots))
        if len(truth.log):  # the colour error against the full scene without fog
            write_truth_csv(out / "truth.csv", truth.log)
            pct = _pct
            rows = _colour_rows(s.get("colour"), pct)
            parts.append(
                "<h3>Colour error against the full scene (no fog)</h3><table>"
                + "".join(f"<tr><th>{html.escape(k)}</th><td class='v'>{html.escape(v)}</td></tr>" for k, v in rows)
                + "</table><p>Per compared frame: <a href='truth.csv'>truth.csv</a></p>"
            )
            parts.append(_figures(["error.png"], _CAPTIONS, plots))
        if truth.colour_worst is not None:
            parts.append(write_colour_worst(out, truth.colour_worst, plots))
        return "\n".join(parts)
    write_truth_csv(out / "truth.csv", truth.log)

    pct = _pct
    rows = [
        ("frames compared", str(s.get("frames", 0))),
        ("differing pixels, mean", pct(s.get("differing_pixels_mean"))),
        ("frames missing > 0.5 % (from the first perfect frame)", pct(s.get("over_half_percent_ratio"))),
        (
            "frames whose PVS misses > 0.01 % (from the first perfect frame)",
            pct(s.get("pvs_over_hundredth_percent_ratio")),
        ),
    ]
    for name, b in (s.get("below_horizon") or {}).items():
        rows.append(
            (f"below the horizon: {name.replace('_', ' ')} (mean / p95 / max)",
             " / ".join(pct(b.get(k)) for k in ("mean", "p95", "max")))
        )
    for c in CAUSES:
        m = (s.get("missing") or {}).get(c) or {}
        rows.append(
            (f"missing: {c} (mean / p95 / max)", " / ".join(pct(m.get(k)) for k in ("mean", "p95", "max")))
        )
    rows += _colour_rows(s.get("colour"), pct)
    parts.append(
        "<table>"
        + "".join(f"<tr><th>{html.escape(k)}</th><td class='v'>{html.escape(v)}</td></tr>" for k, v in rows)
        + "</table><p>Per compared frame: <a href='truth.csv'>truth.csv</a></p>"
    )
    parts.append(_figures(["error.png"], _CAPTIONS, plots))
    w = truth.worst
    if w is not None:
        (out / "truth").mkdir(exist_ok=True)
        names = {"client": "worst_client.png", "truth": "worst_truth.png", "mask": "worst_missing.png"}
        for key, name in names.items():
            _save_png(out / "truth" / name, getattr(w, key))
        legend = ", ".join(
            f"<span style='color:rgb{CAUSE_RGB[c]}'>&#9632;</span> {html.escape(c)}" for c in CAUSES
        )
        caps = {
            "client": "the client's frame",
            "truth": "the ground truth (every object within the view distance at LOD2)",
            "mask": "missing pixels by cause",
        }
        figs = "".join(
            f"<figure><a href='truth/{names[k]}'><img src='truth/{names[k]}' alt='{k}'></a>"
            f"<figcaption>{html.escape(caps[k])}</figcaption></figure>"
            for k in ("client", "truth", "mask")
        )
        parts.append(
            f"<h3>Worst compared frame: frame {w.frame} at {w.t:.2f} s, "
            f"{100.0 * float(w.missing[:5].sum()):.3f} % of its pixels missing, "
            f"{100.0 * w.differing:.2f} % differing</h3>"
            f"<div class='snaps'>{figs}</div><p>Mask colours: {legend}</p>"
        )
    if truth.colour_worst is not None:
        parts.append(write_colour_worst(out, truth.colour_worst, plots))
    return "\n".join(parts)


def _pct(v: Any) -> str:
    return "n/a" if v is None else f"{100.0 * v:.3f} %"


def _colour_rows(c: Mapping[str, Any] | None, pct: Callable[[Any], str]) -> list[tuple[str, str]]:
    """The colour figures' rows of the ground-truth table (none without them)."""
    if not c or not c.get("frames"):
        return []
    me, vp, ps = c.get("mean_error") or {}, c.get("visible_pixels") or {}, c.get("psnr_db") or {}
    de = c.get("delta_e_mean") or {}

    def num(v: Any, unit: str) -> str:
        return "n/a" if v is None else f"{v:.2f}{unit}"

    ic = c.get("impostor") or {}
    imp = [] if not c.get("error_causes", {}).get("impostor") and not (ic.get("visible") or {}).get("max") else [
        ("error from impostors, % of full scale (median / p99 / max)",
         " / ".join(pct((ic.get("error") or {}).get(k)) for k in ("median", "p99", "max"))),
        ("pixels wrong where an impostor stands in (median / p99 / max)",
         " / ".join(pct((ic.get("visible") or {}).get(k)) for k in ("median", "p99", "max"))),
        ("frames within 1 % error and 0.5 % pixels from impostors", pct(ic.get("frames_within_ratio"))),
    ]
    if imp and ic.get("visible_scielab") is not None:
        imp += [
            ("pixels wrong where an impostor stands in, viewer's scale (median / p99 / max)",
             " / ".join(pct((ic.get("visible_scielab") or {}).get(k)) for k in ("median", "p99", "max"))),
            ("frames within 1 % error and 0.5 % pixels from impostors, viewer's scale",
             pct(ic.get("frames_within_scielab_ratio"))),
        ]
    sv = c.get("visible_scielab_pixels")
    scielab = [] if sv is None else [
        (f"pixels over dE00 {c.get('visible_scielab_threshold')} at the viewer's scale (S-CIELAB, "
         f"{num(c.get('viewer_ppd'), ' px/deg')}; median / p95 / max)", " / ".join(pct(sv.get(k)) for k in ("median", "p95", "max"))),
        ("frames with > 0.5 % of pixels over it at the viewer's scale", pct(c.get("frames_over_visible_scielab_ratio"))),
    ]
    return [
        ("colour error, linear RGB, % of full scale (median / p95 / max)", " / ".join(pct(me.get(k)) for k in ("median", "p95", "max"))),
        ("mean dE00 per pixel (median / p95 / max)", " / ".join(num(de.get(k), "") for k in ("median", "p95", "max"))),
        (f"pixels over dE00 {c.get('visible_threshold')} (median / p95 / max)", " / ".join(pct(vp.get(k)) for k in ("median", "p95", "max"))),
        ("frames with > 0.5 % of pixels over it", pct(c.get("frames_over_visible_ratio"))),
        *scielab,
        ("PSNR (median / worst 5 % / min)", " / ".join(num(ps.get(k), " dB") for k in ("median", "p5", "min"))),
        *imp,
    ]


def _culled_section(out: Path, s: Mapping[str, Any], truth: TruthResult, plots: bool = True) -> str:
    """A walk with rooms: its culled-pixel figures, ``culled.png`` and the worst frame
    beside its truth with a mask of its culled pixels coloured by cell."""
    from walkstream.client.report.plots import plot_culled
    from walkstream.client.truth.culledview import PINHOLE_RGB, cell_rgb

    rows = truth.culled
    if plots:
        plot_culled(out / "culled.png", [r.t for r in rows], [r.culled_pixels for r in rows],
                    [r.pinholes for r in rows], [r.refused for r in rows], "culled pixels per compared frame")
    keys = ("frames", "culled_pixels", "culled_frames", "pinholes", "refused_poses", "tightness_p95")
    table = "".join(f"<tr><th>{html.escape(k)}</th><td class='v'>{html.escape(str(s.get(k)))}</td></tr>"
                    for k in keys if k in s)
    parts = [f"<table>{table}</table>", _figures(["culled.png"], _CAPTIONS, plots)]
    w = truth.culled_worst
    if w is None:
        parts.append("<p>No compared frame culled a pixel the truth shows (nor a pinhole).</p>")
        return "\n".join(parts)
    (out / "truth").mkdir(exist_ok=True)
    names = {"client": "worst_client.png", "truth": "worst_truth.png", "mask": "worst_culled.png"}
    for key, name in names.items():
        _save_png(out / "truth" / name, getattr(w, key))
    caps = {"client": "the client's frame (what it drew)", "truth": "the ground truth (every room part)",
            "mask": "culled pixels coloured by the cell shown there; pinholes white"}
    figs = "".join(
        f"<figure><a href='truth/{names[k]}'><img src='truth/{names[k]}' alt='{k}'></a>"
        f"<figcaption>{html.escape(caps[k])}</figcaption></figure>"
        for k in ("client", "truth", "mask")
    )
    legend = ", ".join(f"<span style='color:rgb{cell_rgb(c)}'>&#9632;</span> cell {c}" for c in w.cells[:12])
    legend += f", <span style='color:rgb{PINHOLE_RGB}'>&#9632;</span> pinhole"
    parts.append(f"<h3>Worst compared frame: frame {w.frame} at {w.t:.2f} s, {w.culled_pixels:,} culled pixels, "
                 f"{w.pinholes} pinholes</h3><div class='snaps'>{figs}</div><p>Mask colours: {legend}</p>")
    return "\n".join(parts)


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
    truth: TruthResult | None = None,
    phases: NDArray[np.float64] | None = None,
    interior: Mapping[str, NDArray[np.float64]] | None = None,
    plots: bool = True,
) -> Path:
    """Write the report folder of one replay and return the path of its ``index.html``.

    Parameters
    ----------
    out_dir : path
        The report folder; created when missing.  Files of an earlier report there are
        replaced one by one, each atomically.
    summary : mapping
        The figures (:func:`~walkstream.client.report.metrics.summarise` plus the replay's own keys);
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
    truth : TruthResult, optional
        The frames compared with the ground truth: adds ``error.png``, ``truth.csv``
        and the worst compared frame (``truth/*.png``) with its truth and its missing
        pixels to the page.
    phases : (frames, len(PHASES)) float, optional
        Seconds per phase of the frame loop per frame
        (:data:`~walkstream.client.draw.phases.PHASES`): adds ``phases.csv`` and
        ``phases.png``.
    interior : dict of (frames,) arrays, optional
        An interior walk's ``cells``, ``portals``, ``triangles``, ``cull_ms``,
        ``fog_m`` per frame: adds ``interior.png``.
    plots : bool
        False: no plot is drawn (``replay --no-plots``), only the figures, the CSV files
        and the worst frames' pictures; drawing the plots is most of a report's time.

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
    run = make_run(title, safe, log, bytes_log, 0)
    write_frames_csv(out / "frames.csv", log)
    write_bytes_csv(out / "bytes.csv", bytes_log)
    if plots:
        plot_bytes(out / "bytes.png", [run], f"{title}: bytes downloaded")
        plot_quality(out / "quality.png", [run], f"{title}: download and rewrite quality per frame")
        plot_fps(out / "fps.png", [run], f"{title}: frame rate")
        plot_budget(out / "budget.png", [run], f"{title}: polygon budget")
    names = list(BASE_PLOT_NAMES)
    if phases is not None and len(phases) == len(log.t):
        write_phases_csv(out / "phases.csv", log.t, phases)
        if plots:
            plot_phases(
                out / "phases.png", log.t - run.t0, phases, f"{title}: frame loop time per phase"
            )
        names.append("phases.png")
    if interior is not None and len(log.t):
        from walkstream.client.report.plots import plot_interior

        if plots:
            plot_interior(out / "interior.png", log.t - run.t0, dict(interior), f"{title}: cells, culling and fog")
        names.append("interior.png")
    if plots and truth is not None and (not truth.culled or len(truth.log)):
        plot_error(out / "error.png", run, truth.log, f"{title}: frame rate and image error against the truth")
    truth_html = _truth_section(out, safe, truth, plots)
    placed = _place_snapshots(out, snapshots)
    write_json(out / "report.json", safe)
    summary_json = json.dumps(safe, indent=2, allow_nan=False)
    body = "\n".join(
        [
            _headline_table(safe),
            "<p>Files: <a href='report.json'>report.json</a> · <a href='frames.csv'>frames.csv</a>"
            " (one row per frame) · <a href='bytes.csv'>bytes.csv</a> (link samples)</p>",
            "<h2>Plots</h2>",
            _figures(names, _CAPTIONS, plots),
            truth_html,
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
    with atomic_open(index) as f:
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
        make_run(r[0], s, r[2], r[3], i) for i, (r, s) in enumerate(zip(runs, safe, strict=True))
    ]
    written = [
        plot_bytes(out / "compare_bytes.png", prepared, f"{title}: bytes downloaded"),
        plot_quality(out / "compare_quality.png", prepared, f"{title}: quality per frame"),
        plot_fps(out / "compare_fps.png", prepared, f"{title}: frame rate"),
        plot_budget(out / "compare_budget.png", prepared, f"{title}: polygon budget"),
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
    keys = [k for k, _, _ in HEADLINE if any(k in s for s in safe)]
    names = {k: label for k, label, _ in HEADLINE}
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
    with atomic_open(index) as f:
        f.write(_page(title, body))
    written.append(index)
    return written
