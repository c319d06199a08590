"""How many view cells per second the visibility bake renders, per resolution and LOD.

``walkstream bench render [--size 700] [--cells 40] [--runs 3] [--resolutions 64 128 256]
[--lods 0 1 2] [--no-cull]`` prints the lines of :func:`run_render_speed` as they come.

Builds a generated city (default 700 m, seed 1), takes ~40 street cells spread over it
(:func:`~walkstream.server.bake.cells.make_cells`), computes their 8 sample points once and then times
``VisibilityRenderer.cell_counts`` (culling, 48 cube-face images per cell, read-back
and counting) for every resolution and building LOD, median of ``--runs`` runs.  It
also prints the mean PVS size and, for the coarser LODs, how many objects their PVS
misses or adds compared with LOD2 at the same resolution (the paper renders the
highest LOD "because it avoids occlusion errors"; this measures what a coarser one
costs).

"""

from __future__ import annotations

import os
import statistics
import time
from collections.abc import Iterator, Sequence

import numpy as np
import shapely
from numpy.typing import NDArray

from walkstream.server.bake.cells import make_cells
from walkstream.server.bake.idpack import meshes_for_scene
from walkstream.server.bake.samples import sample_points
from walkstream.server.bake.visibility import VisibilityRenderer
from walkstream.server.sources.citygen import generate_city
from walkstream.server.sources.geojson import load_geojson_dict
from walkstream.server.sources.scene import SourceScene
from walkstream.shared.gl import create_context

__all__ = ["run_render_speed"]




def _bench_cells(
    scene: SourceScene, n: int
) -> tuple[str, list[tuple[NDArray[np.float64], float, float]]]:
    """About ``n`` cells spread evenly over the scene's cell list."""
    cells = make_cells(scene)
    pick = np.unique(np.linspace(0, len(cells) - 1, min(n, len(cells))).round().astype(int))
    chosen = [(np.asarray(cells[i].polygon), cells[i].zmin, cells[i].zmax) for i in pick]
    return f"make_cells ({len(cells)} cells in the scene)", chosen


def run_render_speed(
    *,
    size: float = 700.0,
    seed: int = 1,
    cells_wanted: int = 40,
    runs: int = 3,
    resolutions: Sequence[int] = (64, 128, 256),
    lods: Sequence[int] = (0, 1, 2),
    view_distance: float = 800.0,
    no_cull: bool = False,
) -> Iterator[str]:
    """Render cells at every resolution and LOD; yields the report's lines as they are measured."""
    t0 = time.perf_counter()
    scene = load_geojson_dict(generate_city(size, seed))
    footprints = shapely.STRtree(
        [shapely.Polygon(b.rings[0], b.rings[1:]) for b in scene.buildings]
    )
    how, cells = _bench_cells(scene, cells_wanted)
    t1 = time.perf_counter()
    points = [sample_points(p, z0, z1, footprints=footprints) for p, z0, z1 in cells]
    t_pts = (time.perf_counter() - t1) / max(len(cells), 1)
    ctx = create_context()
    yield (
        f"city {size:.0f} m seed {seed}: {len(scene.buildings)} buildings, "
        f"{len(scene.streets)} street pieces (built in {t1 - t0:.1f} s)"
    )
    yield f"cells: {len(cells)} from {how}; sample_points {t_pts * 1e3:.1f} ms/cell"
    yield (
        f"GL: {ctx.info['GL_RENDERER']} | OpenGL {ctx.version_code} | "
        f"cpus {os.cpu_count()} | back-face culling {'off' if no_cull else 'on'} | "
        f"view distance {view_distance:.0f} m | median of {runs} runs"
    )
    yield f"{'LOD':>3} {'tris':>9} {'res':>4} {'cells/s':>8} {'ms/cell':>8} {'PVS':>6}  vs LOD2"

    pvs: dict[tuple[int, int], list[set[int]]] = {}
    try:
        for lod in sorted(lods, reverse=True):  # LOD2 first: it is the reference
            meshes, ids = meshes_for_scene(scene, lod)
            tris = sum(m.triangles for m in meshes)
            for res in resolutions:
                with VisibilityRenderer(
                    meshes,
                    ids,
                    resolution=res,
                    view_distance=view_distance,
                    ctx=ctx,
                    cull_back_faces=not no_cull,
                ) as r:
                    for p in points[:2]:  # warm-up: shader compile, first allocations
                        r.cell_counts(p)
                    rates = []
                    for _ in range(runs):
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
                yield (
                    f"{lod:>3} {tris:>9} {res:>4} {rate:>8.1f} {1e3 / rate:>8.1f} "
                    f"{np.mean([len(s) for s in sets]):>6.1f}  {cmp}"
                )
    finally:
        ctx.release()
