"""``walkstream generate``, ``buildings`` and ``grammar``: scene sources and the buildings in them.

::

    walkstream generate city --size 700 --seed 1 -o city.geojson
    walkstream generate interior --storeys 3 --seed 1 [--size 60x20] [--preset paper|paper10|hall] -o office.json
    walkstream buildings stats FILE.geojson [--json]
    walkstream buildings render FILE.geojson --id ID -o lods.png [--gltf out.glb --lod 2 --all]
    walkstream grammar [FILE] [--check]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

from walkstream.shared.errors import WalkstreamError
from walkstream.terminal import building_bar, print_summary

__all__ = ["add_build_parsers", "load_source", "print_rebuild_stats"]


def load_source(path: str | Path) -> Any:
    """The scene of a city source file (GeoJSON, OpenStreetMap: any format the bake reads)."""
    from walkstream.server.sources.read import read_source
    from walkstream.server.sources.scene import SourceScene
    from walkstream.shared.errors import InputError

    scene = read_source(path)
    if not isinstance(scene, SourceScene):
        raise InputError(f"{path}: an interior, not a city: this command takes a city source")
    return scene


def cmd_generate_city(args: argparse.Namespace) -> int:
    """Handler of ``walkstream generate city``."""
    from walkstream.server.sources.citygen import write_city
    from walkstream.server.sources.citysummary import city_summary

    t0 = time.perf_counter()
    write_city(args.output, args.size, args.seed)
    fc = json.loads(Path(args.output).read_text())
    summary = city_summary(fc)
    summary["seconds"] = round(time.perf_counter() - t0, 2)
    summary["output"] = str(args.output)
    print_summary("city", summary, args.json)
    return 0


def cmd_generate_interior(args: argparse.Namespace) -> int:
    """Handler of ``walkstream generate interior``."""
    from dataclasses import replace

    from walkstream.server.sources.hallgen import HALL_PRESETS, generate_hall
    from walkstream.server.sources.interiorgen import (
        PRESETS,
        InteriorPlan,
        write_interior,
        write_interior_doc,
    )

    boundaries = bool(getattr(args, "space_boundaries", False))
    schema = str(getattr(args, "ifc_schema", None) or "IFC4").upper()
    if (boundaries or getattr(args, "ifc_schema", None)) and not str(args.output).lower().endswith(".ifc"):
        raise WalkstreamError(f"--space-boundaries, --ifc-schema: only for an .ifc output, not {args.output}")
    if args.preset in HALL_PRESETS:
        if args.storeys is not None or args.size is not None:
            raise WalkstreamError(f"--preset {args.preset}: a hall of fixed bays takes --seed only, not --storeys or --size")
        hall = HALL_PRESETS[args.preset]
        t0 = time.perf_counter()
        summary = write_interior_doc(args.output, generate_hall(replace(hall, seed=hall.seed if args.seed is None else args.seed)),
                                     boundaries, schema)
        summary["seconds"] = round(time.perf_counter() - t0, 2)
        summary["output"] = str(args.output)
        print_summary("interior", summary, args.json)
        return 0
    if args.preset is not None:
        if args.preset not in PRESETS:
            raise WalkstreamError(f"--preset {args.preset!r}: choose one of {', '.join([*PRESETS, *HALL_PRESETS])}")
        plan = PRESETS[args.preset]
    else:
        plan = InteriorPlan()
    changes: dict[str, Any] = {}
    if args.storeys is not None:
        changes["storeys"] = args.storeys
    if args.seed is not None:
        changes["seed"] = args.seed
    if args.size is not None:
        try:
            length, width = (float(v) for v in args.size.lower().split("x"))
        except ValueError:
            raise WalkstreamError(f"--size {args.size!r}: expected LENGTHxWIDTH in metres, e.g. 60x20") from None
        changes |= {"length": length, "width": width}
    t0 = time.perf_counter()
    summary = write_interior(args.output, replace(plan, **changes), boundaries, schema)
    summary["seconds"] = round(time.perf_counter() - t0, 2)
    summary["output"] = str(args.output)
    print_summary("interior", summary, args.json)
    return 0


def print_rebuild_stats(stats: dict[str, Any], title: str) -> None:
    """The rebuild figures of :func:`~walkstream.benchmarks.rebuild.building_stats` as a table."""
    print(title)
    print(f"  {'':<22}{'LOD0':>12}{'LOD1':>12}{'LOD2':>12}")
    print(f"  {'triangles':<22}" + "".join(f"{t:>12,}" for t in stats["triangles"]))
    print(f"  {'rebuild buildings/s':<22}" + "".join(f"{t:>12,.0f}" for t in stats["rebuild_per_s"]))
    print(f"  parameters (msgpack)  {stats['param_bytes']:,} bytes")
    print(f"  LOD2 geometry (GPU)   {stats['lod2_bytes']:,} bytes")
    print(f"  ratio                 {100 * float(stats['ratio']):.4f} %")


def cmd_buildings_stats(args: argparse.Namespace) -> int:
    """Handler of ``walkstream buildings stats``."""
    from walkstream.benchmarks.rebuild import building_stats

    scene = load_source(args.file)
    skipped = sum(1 for i in scene.issues if i.action == "skipped")
    with building_bar(len(scene.buildings), "rebuilding") as bar:
        stats = building_stats(scene.buildings, skipped=skipped, progress=bar.update)
    if args.json:
        print(json.dumps(stats))
        return 0
    print_rebuild_stats(
        stats, f"{args.file}: {stats['buildings']} buildings kept, {stats['skipped']} skipped"
    )
    return 0


def _pick_building(scene: Any, ident: str) -> Any:
    for b in scene.buildings:
        if str(b.id) == ident or b.source_id == ident:
            return b
    ids = ", ".join(b.source_id or str(b.id) for b in scene.buildings[:5])
    raise WalkstreamError(f"no building with id {ident!r} (ids look like: {ids}, ...)")


def cmd_buildings_render(args: argparse.Namespace) -> int:
    """Handler of ``walkstream buildings render``."""
    from walkstream.shared.buildings import build_lods

    scene = load_source(args.file)
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
        with building_bar(len(chosen), f"LOD{args.lod}") as bar:
            out = []
            for c in chosen:
                out.append(build_lod(c, args.lod))
                bar.update(1)
        n = export_glb(out, args.gltf)
        print(f"wrote {args.gltf} ({len(out)} buildings at LOD{args.lod}, {n:,} bytes)")
    if not args.output and not args.gltf:
        raise WalkstreamError("nothing to do: give -o PNG and/or --gltf GLB")
    return 0


def cmd_grammar(args: argparse.Namespace) -> int:
    """Handler of ``walkstream grammar``."""
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


def add_build_parsers(sub: Any) -> None:
    """Register ``generate``, ``buildings`` and ``grammar``."""
    from walkstream.server.sources.citygen import DEFAULT_SEED, DEFAULT_SIZE

    g = sub.add_parser("generate", help="generate a procedural scene source")
    gsub = g.add_subparsers(dest="what", metavar="WHAT", required=True)
    gc = gsub.add_parser("city", help="a procedural city as GeoJSON (streets, crossroads, squares, buildings)")
    gc.add_argument("--size", type=float, default=DEFAULT_SIZE, help="side of the square city in metres (100-5000, default 700)")
    gc.add_argument("--seed", type=int, default=DEFAULT_SEED, help="random seed (default 1); same seed, same city")
    gc.add_argument("-o", "--output", required=True, help="GeoJSON file to write")
    gc.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    gc.set_defaults(func=cmd_generate_city)
    gi = gsub.add_parser("interior", help="a procedural office interior (walkstream-interior format): corridors, rooms, doors, windows, stairs, furniture")
    gi.add_argument("--storeys", type=int, help="storeys (default 3)")
    gi.add_argument("--seed", type=int, help="random seed (default 1); same arguments, same file")
    gi.add_argument("--size", help="LENGTHxWIDTH of the building in metres (default 60x20)")
    gi.add_argument("--preset", help="a named plan: paper (the scale of Mulloni et al.'s model), paper10 (ten times its cells), "
                    "hall (an open production hall of machines, robots and racks, 96 x 60 m in 40 bays)")
    gi.add_argument("-o", "--output", required=True,
                    help="interior file to write: .json (walkstream-interior), or .ifc (an IFC4 model; needs the ifc extra)")
    gi.add_argument("--space-boundaries", action="store_true",
                    help="with an .ifc output: a space boundary (IfcRelSpaceBoundary) from each door and window to "
                    "each space it opens into, as exporters that write boundaries do (default: none, rooms found from the geometry)")
    gi.add_argument("--ifc-schema", help="with an .ifc output: IFC4 (default) or IFC2X3")
    gi.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    gi.set_defaults(func=cmd_generate_interior)

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
