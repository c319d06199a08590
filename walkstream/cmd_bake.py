"""``walkstream bake``, ``inspect`` and ``serve``: scene databases, made, looked at and served.

::

    walkstream bake SOURCE.geojson|.osm|.osm.pbf -o scene.db [--cells street|grid|sections] [--cell-size M]
                   [--field-spacing M] [--redundancy R] [--min-size M2] [--section-shape axis|aligned]
                   [--section-cover walkable|free]
                   [--sampling region|boundary|corners|field]
                   [--network walk|drive] [--bbox X0,Y0,X1,Y1 [--bbox-crs local|lonlat]] ...
    walkstream bake --default-city -o scene.db
    walkstream bake city.geojson -o scene.db --interior office.json [--building ID|auto]
    walkstream inspect scene.db [--json] [--map map.png]
    walkstream cutaway interior.db [--storey N] [--cut 1.4] -o cut.png
    walkstream serve scene.db [more.db ...] [--host H] [--port P] [--workers N]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from walkstream.shared.errors import WalkstreamError
from walkstream.terminal import count_bar, print_summary, stage_setter

__all__ = ["add_bake_parsers", "default_city_source", "parse_bbox", "run_bake"]


def parse_bbox(text: str | None) -> tuple[float, float, float, float] | None:
    """``--bbox MINX,MINY,MAXX,MAXY`` as four numbers (None when not given); a bad one is a one-line error."""
    if text is None:
        return None
    try:
        parts = tuple(float(v) for v in text.split(","))
    except ValueError:
        parts = ()
    if len(parts) != 4:
        raise WalkstreamError(f"--bbox: expected MINX,MINY,MAXX,MAXY (scene-local metres or lon/lat), got {text!r}")
    return parts[0], parts[1], parts[2], parts[3]


def default_city_source(folder: Path) -> Path:
    """The default city's GeoJSON in ``folder``, generated when it is not there yet or
    was made by an older generator (its ``walkstream.version``)."""
    from walkstream.server.sources.citygen import (
        DEFAULT_SEED,
        DEFAULT_SIZE,
        GENERATOR_VERSION,
        write_city,
    )

    folder.mkdir(parents=True, exist_ok=True)
    city = folder / "city.geojson"
    if city.exists() and _generator_version(city) != GENERATOR_VERSION:
        print(f"{city} was made by an older city generator: generating it again")
        city.unlink()
    if not city.exists():
        print(f"generating the default city ({DEFAULT_SIZE:.0f} m, seed {DEFAULT_SEED}) -> {city}")
        write_city(city, DEFAULT_SIZE, DEFAULT_SEED)
    return city


def _generator_version(city: Path) -> object:
    """The ``walkstream.version`` member of a generated city file (None when unreadable)."""
    import json

    try:
        meta = json.loads(city.read_text(encoding="utf-8")).get("walkstream") or {}
    except (OSError, ValueError, AttributeError):
        return None
    return meta.get("version") if isinstance(meta, dict) else None


def run_bake(source: str | Path, output: str | Path, **kw: Any) -> dict[str, Any]:
    """Bake with a progress bar on stderr; returns the summary."""
    from walkstream.server.bake import bake

    bar, progress = count_bar("reading the source", "step")
    try:
        return bake(source, output, progress=progress, log=lambda m: bar.write(m, file=sys.stderr),
                    stage=stage_setter(bar), **kw)
    finally:
        bar.close()


def cmd_bake(args: argparse.Namespace) -> int:
    """Handler of ``walkstream bake``."""
    from walkstream.server.bake import BakeSettings

    if args.default_city:
        source: Path = default_city_source(Path(args.output).resolve().parent)
    elif args.source:
        source = Path(args.source)
    else:
        raise WalkstreamError("give a SOURCE (.geojson, .osm, .osm.pbf) or --default-city")
    st = BakeSettings(
        cells=args.cells,
        cell_size=args.cell_size,
        max_length=args.cell_size,
        view_distance=args.view_distance,
        bbox=parse_bbox(args.bbox),
        bbox_crs=args.bbox_crs,
        network=args.network,
        centre=args.centre,
        threshold=args.threshold,
        pvs_budget=args.pvs_budget / 100.0,
        **{k: v for k, v in (("resolution", args.resolution), ("occluder_lod", args.occluder_lod)) if v is not None},
        **{k: v for k, v in (("field_spacing", args.field_spacing), ("redundancy", args.redundancy), ("min_size", args.min_size), ("section_shape", args.section_shape), ("section_cover", args.section_cover)) if v is not None},
        **{k: v for k, v in (("sampling", args.sampling), ("spacing", args.spacing), ("height_step", args.height_step), ("edge_pass", args.edge_pass), ("thin_pass", args.thin_pass), ("thin_depth", args.thin_depth), ("split", args.split), ("far_band", args.far_band), ("far_pixels", args.far_pixels), ("far_axis", args.far_axis), ("far_edges", args.far_edges)) if v is not None},
    )
    st.check()  # a bad setting fails before any progress bar
    if args.building is not None and args.interior is None:
        raise WalkstreamError("--building: give --interior FILE too (the interior to place in the building)")
    extra: dict[str, Any] = {} if args.interior is None else {"interior": args.interior, "building": args.building}
    imp_flags = (args.impostor_distance, args.impostor_error, args.impostor_size, args.complex_triangles, args.impostor_sampling,
                 args.impostor_projection)
    if args.impostors:
        from walkstream.server.bake import ImpostorSettings

        names = ("distance", "error_deg", "size", "complex_triangles", "sampling", "projection")
        extra["impostors"] = ImpostorSettings(**{k: v for k, v in zip(names, imp_flags, strict=True) if v is not None}).check()
    elif any(v is not None for v in imp_flags):
        raise WalkstreamError("--impostor-distance/-error/-size/-sampling/-projection, --complex-triangles: give --impostors too")
    wall_flags = (args.wall_error, args.wall_pitch, args.wall_keep, args.wall_ring_min, args.wall_region, args.wall_depth,
                  args.wall_view)
    texture_flags = (args.wall_texels, args.wall_max_side, args.wall_quality)
    if args.virtual_walls:
        from walkstream.server.bake.wallplan import WallSettings, parse_wall_quality

        wall_names = ("error_deg", "pitch", "keep", "ring_min", "region", "depth_grid", "view_height")
        extra["walls"] = WallSettings(**{k: v for k, v in zip(wall_names, wall_flags, strict=True) if v is not None}
                                      ).with_texture(texels=args.wall_texels, max_side=args.wall_max_side,
                                                     quality=parse_wall_quality(args.wall_quality)).check()
    elif any(v is not None for v in (*wall_flags, *texture_flags)):
        raise WalkstreamError("--wall-error/--wall-pitch/--wall-keep/--wall-ring-min/--wall-region/--wall-depth/"
                              "--wall-view/--wall-texels/--wall-max-side/--wall-quality: give --virtual-walls too")
    summary = run_bake(source, args.output, settings=st, name=args.name, workers=args.workers, scheduler=args.scheduler, **extra)
    print_summary(f"baked {args.output}", summary, args.json)
    return 0


def cmd_inspect(args: argparse.Namespace) -> int:
    """Handler of ``walkstream inspect``."""
    from walkstream.server.store import SceneReader

    reader = SceneReader.open(args.db)
    try:
        summary = reader.summary()
        if args.map and reader.meta.kind == "crossing":
            from walkstream.server.bake.crossplot import draw_crossing_map

            draw_crossing_map(reader, args.map)
        elif args.map and reader.meta.kind == "interior":
            from walkstream.server.bake.roomplot import draw_interior_map

            draw_interior_map(reader, args.map)
        elif args.map:
            from walkstream.server.bake.mapplot import draw_map

            draw_map(reader, args.map)
    finally:
        reader.close()
    if args.json:
        print(json.dumps(summary))
    else:
        print_summary(str(args.db), summary, False)
        if args.map:
            print(f"map: {args.map}")
    return 0


def cmd_cutaway(args: argparse.Namespace) -> int:
    """Handler of ``walkstream cutaway``."""
    from walkstream.client.draw.cutaway import render_cutaway
    from walkstream.server.bake.roomplot import storey_meshes
    from walkstream.server.store import SceneReader

    with SceneReader.open(args.db) as reader:
        if reader.meta.kind != "interior":
            raise WalkstreamError(f"{args.db}: a city scene: cut-aways are of interiors (see walkstream buildings render)")
        storeys = reader.storeys()
        if args.storey is None:
            rooms = reader.rooms()
            k = min(r.storey for r in rooms.values() if r.storey >= 0)
        else:
            names = [s.name for s in storeys]
            k = names.index(args.storey) if args.storey in names else -1
            if k < 0:
                try:
                    k = int(args.storey)
                except ValueError:
                    raise WalkstreamError(f"--storey {args.storey!r}: not a storey (storeys: {', '.join(names)})") from None
        meshes = storey_meshes(reader, k, args.cut)
        title = f"{reader.meta.name}, storey {storeys[k].name if 0 <= k < len(storeys) else k}, cut at {args.cut:g} m"
    tris = render_cutaway(meshes, args.output, title=title)
    print(f"wrote {args.output} ({title}: {tris:,} triangles)")
    return 0


def cmd_serve(args: argparse.Namespace) -> int:
    """Handler of ``walkstream serve``."""
    from walkstream.server.service import serve

    serve(args.db, host=args.host, port=args.port, workers=args.workers)
    return 0


def add_bake_parsers(sub: Any) -> None:
    """Register ``bake``, ``inspect`` and ``serve``."""
    bk = sub.add_parser("bake", help="bake a source into a scene database (a city: cells, PVS, ACH; an interior: rooms, portals, contents)")
    bk.add_argument("source", nargs="?", help="GeoJSON FeatureCollection (generated city or real footprints), an OpenStreetMap "
                    "extract (.osm, .osm.pbf), an IFC model (.ifc) or a walkstream-interior file (.json, walkstream generate interior)")
    bk.add_argument("-o", "--output", required=True, help="scene database to write (SQLite, replaced atomically)")
    bk.add_argument("--default-city", action="store_true", help="bake the default 700 m city (generated beside the output)")
    bk.add_argument("--name", help="scene name (default: the database file's stem)")
    bk.add_argument("--cells", choices=("auto", "street", "grid", "sections"), default="auto", help="street cells (needs streets), a grid, "
                    "or sections grown over a dense visibility field (Brosnan et al.; default auto: street cells, else a grid)")
    bk.add_argument("--field-spacing", type=float, default=None, help="sections and --sampling field: metres between the points of the visibility field (default 4)")
    bk.add_argument("--redundancy", type=int, default=None, help="sections: objects a section may hold beyond what its seed point sees (default: from the field, the smallest R whose sections average 2,400 m² of the walkable cover)")
    bk.add_argument("--min-size", type=float, default=None, help="sections: smallest section the first pass accepts, square metres (default 64)")
    bk.add_argument("--section-shape", default=None, help="sections: axis (rectangles along the x and y axes, as the paper's; default) or aligned (turned to the scene's prevailing street direction)")
    bk.add_argument("--section-cover", default=None, help="sections: walkable (over the field points of the walkable cells: the street cells, or the grid cells where the scene has no streets; default) or free (over all the free space, as the paper's)")
    bk.add_argument("--cell-size", type=float, default=40.0, help="grid cell side / longest street cell, metres (default 40)")
    bk.add_argument("--view-distance", type=float, default=800.0, help="far plane, metres (default 800)")
    bk.add_argument("--bbox", help="MINX,MINY,MAXX,MAXY: bake only this part; objects crossing it are clipped to it")
    bk.add_argument("--bbox-crs", choices=("local", "lonlat"), default="local", help="--bbox in scene-local metres (default) or lon/lat degrees")
    bk.add_argument("--network", choices=("walk", "drive"), default="walk", help="street network of OSM highways: what a pedestrian (default) or a car may use")
    bk.add_argument("--resolution", type=int, default=None, help="pixels per cube face (default: see bench visibility)")
    bk.add_argument("--occluder-lod", type=int, choices=(0, 1, 2), default=None, help="LOD rendered as occluder")
    bk.add_argument("--sampling", choices=("region", "boundary", "corners", "field"), default=None, help="sample points: the cell's outline, a grid inside and both ends of its height range (region), the outline at the top height (boundary), the 8 box corners of the first bake (corners), or the dense visibility field's points in and around the cell, every --field-spacing metres, rendered once and kept beside the database (field) (default: see bench visibility)")
    bk.add_argument("--spacing", type=float, default=None, help="region/boundary sampling: metres between points along an edge and of the inside grid (default 20)")
    bk.add_argument("--height-step", type=float, default=None, help="region/boundary sampling: every point at one more eye height per this many metres of the cell's height range (default 1)")
    bk.add_argument("--split", type=float, default=None, help="adaptive sampling: add points between two whose visible sets differ by more than this Jaccard distance (0..1; default 0: off)")
    bk.add_argument("--thin-pass", type=float, default=None, metavar="PX", help="after the fill, test again the objects a cube face did not show whose box is at most PX pixels across (narrower direction), as lines and points against the fill's depth: objects under a pixel enter the PVS unless hidden (0: off)")
    bk.add_argument("--far-band", type=float, default=None, metavar="DEG", help="render every sample point again as a band DEG degrees above and below the horizon at --far-pixels across 90 degrees: the far field at the client's pixel size, adding what is under a bake pixel there (0: off, the default)")
    bk.add_argument("--far-pixels", type=int, default=None, metavar="N", help="with --far-band: the band's pixels across each 90-degree face (default 1109: a 640-pixel, 60-degree client's pixels per degree)")
    bk.add_argument("--far-axis", type=float, default=None, metavar="M", help="with --far-band: render the band also at points every M metres along each cell's long axis (the middle of a street, where a walker sees far buildings past the near facades that the outline points hug); 0: off, the default")
    bk.add_argument("--far-edges", action="store_true", default=None, help="with --far-band: draw the band's triangle edges again as one-pixel lines after its fill (a street piece far ahead thinner than a band pixel still counts)")
    bk.add_argument("--thin-depth", action="store_true", default=None, help="with --thin-pass: test against the fill's depth taken as the farthest over each pixel's 3x3 neighbours (occluders shrunk by a pixel for that test)")
    bk.add_argument("--edge-pass", action="store_true", default=None, help="also draw every triangle's edges, adding objects thinner than a pixel (about 2x the render time)")
    bk.add_argument("--centre", action="store_true", help="also sample the cell centre")
    bk.add_argument("--threshold", type=int, default=0, help="hardly-visible threshold (m-LOMA): pixels an object must exceed over the cell's images to enter the PVS (default 0)")
    bk.add_argument("--pvs-budget", type=float, default=0.0, metavar="PCT", help="per cell, leave out of the PVS the least-seen objects "
                    "while, at every sample point (its cube; with --far-band, its band too), the pixels they cover together stay "
                    "within PCT %% of what it sees (default 0: off)")
    bk.add_argument("--workers", type=int, default=1, help="local processes rendering cells (default 1)")
    bk.add_argument("--scheduler", help="tcp://HOST:PORT of a Dask scheduler to run the cell tasks on")
    bk.add_argument("--interior", metavar="FILE", help="an interior (.ifc or walkstream-interior .json) to place in one of the city's "
                    "buildings, its entrance joined to the street in front: one scene of streets and rooms (kind crossing)")
    bk.add_argument("--building", metavar="ID", help="with --interior: the building to put it in, an object id or the source's "
                    "feature id (default auto: one it fits with its door on a street, nearest the middle)")
    bk.add_argument("--impostors", action="store_true", help="also bake impostor images of far and complex buildings (docs/bake.md, impostors)")
    bk.add_argument("--impostor-distance", type=float, default=None, metavar="D", help="with --impostors: a building at least D metres from every point of a cell is far (default 250)")
    bk.add_argument("--impostor-error", type=float, default=None, metavar="A", help="with --impostors: the largest angle, degrees, under which a point of an impostor may move (default 2)")
    bk.add_argument("--impostor-size", type=int, default=None, metavar="S", help="with --impostors: the largest image side, texels, a power of two (default 128)")
    bk.add_argument("--impostor-projection", choices=("ortho", "perspective"), default=None, help="with --impostors: each image orthographic along its direction (ortho, default) or in perspective from its level's sampling eye onto the quad's plane (perspective: no orthographic parallax from that eye; docs/benchmarks.md)")
    bk.add_argument("--impostor-sampling", choices=("point", "area"), default=None, help="with --impostors: each texel the surface under its centre (point, default: as the truth samples a pixel) or the mean of 2x2 samples (area)")
    bk.add_argument("--complex-triangles", type=int, default=None, metavar="N", help="with --impostors: buildings over N triangles at LOD2 are impostors wherever the error bound allows (default 12000)")
    bk.add_argument("--virtual-walls", action="store_true", help="interiors: cut open rooms by textured virtual walls; cities: ring the cells whose PVS is large by walls that carry their far field (docs/bake.md, virtual walls)")
    bk.add_argument("--wall-error", type=float, default=None, metavar="A", help="with --virtual-walls: the angle of error, degrees, that sets the zones (default 10)")
    bk.add_argument("--wall-keep", type=int, default=None, metavar="K", help="with --virtual-walls on a city: a region of cells whose PVS holds more than K objects gets a ring of walls, as far out as keeps about K as geometry (default 8)")
    bk.add_argument("--wall-ring-min", type=float, default=None, metavar="M", help="with --virtual-walls on a city: the ring's least distance from its cell, metres (default 10)")
    bk.add_argument("--wall-region", type=float, default=None, metavar="S", help="with --virtual-walls on a city: neighbouring cells within S by S metres share one ring and its textures (default 40; 0: a ring per cell)")
    bk.add_argument("--wall-depth", type=int, default=None, metavar="G", help="with --virtual-walls: store each texture's G x G grid of depths (0, 4, 8 or 16; default 0: none) and draw it as a textured depth mesh (docs/usage.md)")
    bk.add_argument("--wall-view", type=int, default=None, metavar="H", help="with --virtual-walls: size each wall's textures for a view H pixels high (60 degrees): a texel at most a pixel from the wall's nearest viewing distance, capped by --wall-max-side (0: --wall-texels a metre; docs/usage.md)")
    bk.add_argument("--wall-texels", type=float, default=None, metavar="T", help="with --virtual-walls and --wall-view 0: texels a metre of the wall textures (default 16 indoors, 4 outdoors)")
    bk.add_argument("--wall-max-side", type=int, default=None, metavar="S", help="with --virtual-walls: the largest wall texture side, texels (8 to 1024; default 512 indoors, 256 outdoors)")
    bk.add_argument("--wall-quality", default=None, metavar="Q", help="with --virtual-walls: the wall textures lossy WebP at quality Q (1 to 100) or lossless (default 75 outdoors, lossless indoors)")
    bk.add_argument("--wall-pitch", type=float, default=None, metavar="S", help="with --virtual-walls: a room part over 2 S^2 is cut into cells about S metres square (default 8)")
    bk.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    bk.set_defaults(func=cmd_bake)

    ins = sub.add_parser("inspect", help="summary of a scene database; --map draws its cells")
    ins.add_argument("db", help="scene database")
    ins.add_argument("--map", help="PNG: top view of the cells coloured by PVS size over the footprints; "
                     "an interior: a plan per storey, cells coloured by triangles, portals as thick lines; "
                     "a crossing scene: the city with the building's plan, its entrance and the enter walk, and a close-up")
    ins.add_argument("--json", action="store_true", help="print one JSON object")
    ins.set_defaults(func=cmd_inspect)

    cu = sub.add_parser("cutaway", help="a cut-away picture of an interior storey (cut above eye height)")
    cu.add_argument("db", help="interior scene database")
    cu.add_argument("--storey", help="storey name or index (default: the lowest with rooms)")
    cu.add_argument("--cut", type=float, default=1.4, help="cut this many metres above the storey's floor (default 1.4)")
    cu.add_argument("-o", "--output", required=True, help="PNG to write")
    cu.set_defaults(func=cmd_cutaway)

    sv = sub.add_parser("serve", help="serve scene databases over HTTP (FastAPI + uvicorn)")
    sv.add_argument("db", nargs="+", help="scene database(s), each served under its scene name")
    sv.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1)")
    sv.add_argument("--port", type=int, default=8000, help="port (default 8000)")
    sv.add_argument("--workers", type=int, default=1, help="uvicorn worker processes (default 1)")
    sv.set_defaults(func=cmd_serve)
