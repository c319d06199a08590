"""``walkstream bench pvs-misses``: why the PVS misses what a walker sees, pose by pose;
registered under ``bench`` by :mod:`walkstream.cmd_bench`."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from walkstream.terminal import count_bar

__all__ = ["add_pvs_benches"]


def cmd_bench_pvs_misses(args: argparse.Namespace) -> int:
    """Handler of ``walkstream bench pvs-misses``."""
    from walkstream.benchmarks.pvsmisses import format_pvs_misses, run_pvs_misses

    bar, progress = count_bar("poses", "pose")
    try:
        result = run_pvs_misses(Path(args.db), [p for p in args.paths.split(",") if p], every=args.every,
                            top=args.top, yardstick=args.yardstick, progress=progress)
    finally:
        bar.close()
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1, default=str))
    print(format_pvs_misses(result, args.worst))
    return 0


def add_pvs_benches(besub: Any) -> None:
    """Register ``bench pvs-misses`` under the ``bench`` subparsers ``besub``."""
    p = besub.add_parser(
        "pvs-misses",
        help="why the PVS misses what a walker sees: per pose along recorded paths, each missed object, its pixels and reason",
    )
    p.add_argument("db", help="a baked city database (street or grid cells)")
    p.add_argument("--paths", default="SE,drive", help="comma-separated recorded paths (default SE,drive)")
    p.add_argument("--every", type=float, default=1.0, help="seconds of walk time between poses (default 1: bench stream's every 25th frame)")
    p.add_argument("--top", type=int, default=5, help="objects listed per pose (default 5)")
    p.add_argument("--worst", type=int, default=8, help="poses listed (default 8)")
    p.add_argument("--yardstick", help="another bake of the same source and cells (e.g. --sampling corners --resolution 64): "
                   "the floor's PVS sizes set beside its own")
    p.add_argument("--json", help="write every pose over 0.01 %% and the figures to this JSON file")
    p.set_defaults(func=cmd_bench_pvs_misses)
