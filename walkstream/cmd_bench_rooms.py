"""``walkstream bench interiors`` and ``walkstream bench portals``: the benchmarks of
interiors (cells, portals and their contents; portal culling, its tightness and cost,
the generated seeds' tours at 56 kbit/s), registered under ``bench`` by
:mod:`walkstream.cmd_bench`.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from walkstream.shared.errors import InputError

__all__ = ["add_room_benches"]


def cmd_bench_interiors(args: argparse.Namespace) -> int:
    """Handler of ``walkstream bench interiors``."""
    from walkstream.benchmarks.interiors import (
        default_ifc_files,
        generated_sources,
        interior_figures,
        interiors_table,
    )

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    ifc = [Path(f) for f in args.ifc] if args.ifc else default_ifc_files()
    if not ifc:
        print("walkstream: note: no IFC models given or found in ../shared/data/indoor", file=sys.stderr)
    sources = ifc + generated_sources(out, args.presets)
    from walkstream.benchmarks.cellcodec import codec_rows, codec_table

    rows = []
    codec: list[dict[str, Any]] = []
    for src in sources:
        print(f"bench interiors: {src.name}", file=sys.stderr)
        rows.append(interior_figures(src, out / f"{src.stem}.db"))
        if not args.no_codec:
            codec += codec_rows(src, out / f"{src.stem}.db", rows[-1]["contents_encode_s"], out)
    if args.json:
        print(json.dumps({"interiors": rows, "cellmesh": codec}, indent=2))
    else:
        print(interiors_table(rows))
        if codec:
            print()
            print(codec_table(codec))
    return 0


def cmd_bench_portals(args: argparse.Namespace) -> int:
    """Handler of ``walkstream bench portals``."""
    from walkstream.benchmarks.portals import portals_tables, run_portals_bench

    if args.cull is not None:
        from walkstream.benchmarks.cullcpu import cull_cpu_rows, cull_cpu_table

        rows = cull_cpu_rows(args.cull, Path(args.out), against=args.cull_against, hall_frames=args.cull_frames,
                             cache=args.cull_cache, log=lambda s: print(s, file=sys.stderr))
        print(json.dumps({"culling_cpu": rows}, indent=2) if args.json else cull_cpu_table(rows))
        return 0
    if args.triangles is not None:
        from walkstream.benchmarks.trianglecost import triangle_rows, triangle_table

        trows = triangle_rows(args.triangles, Path(args.out), step_s=args.step, log=lambda s: print(s, file=sys.stderr))
        print(json.dumps({"triangles": trows}, indent=2) if args.json else triangle_table(trows))
        return 0
    if args.seed_truth_every < 0:
        raise InputError(f"--seed-truth-every {args.seed_truth_every}: expected 0 (no truth) or a positive count of frames")
    if args.seeds and args.seed_duration != "whole":
        from walkstream.client.units import parse_duration

        parse_duration(args.seed_duration)  # a bad duration named before the first bake, not after it
    scenes, halls = run_portals_bench(
        Path(args.out), args.presets, frames=args.frames, step_s=args.step, truth_frames=args.truth,
        gl=not args.no_gl, log=lambda s: print(s, file=sys.stderr),
    )
    replays = []
    if args.replays:
        from walkstream.benchmarks.portals import replay_rows, replay_table
        from walkstream.cmd_replay import replay_with_options

        db = Path(args.out) / f"{args.presets[0]}.db"
        replays = replay_rows(db, replay_with_options, Path(args.out), duration=args.replays)
    seeds = []
    if args.seeds:
        from walkstream.benchmarks.portals import seed_rows, seed_table
        from walkstream.cmd_replay import replay_with_options

        seeds = seed_rows(args.seeds, replay_with_options, Path(args.out), duration=args.seed_duration, truth_every=args.seed_truth_every,
                          log=lambda s: print(s, file=sys.stderr))
    if args.json:
        print(json.dumps({"scenes": scenes, "halls": halls, "replays": replays, "seeds": seeds}, indent=2))
    else:
        print(portals_tables(scenes, halls))
        print("(culling CPU and gl frame times measured here; pda: the cost model fitted to Table 1, no fog)")
        if replays:
            print(replay_table(replays))
            print("(simulated clock; tour of the first preset)")
        if seeds:
            print(seed_table(seeds))
            part = "the whole tour" if args.seed_duration == "whole" else f"the first {args.seed_duration} of each tour"
            truth = (f"every {args.seed_truth_every}th frame against the truth at 160x120" if args.seed_truth_every
                     else "no truth: culled pixels not measured")
            print(f"(generated offices, 3 storeys; {part}, 56 kbit/s, 200 ms, simulated clock, desktop2003, {truth}; "
                  "cpu ms/fr: this process's CPU time per frame walked)")
    return 0


def add_room_benches(besub: Any) -> None:
    """Register ``interiors`` and ``portals`` under ``bench``'s sub-parsers ``besub``."""
    from walkstream.server.sources.interiorgen import PRESETS

    bi = besub.add_parser("interiors", help="interiors per IFC model and generated size: cells, portals, triangles, bytes per cell, error")
    bi.add_argument("--ifc", nargs="*", help="IFC models (default: ../shared/data/indoor/*.ifc)")
    bi.add_argument("--presets", nargs="*", default=["paper", "paper10"], help="generated interiors (default: paper paper10)")
    bi.add_argument("--out", default="out/bench-interiors", help="folder for the generated files and databases")
    bi.add_argument("--json", action="store_true", help="print the figures as JSON")
    bi.add_argument("--no-codec", action="store_true",
                    help="skip the cellmesh /1, /2, /3, /4 table (it bakes each source three times more)")
    bi.set_defaults(func=cmd_bench_interiors)

    bp = besub.add_parser("portals", help="portal culling against frustum culling alone and drawing all (Table 1, tightness, cost)")
    bp.add_argument("--presets", nargs="*", default=["paper", "paper10"], choices=sorted(PRESETS),
                    help="generated interiors (default: paper paper10)")
    bp.add_argument("--frames", type=int, default=200, help="frames along each tour (default 200)")
    bp.add_argument("--step", type=float, default=1.0, help="seconds of tour between frames (default 1)")
    bp.add_argument("--truth", type=int, default=60, help="frames of the first scene compared with the id truth (default 60)")
    bp.add_argument("--no-gl", action="store_true", help="no gl frame times (the pda model only)")
    bp.add_argument("--out", default="out/bench-portals", help="folder for the generated files and databases")
    bp.add_argument("--seeds", nargs="*", type=int, default=[], metavar="SEED",
                    help="also generate offices of these seeds (3 storeys), bake them and replay each tour at "
                    "56 kbit/s against the truth")
    bp.add_argument("--seed-duration", default="30s", metavar="DURATION",
                    help="with --seeds: replay this much of each tour (default 30s; whole: each tour to its end)")
    bp.add_argument("--seed-truth-every", type=int, default=50, metavar="N",
                    help="with --seeds: compare every Nth frame with the id truth (default 50; 0: none, "
                    "for whole tours, whose truth takes longer than the replay)")
    bp.add_argument("--replays", metavar="DURATION", help="also replay the first preset's tour this long (e.g. 180s): "
                    "56 kbit/s with the default and a small cache, pda with the fog set by the budget through a cost step")
    bp.add_argument("--cull", nargs="*", type=int, metavar="SEED", default=None,
                    help="only the culling's CPU time per frame (walk, parts, both; median and p99): the open 16x16 "
                    "hall with 16 parts a cell (200-236 cells visible) and the tours of these generated seeds")
    bp.add_argument("--cull-against", metavar="REV",
                    help="with --cull: time the culling of this git revision beside today's, frame by frame")
    bp.add_argument("--cull-frames", type=int, default=120, metavar="N",
                    help="with --cull: frames of the hall (default 120), each culled twice")
    bp.add_argument("--cull-cache", action="store_true",
                    help="with --cull: time the culling reused frame to frame (a guard view, shared/cullcache.py) "
                    "against each frame culled anew (today's, or --cull-against's revision)")
    bp.add_argument("--triangles", nargs="+", metavar="SRC", default=None,
                    help="only the kept parts' triangles tested, pose by pose (every --step s) along the tour of "
                    "each SRC (a generated office's seed, or a baked interior database): parts and triangles kept "
                    "by the boxes and by the triangles, and each step's CPU time")
    bp.add_argument("--json", action="store_true", help="print the figures as JSON")
    bp.set_defaults(func=cmd_bench_portals)
