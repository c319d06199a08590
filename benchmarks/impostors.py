"""``walkstream bench impostors``: the same walks with and without impostors on scenes baked with ``--impostors``.

Each walk (``--path``, default SE, at 56 kbit/s / 200 ms unless told) is replayed twice on
each database and one device: drawing the far buildings the cell records list as their
images, and geometry only (``ReplayConfig.impostors`` off: the same cell records, no
image asked for); ``--facades both`` replays each of them again with plain boxes
(``ReplayConfig.facades`` off), ``fac/fr`` counts the boxes drawn with facade textures.  Several databases (bakes of one city at other D, A and S, or of
another scene) make a sweep: each row is labelled with its bake's D, A and S (read from
the database's settings record).  One table: frames within 10 % of the target rate, the
frame time the device took (median), triangles per frame, impostors per frame, bytes
down (all, and the images' share), texture bytes per frame, perfect frames, and with
``--truth-every`` the colour error against the full scene (median and p95 of the mean
linear-RGB error, the pixels over ΔE00 2.3, the frames over the visible threshold, PSNR,
and the error split by cause: the boxes' ``lod_colour``, ``impostor``, the rest) and the
pop at the switch (``pop``: the mean frame-to-frame change of the pixels of buildings
switching between image and geometry over that of the buildings in plain motion on the
same frame pairs, :mod:`walkstream.client.truth.pop`; at most 1: no pop; it compares
successive compared frames, so ``--truth-every 1`` measures it frame to frame; ``pop~``
the same against plain motion of objects of the same size on screen, ``ratio_matched``;
``pop=`` the switch's own change against the same buildings' own motion on the same
frames, ``ratio_own``, the like-with-like reading);
the impostors' own error frame by frame (``imp p99``: the 99th percentile over the
compared frames of the frame's mean error from impostors, % of full scale; ``impv p99``:
of the share of its pixels visibly wrong where an impostor stands in; ``imp ok%``: the
frames within 1 % and 0.5 %, the issue's figure asks 99 %);
``bench_impostors.png`` plots the colour error against the frame time, one point a row.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from walkstream.shared.errors import WalkstreamError

__all__ = ["bake_label", "format_impostor_table", "plot_impostors", "run_impostor_bench"]

Replayer = Callable[[str, dict[str, Any], str], Any]


def bake_label(db: str) -> str:
    """``city D250 A2 S128``: a database's file stem and the D, A, S of its settings record
    (`` persp`` after them for perspective images)."""
    from walkstream.server.store import SceneReader

    if db.startswith(("http://", "https://")):
        return db.rstrip("/").rsplit("/", 1)[-1]
    try:
        reader = SceneReader.open(Path(db))
    except WalkstreamError:
        return Path(db).stem
    try:
        st = (reader.meta.settings or {}).get("impostors")
    finally:
        reader.close()
    if not st:
        return f"{Path(db).stem} (no impostors)"
    persp = " persp" if st.get("projection") == "perspective" else ""
    return f"{Path(db).stem} D{float(st['distance']):g} A{float(st['error_deg']):g} S{int(st['size'])}{persp}"


def run_impostor_bench(
    db: str | Sequence[str],
    replay: Replayer,
    *,
    out: Path,
    paths: Sequence[str] = ("SE",),
    device: str = "pda",
    truth_every: int = 0,
    duration: str | None = None,
    link: dict[str, Any] | None = None,
    size: str | None = None,
    extra: Mapping[str, Any] | None = None,
    facades: Sequence[bool | None] = (None,),
) -> list[dict[str, Any]]:
    """Replay each of ``paths`` on each of ``db`` with and without impostors (and with each
    of ``facades``: facade textures on the boxes, plain boxes, or None: the replay's
    default, on a simulated device only); one row (summary,
    ``scenario``, ``walk``, ``bake``, ``with_impostors``, ``with_facades``,
    ``frame_time_median_ms``) per replay that ran; ``bench_impostors.json`` and
    ``bench_impostors.png`` into ``out``."""
    dbs = [db] if isinstance(db, str) else list(db)
    rows = []
    runs = [(d, p, fac, imp) for d in dbs for p in paths for fac in facades for imp in (True, False)]
    labels = {d: bake_label(d) for d in dbs}
    for k, (d, path, fac, imp) in enumerate(runs, 1):
        name = f"{path} {'impostors' if imp else 'geometry'}{' boxes' if fac is False else ''}"
        options: dict[str, Any] = {"device": device, "path": path, **(link or {}), **(extra or {}), "impostors": imp,
                                   **({} if fac is None else {"facades": "on" if fac else "off"}),
                                   "report": str(out / f"{k:02d}-{name.replace(' ', '-').lower()}")}
        if duration:
            options["duration"] = duration
        if truth_every:
            options["truth_every"] = truth_every
        if size:
            options["size"] = size
        print(f"[{k}/{len(runs)}] {labels[d]}: {name} ...", file=sys.stderr, flush=True)
        try:
            result = replay(d, options, name)
        except WalkstreamError as exc:
            print(f"  {name}: {exc}", file=sys.stderr)
            continue
        ft = np.asarray(getattr(getattr(result, "log", None), "frame_time", []), np.float64)
        rows.append({"scenario": name, "walk": path, "bake": labels[d], "db": d, "with_impostors": imp,
                     "with_facades": fac, **result.summary,
                     "frame_time_median_ms": float(np.median(ft)) * 1e3 if ft.size else None})
    if rows:
        out.mkdir(parents=True, exist_ok=True)
        (out / "bench_impostors.json").write_text(json.dumps(rows, indent=2, default=str))
        if truth_every:
            plot_impostors(out / "bench_impostors.png", rows)
    return rows


def _pct(v: Any, digits: int = 2) -> str:
    return "n/a" if v is None else f"{100 * v:.{digits}f}"


def _colour(r: Mapping[str, Any]) -> dict[str, Any]:
    return dict((r.get("truth") or {}).get("colour") or {})


def format_impostor_table(rows: list[dict[str, Any]]) -> str:
    """One line per replay (see the module docstring)."""
    head = (
        f"{'bake':<24} {'walk':<20} {'device':<6} {'fps10%':>6} {'ft ms':>6} {'tri/fr':>6} {'imp/fr':>6} {'fac/fr':>6} "
        f"{'bytes down':>10} {'images B':>9} {'tex kB max':>10} {'perfect%':>8} {'err% med':>8} {'err% p95':>8} "
        f"{'vis% med':>8} {'over%':>6} {'PSNR med':>8} {'e:boxes':>7} {'e:imp':>6} {'e:rest':>6} {'imp p99':>7} {'impv p99':>8} {'imp ok%':>7} {'pop':>5} {'pop~':>5} {'pop=':>5}"
    )
    lines = [head, "-" * len(head)]
    for r in rows:
        imp = r.get("impostors") or {}
        c = _colour(r)
        err, vis, ps = c.get("mean_error") or {}, c.get("visible_pixels") or {}, (c.get("psnr_db") or {}).get("median")
        ec = c.get("error_causes") or {}
        boxes, by_imp = ec.get("lod_colour"), ec.get("impostor")
        rest = None if not ec else sum(v or 0.0 for v in ec.values()) - (boxes or 0.0) - (by_imp or 0.0)
        ft = r.get("frame_time_median_ms")
        pops = (r.get("truth") or {}).get("pop") or {}
        pop, pop_m, pop_o = pops.get("ratio"), pops.get("ratio_matched"), pops.get("ratio_own")
        ic = c.get("impostor") or {}
        fac = r.get("facades") or {}
        lines.append(
            f"{r.get('bake', ''):<24} {r['scenario']:<20} {r.get('device', '?'):<6} "
            f"{_pct(r.get('fps_within_10pct_ratio'), 1):>6} {'n/a' if ft is None else f'{ft:.1f}':>6} "
            f"{r.get('triangles_mean') or 0:>6.0f} {imp.get('impostors_mean', 0.0):>6.1f} "
            f"{fac.get('facades_mean', 0.0):>6.1f} "
            f"{r.get('bytes_received') or 0:>10,} {imp.get('image_bytes', 0):>9,} "
            f"{imp.get('texture_bytes_max', 0) / 1e3:>10.1f} {_pct(r.get('perfect_frame_ratio')):>8} "
            f"{_pct(err.get('median')):>8} {_pct(err.get('p95')):>8} {_pct(vis.get('median')):>8} "
            f"{_pct(c.get('frames_over_visible_ratio'), 1):>6} "
            f"{'n/a' if ps is None else f'{ps:.1f}':>8} {_pct(boxes):>7} {_pct(by_imp):>6} {_pct(rest):>6} "
            f"{_pct((ic.get('error') or {}).get('p99')):>7} {_pct((ic.get('visible') or {}).get('p99')):>8} "
            f"{_pct(ic.get('frames_within_ratio'), 1):>7} "
            f"{'n/a' if pop is None else f'{pop:.2f}':>5} {'n/a' if pop_m is None else f'{pop_m:.2f}':>5} "
            f"{'n/a' if pop_o is None else f'{pop_o:.2f}':>5}"
        )
    return "\n".join(lines)


def plot_impostors(path: Path, rows: Sequence[Mapping[str, Any]]) -> Path:
    """``bench_impostors.png``: the colour error (median, % of full scale) against the frame
    time (median, ms), one point per row: one colour per bake, filled with impostors, open
    without; each walk's two points joined."""
    from walkstream.client.report.plots import grid_figure, save_figure

    fig, (ax,) = grid_figure(1, height=4.2)
    colours = ["#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9", "#000000"]
    bakes = list(dict.fromkeys(str(r.get("bake", "")) for r in rows))
    pairs: dict[tuple[str, str], list[tuple[float, float]]] = {}
    for r in rows:
        err = (_colour(r).get("mean_error") or {}).get("median")
        ft = r.get("frame_time_median_ms")
        if err is None or ft is None:
            continue
        bake, imp = str(r.get("bake", "")), bool(r.get("with_impostors"))
        fac = r.get("with_facades") is not False
        colour = colours[bakes.index(bake) % len(colours)]
        walk = str(r.get("walk") or str(r["scenario"]).split(" ", 1)[0]) + ("" if fac else " boxes")
        ax.scatter([ft], [100.0 * err], s=46, marker="o" if fac else "s", facecolors=colour if imp else "none",
                   edgecolors=colour, label=f"{bake} {walk} {'impostors' if imp else 'geometry'}", zorder=3)
        pairs.setdefault((bake, walk), []).append((float(ft), 100.0 * float(err)))
    for (bake, _), pts in pairs.items():
        if len(pts) == 2:
            (x0, y0), (x1, y1) = pts
            ax.plot([x0, x1], [y0, y1], color=colours[bakes.index(bake) % len(colours)], lw=0.8, alpha=0.6)
    ax.set_xlabel(f"frame time on the device, ms (median; {rows[0].get('device', '?') if rows else '?'})")
    ax.set_ylabel("colour error vs the full scene,\n% of full scale (median)")
    ax.set_title("bench impostors: one colour per bake; filled with impostors, open geometry only;\n"
                 "circles facade textures on the boxes, squares plain boxes", fontsize=10)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5))
    return save_figure(fig, path)
