"""``walkstream bench impostors``, ``bench impostor-sampling``, ``bench walls`` and ``bench wall-floor``: the
benchmarks of what images stand in for (impostors, facade pictures, textured virtual
walls) and of their colour error, registered under ``bench`` by
:mod:`walkstream.cmd_bench`.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

__all__ = ["add_image_benches"]


def cmd_bench_impostors(args: argparse.Namespace) -> int:
    """Handler of ``walkstream bench impostors``."""
    from walkstream.benchmarks.impostors import format_impostor_table, run_impostor_bench
    from walkstream.cmd_replay import replayer
    from walkstream.shared.errors import InputError

    for db in args.db:
        if not str(db).startswith(("http://", "https://")) and not Path(db).is_file():
            raise InputError(f"{db}: no such scene database")
    paths = [p.strip() for p in args.paths.split(",") if p.strip()]
    link = {"bandwidth": args.bandwidth, "rtt": args.rtt}
    extra = {"clock": args.clock, **({"ach_shares": True} if args.ach_shares else {}),
             **({} if args.impostor_blend is None else {"impostor_blend": args.impostor_blend}),
             **({} if args.impostor_fade is None else {"impostor_fade": args.impostor_fade})}
    facades: tuple[bool | None, ...] = {"auto": (None,), "on": (True,), "off": (False,), "both": (True, False)}[
        args.facades]
    rows = run_impostor_bench(args.db, replayer(not args.no_plots), out=Path(args.out), paths=paths, device=args.device,
                              truth_every=args.truth_every, duration=args.duration, link=link, size=args.size,
                              extra=extra, facades=facades)
    if not rows:
        return 1  # each failed walk said why on stderr
    print(format_impostor_table(rows))
    if args.truth_every:
        print(f"plot: {Path(args.out) / 'bench_impostors.png'}")
    return 0


def cmd_bench_impostor_sampling(args: argparse.Namespace) -> int:
    """Handler of ``walkstream bench impostor-sampling``."""
    from walkstream.benchmarks.impostorsampling import (
        format_sampling_table,
        plot_sampling_picture,
        run_sampling_bench,
    )
    from walkstream.client.truth.antialias import check_sampling, parse_sampling
    from walkstream.cmd_bake import default_city_source
    from walkstream.cmd_build import load_source

    samplings = [parse_sampling(t) for t in args.truth_samples]
    reference = parse_sampling(args.reference, "--reference")
    for sampling in (*samplings, reference):
        check_sampling(sampling, "--reference" if sampling is reference else "--truth-samples")
    src = args.source or str(default_city_source(Path("out/demo")))
    picture: dict[str, Any] | None = {} if args.picture else None
    rows = run_sampling_bench(load_source(src).buildings, count=args.buildings, error_deg=args.impostor_error,
                              picture=picture, ppds=args.ppd, against_aa=args.against_aa,
                              truth_samples=samplings, reference=reference,
                              projections=args.projection, distance=args.impostor_distance)
    print(json.dumps(rows) if args.json else format_sampling_table(rows))
    if picture:
        print(f"picture: {plot_sampling_picture(picture, Path(args.picture))}")
    return 0


def cmd_bench_walls(args: argparse.Namespace) -> int:
    """Handler of ``walkstream bench walls``."""
    from walkstream.benchmarks.walls import (
        SCENES,
        format_walls_table,
        parse_texture_variants,
        run_walls_bench,
    )
    from walkstream.cmd_replay import replayer
    from walkstream.shared.errors import InputError
    from walkstream.shared.walldepth import check_depth_grid

    scenes = [s.strip() for s in args.scenes.split(",") if s.strip()]
    bad = [s for s in scenes if s not in SCENES]
    if bad or not scenes:
        raise InputError(f"--scenes {args.scenes!r}: choose from {', '.join(SCENES)}")
    try:
        errors = [float(v) for v in args.wall_errors.split(",") if v.strip()]
    except ValueError:
        raise InputError(f"--wall-errors {args.wall_errors!r}: expected degrees such as 5,10,15,20") from None
    if not errors or any(not 0.5 <= a <= 45.0 for a in errors):
        raise InputError(f"--wall-errors {args.wall_errors!r}: expected angles from 0.5 to 45 degrees")
    quick = args.quick
    result = run_walls_bench(
        replayer(not args.no_plots), out=Path(args.out), data=Path(args.data),
        scenes=["hall"] if quick else scenes, wall_errors=[10.0] if quick else errors,
        duration="4s" if quick else args.duration, gl_duration="3s" if quick else args.gl_duration,
        truth_every=40 if quick else args.truth_every, size="160x120" if quick else args.size,
        gl=not args.no_gl, quick=quick, frustum_frames=5 if quick else args.frames,
        wall_depth=check_depth_grid(args.wall_depth), wall_textures=parse_texture_variants(args.wall_textures),
    )
    if args.json:
        print(json.dumps(result, default=str))
    else:
        print(format_walls_table(result))
        print(f"(plot: {Path(args.out) / 'bench_walls.png'}; rows: {Path(args.out) / 'bench_walls.json'})")
    return 0


def _factors(text: str, flag: str) -> list[float]:
    """``--densities`` / ``--frame-res``: factors separated by commas, each above 0 and at most 16."""
    from walkstream.shared.errors import InputError

    try:
        out = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise InputError(f"{flag} {text!r}: expected numbers separated by commas, such as 1,2,4") from None
    if any(not 0.0 < v <= 16.0 for v in out):
        raise InputError(f"{flag} {text!r}: expected factors above 0 and at most 16")
    return out


def cmd_bench_wall_floor(args: argparse.Namespace) -> int:
    """Handler of ``walkstream bench wall-floor``."""
    from walkstream.benchmarks.wallfloor import measure, table, write
    from walkstream.cmd_replay import replay_with_options
    from walkstream.shared.errors import InputError

    for what, p in (("DB", args.db), ("SOURCE", args.source)):
        if not Path(p).is_file():
            raise InputError(f"{what} {p}: no such file")
    densities, frame_res = _factors(args.densities, "--densities"), _factors(args.frame_res, "--frame-res")
    out = Path(args.report)
    out.mkdir(parents=True, exist_ok=True)
    run = measure(args.db, args.source, str(out), replay_with_options, path=args.path, device=args.device,
                  size=args.size, duration=args.duration, truth_every=args.truth_every, bandwidth=args.bandwidth,
                  rtt=args.rtt, fps=args.fps, densities=densities, frame_res=frame_res, costs=not args.no_costs,
                  viewer_ppd=args.viewer_ppd,
                  samples={k: v for k, v in (("truth_samples", args.truth_samples),
                                             ("picture_samples", args.picture_samples)) if v})
    write(run, out, args.plot)
    print(table(run))
    print(f"(per frame: {out / 'floor.csv'}{'; plot: ' + str(out / 'floor.png') if args.plot else ''})")
    return 0


def add_image_benches(besub: Any) -> None:
    """Register ``impostors``, ``impostor-sampling`` and ``walls`` under ``bench``'s
    sub-parsers ``besub``."""
    b = besub.add_parser("impostors", help="the same walks with and without impostors: triangles, bytes, textures, colour error")
    b.add_argument("db", nargs="+", help="scene databases baked with --impostors (several: a sweep of D, A, S or scenes)")
    b.add_argument("--paths", default="SE", help="comma-separated recorded paths (default SE)")
    b.add_argument("--device", default="pda", choices=("gl", "desktop2003", "pda"), help="device (default pda)")
    b.add_argument("--clock", default="sim", choices=("sim", "real"), help="simulated clock (default) or real time (with --device gl: frames drawn and timed for real)")
    b.add_argument("--size", help="frame size WIDTHxHEIGHT of the walks and their truth (default the replay's 640x480)")
    b.add_argument("--ach-shares", action="store_true", help="share the triangle budget by the paper's ACH shares (the older rule)")
    b.add_argument("--bandwidth", default="56kbit", help="link bandwidth (default 56kbit)")
    b.add_argument("--rtt", default="200ms", help="round-trip time (default 200ms)")
    b.add_argument("--truth-every", type=int, default=25, metavar="N", help="compare every Nth frame with the ground truth, colour error included (default 25; 0: never)")
    b.add_argument("--duration", help="limit every walk, e.g. 60s")
    b.add_argument("--impostor-blend", type=float, default=None, metavar="M", help="metres over which an impostor fades in over its geometry (default a tenth of the bake's D; 0: none; the 'pop' column measures it, with --truth-every 1)")
    b.add_argument("--impostor-fade", type=float, default=None, metavar="S", help="seconds an impostor's opacity takes at least from 0 to 1 (default 2; 0 with --impostor-blend 0: a hard switch)")
    b.add_argument("--facades", default="auto", choices=("auto", "on", "off", "both"), help="facade textures on the boxes: the replay's default (auto: on a simulated device), always (on), never (off), or each walk both ways (both)")
    b.add_argument("--out", default="out/bench-impostors", help="folder for the reports")
    b.add_argument("--no-plots", action="store_true", help="each replay's report without its plots (as replay --no-plots); the bench's own plot is drawn")
    b.set_defaults(func=cmd_bench_impostors)

    b = besub.add_parser("impostor-sampling", help="one impostor against its truth, alone, per view, bake sampling and texture filter: pixels over the visible threshold")
    b.add_argument("source", nargs="?", help="city source (default: the demo city, generated into out/demo if missing)")
    b.add_argument("--buildings", type=int, default=20, help="the N tallest buildings (default 20)")
    b.add_argument("--impostor-error", type=float, default=2.0, metavar="A", help="the bound A, degrees, that picks the direction bin of the perspective view (default 2)")
    b.add_argument("--projection", nargs="+", choices=("ortho", "perspective"), default=["ortho"], help="the images orthographic and/or in perspective from their level's sampling eye (rows 'S persp'; default ortho)")
    b.add_argument("--impostor-distance", type=float, default=60.0, metavar="D", help="with --projection perspective: the bake's D the sampling eye is placed for (default 60)")
    b.add_argument("--ppd", type=float, nargs="+", default=[1.81, 24.0], metavar="P", help="pixels per degree of the viewer-scale (S-CIELAB) columns (default 1.81, the 160x120 view's own, and 24, a handheld's screen)")
    b.add_argument("--against-aa", action="store_true", help="compare the images with the truth drawn anti-aliased (4x4 samples a pixel, averaged) instead of the truth")
    b.add_argument("--truth-samples", nargs="+", default=[], metavar="S", help="also the truth drawn at each sampling S (1, N or NxN supersampled, msaaS) against the truth drawn at --reference: the anti-aliased truth's own error, a row per view and S")
    b.add_argument("--reference", default="8", metavar="S", help="the sampling --truth-samples is compared with (default 8: 8x8 samples a pixel)")
    b.add_argument("--picture", metavar="PNG", help="also draw one building's frames (the middle one by height) and their pixels over the threshold")
    b.add_argument("--json", action="store_true", help="print the rows as JSON")
    b.set_defaults(func=cmd_bench_impostor_sampling)

    b = besub.add_parser("walls", help="the open scenes (hall, city, West Oakland, village) with and without virtual walls")
    b.add_argument("--scenes", default="hall,city,west-oakland,village", help="comma-separated scenes: hall, hall-ifc (the same hall as an IFC model, read by the IFC reader), city, squares, west-oakland, village (default hall, city, west-oakland, village)")
    b.add_argument("--wall-errors", default="5,10,15,20", help="wall errors A in degrees, one walls bake each (default 5,10,15,20)")
    b.add_argument("--wall-depth", type=int, default=0, metavar="G", help="also bake each A with --wall-depth G (4, 8 or 16) and play it beside the walls without (variant 'walls A=a G=g'; default 0: not)")
    b.add_argument("--wall-textures", default="", metavar="SPECS", help="also bake each A with other wall texture settings and play it beside: variants split by ';', each key=value pairs split by ',' of view, texels, max-side, quality (bake's --wall-view, --wall-texels, --wall-max-side, --wall-quality), e.g. 'view=120;texels=4,quality=lossless'")
    b.add_argument("--data", default="../shared/data/osm", help="folder of the OpenStreetMap extracts")
    b.add_argument("--duration", default="60s", help="walk length of the pda replays (default 60s)")
    b.add_argument("--gl-duration", default="20s", help="walk length of the real-clock gl replays (default 20s)")
    b.add_argument("--truth-every", type=int, default=25, metavar="N", help="compare every Nth pda frame with the full scene (default 25; 0: never)")
    b.add_argument("--size", default="640x480", help="frame size (default 640x480)")
    b.add_argument("--frames", type=int, default=40, help="hall tour frames for frustum culling alone and drawing whole (default 40)")
    b.add_argument("--no-gl", action="store_true", help="skip the gl replays and gl draws")
    b.add_argument("--quick", action="store_true", help="a small hall only, short walks, a small frame (a test)")
    b.add_argument("--no-plots", action="store_true", help="each replay's report without its plots (as replay --no-plots); the bench's own plot is drawn")
    b.add_argument("--json", action="store_true", help="print the rows as JSON")
    b.add_argument("--out", default="out/bench-walls", help="folder for the databases, reports and plot")
    b.set_defaults(func=cmd_bench_walls)

    b = besub.add_parser("wall-floor", help="the walls' visibly wrong share of the frame with ideal textures from the eye at 1, 2, 4 times the stored density: the floor under wall1%")
    b.add_argument("db", help="a walls database (bench walls' SCENE-walls-A.db)")
    b.add_argument("source", help="the scene's source (the OSM file) the database was baked from")
    b.add_argument("--report", default="out/wall-floor", help="folder for the replay's report, floor.csv, floor.json and floor.png (default out/wall-floor)")
    b.add_argument("--path", default="bench", help="the recorded path to walk (default bench)")
    b.add_argument("--device", default="pda", choices=("gl", "desktop2003", "pda"), help="device (default pda)")
    b.add_argument("--size", default="160x120", help="frame size (default 160x120)")
    b.add_argument("--duration", default="60s", help="walk length (default 60s)")
    b.add_argument("--truth-every", type=int, default=25, metavar="N", help="compare every Nth frame (default 25)")
    b.add_argument("--bandwidth", default="56kbit", help="link bandwidth (default 56kbit)")
    b.add_argument("--rtt", default="200ms", help="round-trip time (default 200ms)")
    b.add_argument("--fps", type=float, default=25.0, help="frame loop tick rate (default 25)")
    b.add_argument("--densities", default="1,2,4", help="the ideal textures' texels a metre as factors of the stored (default 1,2,4)")
    b.add_argument("--frame-res", default="1", help="texels a frame pixel of the check at the frame's resolution (default 1; '' none)")
    b.add_argument("--viewer-ppd", type=float, default=None, metavar="P", help="also count at the viewer's scale (S-CIELAB) for a display of P pixels a degree (slower)")
    b.add_argument("--truth-samples", help="the truth's colour anti-aliased (as replay --truth-samples: 4 for 4 x 4, msaa4)")
    b.add_argument("--picture-samples", help="the client's picture anti-aliased (as replay --picture-samples)")
    b.add_argument("--no-costs", action="store_true", help="skip rendering and encoding the textures for their bytes")
    b.add_argument("--plot", action="store_true", help="write floor.png (each variant's frames sorted by their walls' share)")
    b.set_defaults(func=cmd_bench_wall_floor)
