"""``walkstream demo``: the main job on the built-in default scene (``make demo``).

Generates the default 700 m city, rebuilds its buildings at three LODs (figures and a
picture), bakes it (once), starts the real server on a free local port and replays
path ``SE`` against it over real sockets through a simulated 56 kbit/s, 200 ms link,
then prints the headline figures and where the report is.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

from walkstream.cmd_bake import default_city_source, run_bake
from walkstream.cmd_build import load_source
from walkstream.shared.errors import WalkstreamError
from walkstream.terminal import building_bar, print_summary

__all__ = ["add_demo_parser", "stale_reason"]


def cmd_demo(args: argparse.Namespace) -> int:
    """Handler of ``walkstream demo``: the main job on the built-in default scene."""
    from walkstream.server.sources.citysummary import city_summary

    out = Path(args.out)
    city = default_city_source(out)
    summary = city_summary(json.loads(city.read_text()))
    print_summary("default city", summary, False)
    from walkstream.benchmarks.rebuild import building_stats

    scene = load_source(str(city))
    with building_bar(len(scene.buildings), "rebuilding") as bar:
        stats = building_stats(scene.buildings, progress=bar.update)
    print(
        f"rebuilt {stats['buildings']} buildings: triangles per LOD {stats['triangles']}, "
        f"buildings/s per LOD {stats['rebuild_per_s']}"
    )
    print(
        f"parameters {stats['param_bytes']:,} B vs LOD2 geometry {stats['lod2_bytes']:,} B "
        f"({100 * float(stats['ratio']):.4f} %)"
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
    stale = stale_reason(db, ("SE",)) if db.exists() else None
    if stale is None and db.exists() and city.stat().st_mtime > db.stat().st_mtime:
        stale = "is older than its city"
    if stale is not None:
        print(f"scene database {db} {stale} (an older bake): baking again")
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


def stale_reason(db: Path, names: tuple[str, ...]) -> str | None:
    """Why the demo must bake ``db`` again, or ``None`` when it can keep it.

    It bakes again when ``db`` is unreadable, lacks a path in ``names``, or was baked
    with bake settings other than today's defaults (an upgrade that changed the
    default sampling must show its own figures, not the last release's).
    """
    from walkstream.server.bake import BakeSettings
    from walkstream.server.store import SceneReader
    from walkstream.shared.errors import StoreError

    try:
        reader = SceneReader.open(db)
    except StoreError:
        return "is not a readable scene database"
    try:
        missing = sorted(set(names) - set(reader.path_names()))
        stored = reader.meta.settings
    finally:
        reader.close()
    if missing:
        return f"has no recorded path {', '.join(missing)}"
    today = BakeSettings().record()
    changed = [k for k, v in today.items() if k in stored and stored[k] != v]
    changed += [k for k in today if k not in stored]
    if changed:
        return f"was baked with other settings than today's defaults ({', '.join(sorted(changed))})"
    return None


def _demo_replay(db: Path, report: Path, args: argparse.Namespace) -> int:
    """Replay SE against the real server on a free local port (simulated 56 kbit/s link)."""
    from walkstream.client.config import ReplayConfig
    from walkstream.client.net.link import LinkProfile
    from walkstream.client.report import format_headline
    from walkstream.client.units import parse_duration
    from walkstream.cmd_replay import replay_to_report
    from walkstream.server.service.process import server_process

    config = ReplayConfig(
        link=LinkProfile(56_000.0, 56_000.0, 0.2),
        path="SE",
        fps=25.0,
        clock="sim",
        device="desktop2003",
        snapshot_every=250,
        report_dir=report,
        duration_s=parse_duration(args.duration) if args.duration else None,
    )
    t0 = time.perf_counter()
    with server_process([db]) as (host, port):
        url = f"http://{host}:{port}"
        print(f"server on {url}; replaying SE over a simulated 56 kbit/s, 200 ms link ...")
        result = replay_to_report(url, config, title="walkstream demo: SE at 56 kbit/s")
    print(format_headline(result.summary))
    print(f"replayed {result.summary['walk_s']:.0f} s of walk in {time.perf_counter() - t0:.1f} s")
    print(f"report: {report / 'index.html'}")
    return 0


def add_demo_parser(sub: Any) -> None:
    """Register ``demo``."""
    d = sub.add_parser("demo", help="the main job on the built-in default scene (make demo)")
    d.add_argument("--out", default="out/demo", help="folder for everything the demo writes (default out/demo)")
    d.add_argument("--no-replay", action="store_true", help="stop after the bake (no server, no replay)")
    d.add_argument("--workers", type=int, default=1, help="local processes for the bake (default 1)")
    d.add_argument("--duration", help="replay only the first part of SE, e.g. 30s (default: the whole walk)")
    d.set_defaults(func=cmd_demo)
