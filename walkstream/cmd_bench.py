"""``walkstream bench ...``: every benchmark, each printing one table (and plots where asked).

::

    walkstream bench rebuild [FILE] [--repeat 5] [--batch 32,256] [--beside-loop thread,process [--workers 1,2]]
    walkstream bench visibility scene.db|SOURCE [--sample N] [--settings ...] [--views N] [--plot out.png]
    walkstream bench render [--size 700] [--cells 40] [--runs 3] ...
    walkstream bench server scene.db [--walkers 10,100,1000] [--workers 1,2] ...
    walkstream bench stream [scene.db] [--vienna vienna.db] [--scene LABEL=DB[:PATHS]] [--crossing crossing.db]
        [--only NAMES] [--duration S] [--truth-every N] [--clock sim|real]
    walkstream bench budget [scene.db] [--no-gl] [--seed N] [--gl-runs N] [--gl-real-duration S]
        [--gl-draws batched,per-object] [--rewrite thread,process]
    walkstream bench controller [--frames 3000] [--seeds 1 2 3] [--step 10]
    walkstream bench lod [scene.db] [--plot p.png] [--images v.png]
    walkstream bench fill [scene.db] [--views 6] [--size 1280x960] [--repeat 6] [--json]
    walkstream bench city [--data ../shared/data/osm] [--only NAMES] [--kinds street,grid,sections] [--reuse] [--out DIR] [--truth-every N]
    walkstream bench sections [SRC] [--redundancy R|auto ...] [--min-size M ...] [--section-cover walkable free] [--field-spacing 4] [--walks SE,drive] [--bbox X0,Y0,X1,Y1 [--bbox-crs lonlat]]
    walkstream bench field [SRC ...] [--points 64] [--starts 4] [--field-spacing 4] [--json]
    walkstream bench clusters DB [DB ...] [--min-objects 12] [--max-cells 64] [--plot clusters.png] [--json]
    walkstream bench interiors [--ifc FILE ...] [--presets paper paper10] [--out DIR] [--json]
    walkstream bench portals [--presets paper paper10] [--frames N] [--truth N] [--no-gl] [--out DIR] [--json]
    walkstream bench portals --cull [SEED ...] [--cull-against REV] [--out DIR] [--json]
    walkstream bench impostor-sampling [SRC] [--buildings 20] [--impostor-error 2] [--ppd 1.81 24] [--against-aa] [--truth-samples 1 2 4 msaa4 [--reference 8]] [--picture p.png] [--json]
    walkstream bench walls [--scenes hall,city,west-oakland,village] [--wall-errors 5,10,15,20] [--duration 60s]
        [--gl-duration 20s] [--truth-every N] [--size WxH] [--no-gl] [--quick] [--out DIR] [--json]
    walkstream bench wall-floor DB SOURCE [--report DIR] [--path NAME] [--densities 1,2,4] [--frame-res F]
        [--viewer-ppd P] [--plot]

The benchmarks themselves are :mod:`walkstream.benchmarks`; this module parses their
options, hands the replaying ones a way to run a replay
(:func:`~walkstream.cmd_replay.replay_with_options`) and prints what they return.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from walkstream.cmd_bench_images import add_image_benches
from walkstream.cmd_bench_pvs import add_pvs_benches
from walkstream.cmd_bench_rooms import add_room_benches
from walkstream.shared.errors import WalkstreamError
from walkstream.terminal import building_bar, count_bar

__all__ = ["add_bench_parser"]


def _ints(text: str, flag: str) -> tuple[int, ...]:
    try:
        return tuple(int(v) for v in text.split(","))
    except ValueError:
        raise WalkstreamError(f"{flag}: expected comma-separated integers, got {text!r}") from None


def cmd_bench_rebuild(args: argparse.Namespace) -> int:
    """Handler of ``walkstream bench rebuild``."""
    from walkstream.benchmarks.rebuild import rebuild_run, rebuild_table
    from walkstream.cmd_build import load_source
    from walkstream.server.sources.citygen import DEFAULT_SEED, write_city

    source = args.file
    if source is None:
        source = str(Path(tempfile.mkdtemp()) / "city.geojson")
        write_city(source, args.size, DEFAULT_SEED)
    scene = load_source(source)
    batches = _ints(args.batch, "--batch")
    if min(batches) < 1:
        raise WalkstreamError(f"--batch: expected sizes >= 1, got {args.batch!r}")
    if args.beside_loop:
        return _bench_beside_loop(args, scene.buildings)
    runs = []
    for r in range(args.repeat):
        with building_bar(len(scene.buildings), f"run {r + 1}/{args.repeat}") as bar:
            runs.append(rebuild_run(scene.buildings, batches, progress=bar.update))
    print(rebuild_table(runs, source))
    return 0


def _bench_beside_loop(args: argparse.Namespace, buildings: Any) -> int:
    """``bench rebuild --beside-loop``: the rewrite pool's paths beside a frame-loop stand-in."""
    from walkstream.benchmarks.rebuild import beside_loop, beside_loop_table
    from walkstream.client.rewrite.pool import MODES

    modes = ("none", *_choices(args.beside_loop, "--beside-loop", MODES))
    workers = _ints(args.workers, "--workers")
    if min(workers) < 1:
        raise WalkstreamError(f"--workers: expected counts >= 1, got {args.workers!r}")
    cases = [("none", 1)] + [(m, w) for m in modes[1:] for w in workers]
    runs = []
    for r in range(args.repeat):
        for k, (mode, w) in enumerate(cases):  # interleaved: every case sees the same load
            print(f"[run {r + 1}/{args.repeat}, {k + 1}/{len(cases)}] {mode}, {w} workers ...", file=sys.stderr, flush=True)
            runs.append(beside_loop(buildings, mode, w))
    print(beside_loop_table(runs, len(buildings)))
    return 0


def cmd_bench_visibility(args: argparse.Namespace) -> int:
    """Handler of ``walkstream bench visibility``."""
    from walkstream.benchmarks.visibility import visibility_benchmark
    from walkstream.benchmarks.visinput import load_bench_input
    from walkstream.benchmarks.visref import default_cache_dir
    from walkstream.benchmarks.visreport import format_table, plot_visibility_benchmark
    from walkstream.benchmarks.vissettings import DEFAULT_SETTINGS, parse_setting

    names = [s.strip() for s in args.settings.split(",") if s.strip()] if args.settings else DEFAULT_SETTINGS
    settings = [parse_setting(n) for n in names]  # a bad name fails before any work
    inp = load_bench_input(Path(args.scene))  # a scene database, or any city source
    bar, progress = count_bar("rendering", "cell")
    try:
        res = visibility_benchmark(
            inp,
            settings=settings,
            sample=args.sample,
            seed=args.seed,
            ref_points=args.ref_points,
            ref_resolution=args.ref_resolution,
            views=args.views,
            repeat=args.repeat,
            progress=progress,
            cache=None if args.no_cache else (args.cache or default_cache_dir()),
        )
    finally:
        bar.close()
    print(format_table(res))
    print(f"{res['seconds']:.0f} s in all")
    if args.plot:
        plot_visibility_benchmark(res, args.plot)
        print(f"plot: {args.plot}")
    if args.json:
        Path(args.json).write_text(json.dumps(res, indent=1, default=str))
        print(f"json: {args.json}")
    return 0


def cmd_bench_render(args: argparse.Namespace) -> int:
    """Handler of ``walkstream bench render``."""
    from walkstream.benchmarks.renderspeed import run_render_speed

    for line in run_render_speed(
        size=args.size,
        seed=args.seed,
        cells_wanted=args.cells,
        runs=args.runs,
        resolutions=args.resolutions,
        lods=args.lods,
        view_distance=args.view_distance,
        no_cull=args.no_cull,
    ):
        print(line, flush=True)
    return 0


def cmd_bench_server(args: argparse.Namespace) -> int:
    """Handler of ``walkstream bench server``."""
    from walkstream.benchmarks.load import format_table, run_server_bench

    rows = run_server_bench(
        args.db,
        walkers=_ints(args.walkers, "--walkers"),
        workers=_ints(args.workers, "--workers"),
        ramp_s=args.ramp,
        duration_s=args.duration,
        pin=not args.no_pin,
        progress=lambda row: print(f"done: {row['walkers']} walkers, {row['workers']} worker(s)", file=sys.stderr),
    )
    print(format_table(rows))
    return 0


def cmd_bench_stream(args: argparse.Namespace) -> int:
    """Handler of ``walkstream bench stream``."""
    from walkstream.benchmarks.stream import (
        format_colour_table,
        format_crossing_table,
        format_stream_table,
        format_truth_table,
        parse_extra,
        run_stream_bench,
    )
    from walkstream.cmd_replay import replayer

    out = Path(args.out)
    only = [s.strip() for s in args.only.split(",")] if args.only else []
    rows = run_stream_bench(
        args.db,
        replayer(not args.no_plots),
        out=out,
        vienna=args.vienna,
        extra=[parse_extra(t) for t in args.scene],
        device=args.device,
        duration=args.duration,
        only=only,
        truth_every=args.truth_every,
        crossing=args.crossing,
        clock=args.clock,
    )
    print(format_stream_table(rows))
    if args.truth_every and format_truth_table(rows):
        print()
        print(format_truth_table(rows))
    if args.truth_every and format_colour_table(rows):
        print()
        print("colour error of the client's picture against the full scene (CIEDE2000; % of full scale, linear RGB):")
        print(format_colour_table(rows))
    if format_crossing_table(rows):
        print()
        print(format_crossing_table(rows))
    if rows:
        print(f"plots and per-run reports: {out / 'index.html'}")
    return 0


def _choices(text: str, flag: str, allowed: tuple[str, ...]) -> tuple[str, ...]:
    """A comma-separated list of some of ``allowed`` (a clear error names the bad one)."""
    from walkstream.shared.errors import InputError

    got = tuple(x.strip() for x in text.split(",") if x.strip())
    for x in got:
        if x not in allowed:
            raise InputError(f"{flag} {x!r}: choose from {', '.join(allowed)}")
    if not got:
        raise InputError(f"{flag}: name at least one of {', '.join(allowed)}")
    return got


def cmd_bench_budget(args: argparse.Namespace) -> int:
    """Handler of ``walkstream bench budget``."""
    from walkstream.benchmarks.budget import (
        DRAWS,
        format_budget_table,
        format_gl_real_table,
        run_budget_bench,
    )
    from walkstream.client.rewrite.pool import MODES
    from walkstream.cmd_replay import replayer

    out = Path(args.out)
    rows = run_budget_bench(
        args.db,
        replayer(not args.no_plots),
        out=out,
        duration=args.duration,
        gl_duration=args.gl_duration,
        step_at=args.step_at,
        gl=not args.no_gl,
        seed=args.seed,
        gl_runs=args.gl_runs,
        gl_real_duration=args.gl_real_duration,
        gl_draws=_choices(args.gl_draws, "--gl-draws", DRAWS),
        rewrites=_choices(args.rewrite, "--rewrite", MODES),
    )
    print(format_budget_table(rows))
    real = format_gl_real_table(rows)
    if real:
        print()
        print(real)
    print(f"reports: {out}")
    return 0


def cmd_bench_controller(args: argparse.Namespace) -> int:
    """Handler of ``walkstream bench controller``."""
    from walkstream.benchmarks.controller import format_table, run_controller_bench

    t0 = time.perf_counter()
    rows = run_controller_bench(frames=args.frames, seeds=args.seeds, step_factor=args.step)
    print(format_table(rows))
    print(
        f"{args.frames} frames x {len(args.seeds)} seeds x 2 runs per row, "
        f"step x{args.step:g} at frame {args.frames // 2}; {time.perf_counter() - t0:.1f} s"
    )
    return 0


def _lod_size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT, got {text!r}") from None
    if w <= 0 or h <= 0:
        raise argparse.ArgumentTypeError(f"expected positive sizes, got {text!r}")
    return w, h


def _shares(text: str) -> tuple[float, ...]:
    try:
        vals = tuple(float(v.strip().rstrip("%")) / 100.0 for v in text.split(",") if v.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected percentages like 5,10,25,50, got {text!r}"
        ) from None
    if not vals or any(not (0.0 < v <= 1.0) for v in vals):
        raise argparse.ArgumentTypeError(f"percentages must be in (0, 100], got {text!r}")
    return vals


def _ratio(text: str) -> float | None:
    if text.strip().lower() in ("free", "none"):
        return None
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected a number >= 1 or 'free', got {text!r}"
        ) from None
    if not (math.isfinite(v) and v >= 1.0):
        raise argparse.ArgumentTypeError(f"expected a number >= 1 or 'free', got {text!r}")
    return v


def _redundancy_arg(text: str) -> int | None:
    # bench sections --redundancy: a count of objects, or auto (None: R from the field)
    if text.strip().lower() == "auto":
        return None
    if not text.strip().isdigit():
        raise argparse.ArgumentTypeError(f"expected a number of objects >= 0 or 'auto', got {text!r}")
    return int(text)


def cmd_bench_fill(args: argparse.Namespace) -> int:
    """Handler of ``walkstream bench fill``."""
    from walkstream.benchmarks.fill import format_fill_table, run_fill_bench

    result = run_fill_bench(
        args.db, views=args.views, path_name=args.path, size=args.size, repeats=args.repeat
    )
    print(json.dumps(result) if args.json else format_fill_table(result))
    return 0


def cmd_bench_clusters(args: argparse.Namespace) -> int:
    """Handler of ``walkstream bench clusters``."""
    from walkstream.benchmarks.clusters import (
        format_clusters_table,
        plot_clusters,
        run_clusters_bench,
    )
    from walkstream.server.bake.pvsclusters import ClusterSettings

    if args.min_objects < 1 or args.max_cells < 2:
        raise WalkstreamError("--min-objects must be at least 1 and --max-cells at least 2")
    rows = run_clusters_bench(
        [Path(d) for d in args.db], ClusterSettings(min_objects=args.min_objects, max_cells=args.max_cells)
    )
    if args.json:
        print(json.dumps(rows))
    else:
        print(format_clusters_table(rows))
        print("(bytes from the real encoders: msgpack records as the service sends them; walks sampled every "
              "0.25 s, each cell and cluster fetched once; gzip: as the cells batch sends it, level 6; clusters "
              "ride in the batch of the first cell naming them)")
    if args.plot:
        print(f"plot: {plot_clusters(rows, Path(args.plot))}")
    return 0


def _add_clusters(besub: Any) -> None:
    p = besub.add_parser(
        "clusters",
        help="visibility lists clustered along the cell adjacency (m-LOMA) against delta-coded records: bytes of records and walks",
    )
    p.add_argument("db", nargs="+", help="scene databases (city scenes: cells with a PVS)")
    p.add_argument("--min-objects", type=int, default=12, help="smallest shared set made a cluster (default 12)")
    p.add_argument("--max-cells", type=int, default=64, help="most cells one growth adds (default 64)")
    p.add_argument("--plot", help="bar plot of clustered / delta-coded bytes per scene (PNG)")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")
    p.set_defaults(func=cmd_bench_clusters)


def _add_fill(besub: Any) -> None:
    p = besub.add_parser(
        "fill",
        help="ctx.finish() ms of clear / streets / floor / LOD2 frames, per-fragment vs per-vertex lighting",
    )
    p.add_argument("db", nargs="?", default="out/demo/city.db", help="scene database (default out/demo/city.db)")
    p.add_argument("--views", type=int, default=6, help="viewpoints along the path (default 6)")
    p.add_argument("--path", default="SE", help="recorded path for viewpoints (default SE)")
    p.add_argument("--size", type=_lod_size, default=(1280, 960), help="frame size (default 1280x960)")
    p.add_argument("--repeat", type=int, default=6, help="timed rounds per viewpoint (default 6)")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.set_defaults(func=cmd_bench_fill)


def _add_lod(besub: Any) -> argparse.ArgumentParser:
    from walkstream.benchmarks.lod import DEFAULT_DB, DEFAULT_SHARES, DISTANCE_RATIO, PATH_NAME

    p: argparse.ArgumentParser = besub.add_parser(
        "lod",
        help="image error against frame time: ACH allocation vs distance LODs vs all LOD2",
    )
    p.add_argument(
        "db", nargs="?", default=str(DEFAULT_DB), help=f"scene database (default {DEFAULT_DB})"
    )
    p.add_argument("--views", type=int, default=8, help="viewpoints (default 8)")
    p.add_argument(
        "--budgets",
        type=_shares,
        default=DEFAULT_SHARES,
        help="budgets as percent of the LOD2 triangles (default 5,10,25,50)",
    )
    p.add_argument("--size", type=_lod_size, default=(640, 480), help="frame size (default 640x480)")
    p.add_argument("--repeat", type=int, default=5, help="timed draws per frame (default 5)")
    p.add_argument(
        "--path", default=PATH_NAME, help=f"recorded path for viewpoints (default {PATH_NAME})"
    )
    p.add_argument(
        "--distance-ratio",
        type=_ratio,
        default=DISTANCE_RATIO,
        help="d2/d1 of the distance selection, or 'free' to fit both (default free)",
    )
    p.add_argument("--plot", help="PNG: image error against frame time")
    p.add_argument("--images", help="PNG: LOD2 / ACH / distance / differences at one viewpoint")
    p.add_argument("--json", action="store_true", help="print the rows as JSON")
    p.set_defaults(func=cmd_bench_lod)
    return p


def cmd_bench_lod(args: argparse.Namespace) -> int:
    """Handler of ``walkstream bench lod``."""
    from walkstream.benchmarks.lod import format_table, plot_lod_bench, run_lod_bench

    rows = run_lod_bench(
        args.db,
        views=args.views,
        shares=args.budgets,
        size=args.size,
        repeats=args.repeat,
        path_name=args.path,
        images=args.images,
        distance_ratio=args.distance_ratio,
    )
    if args.json:
        print(json.dumps(rows))
    else:
        print(format_table(rows), end="")
    if args.plot:
        plot_lod_bench(rows, args.plot)
        print(f"plot: {args.plot}")
    if args.images:
        print(f"images: {args.images}")
    return 0


def cmd_bench_city(args: argparse.Namespace) -> int:
    """Handler of ``walkstream bench city``."""
    from walkstream.benchmarks.city import format_city_table, run_city_bench
    from walkstream.cmd_replay import replay_with_options

    only = [s.strip() for s in args.only.split(",")] if args.only else []
    rows = run_city_bench(
        replay_with_options,
        data=Path(args.data),
        out=Path(args.out),
        only=only,
        reuse=args.reuse,
        workers=args.workers,
        truth_every=args.truth_every,
        kinds=[k.strip() for k in args.kinds.split(",") if k.strip()],
    )
    print(format_city_table(rows))
    print("(56 kbit/s, 200 ms, simulated clock, desktop2003; culled% = objects outside the PVS)")
    return 0


def cmd_bench_field(args: argparse.Namespace) -> int:
    """Handler of ``walkstream bench field``."""
    from walkstream.benchmarks.fieldspeed import format_field_speed, run_field_speed
    from walkstream.cmd_bake import default_city_source

    sources = [Path(s) for s in args.source] or [default_city_source(Path(args.out))]
    rows = [run_field_speed(s, points=args.points, starts=args.starts, spacing=args.field_spacing) for s in sources]
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    print(format_field_speed(rows))
    print("(renders = field points x 2 eye heights, 6 cube faces of 128 px each; plain: the renderer as the field "
          "used it before, bake: the field's renderer now (two passes in flight), culled: exact occlusion culling, "
          "not adopted; per CPU-s counts every thread of the process, the rasteriser's too; same sets / same px: points whose visible set / pixel counts "
          "equal the plain render's; max dpx: the largest pixel difference of one object)")
    return 0


def cmd_bench_sections(args: argparse.Namespace) -> int:
    """Handler of ``walkstream bench sections``."""
    from walkstream.benchmarks.sections import (
        format_sections_table,
        plot_sections_trade,
        run_sections_bench,
    )
    from walkstream.cmd_bake import default_city_source, parse_bbox
    from walkstream.cmd_replay import replay_with_options

    out = Path(args.out)
    source = Path(args.source) if args.source else default_city_source(out)
    rows = run_sections_bench(
        replay_with_options, source=source, out=out, redundancies=args.redundancy, min_sizes=args.min_size,
        field_spacing=args.field_spacing, walks=[w.strip() for w in args.walks.split(",") if w.strip()],
        covers=args.section_cover, reuse=args.reuse, workers=args.workers,
        bbox=parse_bbox(args.bbox), bbox_crs=args.bbox_crs,
    )
    print(format_sections_table(rows))
    print("(56 kbit/s, 200 ms, simulated clock, desktop2003; R* = R from the field (auto); redund. = objects a section holds that the "
          "field point where the walker stands does not see, mean; objects, records, index = bytes/km of the "
          "objects, the cell records and the index tiles; overf. = share of the bytes never used in a cell entered)")
    plot = out / "sections_trade.png"
    plot_sections_trade(rows, plot)
    print(f"plot: {plot}")
    return 0


def add_bench_parser(sub: Any) -> None:
    """Register ``bench`` and every benchmark under it."""
    from walkstream.server.sources.citygen import DEFAULT_SIZE

    be = sub.add_parser("bench", help="benchmarks that print a table")
    besub = be.add_subparsers(dest="what", metavar="WHAT", required=True)
    bb = besub.add_parser("rebuild", help="rebuild throughput per LOD and parameter/geometry bytes")
    bb.add_argument("file", nargs="?", help="GeoJSON source (default: the default 700 m city)")
    bb.add_argument("--size", type=float, default=DEFAULT_SIZE, help="city size when no file is given")
    bb.add_argument("--repeat", type=int, default=5, help="runs; the table shows medians (default 5)")
    bb.add_argument(
        "--batch", default="32,256", help="batch sizes of the batched rows, comma-separated (default 32,256)"
    )
    bb.add_argument("--beside-loop", metavar="PATHS", help="instead: rebuild the scene with the client's rewrite pool in these paths (thread,process) beside a 60 Hz frame-loop stand-in, and time the stand-in")
    bb.add_argument("--workers", default="1,2", help="with --beside-loop: rewrite workers, comma-separated (default 1,2)")
    bb.set_defaults(func=cmd_bench_rebuild)
    bv = besub.add_parser("visibility", help="what the PVS misses against a dense reference and at random eye points, against bake time, per sampling setting")
    bv.add_argument("scene", help="scene database (read alone: any source it was baked from) or a scene source file")
    bv.add_argument("--sample", type=int, default=12, help="cells compared (default 12)")
    bv.add_argument("--seed", type=int, default=0, help="seed of the cells, reference points and eye points (default 0)")
    bv.add_argument("--settings", help="comma-separated settings, e.g. corners-64,boundary20-128,boundary20-128-t2 (default: a dozen)")
    bv.add_argument("--ref-points", type=int, default=64, help="reference viewpoints per cell (default 64)")
    bv.add_argument("--ref-resolution", type=int, default=512, help="reference pixels per cube face (default 512)")
    bv.add_argument("--views", type=int, default=4, help="random eye points per cell for the image error (default 4; 0: none)")
    bv.add_argument("--repeat", type=int, default=3, help="renders per cell and setting; the fastest counts (default 3)")
    bv.add_argument("--cache", help="folder of reference counts kept between runs (default ~/.cache/walkstream/visibility-reference)")
    bv.add_argument("--no-cache", action="store_true", help="render the reference again and keep nothing")
    bv.add_argument("--plot", help="PNG: misses against bake time and PVS size, missed objects' sizes")
    bv.add_argument("--json", help="write the full result as JSON here")
    bv.set_defaults(func=cmd_bench_visibility)
    brs = besub.add_parser("render", help="cells per second the visibility renderer bakes, per resolution and LOD")
    brs.add_argument("--size", type=float, default=DEFAULT_SIZE, help="generated city size, metres (default 700)")
    brs.add_argument("--seed", type=int, default=1, help="city seed (default 1)")
    brs.add_argument("--cells", type=int, default=40, help="cells timed (default 40)")
    brs.add_argument("--runs", type=int, default=3, help="runs; the median is shown (default 3)")
    brs.add_argument("--resolutions", type=int, nargs="+", default=[64, 128, 256], help="pixels per cube face")
    brs.add_argument("--lods", type=int, nargs="+", default=[0, 1, 2], help="occluder LODs")
    brs.add_argument("--view-distance", type=float, default=800.0, help="far plane, metres (default 800)")
    brs.add_argument("--no-cull", action="store_true", help="draw back faces too")
    brs.set_defaults(func=cmd_bench_render)
    bsv = besub.add_parser("server", help="simulated walkers against a real server on loopback: req/s, p50/p99, errors")
    bsv.add_argument("db", help="scene database to serve")
    bsv.add_argument("--walkers", default="10,100,1000", help="walker counts (default 10,100,1000)")
    bsv.add_argument("--workers", default="1,2", help="server worker counts (default 1,2)")
    bsv.add_argument("--ramp", type=float, default=60.0, help="seconds over which walkers start (default 60)")
    bsv.add_argument("--duration", type=float, default=30.0, help="measured seconds after the ramp (default 30)")
    bsv.add_argument("--no-pin", action="store_true", help="do not pin server and load generator to separate cores")
    bsv.set_defaults(func=cmd_bench_server)

    b = besub.add_parser("stream", help="replays under the simulated clock: quality, bytes, overfetch per link and mode")
    b.add_argument("db", nargs="?", default="out/demo/city.db", help="scene database (default out/demo/city.db from make demo)")
    b.add_argument("--vienna", help="a baked Vienna database with the imported walk (path 'walk')")
    b.add_argument("--scene", action="append", default=[], metavar="LABEL=DB[:PATH,...]", help="more scene databases: rows for each recorded path (or those named), GPRS and 56k; repeatable")
    b.add_argument("--crossing", metavar="DB", help="a crossing scene (bake CITY --interior FILE): rows for its walk 'enter' at 56k and GPRS, compared with the ground truth")
    b.add_argument("--device", default="desktop2003", choices=("gl", "desktop2003", "pda"), help="device (default desktop2003)")
    b.add_argument("--duration", help="limit every walk, e.g. 60s")
    b.add_argument("--only", help="comma-separated scenario name parts to run")
    b.add_argument("--truth-every", type=int, default=0, metavar="N", help="compare every Nth frame of each walk with the ground truth (a second table, and the colour error; default 0: never)")
    b.add_argument("--clock", default="sim", choices=("sim", "real"), help="simulated clock (default) or real time (with --device gl: frames drawn and timed for real)")
    b.add_argument("--out", default="out/bench-stream", help="folder for reports and plots")
    b.add_argument("--no-plots", action="store_true", help="each replay's report without its plots (as replay --no-plots); the comparison's own plots are drawn")
    b.set_defaults(func=cmd_bench_stream)

    add_image_benches(besub)

    b = besub.add_parser("budget", help="frame rate and polygon budget per device and target, with a tenfold cost step")
    b.add_argument("db", nargs="?", default="out/demo/city.db", help="scene database (default out/demo/city.db)")
    b.add_argument("--duration", default="180s", help="walk length for the simulated devices (default 180s)")
    b.add_argument("--gl-duration", default="20s", help="walk length for the gl device (default 20s)")
    b.add_argument("--step-at", type=float, default=60.0, help="walk second of the tenfold cost step (default 60)")
    b.add_argument("--no-gl", action="store_true", help="skip the gl rows (the real-clock ones too)")
    b.add_argument("--gl-runs", type=int, default=3, help="runs per real-clock gl row, medians reported (default 3; 0: no real-clock rows)")
    b.add_argument("--gl-real-duration", default="20s", help="walk length of each real-clock gl run (default 20s)")
    b.add_argument("--gl-draws", default="batched,per-object", help="draw paths of the real-clock gl rows (default batched,per-object)")
    b.add_argument("--rewrite", default="process", help="rebuild paths of the real-clock gl rows, e.g. thread,process (default process)")
    b.add_argument("--seed", type=int, default=0, help="seed of the device noise and spikes (default 0)")
    b.add_argument("--out", default="out/bench-budget", help="folder for the reports")
    b.add_argument("--no-plots", action="store_true", help="each replay's report without its plots (as replay --no-plots); the table is the same")
    b.set_defaults(func=cmd_bench_budget)

    bc = besub.add_parser("controller", help="the budget controller alone on the device cost models, many seeds")
    bc.add_argument("--frames", type=int, default=3_000, help="frames per run (default 3000)")
    bc.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3], help="noise/walk seeds (default 1 2 3)")
    bc.add_argument("--step", type=float, default=10.0, help="per-triangle cost step factor (default 10)")
    bc.set_defaults(func=cmd_bench_controller)

    add_room_benches(besub)
    add_pvs_benches(besub)
    _add_lod(besub)
    _add_fill(besub)
    _add_clusters(besub)

    b = besub.add_parser("sections", help="the section-size trade: street cells against sections for every --redundancy and --min-size (bake, replay)")
    b.add_argument("source", nargs="?", help="city source (default: the default 700 m city, generated in --out)")
    b.add_argument("--redundancy", type=_redundancy_arg, nargs="+", default=[32, 64, 96],
                   help="redundancies R to bake; auto: the bake's default, R from the field (default 32 64 96)")
    b.add_argument("--min-size", type=float, nargs="+", default=[64.0], help="minimum sizes M to bake, square metres (default 64)")
    b.add_argument("--field-spacing", type=float, default=4.0, help="metres between field points (default 4)")
    b.add_argument("--walks", default="SE,drive", help="comma-separated walks to replay (default SE,drive)")
    b.add_argument("--section-cover", nargs="+", default=["walkable"], help="covers to bake, of walkable and free (default walkable)")
    b.add_argument("--reuse", action="store_true", help="keep databases already baked in --out")
    b.add_argument("--workers", type=int, default=1, help="local processes rendering the field (default 1)")
    b.add_argument("--bbox", help="MINX,MINY,MAXX,MAXY: bake only this part of the source (as bake --bbox)")
    b.add_argument("--bbox-crs", choices=("local", "lonlat"), default="local", help="--bbox in scene-local metres (default) or lon/lat degrees")
    b.add_argument("--out", default="out/bench-sections", help="folder for the databases, reports and the plot")
    b.set_defaults(func=cmd_bench_sections)

    b = besub.add_parser("field", help="how fast the dense visibility field renders: the bake's renderer against exact occlusion culling, same points")
    b.add_argument("source", nargs="*", help="city sources (default: the default 700 m city, generated in --out)")
    b.add_argument("--points", type=int, default=64, help="consecutive field points per run (default 64, one block)")
    b.add_argument("--starts", type=int, default=4, help="runs spread over the lattice (default 4)")
    b.add_argument("--field-spacing", type=float, default=4.0, help="metres between field points (default 4)")
    b.add_argument("--out", default="out/bench-field", help="folder for the generated city")
    b.add_argument("--json", action="store_true", help="print the rows as JSON")
    b.set_defaults(func=cmd_bench_field)

    b = besub.add_parser("city", help="OpenStreetMap extracts: street cells against grid cells (bake, PVS, replay)")
    b.add_argument("--data", default="../shared/data/osm", help="folder of the extracts (default ../shared/data/osm)")
    b.add_argument("--only", help="comma-separated extract names (kouvola, west-oakland, village)")
    b.add_argument("--reuse", action="store_true", help="keep databases already baked in --out")
    b.add_argument("--workers", type=int, default=1, help="local processes rendering cells (default 1)")
    b.add_argument("--kinds", default="street,grid", help="cell kinds baked and replayed, of street, grid, sections (default street,grid; street is always baked: the walk is its)")
    b.add_argument("--out", default="out/bench-city", help="folder for the databases and reports")
    b.add_argument("--truth-every", type=int, default=0, metavar="N", help="compare every Nth frame with the ground truth: the sky below the horizon, in two more columns (default 0: never)")
    b.set_defaults(func=cmd_bench_city)
