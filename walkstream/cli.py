"""The ``walkstream`` command: where server, client and shared pieces are wired together.

Every subcommand imports what it needs lazily so ``walkstream --help`` stays fast.
Errors a user can cause (``WalkstreamError``, unreadable files) end as one line on
stderr and exit status 2; nothing else is caught, so a bug still shows its traceback.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

from walkstream.shared.errors import WalkstreamError

__all__ = ["main", "build_parser"]

DEFAULT_CITY_SIZE = 700.0
DEFAULT_CITY_SEED = 1


def _progress(total: int, desc: str) -> Any:
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="bldg", file=sys.stderr, leave=False, dynamic_ncols=True)


# ---------------------------------------------------------------- generate


def cmd_generate_city(args: argparse.Namespace) -> int:
    from walkstream.server.sources.citygen import city_summary, write_city

    t0 = time.perf_counter()
    write_city(args.output, args.size, args.seed)
    fc = json.loads(Path(args.output).read_text())
    summary = city_summary(fc)
    summary["seconds"] = round(time.perf_counter() - t0, 2)
    summary["output"] = str(args.output)
    _print_summary("city", summary, args.json)
    return 0


def _print_summary(title: str, summary: dict[str, Any], as_json: bool) -> None:
    if as_json:
        print(json.dumps(summary))
        return
    print(f"{title}:")
    width = max(len(k) for k in summary)
    for k, v in summary.items():
        print(f"  {k:<{width}}  {v}")


# ---------------------------------------------------------------- buildings


def _load(path: str) -> Any:
    from walkstream.server.sources.geojson import load_geojson

    return load_geojson(path)


def cmd_buildings_stats(args: argparse.Namespace) -> int:
    from walkstream.shared.buildstats import building_stats
    from walkstream.shared.codec import encode_building

    scene = _load(args.file)
    skipped = sum(1 for i in scene.issues if i.action == "skipped")
    with _progress(len(scene.buildings), "rebuilding") as bar:
        stats = building_stats(scene.buildings, encode_building, skipped=skipped, progress=bar.update)
    if args.json:
        print(json.dumps(stats))
        return 0
    print(f"{args.file}: {stats['buildings']} buildings kept, {stats['skipped']} skipped")
    print(f"  {'':<22}{'LOD0':>12}{'LOD1':>12}{'LOD2':>12}")
    print(f"  {'triangles':<22}" + "".join(f"{t:>12,}" for t in stats["triangles"]))  # type: ignore[attr-defined]
    print(f"  {'rebuild buildings/s':<22}" + "".join(f"{t:>12,.0f}" for t in stats["rebuild_per_s"]))  # type: ignore[attr-defined]
    print(f"  parameters (msgpack)  {stats['param_bytes']:,} bytes")
    print(f"  LOD2 geometry (GPU)   {stats['lod2_bytes']:,} bytes")
    print(f"  ratio                 {100 * float(stats['ratio']):.4f} %")  # type: ignore[arg-type]
    return 0


def _pick_building(scene: Any, ident: str) -> Any:
    for b in scene.buildings:
        if str(b.id) == ident or b.source_id == ident:
            return b
    ids = ", ".join(b.source_id or str(b.id) for b in scene.buildings[:5])
    raise WalkstreamError(f"no building with id {ident!r} (ids look like: {ids}, ...)")


def cmd_buildings_render(args: argparse.Namespace) -> int:
    from walkstream.shared.buildings import build_lods

    scene = _load(args.file)
    b = _pick_building(scene, args.id)
    meshes = list(build_lods(b))
    if args.output:
        from walkstream.client.draw.meshes import render_lods_figure

        render_lods_figure(meshes, args.output)
        print(f"wrote {args.output} (building {b.source_id or b.id}: triangles {[m.triangles for m in meshes]})")
    if args.gltf:
        from walkstream.shared.buildings import build_lod
        from walkstream.shared.export import export_glb

        chosen = scene.buildings if args.all else [b]
        with _progress(len(chosen), f"LOD{args.lod}") as bar:
            out = []
            for c in chosen:
                out.append(build_lod(c, args.lod))
                bar.update(1)
        n = export_glb(out, args.gltf)
        print(f"wrote {args.gltf} ({len(out)} buildings at LOD{args.lod}, {n:,} bytes)")
    if not args.output and not args.gltf:
        raise WalkstreamError("nothing to do: give -o PNG and/or --gltf GLB")
    return 0


# ---------------------------------------------------------------- grammar


def cmd_grammar(args: argparse.Namespace) -> int:
    from walkstream.shared.buildings import default_grammar_text
    from walkstream.shared.lsystem.grammar import load_grammar, parse_grammar

    if args.file:
        g = load_grammar(args.file)
        print(f"{args.file}: grammar {g.name} version {g.version}, {sum(len(p) for p in g.productions.values())} productions, id {g.id}")
    else:
        text = default_grammar_text()
        if args.check:
            g = parse_grammar(text)
            print(f"built-in grammar {g.id} ok")
        else:
            sys.stdout.write(text)
    return 0


# ---------------------------------------------------------------- bench


def cmd_bench_rebuild(args: argparse.Namespace) -> int:
    import statistics
    import tempfile

    from walkstream.shared.buildstats import building_stats
    from walkstream.shared.codec import encode_building

    source = args.file
    if source is None:
        from walkstream.server.sources.citygen import write_city

        source = str(Path(tempfile.mkdtemp()) / "city.geojson")
        write_city(source, args.size, DEFAULT_CITY_SEED)
    scene = _load(source)
    runs = []
    for r in range(args.repeat):
        with _progress(len(scene.buildings), f"run {r + 1}/{args.repeat}") as bar:
            runs.append(building_stats(scene.buildings, encode_building, progress=bar.update))
    first = runs[0]
    print(f"rebuild benchmark: {source} ({first['buildings']} buildings, {args.repeat} runs, one core)")
    print(f"{'LOD':<6}{'median b/s':>12}{'min':>10}{'max':>10}{'triangles':>14}{'goal b/s':>10}")
    goals = (2000, None, 200)
    for lod in range(3):
        rates = [float(r["rebuild_per_s"][lod]) for r in runs]  # type: ignore[index]
        goal = goals[lod]
        print(
            f"LOD{lod:<3}{statistics.median(rates):>12,.0f}{min(rates):>10,.0f}{max(rates):>10,.0f}"
            f"{first['triangles'][lod]:>14,}{goal if goal else '-':>10}"  # type: ignore[index]
        )
    ratio = float(first["ratio"])  # type: ignore[arg-type]
    print(f"parameters {first['param_bytes']:,} B, LOD2 geometry {first['lod2_bytes']:,} B, ratio {100 * ratio:.4f} % (goal <= 0.1 %)")
    return 0


# ---------------------------------------------------------------- bake / inspect / serve


def _parse_bbox(text: str | None) -> tuple[float, float, float, float] | None:
    if text is None:
        return None
    try:
        parts = tuple(float(v) for v in text.split(","))
    except ValueError:
        parts = ()
    if len(parts) != 4:
        raise WalkstreamError(f"--bbox: expected MINX,MINY,MAXX,MAXY in scene-local metres, got {text!r}")
    return parts


def _default_city_source(folder: Path) -> Path:
    from walkstream.server.sources.citygen import write_city

    folder.mkdir(parents=True, exist_ok=True)
    city = folder / "city.geojson"
    if not city.exists():
        print(f"generating the default city ({DEFAULT_CITY_SIZE:.0f} m, seed {DEFAULT_CITY_SEED}) -> {city}")
        write_city(city, DEFAULT_CITY_SIZE, DEFAULT_CITY_SEED)
    return city


def _count_bar(desc: str, unit: str) -> tuple[Any, Any]:
    """A stderr progress bar and the ``(done, total)`` callback that drives it."""
    from tqdm import tqdm

    bar = tqdm(total=0, desc=desc, unit=unit, file=sys.stderr, dynamic_ncols=True)

    def progress(done: int, total: int) -> None:
        bar.total = total
        bar.n = done
        bar.refresh()

    return bar, progress


def run_bake(source: str | Path, output: str | Path, **kw: Any) -> dict[str, Any]:
    """Bake with a progress bar on stderr; returns the summary."""
    from walkstream.server.bake import bake

    bar, progress = _count_bar("baking cells", "cell")
    try:
        return bake(source, output, progress=progress, log=lambda m: bar.write(m, file=sys.stderr), **kw)
    finally:
        bar.close()


def cmd_bake(args: argparse.Namespace) -> int:
    from walkstream.server.bake import BakeSettings

    if args.default_city:
        source: Path = _default_city_source(Path(args.output).resolve().parent)
    elif args.source:
        source = Path(args.source)
    else:
        raise WalkstreamError("give a SOURCE.geojson or --default-city")
    st = BakeSettings(
        cells=args.cells,
        cell_size=args.cell_size,
        max_length=args.cell_size,
        view_distance=args.view_distance,
        bbox=_parse_bbox(args.bbox),
        centre=args.centre,
        threshold=args.threshold,
        **{k: v for k, v in (("resolution", args.resolution), ("occluder_lod", args.occluder_lod)) if v is not None},
    )
    summary = run_bake(source, args.output, settings=st, name=args.name, workers=args.workers, scheduler=args.scheduler)
    _print_summary(f"baked {args.output}", summary, args.json)
    return 0


def cmd_inspect(args: argparse.Namespace) -> int:
    from walkstream.server.store import SceneReader

    reader = SceneReader.open(args.db)
    try:
        summary = reader.summary()
        if args.map:
            from walkstream.server.bake.mapplot import draw_map

            draw_map(reader, args.map)
    finally:
        reader.close()
    if args.json:
        print(json.dumps(summary))
    else:
        _print_summary(str(args.db), summary, False)
        if args.map:
            print(f"map: {args.map}")
    return 0


def cmd_serve(args: argparse.Namespace) -> int:
    from walkstream.server.service.run import serve

    serve(args.db, host=args.host, port=args.port, workers=args.workers)
    return 0


def cmd_bench_visibility(args: argparse.Namespace) -> int:
    from walkstream.server.visbench import (
        format_table,
        load_bench_input,
        plot_visibility_benchmark,
        visibility_benchmark,
    )

    inp = load_bench_input(args.scene, source=args.source)
    bar, progress = _count_bar("rendering", "cell")
    try:
        res = visibility_benchmark(
            inp.scene, inp.cells, sample=args.sample, view_distance=inp.view_distance, progress=progress
        )
    finally:
        bar.close()
    print(format_table(res))
    if args.plot:
        plot_visibility_benchmark(res, args.plot)
        print(f"plot: {args.plot}")
    return 0


def cmd_bench_server(args: argparse.Namespace) -> int:
    from walkstream.server.loadbench import format_table, run_server_bench

    def ints(text: str, flag: str) -> tuple[int, ...]:
        try:
            return tuple(int(v) for v in text.split(","))
        except ValueError:
            raise WalkstreamError(f"{flag}: expected comma-separated integers, got {text!r}") from None

    rows = run_server_bench(
        args.db,
        walkers=ints(args.walkers, "--walkers"),
        workers=ints(args.workers, "--workers"),
        ramp_s=args.ramp,
        duration_s=args.duration,
        pin=not args.no_pin,
        progress=lambda row: print(f"done: {row['walkers']} walkers, {row['workers']} worker(s)", file=sys.stderr),
    )
    print(format_table(rows))
    return 0


# ---------------------------------------------------------------- demo


def cmd_demo(args: argparse.Namespace) -> int:
    from walkstream.server.sources.citygen import city_summary

    out = Path(args.out)
    city = _default_city_source(out)
    summary = city_summary(json.loads(city.read_text()))
    _print_summary("default city", summary, False)
    from walkstream.shared.buildstats import building_stats
    from walkstream.shared.codec import encode_building

    scene = _load(str(city))
    with _progress(len(scene.buildings), "rebuilding") as bar:
        stats = building_stats(scene.buildings, encode_building, progress=bar.update)
    print(
        f"rebuilt {stats['buildings']} buildings: triangles per LOD {stats['triangles']}, "
        f"buildings/s per LOD {stats['rebuild_per_s']}"
    )
    print(
        f"parameters {stats['param_bytes']:,} B vs LOD2 geometry {stats['lod2_bytes']:,} B "
        f"({100 * float(stats['ratio']):.4f} %)"  # type: ignore[arg-type]
    )
    try:
        from walkstream.client.draw.meshes import render_lods_figure
        from walkstream.shared.buildings import build_lods

        # a free-standing building shows every facade; fall back to the most complex one
        free = [b for b in scene.buildings if all((h == 0).all() for h in b.neighbour_heights)]
        biggest = max(free or scene.buildings, key=lambda b: len(b.rings[0]) + b.floors)
        png = out / "lods.png"
        render_lods_figure(list(build_lods(biggest)), png)
        print(f"LOD figure of building {biggest.source_id}: {png}")
    except WalkstreamError as exc:
        print(f"(no LOD figure: {exc})")
    db = out / "city.db"
    if db.exists() and not _has_paths(db, ("SE",)):
        print(f"scene database {db} has no recorded path SE (an older bake): baking again")
        db.unlink()
    if db.exists():
        print(f"scene database {db} exists (delete it to bake again)")
    else:
        t0 = time.perf_counter()
        run_bake(city, db, workers=args.workers)
        print(f"baked {db} in {time.perf_counter() - t0:.1f} s")
    from walkstream.server.bake.mapplot import draw_map
    from walkstream.server.store import SceneReader

    reader = SceneReader.open(db)
    try:
        s = reader.summary()
        draw_map(reader, out / "map.png")
    finally:
        reader.close()
    print(
        f"scene {s['name']} {s['version']}: {s['cells']} cells, {s['objects']} objects, "
        f"PVS mean {s['pvs_mean']:.1f} max {s['pvs_max']}, culled {100 * s['culled_ratio']:.1f} %"
    )
    print(f"map of the cells: {out / 'map.png'}")
    if args.no_replay:
        return 0
    return _demo_replay(db, out / "report", args)


def _has_paths(db: Path, names: tuple[str, ...]) -> bool:
    """Whether ``db`` is a readable scene database holding every path in ``names``."""
    from walkstream.server.store import SceneReader
    from walkstream.shared.errors import StoreError

    try:
        reader = SceneReader.open(db)
    except StoreError:
        return False
    try:
        return set(names) <= set(reader.path_names())
    finally:
        reader.close()


def _demo_replay(db: Path, report: Path, args: argparse.Namespace) -> int:
    """Replay SE against the real server on a free local port (simulated 56 kbit/s link)."""
    from walkstream.client.net.link import LinkProfile
    from walkstream.client.replay import ReplayConfig
    from walkstream.cmd_replay import headline, replay_to_report
    from walkstream.server.service.process import server_process

    config = ReplayConfig(
        link=LinkProfile(56_000.0, 56_000.0, 0.2),
        path="SE",
        fps=25.0,
        clock="sim",
        device="desktop2003",
        snapshot_every=250,
        report_dir=report,
    )
    t0 = time.perf_counter()
    with server_process([db]) as (host, port):
        url = f"http://{host}:{port}"
        print(f"server on {url}; replaying SE over a simulated 56 kbit/s, 200 ms link ...")
        result = replay_to_report(url, config, title="walkstream demo: SE at 56 kbit/s")
    print(headline(result.summary))
    print(f"replayed {result.summary['walk_s']:.0f} s of walk in {time.perf_counter() - t0:.1f} s")
    print(f"report: {report / 'index.html'}")
    return 0


# ---------------------------------------------------------------- parser


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of every subcommand."""
    p = argparse.ArgumentParser(
        prog="walkstream",
        description=(
            "Interactive walkthroughs of large 3D scenes over slow links: procedural "
            "cities and real footprints, L-system buildings at three levels of detail."
        ),
    )
    sub = p.add_subparsers(dest="command", metavar="COMMAND", required=True)

    d = sub.add_parser("demo", help="the main job on the built-in default scene (make demo)")
    d.add_argument("--out", default="out/demo", help="folder for everything the demo writes (default out/demo)")
    d.add_argument("--no-replay", action="store_true", help="stop after the bake (no server, no replay)")
    d.set_defaults(func=cmd_demo)

    d.add_argument("--workers", type=int, default=1, help="local processes for the bake (default 1)")

    bk = sub.add_parser("bake", help="bake a GeoJSON source into a scene database (cells, PVS, ACH)")
    bk.add_argument("source", nargs="?", help="GeoJSON FeatureCollection (generated city or real footprints)")
    bk.add_argument("-o", "--output", required=True, help="scene database to write (SQLite, replaced atomically)")
    bk.add_argument("--default-city", action="store_true", help="bake the default 700 m city (generated beside the output)")
    bk.add_argument("--name", help="scene name (default: the database file's stem)")
    bk.add_argument("--cells", choices=("auto", "street", "grid"), default="auto", help="street cells (needs streets) or a grid (default auto)")
    bk.add_argument("--cell-size", type=float, default=40.0, help="grid cell side / longest street cell, metres (default 40)")
    bk.add_argument("--view-distance", type=float, default=800.0, help="far plane, metres (default 800)")
    bk.add_argument("--bbox", help="MINX,MINY,MAXX,MAXY in scene-local metres: bake only this part")
    bk.add_argument("--resolution", type=int, default=None, help="pixels per cube face (default: see bench visibility)")
    bk.add_argument("--occluder-lod", type=int, choices=(0, 1, 2), default=None, help="LOD rendered as occluder")
    bk.add_argument("--centre", action="store_true", help="also sample the cell centre (10 points instead of 8)")
    bk.add_argument("--threshold", type=int, default=0, help="hardly-visible threshold: pixels an object needs to enter the PVS (default 0)")
    bk.add_argument("--workers", type=int, default=1, help="local processes rendering cells (default 1)")
    bk.add_argument("--scheduler", help="tcp://HOST:PORT of a Dask scheduler to run the cell tasks on")
    bk.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    bk.set_defaults(func=cmd_bake)

    ins = sub.add_parser("inspect", help="summary of a scene database; --map draws its cells")
    ins.add_argument("db", help="scene database")
    ins.add_argument("--map", help="PNG: top view of the cells coloured by PVS size over the footprints")
    ins.add_argument("--json", action="store_true", help="print one JSON object")
    ins.set_defaults(func=cmd_inspect)

    sv = sub.add_parser("serve", help="serve scene databases over HTTP (FastAPI + uvicorn)")
    sv.add_argument("db", nargs="+", help="scene database(s), each served under its scene name")
    sv.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1)")
    sv.add_argument("--port", type=int, default=8000, help="port (default 8000)")
    sv.add_argument("--workers", type=int, default=1, help="uvicorn worker processes (default 1)")
    sv.set_defaults(func=cmd_serve)

    from walkstream.cmd_path import add_path_parser
    from walkstream.cmd_replay import add_replay_parser

    add_replay_parser(sub)
    add_path_parser(sub)

    g = sub.add_parser("generate", help="generate a procedural scene source")
    gsub = g.add_subparsers(dest="what", metavar="WHAT", required=True)
    gc = gsub.add_parser("city", help="a procedural city as GeoJSON (streets, crossroads, squares, buildings)")
    gc.add_argument("--size", type=float, default=DEFAULT_CITY_SIZE, help="side of the square city in metres (100-5000, default 700)")
    gc.add_argument("--seed", type=int, default=DEFAULT_CITY_SEED, help="random seed (default 1); same seed, same city")
    gc.add_argument("-o", "--output", required=True, help="GeoJSON file to write")
    gc.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    gc.set_defaults(func=cmd_generate_city)

    b = sub.add_parser("buildings", help="rebuild buildings of a GeoJSON file: statistics and pictures")
    bsub = b.add_subparsers(dest="what", metavar="WHAT", required=True)
    bs = bsub.add_parser("stats", help="buildings kept/skipped, triangles and rebuild speed per LOD, bytes")
    bs.add_argument("file", help="GeoJSON FeatureCollection (generated city or real footprints)")
    bs.add_argument("--json", action="store_true", help="print one JSON object")
    bs.set_defaults(func=cmd_buildings_stats)
    br = bsub.add_parser("render", help="draw one building's three LODs side by side; export glTF")
    br.add_argument("file", help="GeoJSON FeatureCollection")
    br.add_argument("--id", required=True, help="building id (the feature id, or the object number)")
    br.add_argument("-o", "--output", help="PNG to write (the three LODs side by side)")
    br.add_argument("--gltf", help="binary glTF (.glb) to write")
    br.add_argument("--lod", type=int, choices=(0, 1, 2), default=2, help="LOD for --gltf (default 2)")
    br.add_argument("--all", action="store_true", help="with --gltf: export every building, not only --id")
    br.set_defaults(func=cmd_buildings_render)

    gr = sub.add_parser("grammar", help="print the built-in building grammar, or check a grammar file")
    gr.add_argument("file", nargs="?", help="grammar file to check (default: print the built-in one)")
    gr.add_argument("--check", action="store_true", help="parse the built-in grammar and report its id")
    gr.set_defaults(func=cmd_grammar)

    be = sub.add_parser("bench", help="benchmarks that print a table")
    besub = be.add_subparsers(dest="what", metavar="WHAT", required=True)
    bb = besub.add_parser("rebuild", help="rebuild throughput per LOD and parameter/geometry bytes")
    bb.add_argument("file", nargs="?", help="GeoJSON source (default: the default 700 m city)")
    bb.add_argument("--size", type=float, default=DEFAULT_CITY_SIZE, help="city size when no file is given")
    bb.add_argument("--repeat", type=int, default=5, help="runs; the table shows medians (default 5)")
    bb.set_defaults(func=cmd_bench_rebuild)
    bv = besub.add_parser("visibility", help="PVS miss rate against a dense reference vs bake seconds per cell, per setting")
    bv.add_argument("scene", help="scene database (its source GeoJSON is read again) or a GeoJSON source")
    bv.add_argument("--source", help="the GeoJSON the database was baked from, if it moved")
    bv.add_argument("--sample", type=int, default=12, help="cells compared (default 12)")
    bv.add_argument("--plot", help="PNG: miss rate against seconds per cell")
    bv.set_defaults(func=cmd_bench_visibility)
    bsv = besub.add_parser("server", help="simulated walkers against a real server on loopback: req/s, p50/p99, errors")
    bsv.add_argument("db", help="scene database to serve")
    bsv.add_argument("--walkers", default="10,100,1000", help="walker counts (default 10,100,1000)")
    bsv.add_argument("--workers", default="1,2", help="server worker counts (default 1,2)")
    bsv.add_argument("--ramp", type=float, default=60.0, help="seconds over which walkers start (default 60)")
    bsv.add_argument("--duration", type=float, default=30.0, help="measured seconds after the ramp (default 30)")
    bsv.add_argument("--no-pin", action="store_true", help="do not pin server and load generator to separate cores")
    bsv.set_defaults(func=cmd_bench_server)
    from walkstream.cmd_replay import add_bench_budget_parser, add_bench_stream_parser
    from walkstream.lodbench import add_bench_lod_parser

    add_bench_stream_parser(besub)
    add_bench_budget_parser(besub)
    add_bench_lod_parser(besub)
    return p


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``walkstream`` console command."""
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args))
    except WalkstreamError as exc:
        print(f"walkstream: error: {exc}", file=sys.stderr)
        return 2
    except (FileNotFoundError, IsADirectoryError, PermissionError) as exc:
        print(f"walkstream: error: {exc.filename}: {exc.strerror}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("walkstream: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
