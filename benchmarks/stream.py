"""Streaming under the simulated clock, per link and mode: ``walkstream bench stream``.

Each scenario replays a recorded path of the scene (``SE``, ``SM``, ``drive``) through
the whole client over a shaped link on the simulated clock: perfect frames, download
and rewrite quality, the first perfect frame, bytes received, overfetch (objects,
cell records and index tiles never needed for a frame), link utilisation (over the
whole run, and while requests were in flight), re-downloads and rebuilds, one row
each, with one report per row and comparison plots of every row in
``out/index.html``.  A replay is run by the ``replay`` callable the command line
hands in (it alone may wire a server to the client).

More scene databases join the table with ``extra`` (``--scene LABEL=DB[:PATH,...]``
on the command line): each of their recorded paths (or those named) is replayed
over GPRS (5 kB/s, 500 ms) and over 56 kbit/s (200 ms), as rows ``LABEL PATH
GPRS`` and ``LABEL PATH 56k``; ``--vienna DB`` is ``--scene Vienna=DB:walk``.

A crossing scene (``--crossing DB``: a city and an interior joined at an entrance)
adds the street-to-room-and-back walk ``enter`` at 56 kbit/s and over GPRS, each
compared with the ground truth every :data:`CROSSING_TRUTH_EVERY` frames (unless
``truth_every`` says otherwise); :func:`format_crossing_table` prints their own
figures: the visible set's model switches, the doorway's frames without the first
room's contents, and the culled pixels.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from walkstream.client.report import write_comparison
from walkstream.shared.errors import InputError, WalkstreamError

__all__ = [
    "Replayer",
    "GPRS",
    "parse_extra",
    "stream_scenarios",
    "run_stream_bench",
    "format_stream_table",
    "format_truth_table",
    "format_colour_table",
    "CROSSING_TRUTH_EVERY",
    "crossing_scenarios",
    "format_crossing_table",
]

Replayer = Callable[[str, Mapping[str, Any], str], Any]
"""``replay(server, options, title) -> ReplayResult``: one replay with ``walkstream replay``
options (``bandwidth="5kB/s"``, ``report=folder``, ...) over the defaults."""

GPRS: dict[str, Any] = {"bandwidth": "5kB/s", "rtt": "500ms"}
"""The GPRS-class link of m-LOMA: 5 kB/s, 500 ms round trip."""

_FIRST = "first perfect frame"

CROSSING_TRUTH_EVERY = 25
"""The crossing rows compare every this many frames with the ground truth (the issue's measure)."""


def parse_extra(text: str) -> tuple[str, str, tuple[str, ...]]:
    """``LABEL=DB[:PATH,PATH...]`` -> ``(label, db, paths)`` (no paths: all of the scene's).

    >>> parse_extra("wien=out/w.db:walk,drive")
    ('wien', 'out/w.db', ('walk', 'drive'))
    >>> parse_extra("osm=city.db")
    ('osm', 'city.db', ())
    """
    label, eq, rest = text.partition("=")
    if not eq or not label.strip() or not rest.strip():
        raise InputError(f"--scene {text!r}: expected LABEL=DB or LABEL=DB:PATH,PATH")
    db, colon, paths = rest.partition(":")
    names = tuple(p.strip() for p in paths.split(",") if p.strip()) if colon else ()
    return label.strip(), db.strip(), names


def _paths_of(db: str) -> tuple[str, ...]:
    from walkstream.server.store import SceneReader

    r = SceneReader.open(db)
    try:
        return tuple(r.path_names())
    finally:
        r.close()


def stream_scenarios(
    vienna: str | None = None, extra: Sequence[tuple[str, str, Sequence[str]]] = ()
) -> list[dict[str, Any]]:
    """The rows of ``bench stream``: name, server, option overrides, goal."""
    rows: list[dict[str, Any]] = [
        {"name": "SE 56k prefetch", "over": {}, "goal": f"perfect >= 99.5 %, {_FIRST} <= 2 s"},
        {"name": "SE 56k no-prefetch", "over": {"no_prefetch": True}, "goal": "(reported)"},
        {"name": "SE 56k meshes", "over": {"stream": "meshes"}, "goal": "(reported)"},
        {"name": "SE GPRS prefetch", "over": dict(GPRS), "goal": f"perfect >= 99.5 %, {_FIRST} <= 3 s"},
        {"name": "SE GPRS no-prefetch", "over": {**GPRS, "no_prefetch": True}, "goal": "(reported)"},
        {"name": "drive GPRS prefetch", "over": {"path": "drive", **GPRS}, "goal": f"perfect >= 99 %, {_FIRST} <= 3 s"},
        {"name": "drive GPRS no gzip", "over": {"path": "drive", **GPRS, "no_gzip": True}, "goal": "(reported)"},
        {"name": "SM 56k prefetch", "over": {"path": "SM"}, "goal": "(reported)"},
        {"name": "SE 56k cache 8MB", "over": {"cache": "8MB"}, "goal": "re-downloads counted"},
    ]
    scenes: list[tuple[str, str, Sequence[str]]] = [("Vienna", vienna, ("walk",))] if vienna else []
    scenes += list(extra)
    for label, db, paths in scenes:
        assert db is not None
        for path in paths or _paths_of(db):
            rows.append({"name": f"{label} {path} GPRS", "server": db, "over": {"path": path, **GPRS}, "goal": "(reported)"})
            rows.append({"name": f"{label} {path} 56k", "server": db, "over": {"path": path}, "goal": "(reported)"})
    return rows


def crossing_scenarios(db: str, path: str = "enter") -> list[dict[str, Any]]:
    """The crossing walk's rows: ``path`` of the crossing scene ``db`` at 56 kbit/s and over GPRS."""
    both = "no door frame without the first room, culled pixels 0"
    return [
        {"name": f"crossing {path} 56k", "server": db, "over": {"path": path}, "crossing": True,
         "goal": f"perfect >= 99.5 %, {both}"},
        {"name": f"crossing {path} GPRS", "server": db, "over": {"path": path, **GPRS}, "crossing": True,
         "goal": f"perfect >= 99 %, {both}"},
    ]


def run_stream_bench(
    db: str,
    replay: Replayer,
    *,
    out: Path,
    vienna: str | None = None,
    extra: Sequence[tuple[str, str, Sequence[str]]] = (),
    device: str = "desktop2003",
    duration: str | None = None,
    only: Sequence[str] = (),
    truth_every: int = 0,
    crossing: str | None = None,
    clock: str = "sim",
) -> list[dict[str, Any]]:
    """Replay every scenario (those whose name contains one of ``only``, if given).

    Returns one row per scenario that ran (its summary, name and goal); a scenario
    that fails is reported on stderr and left out.  Every row's overfetch is held
    to 0.5 (the issue's bound) besides its own goal.  Writes the comparison page
    and ``bench_stream.json`` into ``out``.  With ``truth_every`` every N-th frame of
    each walk is compared with the ground truth (``walkstream replay --truth-every``).
    ``crossing``: a crossing scene whose walk ``enter`` joins the table
    (:func:`crossing_scenarios`).  ``clock``: ``"sim"`` (the table's figures) or
    ``"real"`` (the ``gl`` device drawing and timing for real, for the colour error
    of what a real frame rate lets it draw).
    """
    scenarios = stream_scenarios(vienna, extra) + (crossing_scenarios(crossing) if crossing else [])
    if only:
        scenarios = [s for s in scenarios if any(k.lower() in s["name"].lower() for k in only)]
    rows = []
    runs = []
    for k, sc in enumerate(scenarios, 1):
        folder = out / f"{k:02d}-{sc['name'].replace(' ', '-').replace('/', '-').lower()}"
        options: dict[str, Any] = {"device": device, "clock": clock, **sc["over"]}
        if duration:
            options["duration"] = duration
        if truth_every or sc.get("crossing"):
            options["truth_every"] = truth_every or CROSSING_TRUTH_EVERY
        options["report"] = str(folder)
        print(f"[{k}/{len(scenarios)}] {sc['name']} ...", file=sys.stderr, flush=True)
        try:
            result = replay(sc.get("server", db), options, sc["name"])
        except WalkstreamError as exc:
            print(f"  {sc['name']}: {exc}", file=sys.stderr)
            continue
        s = result.summary
        rows.append({"scenario": sc["name"], "goal": sc["goal"], **s})
        runs.append((sc["name"], s, result.log, result.bytes_log, folder))
    if runs:
        write_comparison(out, runs, title="walkstream bench stream")
        (out / "bench_stream.json").write_text(json.dumps(rows, indent=2, default=str))
    return rows


def _pct(v: Any) -> str:
    return "n/a" if v is None else f"{100 * v:.1f}"


def format_stream_table(rows: list[dict[str, Any]]) -> str:
    """One line per scenario."""
    head = (
        f"{'scenario':<22} {'frames':>6} {'perfect%':>8} {'dl q%':>6} {'rw q%':>6} "
        f"{'first s':>7} {'bytes':>9} {'overfetch':>9} {'util%':>6} {'busy%':>6} "
        f"{'redl':>5} {'rebuild':>7}  goal"
    )
    lines = [head, "-" * len(head)]
    for r in rows:
        first = r.get("time_to_first_perfect_frame_s")
        lines.append(
            f"{r['scenario']:<22} {r['frames']:>6} {100 * r['perfect_frame_ratio']:>8.2f} "
            f"{r['download_quality_mean'] or 0:>6.1f} {r['rewrite_quality_mean'] or 0:>6.1f} "
            f"{'never' if first is None else f'{first:.2f}':>7} {r['bytes_received']:>9,} "
            f"{r['overfetch_ratio']:>9.3f} {_pct(r.get('link_utilisation')):>6} "
            f"{_pct(r.get('link_utilisation_busy')):>6} {r['redownloads']:>5} {r['rebuilds']:>7}  "
            f"{r['goal']}"
        )
    return "\n".join(lines)


def format_truth_table(rows: list[dict[str, Any]]) -> str:
    """The ground-truth figures of the rows that have them (``--truth-every``), one line each.

    ``pvs>0.01%``: the share of the compared frames from the first perfect one whose
    PVS-caused missing pixels exceed 0.01 % of the frame; ``pvs% mean``: their mean
    share over every compared frame (:mod:`walkstream.client.report.truth`).
    """
    have = [r for r in rows if r.get("truth") and r.get("kind") != "crossing"]
    if not have:
        return ""

    def pct(v: Any, digits: int = 2) -> str:
        return "n/a" if v is None else f"{100 * v:.{digits}f}"

    head = (
        f"{'scenario':<22} {'compared':>8} {'differ%':>7} {'>0.5%':>6} {'pvs>0.01%':>9} {'pvs% mean':>9} "
        f"{'pvs% max':>8} {'lod% mean':>9} {'culled% max':>11} {'sky% max':>8} {'no obj% mean':>12}"
    )
    lines = [head, "-" * len(head)]
    for r in have:
        t = r["truth"]
        m = t["missing"]
        below = t.get("below_horizon") or {}
        lines.append(
            f"{r['scenario']:<22} {t['frames']:>8} {pct(t['differing_pixels_mean']):>7} "
            f"{pct(t['over_half_percent_ratio'], 1):>6} "
            f"{pct(t.get('pvs_over_hundredth_percent_ratio'), 2):>9} {pct(m['pvs']['mean'], 4):>9} "
            f"{pct(m['pvs']['max'], 3):>8} {pct(m['lod']['mean'], 3):>9} {pct(m['culled']['max'], 3):>11} "
            f"{pct(below.get('sky', {}).get('max')):>8} {pct(below.get('no_object', {}).get('mean')):>12}"
        )
    return "\n".join(lines)


def format_colour_table(rows: list[dict[str, Any]]) -> str:
    """The colour error of the rows that have it (``--truth-every`` on a city walk), one line each.

    Per row: the device and clock, the frames compared, frames within 10 % of the
    target rate, triangles per frame (mean), the mean linear-RGB error per pixel (%
    of full scale, median and p95 over the compared frames), the mean ΔE00 (median),
    the pixels over the visible threshold (median %), the frames with more than 0.5 %
    of their pixels over it, the PSNR (median, dB) and the share of pixels visibly
    wrong because of a coarser LOD's colour (``lod_colour``, mean %).
    """
    have = [r for r in rows if (r.get("truth") or {}).get("colour")]
    if not have:
        return ""

    def pct(v: Any, digits: int = 2) -> str:
        return "n/a" if v is None else f"{100 * v:.{digits}f}"

    head = (
        f"{'scenario':<22} {'device':<6} {'clock':<5} {'compared':>8} {'fps10%':>6} {'tri/fr':>6} "
        f"{'err% med':>8} {'err% p95':>8} {'dE med':>6} {'vis% med':>8} {'fr>0.5%':>7} {'PSNR med':>8} {'lod_col%':>8}"
    )
    lines = [head, "-" * len(head)]
    for r in have:
        c = r["truth"]["colour"]
        ps = c["psnr_db"]["median"]
        de = c["delta_e_mean"]["median"]
        lines.append(
            f"{r['scenario']:<22} {r.get('device', '?'):<6} {r.get('clock', '?'):<5} {c['frames']:>8} "
            f"{pct(r.get('fps_within_10pct_ratio'), 1):>6} {r.get('triangles_mean') or 0:>6.0f} "
            f"{pct(c['mean_error']['median']):>8} {pct(c['mean_error']['p95']):>8} "
            f"{'n/a' if de is None else f'{de:.2f}':>6} {pct(c['visible_pixels']['median']):>8} "
            f"{pct(c['frames_over_visible_ratio'], 1):>7} {'n/a' if ps is None else f'{ps:.1f}':>8} "
            f"{pct(c['causes']['lod_colour']):>8}"
        )
    return "\n".join(lines)


def format_crossing_table(rows: list[dict[str, Any]]) -> str:
    """The crossing rows' own figures, one line each ("" when there are none)."""
    have = [r for r in rows if r.get("kind") == "crossing"]
    if not have:
        return ""
    head = (
        f"{'scenario':<22} {'perfect%':>8} {'switches':>24} {'prefetch s':>10} {'door s':>6} "
        f"{'door fr':>7} {'no room':>7} {'compared':>8} {'culled px':>9} {'requests':>8}"
    )
    lines = [head, "-" * len(head)]
    for r in have:
        t = r.get("truth") or {}
        sw = " ".join(f"{m}@{x:.1f}" for x, m in r["model_switches"])
        pre = r.get("interior_prefetch_from_s")
        door = r.get("door_reached_s")
        lines.append(
            f"{r['scenario']:<22} {100 * r['perfect_frame_ratio']:>8.2f} {sw:>24} "
            f"{'never' if pre is None else f'{pre:.1f}':>10} {'n/a' if door is None else f'{door:.1f}':>6} "
            f"{r['door_frames']:>7} {r['door_frames_without_first_room']:>7} "
            f"{t.get('frames', 0) - t.get('unknown', 0):>8} {t.get('culled_pixels', 'n/a'):>9} {r['requests']:>8}"
        )
    return "\n".join(lines)
