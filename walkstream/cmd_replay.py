"""``walkstream replay`` and the benchmarks built on it (``bench stream``, ``bench budget``).

This is where the client meets a server: a URL gives real sockets
(:class:`httpx.AsyncHTTPTransport`); a scene database path gives the same FastAPI
app in-process (:class:`httpx.ASGITransport`).  The client package only ever sees
an httpx transport.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path
from typing import Any

from walkstream.shared.errors import InputError, WalkstreamError

__all__ = [
    "add_replay_parser",
    "add_bench_stream_parser",
    "add_bench_budget_parser",
    "transport_for",
    "replay_to_report",
    "headline",
]

IN_PROCESS_URL = "http://walkstream.in-process"


@contextlib.contextmanager
def transport_for(server: str) -> Iterator[tuple[Any, str]]:
    """``(httpx transport, base URL)`` for a server URL or a scene database path."""
    import httpx

    if server.startswith(("http://", "https://")):
        transport = httpx.AsyncHTTPTransport(retries=0)
        yield transport, server.rstrip("/")
        return
    db = Path(server)
    if not db.is_file():
        raise InputError(
            f"SERVER {server!r}: not an http(s):// URL and no such scene database file"
        )
    from walkstream.server.service.main import create_app

    app = create_app([db])
    try:
        yield httpx.ASGITransport(app=app), IN_PROCESS_URL
    finally:
        app.state.scenes.close()


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise InputError(f"--size {text!r}: expected WIDTHxHEIGHT, e.g. 640x480") from None
    return w, h


def config_from_args(args: argparse.Namespace) -> Any:
    """A :class:`client.replay.ReplayConfig` from parsed replay arguments."""
    from walkstream.client.net.link import LinkProfile
    from walkstream.client.replay import ReplayConfig
    from walkstream.client.units import parse_bandwidth, parse_duration, parse_size

    down = parse_bandwidth(args.bandwidth)
    up = parse_bandwidth(args.uplink) if args.uplink else down
    if not 0.0 <= args.loss <= 1.0:
        raise InputError(f"--loss {args.loss!r}: expected a probability from 0 to 1")
    link = LinkProfile(down, up, parse_duration(args.rtt), args.loss, seed=args.seed)
    lo, hi = (float(v) for v in args.lod_distances.split(","))
    return ReplayConfig(
        link=link,
        path=args.path,
        scene=args.scene,
        fps=args.fps,
        target_fps=args.target_fps,
        prefetch=not args.no_prefetch,
        stream=args.stream,
        cache_bytes=parse_size(args.cache),
        cache_dir=Path(args.cache_dir) if args.cache_dir else None,
        clock=args.clock,
        device=args.device,
        size=_size(args.size),
        snapshot_every=args.snapshot_every,
        duration_s=parse_duration(args.duration) if args.duration else None,
        workers=args.workers,
        lod_select=args.lod,
        lod_distances=(lo, hi),
        seed=args.seed,
        report_dir=Path(args.report),
    )


class _Bar:
    """A tqdm bar of walk seconds, made on the first progress call (so that a replay
    that fails during setup prints only its error)."""

    def __init__(self, desc: str) -> None:
        self.desc = desc
        self.bar: Any = None

    def __call__(self, done: float, total: float) -> None:
        if self.bar is None:
            from tqdm import tqdm

            self.bar = tqdm(
                total=max(total, 1e-9),
                desc=self.desc,
                unit="s",
                file=sys.stderr,
                leave=False,
                dynamic_ncols=True,
                bar_format="{l_bar}{bar}| {n:.0f}/{total:.0f} s walked [{elapsed}]",
            )
        self.bar.update(min(done, total) - self.bar.n)  # honours tqdm's refresh interval

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def replay_to_report(server: str, config: Any, *, title: str, quiet: bool = False) -> Any:
    """Run one replay against ``server`` and write its report folder; returns the result."""
    from walkstream.client.replay import run_replay
    from walkstream.client.report import write_report

    with transport_for(server) as (transport, url):
        if quiet:
            result = run_replay(transport, url, config)
        else:
            bar = _Bar(f"replay {config.path}")
            try:
                result = run_replay(transport, url, config, bar)
            finally:
                bar.close()
    if config.report_dir is not None:
        write_report(
            config.report_dir,
            result.summary,
            result.log,
            result.bytes_log,
            snapshots=result.snapshots,
            title=title,
        )
    return result


def headline(summary: dict[str, Any]) -> str:
    """The figures a person looks at first, on a few lines."""

    def pct(key: str) -> str:
        v = summary.get(key)
        return "n/a" if v is None else f"{v:.1f} %"

    def ratio(key: str) -> str:
        v = summary.get(key)
        return "n/a" if v is None else f"{100 * v:.1f} %"

    first = summary.get("time_to_first_perfect_frame_s")
    return "\n".join(
        [
            f"frames {summary['frames']}, perfect {ratio('perfect_frame_ratio')}, "
            f"first perfect frame at {'never' if first is None else f'{first:.2f} s'}",
            f"download quality {pct('download_quality_mean')}, rewrite quality "
            f"{pct('rewrite_quality_mean')}",
            f"bytes received {summary['bytes_received']:,}, overfetch "
            f"{ratio('overfetch_ratio')}, re-downloads {summary['redownloads']}, rebuilds "
            f"{summary['rebuilds']}",
            f"fps mean {summary.get('fps_mean') or 0:.1f} (target {summary['fps_target']:g}), "
            f"within 10 % {ratio('fps_within_10pct_ratio')}, floor-limited "
            f"{ratio('floor_limited_ratio')}",
        ]
    )


def cmd_replay(args: argparse.Namespace) -> int:
    config = config_from_args(args)
    result = replay_to_report(args.server, config, title=f"replay {config.path}")
    disk = result.summary.get("disk_cache")
    if disk and not disk["available"]:
        print(f"walkstream: warning: --cache-dir not used: {disk['error']}", file=sys.stderr)
    if result.summary.get("error"):
        print(f"walkstream: warning: {result.summary['error']}", file=sys.stderr)
    if args.json:
        print(json.dumps(result.summary, indent=2, default=str))
    else:
        print(headline(result.summary))
        print(f"report: {Path(args.report) / 'index.html'}")
    return 0


def add_replay_arguments(r: argparse.ArgumentParser) -> None:
    """The replay options (shared by ``replay`` and the benchmarks' defaults)."""
    r.add_argument("--scene", help="scene name (default: the server's first scene)")
    r.add_argument("--path", default="SE", help="recorded path name (default SE)")
    r.add_argument("--bandwidth", default="56kbit", help="link bandwidth, e.g. 56kbit, 7kB/s, 1Mbit (default 56kbit)")
    r.add_argument("--uplink", help="uplink bandwidth (default: the same as --bandwidth)")
    r.add_argument("--rtt", default="200ms", help="round-trip time, e.g. 200ms, 0.5s (default 200ms)")
    r.add_argument("--loss", type=float, default=0.0, help="probability that a response is cut off mid-body")
    r.add_argument("--fps", type=float, default=25.0, help="frame loop tick rate (default 25)")
    r.add_argument("--target-fps", type=float, help="minimum frame rate the polygon budget holds (default --fps)")
    r.add_argument("--no-prefetch", action="store_true", help="fetch only the current cell, when entered")
    r.add_argument("--stream", choices=("params", "meshes"), default="params", help="download parameters (rebuild locally) or LOD2 meshes")
    r.add_argument("--cache", default="64MB", help="cache budget in bytes, e.g. 64MB (default)")
    r.add_argument("--cache-dir", help="persistent cache folder (cells and objects, per scene version)")
    r.add_argument("--clock", choices=("sim", "real"), default="sim", help="simulated (fast, deterministic) or real time")
    r.add_argument("--device", choices=("gl", "desktop2003", "pda"), default="gl", help="gl renders and times for real; the others use a cost model")
    r.add_argument("--size", default="640x480", help="frame size WIDTHxHEIGHT (default 640x480)")
    r.add_argument("--snapshot-every", type=int, default=0, help="write every Nth frame as PNG into the report")
    r.add_argument("--duration", help="replay only the first part of the path, e.g. 60s")
    r.add_argument("--workers", type=int, default=2, help="rewrite workers (default 2)")
    r.add_argument("--lod", choices=("ach", "distance"), default="ach", help="LOD selection: ACH-shared budget or distance")
    r.add_argument("--lod-distances", default="40,120", help="distance selection: LOD2 nearer than D1, LOD1 nearer than D2 (default 40,120)")
    r.add_argument("--seed", type=int, default=0, help="seed of link loss, device noise, backoff jitter")


def add_replay_parser(sub: Any) -> None:
    """Register ``walkstream replay``."""
    r = sub.add_parser("replay", help="walk a recorded path over a shaped link; write a report")
    r.add_argument("server", metavar="SERVER", help="server URL (real sockets) or scene database (in-process)")
    add_replay_arguments(r)
    r.add_argument("--report", required=True, help="report folder (report.json, plots, index.html)")
    r.add_argument("--json", action="store_true", help="print the summary as JSON")
    r.set_defaults(func=cmd_replay)


# ---------------------------------------------------------------- bench stream


def _defaults() -> argparse.Namespace:
    p = argparse.ArgumentParser()
    add_replay_arguments(p)
    ns = p.parse_args([])
    ns.report = "."
    return ns


def stream_scenarios(vienna: str | None) -> list[dict[str, Any]]:
    """The rows of ``bench stream``: name, server, argument overrides, goal."""
    rows: list[dict[str, Any]] = [
        {"name": "SE 56k prefetch", "over": {}, "goal": "perfect >= 99.5 %, overfetch <= 0.5, first <= 3 s"},
        {"name": "SE 56k no-prefetch", "over": {"no_prefetch": True}, "goal": "(reported)"},
        {"name": "SE 56k meshes", "over": {"stream": "meshes"}, "goal": "(reported)"},
        {"name": "SE GPRS prefetch", "over": {"bandwidth": "5kB/s", "rtt": "500ms"}, "goal": "perfect >= 98 %"},
        {"name": "SE GPRS no-prefetch", "over": {"bandwidth": "5kB/s", "rtt": "500ms", "no_prefetch": True}, "goal": "(reported)"},
        {"name": "drive GPRS prefetch", "over": {"path": "drive", "bandwidth": "5kB/s", "rtt": "500ms"}, "goal": "(reported)"},
        {"name": "SM 56k prefetch", "over": {"path": "SM"}, "goal": "(reported)"},
        {"name": "SE 56k cache 8MB", "over": {"cache": "8MB"}, "goal": "re-downloads counted"},
    ]
    if vienna:
        rows.append(
            {"name": "Vienna walk GPRS", "server": vienna,
             "over": {"path": "walk", "bandwidth": "5kB/s", "rtt": "500ms"}, "goal": "(reported)"}
        )
        rows.append(
            {"name": "Vienna walk 56k", "server": vienna, "over": {"path": "walk"}, "goal": "(reported)"}
        )
    return rows


def cmd_bench_stream(args: argparse.Namespace) -> int:
    from walkstream.client.report import write_comparison

    out = Path(args.out)
    rows = []
    runs = []
    scenarios = stream_scenarios(args.vienna)
    if args.only:
        keep = [s.strip() for s in args.only.split(",")]
        scenarios = [s for s in scenarios if any(k.lower() in s["name"].lower() for k in keep)]
    for k, sc in enumerate(scenarios, 1):
        ns = _defaults()
        ns.device = args.device
        ns.clock = "sim"
        for key, v in sc["over"].items():
            setattr(ns, key, v)
        if args.duration:
            ns.duration = args.duration
        folder = out / f"{k:02d}-{sc['name'].replace(' ', '-').lower()}"
        ns.report = str(folder)
        config = config_from_args(ns)
        print(f"[{k}/{len(scenarios)}] {sc['name']} ...", file=sys.stderr, flush=True)
        try:
            result = replay_to_report(sc.get("server", args.db), config, title=sc["name"])
        except WalkstreamError as exc:
            print(f"  {sc['name']}: {exc}", file=sys.stderr)
            continue
        s = result.summary
        rows.append({"scenario": sc["name"], "goal": sc["goal"], **s})
        runs.append((sc["name"], s, result.log, result.bytes_log, folder))
    print(format_stream_table(rows))
    if runs:
        write_comparison(out, runs, title="walkstream bench stream")
        (out / "bench_stream.json").write_text(json.dumps(rows, indent=2, default=str))
        print(f"plots and per-run reports: {out / 'index.html'}")
    return 0


def format_stream_table(rows: list[dict[str, Any]]) -> str:
    """One line per scenario."""
    head = (
        f"{'scenario':<22} {'frames':>6} {'perfect%':>8} {'dl q%':>6} {'rw q%':>6} "
        f"{'first s':>7} {'bytes':>9} {'overfetch':>9} {'redl':>5} {'rebuild':>7}  goal"
    )
    lines = [head, "-" * len(head)]
    for r in rows:
        first = r.get("time_to_first_perfect_frame_s")
        lines.append(
            f"{r['scenario']:<22} {r['frames']:>6} {100 * r['perfect_frame_ratio']:>8.2f} "
            f"{r['download_quality_mean']:>6.1f} {r['rewrite_quality_mean']:>6.1f} "
            f"{'never' if first is None else f'{first:.2f}':>7} {r['bytes_received']:>9,} "
            f"{r['overfetch_ratio']:>9.3f} {r['redownloads']:>5} {r['rebuilds']:>7}  {r['goal']}"
        )
    return "\n".join(lines)


def add_bench_stream_parser(besub: Any) -> None:
    """Register ``walkstream bench stream``."""
    b = besub.add_parser("stream", help="replays under the simulated clock: quality, bytes, overfetch per link and mode")
    b.add_argument("db", nargs="?", default="out/demo/city.db", help="scene database (default out/demo/city.db from make demo)")
    b.add_argument("--vienna", help="a baked Vienna database with the imported walk (path 'walk')")
    b.add_argument("--device", default="desktop2003", choices=("gl", "desktop2003", "pda"), help="device (default desktop2003)")
    b.add_argument("--duration", help="limit every walk, e.g. 60s")
    b.add_argument("--only", help="comma-separated scenario name parts to run")
    b.add_argument("--out", default="out/bench-stream", help="folder for reports and plots")
    b.set_defaults(func=cmd_bench_stream)


# ---------------------------------------------------------------- bench budget


def cmd_bench_budget(args: argparse.Namespace) -> int:
    out = Path(args.out)
    cases = [
        ("desktop2003", 25.0, "within >= 95 %, recover <= 8 frames, never > 20 % slow"),
        ("desktop2003", 40.0, "(reported)"),
        ("pda", 10.0, "within >= 95 %, recover <= 8 frames, never > 20 % slow"),
    ]
    gl = [("gl", t, "(reported)") for t in (25.0, 40.0, 100.0)] if not args.no_gl else []
    rows = []
    for k, (device, target, goal) in enumerate(cases + gl, 1):
        ns = _defaults()
        ns.device = device
        ns.fps = target
        ns.bandwidth = "1Mbit"  # the budget, not the link, is measured here
        ns.rtt = "50ms"
        ns.seed = args.seed
        ns.duration = args.gl_duration if device == "gl" else args.duration
        folder = out / f"{k:02d}-{device}-{target:g}fps"
        ns.report = str(folder)
        config = config_from_args(ns)
        step_at = None
        if device != "gl":
            step_at = args.step_at
            config = replace(config, cost_step_at_s=step_at)
        print(f"[{k}/{len(cases) + len(gl)}] {device} at {target:g} fps ...", file=sys.stderr, flush=True)
        result = replay_to_report(args.db, config, title=f"budget {device} {target:g} fps")
        s = result.summary
        rec, worst = s.get("recovery_frames"), s.get("recovery_worst_slowdown_after")
        rows.append({"device": device, "target": target, "goal": goal, "recover": rec, "worst": worst, **s})
    print(format_budget_table(rows))
    (out / "bench_budget.json").write_text(json.dumps(rows, indent=2, default=str))
    print(f"reports: {out}")
    return 0


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


def add_bench_budget_parser(besub: Any) -> None:
    """Register ``walkstream bench budget``."""
    b = besub.add_parser("budget", help="frame rate and polygon budget per device and target, with a tenfold cost step")
    b.add_argument("db", nargs="?", default="out/demo/city.db", help="scene database (default out/demo/city.db)")
    b.add_argument("--duration", default="180s", help="walk length for the simulated devices (default 180s)")
    b.add_argument("--gl-duration", default="20s", help="walk length for the gl device (default 20s)")
    b.add_argument("--step-at", type=float, default=60.0, help="walk second of the tenfold cost step (default 60)")
    b.add_argument("--no-gl", action="store_true", help="skip the gl rows")
    b.add_argument("--seed", type=int, default=0, help="seed of the device noise and spikes (default 0)")
    b.add_argument("--out", default="out/bench-budget", help="folder for the reports")
    b.set_defaults(func=cmd_bench_budget)
