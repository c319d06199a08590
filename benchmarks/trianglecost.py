"""``walkstream bench portals --triangles``: what testing the kept parts' triangles saves and costs.

The parts culling keeps a part when its box's rectangle meets one of its cell's visible
screen areas; :func:`~walkstream.shared.trianglecull.refine_parts` then drops the kept
parts none of whose triangles does.  For each scene, pose by pose along its tour (every
``step_s`` seconds, culled from the eye's cell at a 40 m fog), this measures the parts and
triangles the boxes keep and the triangles keep, and the CPU time of each step
(``time.process_time``): the portal walk, the boxes, the triangles.

A scene is a generated office's seed (3 storeys, baked into ``out`` once, as ``--cull``
does) or a baked interior database (an IFC model: ``walkstream bake model.ifc -o x.db``).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from walkstream.server.bake import bake
from walkstream.server.service.interiors import InteriorState
from walkstream.server.sources.interiorgen import InteriorPlan, write_interior
from walkstream.server.store import SceneReader
from walkstream.shared.camera import camera
from walkstream.shared.codec.cellpieces import decode_cell_pieces
from walkstream.shared.errors import InputError, NotFoundError
from walkstream.shared.partcull import cull_parts
from walkstream.shared.paths import RecordedPath
from walkstream.shared.portalgraph import PortalGraph
from walkstream.shared.portals import cull_portals
from walkstream.shared.roomcompact import decode_topology_compact
from walkstream.shared.roomview import cell_of, room_projection, stack_planes
from walkstream.shared.trianglecull import refine_parts
from walkstream.shared.trianglekernels import warm_up as warm_up_triangle_test

__all__ = ["triangle_rows", "triangle_table"]

#: Viewports measured: the replays' 160x120 and the culling benchmark's 640x480.
SIZES = ((160, 120), (640, 480))


def _scene_db(src: str, out: Path, log: Callable[[str], None]) -> tuple[str, Path]:
    """``(name, database)`` of a scene argument: a seed (baked into ``out`` once) or a database."""
    if src.isdigit():
        seed = int(src)
        db = out / f"seed{seed}.db"
        if not db.exists():
            out.mkdir(parents=True, exist_ok=True)
            write_interior(out / f"seed{seed}.json", InteriorPlan(storeys=3, seed=seed))
            log(f"bench portals: baking seed {seed}")
            bake(out / f"seed{seed}.json", db)
        return f"seed {seed}", db
    db = Path(src)
    if not db.is_file():
        raise InputError(f"--triangles {src}: expected a generated office's seed or a baked interior database")
    return db.stem, db


def triangle_rows(sources: Sequence[str], out: Path, *, step_s: float = 1.0,
                  log: Callable[[str], None] = lambda s: None) -> list[dict[str, Any]]:
    """A row per scene and viewport (module docstring): poses, parts and triangles kept by the
    boxes and by the triangles (sums over the poses), and per step (``walk``, ``boxes``,
    ``triangles``) the median and p99 milliseconds."""
    rows = []
    warm_up_triangle_test()  # the compiled kernels made or loaded before any pose is timed
    for src in sources:
        name, db = _scene_db(src, out, log)
        with SceneReader.open(db) as r:
            try:
                blob = r.path_blob("tour")
            except NotFoundError:
                raise InputError(f"--triangles {src}: {db} has no path 'tour' (not a baked interior?)") from None
            state = InteriorState(r, list(r.cells()))
            topo = decode_topology_compact(state.topology_compact.content, f"{db}: topology")
            meshes = {c.id: decode_cell_pieces(r.contents(c.id), f"{db}: cell {c.id}") for c in topo.cells}
            tour = RecordedPath.from_msgpack(blob)
        graph = PortalGraph.from_topology(topo)
        ids, planes = stack_planes([c for c in topo.cells if c.kind != "outside" and len(c.planes)])
        boxes = {cid: (np.array([p.bbox[0] for p in m.parts]).reshape(-1, 3),
                       np.array([p.bbox[1] for p in m.parts]).reshape(-1, 3)) for cid, m in meshes.items()}
        tris = {cid: np.array([p.triangles for p in m.parts], np.int64) for cid, m in meshes.items()}
        poses = []
        for t in np.arange(0.0, tour.duration, step_s).tolist():
            xyz, yaw, pitch = tour.at(t)
            eye = np.asarray(xyz, np.float64)
            hit = np.flatnonzero(cell_of(planes, eye))
            if len(hit):
                poses.append((int(ids[hit[0]]), eye, camera(eye, float(yaw), float(pitch)).astype(np.float64)))
        for size in SIZES:
            log(f"bench portals: triangles, {name}, {size[0]}x{size[1]}, {len(poses)} poses")
            proj = room_projection(60.0, size, 40.0)
            ms: dict[str, list[float]] = {"walk": [], "boxes": [], "triangles": []}
            sums = {"parts_boxes": 0, "parts_triangles": 0, "tris_boxes": 0, "tris_triangles": 0}
            for start, eye, view in poses:
                t0 = time.process_time()
                pc = cull_portals(graph, start, eye, view, proj, size, fog_m=40.0)
                t1 = time.process_time()
                keep = cull_parts("portals", pc.order, boxes, eye, view, proj, size, vsas=pc.vsas, fog_m=40.0)
                t2 = time.process_time()
                before = {c: m.copy() for c, m in keep.items()}
                refine_parts(keep, meshes, pc.vsas, view, proj, size)
                t3 = time.process_time()
                ms["walk"].append(t1 - t0)
                ms["boxes"].append(t2 - t1)
                ms["triangles"].append(t3 - t2)
                sums["parts_boxes"] += sum(int(m.sum()) for m in before.values())
                sums["parts_triangles"] += sum(int(m.sum()) for m in keep.values())
                sums["tris_boxes"] += sum(int(tris[c][m].sum()) for c, m in before.items())
                sums["tris_triangles"] += sum(int(tris[c][m].sum()) for c, m in keep.items())
            rows.append({"scene": name, "size": f"{size[0]}x{size[1]}", "poses": len(poses), **sums,
                         "ms": {k: {"median": 1e3 * float(np.median(v)), "p99": 1e3 * float(np.percentile(v, 99))}
                                for k, v in ms.items() if v}})
    return rows


def triangle_table(rows: Sequence[dict[str, Any]]) -> str:
    """The rows of :func:`triangle_rows` as text."""
    out = ["the kept parts' triangles tested (pose by pose along each tour, 40 m fog; time.process_time, "
           "median / p99 ms):",
           f"{'scene':<16}{'size':>9}{'poses':>7}{'parts boxes':>13}{'triangles':>11}{'tris boxes':>12}"
           f"{'triangles':>11}{'saved':>7}{'walk ms':>14}{'boxes ms':>14}{'triangles ms':>14}"]

    def mp(r: dict[str, float]) -> str:
        return f"{r['median']:.2f} / {r['p99']:.2f}"

    for r in rows:
        saved = 1.0 - r["tris_triangles"] / r["tris_boxes"] if r["tris_boxes"] else math.nan
        out.append(f"{r['scene']:<16}{r['size']:>9}{r['poses']:>7}{r['parts_boxes']:>13,}{r['parts_triangles']:>11,}"
                   f"{r['tris_boxes']:>12,}{r['tris_triangles']:>11,}{saved:>7.1%}{mp(r['ms']['walk']):>14}"
                   f"{mp(r['ms']['boxes']):>14}{mp(r['ms']['triangles']):>14}")
    return "\n".join(out)
