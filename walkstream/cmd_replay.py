"""``walkstream replay``: walk a recorded path over a shaped link and write a report.

This is where the client meets a server: a URL gives real sockets
(:class:`httpx.AsyncHTTPTransport`); a scene database path gives the same FastAPI
app in-process (:class:`httpx.ASGITransport`).  The client package only ever sees
an httpx transport.  :func:`replay_with_options` is how the benchmarks and the demo
run a replay with the same options and defaults as this command.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import sys
from collections.abc import Iterator, Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any

from walkstream.shared.errors import InputError, WalkstreamError
from walkstream.terminal import WalkBar, count_bar, say_if_slow

__all__ = [
    "MAX_OUTAGE_SHARE",
    "REPLAY_FAILED",
    "outage_line",
    "replay_failure",
    "add_replay_parser",
    "add_replay_arguments",
    "transport_for",
    "config_from_args",
    "replay_to_report",
    "replayer",
    "replay_with_options",
    "scene_kind",
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


def _seconds(text: str) -> float:
    try:
        s = float(text)
    except ValueError:
        s = math.nan
    if not (math.isfinite(s) and 0 <= s <= 86_400):
        raise argparse.ArgumentTypeError(f"expected seconds from 0 to 86400, got {text!r:.40}")
    return s


def _frame_times(source: str) -> tuple[float, ...]:
    """The ``frame_time`` column of a report's ``frames.csv`` (the report folder or the file)."""
    from walkstream.client.report.files import read_frames_csv

    p = Path(source)
    p = p / "frames.csv" if p.is_dir() else p
    if not p.is_file():
        raise InputError(f"--frame-times {source}: no such report folder or frames.csv")
    return tuple(float(v) for v in read_frames_csv(p).frame_time.tolist())


def config_from_args(args: argparse.Namespace) -> Any:
    """A :class:`~walkstream.client.config.ReplayConfig` from parsed replay arguments."""
    from walkstream.client.config import ReplayConfig
    from walkstream.client.net.link import LinkProfile
    from walkstream.client.truth.antialias import check_sampling, parse_sampling
    from walkstream.client.units import parse_bandwidth, parse_duration, parse_size

    samplings = {flag: parse_sampling(text, flag) for flag, text in
                 (("--truth-samples", args.truth_samples), ("--picture-samples", args.picture_samples))}
    if args.truth_every:
        for flag, sampling in samplings.items():
            check_sampling(sampling, flag)  # the truth draws after the walk: refuse now, not then
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
        rewrite=args.rewrite,
        shm_bytes=parse_size(args.shm),
        lod_select=args.lod,
        lod_greedy=not args.ach_shares,
        lod_hold_s=args.lod_hold,
        lod_distances=(lo, hi),
        seed=args.seed,
        fog_m=args.fog,
        culling=args.culling,
        fog_budget=not args.no_fog_budget,
        triangle_cull=not args.no_triangle_cull,
        rooms={"flush_s": args.flush_after, "flush_policy": args.flush_policy, "flush_fill": args.flush_fill,
               "batch_bytes": parse_size(args.contents_batch), "cull_cache": args.cull_cache,
               "cull_guard": _cull_guard(args.cull_guard),
               **({} if args.prefetch_portals is None else {"beyond_portals": args.prefetch_portals})},
        report_dir=Path(args.report),
        start_bundle=not args.no_start_bundle,
        start_contents=not args.no_start_contents,
        path_head_s=args.path_head or None,
        start_heads=not args.no_start_heads,
        start_pose=not args.no_start_pose,
        start_walls=not args.no_start_walls,
        start_hold_s=args.start_hold,
        gzip=not args.no_gzip,
        truth_every=args.truth_every,
        viewer_ppd=args.viewer_ppd,
        truth_samples=samplings["--truth-samples"],
        picture_samples=samplings["--picture-samples"],
        frame_times=_frame_times(args.frame_times) if args.frame_times else None,
        batched_draws=not args.per_object_draws,
        impostors=not args.no_impostors,
        impostor_blend_m=args.impostor_blend,
        impostor_fade_s=args.impostor_fade,
        impostor_max_size_deg=args.impostor_max_size,
        impostor_perspective=args.impostor_perspective,
        virtual_walls=not args.no_walls,
        wall_zone_blend=args.wall_zone_blend,
        wall_parallax=args.wall_parallax,
        facades=False if args.no_facades else {"auto": None, "on": True, "off": False}[args.facades],
        facade_lookalike=not args.no_facade_lookalike,
        facade_grazing_deg=args.facade_grazing,
        facade_filter=args.facade_filter,
        facade_parallax_px=args.facade_parallax,
        facade_texels_per_m=args.facade_texels,
        facade_budget_bytes=parse_size(args.facade_budget),
        facade_bake_share=args.facade_bake_share,
    )




def scene_kind(server: str, scene: str | None) -> str | None:
    """``city`` or ``interior``: from the database's meta, or the server's manifest (a
    plain request outside the replay's shaped link); None when it cannot be told."""
    if not server.startswith(("http://", "https://")):
        from walkstream.server.store import SceneReader

        try:
            with SceneReader.open(server) as reader:
                return reader.meta.kind
        except WalkstreamError:
            return None
    import httpx

    try:
        base = server.rstrip("/")
        name = scene
        if name is None:
            listing = httpx.get(f"{base}/v1/scenes", headers={"Accept": "application/json"}, timeout=10).json()
            name = sorted(s["name"] for s in listing)[0]
        m = httpx.get(f"{base}/v1/scenes/{name}", headers={"Accept": "application/json"}, timeout=10).json()
        return str(m.get("kind", "city"))
    except (httpx.HTTPError, ValueError, KeyError, IndexError, TypeError):
        return None


def _warm_up_culling(triangles: bool) -> None:
    """The interiors' compiled culling made or loaded (the replay does it again, at no cost
    then, before its clock starts: this is only where the terminal can say so)."""
    from walkstream.shared.cullkernels import warm_up
    from walkstream.shared.trianglekernels import warm_up as warm_up_triangles

    warm_up()
    if triangles:
        warm_up_triangles()


def replay_to_report(server: str, config: Any, *, title: str, quiet: bool = False, plots: bool = True) -> Any:
    """Run one replay against ``server`` and write its report folder; returns the result.

    ``plots`` False writes the report without its plots (``--no-plots``)."""
    from walkstream.client.replay import run_replay
    from walkstream.client.report import write_report

    if config.kind is None:
        config = replace(config, kind=scene_kind(server, config.scene))

    if not quiet and config.kind != "city" and config.culling == "portals":
        say_if_slow(lambda: _warm_up_culling(config.triangle_cull),
                    "compiling the interiors' culling (the first run only; cached after)")
    with transport_for(server) as (transport, url):
        if quiet:
            result = run_replay(transport, url, config)
        else:
            bar = WalkBar(f"replay {config.path}")
            truth_bar = None
            try:
                if config.truth_every:
                    truth_bar, truth_progress = count_bar("ground truth", "frame")
                else:
                    truth_progress = None
                result = run_replay(transport, url, config, bar, truth_progress)
            finally:
                bar.close()
                if truth_bar is not None:
                    truth_bar.close()
    if config.report_dir is not None:
        write_report(
            config.report_dir,
            result.summary,
            result.log,
            result.bytes_log,
            snapshots=result.snapshots,
            title=title,
            truth=result.truth,
            phases=result.phases,
            interior=result.interior,
            plots=plots,
        )
    return result




def cmd_replay(args: argparse.Namespace) -> int:
    """Handler of ``walkstream replay``."""
    from walkstream.client.report import format_headline

    config = config_from_args(args)
    result = replay_to_report(args.server, config, title=f"replay {config.path}", plots=not args.no_plots)
    disk = result.summary.get("disk_cache")
    if disk and not disk["available"]:
        print(f"walkstream: warning: --cache-dir not used: {disk['error']}", file=sys.stderr)
    if args.json:
        print(json.dumps(result.summary, indent=2, default=str))
    else:
        print(format_headline(result.summary))
        outages = outage_line(result.summary)
        if outages:
            print(outages)
        print(f"report: {Path(args.report) / 'index.html'}")
    failure = replay_failure(result.summary)
    if failure:
        print(f"walkstream: error: {failure}", file=sys.stderr)
        return REPLAY_FAILED
    return 0


#: Exit status of a replay that ran but did not walk as asked (the scene never
#: arrived, or the server was unreachable for more than :data:`MAX_OUTAGE_SHARE` of
#: the walk); 2 stays for input errors.
REPLAY_FAILED = 3
#: The share of the walk the server may be unreachable before the replay fails.
MAX_OUTAGE_SHARE = 0.2


def outage_line(summary: Mapping[str, Any]) -> str | None:
    """One line naming the outages a replay lived through, or None when there was none."""
    n = int(summary.get("outages") or 0)
    if not n:
        return None
    end = ", still unreachable at the end" if summary.get("down_at_end") else ""
    return (
        f"server unreachable {n} time{'s' if n > 1 else ''}, {summary.get('outage_s', 0.0):.1f} s in all "
        f"(longest {summary.get('longest_outage_s', 0.0):.1f} s), {summary.get('retries', 0)} retries{end}"
    )


def replay_failure(summary: Mapping[str, Any]) -> str | None:
    """Why a replay's exit status is :data:`REPLAY_FAILED`, in one line; None when it walked.

    The scene (or its path) never arrived, or the server was unreachable for more
    than :data:`MAX_OUTAGE_SHARE` of the walk (outages counted on the walk's clock).
    """
    if summary.get("error"):
        return str(summary["error"])
    walk = float(summary.get("duration_s") or 0.0)
    out = float(summary.get("outage_s") or 0.0)
    if walk > 0 and out > MAX_OUTAGE_SHARE * walk:
        return (
            f"the server was unreachable for {out:.1f} s of the {walk:.1f} s walk ({100 * out / walk:.0f} %, "
            f"more than {100 * MAX_OUTAGE_SHARE:.0f} %; {summary.get('retries', 0)} retries): the figures are not the link's"
        )
    return None


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
    r.add_argument("--rewrite", default="auto", help="real clock: rebuild in worker 'process'es or in 'thread's of the client (the older path); default 'auto': processes when there is a core for each worker besides two")
    r.add_argument("--shm", default="16MB", help="process rewrite: bound on the shared memory geometry comes back through (default 16MB; 0: through the pipe)")
    r.add_argument("--lod", choices=("ach", "distance"), default="ach", help="LOD selection: ACH-shared budget or distance")
    r.add_argument("--ach-shares", action="store_true",
                   help="ACH selection by the paper's shares of the budget (the older rule; default: in descending "
                        "ACH each object takes the best LOD that still fits)")
    r.add_argument("--lod-hold", type=float, default=None, metavar="S",
                   help="ACH selection: the least of the objects' budget over the last S seconds, and an object "
                        "whose LOD changed less than S seconds ago may only go down (no LOD flipping frame to "
                        "frame with the budget; default 1 on a simulated device, 0 on gl; 0: no hold)")
    r.add_argument("--lod-distances", default="40,120", help="distance selection: LOD2 nearer than D1, LOD1 nearer than D2 (default 40,120)")
    r.add_argument("--seed", type=int, default=0, help="seed of link loss, device noise, backoff jitter")
    r.add_argument("--fog", type=float, default=40.0, help="interiors: portals farther than this many metres are not looked through (default 40)")
    r.add_argument("--no-fog-budget", action="store_true",
                   help="interiors: keep the fog at --fog (default: the budget controller sets it, at most --fog)")
    r.add_argument("--culling", choices=("portals", "frustum", "none"), default="portals",
                   help="interiors: portal culling with visible screen areas (default), portals in the frustum "
                   "only, or every part of the visible cells")
    r.add_argument("--cull-cache", nargs="?", const="guard", default="", choices=("guard", "frustum"),
                   help="interiors, portal culling: reuse a frame's culling while the view stays within a guard "
                   "view (less CPU per frame, more parts drawn; default: each frame culled anew); guard (the "
                   "default with the flag): the guard's parts, frustum: the guard's parts cut by the frame's frustum")
    r.add_argument("--cull-guard", default="0.3,10", metavar="M,DEG",
                   help="--cull-cache: the step in metres and the turn in degrees a guard allows (default 0.3,10)")
    r.add_argument("--no-triangle-cull", action="store_true",
                   help="interiors: cull parts by their boxes only (default: a part the boxes keep is dropped "
                   "when none of its triangles meets its cell's visible screen areas)")
    r.add_argument("--flush-after", type=float, default=30.0, metavar="S",
                   help="interiors: a cell not visible for S seconds is flushed (default 30)")
    r.add_argument("--flush-policy", choices=("crowded", "paper"), default="crowded",
                   help="interiors: flush only while the cache is more than 90 %% full (default: nothing is "
                   "downloaded twice while the walk fits the cache), or always (the paper's policy)")
    r.add_argument("--flush-fill", type=float, default=0.9, metavar="SHARE",
                   help="interiors: the crowded policy flushes only while the cache is fuller than this share "
                   "of its budget (default 0.9; 1: never, the byte-budget LRU alone)")
    r.add_argument("--contents-batch", default="8kB", metavar="BYTES",
                   help="interiors: cells' contents in batches (every missing visible cell, then predicted ones "
                   "up to BYTES stored; one gzip stream, default 8kB); 0: one request per cell")
    r.add_argument("--prefetch-portals", type=int, default=None, metavar="N",
                   help="interiors: last in the prefetch, the cells up to N portals beyond the visible ones "
                   "(default 1)")
    r.add_argument("--no-start-bundle", action="store_true", help="start with scene list, manifest and path instead of the one-round-trip start bundle")
    r.add_argument("--no-start-contents", action="store_true",
                   help="interiors: the start bundle leaves out the first view's contents (they come by the streamer's own requests)")
    r.add_argument("--no-start-heads", action="store_true",
                   help="interiors: the start bundle sends each cell of the first view whole (default: a cell "
                   "the first pose sees in part first as the pieces it draws, whole after the others)")
    r.add_argument("--no-start-pose", action="store_true",
                   help="interiors: the start bundle sends the path's head before the topology (default: the "
                   "first pose alone there, the head once the first pose's view is in)")
    r.add_argument("--no-start-walls", action="store_true",
                   help="a scene baked with --virtual-walls: the start bundle leaves out the wall sides and the "
                   "first view's wall textures (they come by their own requests)")
    r.add_argument("--path-head", type=_seconds, default=10.0, metavar="S",
                   help="interiors: the start bundle sends only the path's first S seconds; the whole path is "
                   "fetched when the link is idle (default 10; 0: the whole path in the bundle)")
    r.add_argument("--start-hold", type=_seconds, default=3.0, metavar="S",
                   help="interiors: the walker stands at the path's start until its first view is complete (every "
                   "cell it shows in, and no contents on the link), at most S seconds (default 3; "
                   "0: walks at once)")
    r.add_argument("--no-gzip", action="store_true", help="ask for the streams uncompressed")
    r.add_argument("--frame-times", metavar="REPORT", help="a recorded frame schedule: take each frame's time from an earlier report's frames.csv (its folder or the file) instead of measuring it, so that a gl replay, and the frames --truth-every compares, repeat exactly")
    r.add_argument("--truth-every", type=int, default=0, metavar="N", help="compare every Nth frame with a ground truth (every object at LOD2) after the walk: report.json 'truth', error.png (default 0: never)")
    r.add_argument("--viewer-ppd", type=float, default=None, metavar="P", help="with --truth-every: also measure the colour error at the viewer's scale (S-CIELAB) for a display of P pixels per degree, beside the per-pixel figures (the view's own: its height over its field of view, 1.81 at 160x120; a handheld about 24); off by default, as the filtering costs 0.1-1 s a compared frame")
    r.add_argument("--truth-samples", default="1", metavar="N", help="with --truth-every: the colour error's full scene anti-aliased, N x N samples a pixel averaged (N 2 to 8, or NxN), or msaaS for S-sample GL multisampling; the id comparison stays point-sampled (default 1: one sample at the pixel centre; costs a second drawing of each compared frame)")
    r.add_argument("--picture-samples", default="1", metavar="N", help="with --truth-every: the client's picture in the colour error sampled so too (as --truth-samples; a client drawing with a GPU's anti-aliasing; default 1, as the client draws)")
    r.add_argument("--wall-zone-blend", type=float, default=0.5, metavar="Z", help="zone widths around a virtual wall's zone border over which the two zones' textures blend (default 0.5; 0: a hard swap; the seam figure, truth.seam, measures it with --truth-every 1)")
    r.add_argument("--wall-parallax", type=float, default=0.5, metavar="R", help="share of the parallax by which a virtual wall zone's texture is laid for the viewer: slid along the wall with its offset from the zone's sampling line, scaled for its distance against the sampling point's (default 0.5: exact for what stands as far behind the wall as the viewer stands before it; 0: the texture fixed on the wall)")
    r.add_argument("--no-walls", action="store_true", help="open every virtual wall on an interior baked with --virtual-walls (geometry only, no texture asked for)")
    r.add_argument("--no-impostors", action="store_true", help="draw geometry only on a scene baked with --impostors (no image asked for)")
    r.add_argument("--facades", default="auto", choices=("auto", "on", "off"), help="a building left at its LOD0 box carries textures of its LOD2 facades, rendered by the client: on a simulated device (auto, default), always (on) or never (off)")
    r.add_argument("--no-facades", action="store_true", help="draw a building left at its LOD0 box plain (--facades off)")
    r.add_argument("--no-facade-lookalike", action="store_true", help="give facade textures to the boxes only (by default a building at LOD2 is drawn as its box with textures where the two look alike from the eye: the relief's parallax and a texel each within a pixel)")
    r.add_argument("--facade-grazing", type=float, default=70.0, metavar="DEG", help="look-alike boxes: the largest angle between a face's normal and the eye at which its texture stands for LOD2 (default 70; 90: no limit, fewer triangles, more error at the pixel level)")
    r.add_argument("--facade-parallax", type=float, default=1.0, metavar="PX", help="look-alike boxes: the largest parallax of a facade's relief, in pixels, at which its picture stands for LOD2 (default 1; 1.5 with --facade-filter anisotropic on gl: fewer triangles at no more colour error against an anti-aliased truth)")
    r.add_argument("--facade-filter", default="point", choices=("point", "anisotropic"), help="how a facade picture is read where it is drawn smaller than baked: the texel under each pixel's centre (point, default; the closest to the point-sampled truth) or the mean under the pixel's footprint, mipmapped with 16x anisotropy (anisotropic; the closest to an anti-aliased truth, --truth-samples 4)")
    r.add_argument("--facade-texels", type=float, default=8.0, metavar="T", help="texels per metre of a facade texture (default 8)")
    r.add_argument("--facade-budget", default="8MB", metavar="BYTES", help="bytes of facade textures held and drawn (default 8MB)")
    r.add_argument("--facade-bake-share", type=float, default=0.3, metavar="S", help="share of the frame's triangle budget baking facade textures may take on average (default 0.3)")
    r.add_argument("--impostor-blend", type=float, default=None, metavar="M", help="metres beyond the bake's D over which an impostor fades in over its geometry (default a tenth of D; 0: none)")
    r.add_argument("--impostor-max-size", type=float, default=6.0, metavar="DEG", help="the largest angular radius, degrees, of a building's bounding sphere at which its image stands in; a building larger on the screen fades to geometry (default 6; inf: no limit)")
    r.add_argument("--impostor-fade", type=float, default=None, metavar="S", help="seconds an impostor's opacity takes at least from 0 to 1, so an image arriving or a building joining the cell's list does not pop (default 2; 0 with --impostor-blend 0: a hard switch)")
    r.add_argument("--impostor-perspective", action="store_true", help="hold an impostor to the bake's error bound A counting the parallax of its orthographic image in the perspective view as well (fewer impostors near D, each within A)")
    r.add_argument("--per-object-draws", action="store_true", help="gl device: one draw call per object instead of one multi-draw call per frame (the older path, for comparison)")


def add_replay_parser(sub: Any) -> None:
    """Register ``walkstream replay``."""
    r = sub.add_parser("replay", help="walk a recorded path over a shaped link; write a report")
    r.add_argument("server", metavar="SERVER", help="server URL (real sockets) or scene database (in-process)")
    add_replay_arguments(r)
    r.add_argument("--report", required=True, help="report folder (report.json, plots, index.html)")
    r.add_argument("--no-plots", action="store_true", help="write the report without its plots: the figures, the CSV files and the worst frames' pictures (most of a report's time is drawing the plots; for sweeps)")
    r.add_argument("--json", action="store_true", help="print the summary as JSON")
    r.set_defaults(func=cmd_replay)


def _defaults() -> argparse.Namespace:
    p = argparse.ArgumentParser()
    add_replay_arguments(p)
    ns = p.parse_args([])
    ns.report = "."
    ns.no_plots = False
    return ns


def replay_with_options(server: str, options: Mapping[str, Any], title: str) -> Any:
    """One replay with ``walkstream replay`` options over its defaults; writes the report.

    ``options`` are argument names (``bandwidth="5kB/s"``, ``no_prefetch=True``,
    ``report=folder``, ...); a :class:`~walkstream.client.config.ReplayConfig` field
    that has no option (``cost_step_at_s``) is set on the config directly.
    """
    from walkstream.client.config import ReplayConfig

    ns = _defaults()
    direct = {}
    for key, value in options.items():
        if hasattr(ns, key):
            setattr(ns, key, value)
        elif key in ReplayConfig.__dataclass_fields__:
            direct[key] = value
        else:
            raise InputError(f"replay option {key!r} does not exist")
    config = replace(config_from_args(ns), **direct)
    return replay_to_report(server, config, title=title, plots=not ns.no_plots)


def replayer(plots: bool = True) -> Any:
    """:func:`replay_with_options` for a benchmark; ``plots`` False (its ``--no-plots``)
    writes each replay's report without its plots."""
    if plots:
        return replay_with_options

    def replay(server: str, options: Mapping[str, Any], title: str) -> Any:
        return replay_with_options(server, {**options, "no_plots": True}, title)

    return replay


def _cull_guard(text: str) -> tuple[float, float]:
    """``--cull-guard M,DEG``: the step and the turn, each finite and above 0 (the turn below 80)."""
    try:
        m, deg = (float(v) for v in text.split(","))
    except ValueError:
        raise InputError(f"--cull-guard {text!r}: expected METRES,DEGREES such as 0.3,10") from None
    if not (0.0 < m < math.inf and 0.0 < deg < 80.0):
        raise InputError(f"--cull-guard {text!r}: expected a step above 0 m and a turn from 0 to 80 degrees")
    return m, deg
