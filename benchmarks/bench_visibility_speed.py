"""How many view cells per second the visibility bake renders, per resolution and LOD.

Builds a generated city (default 700 m, seed 1), takes ~40 street cells spread over it
(``server.cells.make_cells``; 40 m boxes along street pieces if that module is
missing), computes their 8 sample points once and then times
``VisibilityRenderer.cell_counts`` (culling, 48 cube-face images per cell, read-back
and counting) for every resolution and building LOD, median of ``--runs`` runs.  It
also prints the mean PVS size and, for the coarser LODs, how many objects their PVS
misses or adds compared with LOD2 at the same resolution (the paper renders the
highest LOD "because it avoids occlusion errors"; this measures what a coarser one
costs).

Run: ``.venv/bin/python benchmarks/bench_visibility_speed.py [--no-cull] [...]``
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np
import shapely
from numpy.typing import NDArray

from walkstream.server.bake.samples import sample_points
from walkstream.server.bake.visibility import VisibilityRenderer, meshes_for_scene
from walkstream.server.sources.citygen import generate_city
from walkstream.server.sources.geojson import load_geojson_dict
from walkstream.server.sources.scene import SourceScene
from walkstream.shared.gl import create_context


def street_boxes(scene: SourceScene, n: int) -> list[tuple[NDArray[np.float64], float, float]]:
    """Fallback cells: 40 m boxes around street pieces, clipped to the street."""
    streets = [s for s in scene.streets if s.kind == "street"] or list(scene.streets)
    out = []
    for s in streets[:: max(1, len(streets) // n)][:n]:
        poly = shapely.Polygon(s.ring)
        c = poly.centroid
        cell = poly.intersection(shapely.box(c.x - 20, c.y - 20, c.x + 20, c.y + 20))
        if cell.geom_type != "Polygon":
            cell = max(getattr(cell, "geoms", []), key=lambda g: g.area, default=None)
        if cell is not None and cell.area > 1.0:
            out.append((np.asarray(cell.exterior.coords)[:-1], 1.5, 2.0))
    return out


def bench_cells(
    scene: SourceScene, n: int
) -> tuple[str, list[tuple[NDArray[np.float64], float, float]]]:
    """About ``n`` cells spread evenly over the scene's cell list."""
    try:
        from walkstream.server.bake.cells import make_cells
    except ImportError:
        return "street boxes (server.cells missing)", street_boxes(scene, n)
    cells = make_cells(scene)
    pick = np.unique(np.linspace(0, len(cells) - 1, min(n, len(cells))).round().astype(int))
    chosen = [(np.asarray(cells[i].polygon), cells[i].zmin, cells[i].zmax) for i in pick]
    return f"server.cells.make_cells ({len(cells)} cells in the scene)", chosen


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--size", type=float, default=700.0)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--cells", type=int, default=40)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--resolutions", type=int, nargs="+", default=[64, 128, 256])
    ap.add_argument("--lods", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--view-distance", type=float, default=800.0)
    ap.add_argument("--no-cull", action="store_true", help="draw back faces too")
    args = ap.parse_args()

    t0 = time.perf_counter()
    scene = load_geojson_dict(generate_city(args.size, args.seed))
    footprints = shapely.STRtree(
        [shapely.Polygon(b.rings[0], b.rings[1:]) for b in scene.buildings]
    )
    how, cells = bench_cells(scene, args.cells)
    t1 = time.perf_counter()
    points = [sample_points(p, z0, z1, footprints=footprints) for p, z0, z1 in cells]
    t_pts = (time.perf_counter() - t1) / max(len(cells), 1)
    ctx = create_context()
    print(
        f"city {args.size:.0f} m seed {args.seed}: {len(scene.buildings)} buildings, "
        f"{len(scene.streets)} street pieces (built in {t1 - t0:.1f} s)"
    )
    print(f"cells: {len(cells)} from {how}; sample_points {t_pts * 1e3:.1f} ms/cell")
    print(
        f"GL: {ctx.info['GL_RENDERER']} | OpenGL {ctx.version_code} | "
        f"cpus {os.cpu_count()} | back-face culling {'off' if args.no_cull else 'on'} | "
        f"view distance {args.view_distance:.0f} m | median of {args.runs} runs"
    )
    print(f"{'LOD':>3} {'tris':>9} {'res':>4} {'cells/s':>8} {'ms/cell':>8} {'PVS':>6}  vs LOD2")

    pvs: dict[tuple[int, int], list[set[int]]] = {}
    try:
        for lod in sorted(args.lods, reverse=True):  # LOD2 first: it is the reference
            meshes, ids = meshes_for_scene(scene, lod)
            tris = sum(m.triangles for m in meshes)
            for res in args.resolutions:
                with VisibilityRenderer(
                    meshes,
                    ids,
                    resolution=res,
                    view_distance=args.view_distance,
                    ctx=ctx,
                    cull_back_faces=not args.no_cull,
                ) as r:
                    for p in points[:2]:  # warm-up: shader compile, first allocations
                        r.cell_counts(p)
                    rates = []
                    for _ in range(args.runs):
                        t = time.perf_counter()
                        out = [r.cell_counts(p) for p in points]
                        rates.append(len(points) / (time.perf_counter() - t))
                rate = statistics.median(rates)
                sets = [set(o[0].tolist()) for o in out]
                pvs[(lod, res)] = sets
                ref = pvs.get((2, res))
                cmp = ""
                if ref is not None and lod != 2:
                    missed = np.mean([len(b - a) for a, b in zip(sets, ref, strict=True)])
                    extra = np.mean([len(a - b) for a, b in zip(sets, ref, strict=True)])
                    cmp = f"misses {missed:.2f}, adds {extra:.2f} objects/cell"
                print(
                    f"{lod:>3} {tris:>9} {res:>4} {rate:>8.1f} {1e3 / rate:>8.1f} "
                    f"{np.mean([len(s) for s in sets]):>6.1f}  {cmp}",
                    flush=True,
                )
    finally:
        ctx.release()


if __name__ == "__main__":
    main()
