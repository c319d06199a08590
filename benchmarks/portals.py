"""``walkstream bench portals``: portal culling against frustum culling alone and drawing everything.

For each generated interior (default: the presets ``paper``, the paper's 93-cell
scale, and ``paper10``, ten times its cells), baked once into ``--out``: frames along
its tour (every ``--step`` seconds, at most ``--frames``), each culled three ways
(:data:`~walkstream.shared.portals.CULLING_MODES`: ``portals`` with visible
screen areas; ``frustum``, the cells behind portals in the frustum and their parts in
the frustum; ``none``, every part of every cell of the building, the paper's "draw
all").  Per mode: visible cells, triangles drawn, culling CPU microseconds (cells and
parts, measured here), the frame time on the ``gl`` device (moderngl, measured) and
on the ``pda`` cost model (fitted to the paper's Table 1, no fog column).

Tightness (the first scene only, ``--truth`` frames): triangles drawn over the
triangles of the parts truly visible in an id frame of the whole building
(:class:`~walkstream.client.truth.render.TruthRenderer`), mean and 95th percentile,
for portal culling and the frustum alone; the missed pixels of portal culling are
counted too (they must be 0).

Table 1 scenes: frames of the first scene where portal culling sees 1, 2, 3 and 4
cells, the one whose visible cells hold the triangles nearest the paper's (188, 532,
766, 1,156) chosen for each; the triangles drawn beyond the visible cells' own, the
culling microseconds and the pda model's frame rate at the triangles drawn.

Culling cost at scale: an open hall of ``k x k`` cells of 4 m (every wall between two
cells an open portal) looked across from a corner, so that about a hundred cells are
visible: cells-to-cells microseconds per frame against the visible cells, for the walk
and, timed alternately with it, the reference walk of
:mod:`~walkstream.benchmarks.portalwalk` (``before``); the tour's portal
culling is timed both ways too (``cull us`` and ``before``, cells and parts).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from walkstream.benchmarks.portalwalk import cull_portals_reference
from walkstream.client.draw.devices import make_device
from walkstream.client.draw.frames import FrameRenderer
from walkstream.client.truth.culled import check_kept
from walkstream.client.truth.render import TruthRenderer
from walkstream.server.bake import bake
from walkstream.server.service.interiors import InteriorState
from walkstream.server.sources.interiorgen import PRESETS, InteriorPlan, write_interior
from walkstream.server.store import SceneReader
from walkstream.shared.camera import camera, perspective
from walkstream.shared.codec.cellmesh import CellMesh
from walkstream.shared.codec.cellpieces import decode_cell_pieces
from walkstream.shared.cullkernels import warm_up as warm_up_culling
from walkstream.shared.errors import WalkstreamError
from walkstream.shared.partcull import cull_parts
from walkstream.shared.paths import RecordedPath
from walkstream.shared.portalgraph import PortalGraph
from walkstream.shared.portals import CULLING_MODES, cull_portals, frustum_cells
from walkstream.shared.roomview import cell_of, stack_planes
from walkstream.shared.roomwire import ContentsRef, PortalRef, RoomRecord, Topology, decode_topology

__all__ = [
    "TABLE1",
    "hall_topology",
    "portal_figures",
    "hall_figures",
    "portals_tables",
    "run_portals_bench",
    "replay_rows",
    "replay_table",
]

#: The paper's Table 1: visible cells, triangles, fps without fog, fps with fog.
TABLE1: tuple[tuple[int, int, float, float], ...] = (
    (1, 188, 56.4, 42.7), (2, 532, 35.8, 34.7), (3, 766, 22.6, 20.7), (4, 1156, 19.4, 18.6),
)


def _scene(preset: str, out: Path, log: Callable[[str], None]) -> Path:
    db = out / f"{preset}.db"
    if not db.exists():
        src = out / f"{preset}.json"
        write_interior(src, PRESETS[preset])
        log(f"bench portals: baking {preset}")
        bake(src, db)
    return db


def _load(db: Path) -> tuple[Topology, dict[int, CellMesh], RecordedPath]:
    with SceneReader.open(db) as r:
        state = InteriorState(r, list(r.cells()))
        topo = decode_topology(state.topology["msgpack"].content, f"{db}: topology")
        meshes = {c.id: decode_cell_pieces(r.contents(c.id), f"{db}: cell {c.id}") for c in topo.cells}
        tour = RecordedPath.from_msgpack(r.path_blob("tour"))
    return topo, meshes, tour


def _stats(x: Sequence[float]) -> dict[str, float]:
    a = np.asarray(x, np.float64)
    if len(a) == 0:
        return {"mean": 0.0, "median": 0.0, "p95": 0.0, "max": 0.0}
    return {"mean": float(a.mean()), "median": float(np.median(a)), "p95": float(np.percentile(a, 95)), "max": float(a.max())}


def portal_figures(
    db: Path,
    *,
    frames: int = 200,
    step_s: float = 1.0,
    size: tuple[int, int] = (640, 480),
    truth_frames: int = 0,
    gl: bool = True,
    fog_m: float = 40.0,
    log: Callable[[str], None] = lambda s: None,
) -> dict[str, Any]:
    """Cull the frames of ``db``'s tour three ways and measure them (module docstring)."""
    topo, meshes, tour = _load(db)
    graph = PortalGraph.from_topology(topo)
    inside = [c for c in topo.cells if c.kind != "outside" and len(c.planes)]
    ids, planes = stack_planes(inside)
    boxes = {
        cid: (np.array([p.bbox[0] for p in m.parts]).reshape(-1, 3), np.array([p.bbox[1] for p in m.parts]).reshape(-1, 3))
        for cid, m in meshes.items()
    }
    tris = {cid: np.array([p.triangles for p in m.parts], np.int64) for cid, m in meshes.items()}
    proj = perspective(60.0, size[0] / size[1], 0.1, 100.0).astype(np.float64)
    pda = make_device("pda", noise=False)
    renderer = FrameRenderer(size=size, fov_deg=60.0, near=0.1, far=100.0) if gl else None
    # one context for both: a second one made current would leave the renderer's objects invalid
    truth = (TruthRenderer(size=(160, 120), rooms=meshes, near=0.1, far=100.0, two_sided=True,
                           ctx=None if renderer is None else renderer.ctx) if truth_frames else None)
    try:
        if renderer is not None:
            for cid, m in meshes.items():
                for k, part in enumerate(m.parts):
                    if part.triangles:
                        renderer.upload((cid, k), part.mesh())
        ts = np.arange(0.0, tour.duration, step_s)[:frames]
        per: dict[str, dict[str, list[float]]] = {
            m: {"cells": [], "tris": [], "cull_us": [], "cull_before_us": [], "gl_ms": [], "gl_fog_ms": [], "pda_ms": [],
                "parts": []}
            for m in CULLING_MODES
        }
        tight: dict[str, list[float]] = {"portals": [], "frustum": []}
        missed = 0
        table1: list[dict[str, Any]] = []
        current: int | None = None
        for i, t in enumerate(ts.tolist()):
            xyz, yaw, pitch = tour.at(t)
            eye = np.asarray(xyz, np.float64)
            hit = np.flatnonzero(cell_of(planes, eye))
            if len(hit):
                current = int(ids[hit[0]]) if current not in {int(ids[h]) for h in hit} else current
            if current is None:
                continue
            view = camera(eye, float(yaw), float(pitch)).astype(np.float64)
            kept_by: dict[str, dict[int, NDArray[np.bool_]]] = {}
            for mode in CULLING_MODES:
                t0 = time.perf_counter()
                if mode == "portals":
                    pc = cull_portals(graph, current, eye, view, proj, size)
                    cells = pc.order
                    keep = cull_parts(mode, cells, boxes, eye, view, proj, size, vsas=pc.vsas)
                elif mode == "frustum":
                    cells = frustum_cells(graph, current, eye, proj @ view)
                    keep = cull_parts(mode, cells, boxes, eye, view, proj, size)
                else:
                    cells = list(meshes)
                    keep = {c: np.ones(len(tris[c]), bool) for c in cells}
                dt = time.perf_counter() - t0
                if mode == "portals":
                    t1 = time.perf_counter()
                    ref = cull_portals_reference(graph, current, eye, view, proj, size)
                    cull_parts(mode, ref.order, boxes, eye, view, proj, size, vsas=ref.vsas)
                    per[mode]["cull_before_us"].append((time.perf_counter() - t1) * 1e6)
                kept_by[mode] = keep
                n = int(sum(int(tris[c][m].sum()) for c, m in keep.items()))
                parts = int(sum(int(m.sum()) for m in keep.values()))
                rec = per[mode]
                rec["cells"].append(len(cells))
                rec["tris"].append(n)
                rec["parts"].append(parts)
                rec["cull_us"].append(dt * 1e6)
                rec["pda_ms"].append(1e3 * float(pda.frame_time(n, parts)))
                if renderer is not None:
                    keys = [(c, k) for c, m in keep.items() for k in np.flatnonzero(m).tolist()]
                    rec["gl_ms"].append(1e3 * renderer.draw(keys, view, proj))
                    if mode == "portals":
                        # the same frame with fog fading on (the fragment's distance, a smoothstep, a mix)
                        renderer.fog_m = fog_m
                        rec["gl_fog_ms"].append(1e3 * renderer.draw(keys, view, proj))
                        renderer.fog_m = 0.0
                if mode == "portals" and 1 <= len(cells) <= 4:
                    own = int(sum(int(tris[c].sum()) for c in cells))
                    table1.append({"t": t, "cells": len(cells), "cell_triangles": own, "drawn": n,
                                   "cull_us": dt * 1e6, "pda_fps": 1.0 / float(pda.frame_time(n, parts))})
            if truth is not None and i < truth_frames:
                for mode in ("portals", "frustum"):
                    kept = [(c, k) for c, m in kept_by[mode].items() for k in np.flatnonzero(m).tolist()]
                    chk = check_kept(truth, kept, eye, view)
                    if mode == "portals":
                        missed += chk.missed_pixels - chk.pinholes
                    if chk.visible_triangles:
                        tight[mode].append(per[mode]["tris"][-1] / chk.visible_triangles)
            if i % 50 == 0:
                log(f"bench portals: {db.stem} frame {i}/{len(ts)}")
    finally:
        if truth is not None:
            truth.release()
        if renderer is not None:
            renderer.release()
    picked = []
    for k, want, fps, fps_fog in TABLE1:
        cand = [r for r in table1 if r["cells"] == k]
        if cand:
            best = min(cand, key=lambda r: abs(r["cell_triangles"] - want))
            picked.append({**best, "paper_triangles": want, "paper_fps": fps, "paper_fps_fog": fps_fog})
    return {
        "scene": db.stem,
        "cells": len(inside),
        "portals": len(topo.portals),
        "triangles": int(sum(int(t.sum()) for t in tris.values())),
        "frames": len(per["portals"]["tris"]),
        "modes": {m: {k: _stats(v) for k, v in rec.items()} for m, rec in per.items()},
        "tightness": {m: _stats(v) for m, v in tight.items()},
        "truth_frames": len(tight["portals"]),
        "missed_pixels": missed,
        "table1": picked,
    }


def hall_topology(k: int, cell_m: float = 4.0, height: float = 3.0) -> Topology:
    """An open hall of ``k x k`` square cells, every shared wall an open portal (no contents)."""
    cells = []
    refs: dict[int, list[PortalRef]] = {i: [] for i in range(k * k)}
    pid = 0
    for y in range(k):
        for x in range(k):
            i = y * k + x
            x0, y0 = x * cell_m, y * cell_m
            if x + 1 < k:
                poly = np.array([[x0 + cell_m, y0, 0], [x0 + cell_m, y0 + cell_m, 0], [x0 + cell_m, y0 + cell_m, height], [x0 + cell_m, y0, height]])
                refs[i].append(PortalRef(pid, "opening", poly, i + 1))
                refs[i + 1].append(PortalRef(pid, "opening", poly, i))
                pid += 1
            if y + 1 < k:
                poly = np.array([[x0, y0 + cell_m, 0], [x0 + cell_m, y0 + cell_m, 0], [x0 + cell_m, y0 + cell_m, height], [x0, y0 + cell_m, height]])
                refs[i].append(PortalRef(pid, "opening", poly, i + k))
                refs[i + k].append(PortalRef(pid, "opening", poly, i))
                pid += 1
    for y in range(k):
        for x in range(k):
            i = y * k + x
            x0, y0, x1, y1 = x * cell_m, y * cell_m, (x + 1) * cell_m, (y + 1) * cell_m
            planes = np.array([[-1, 0, 0, x0], [1, 0, 0, -x1], [0, -1, 0, y0], [0, 1, 0, -y1], [0, 0, -1, 0], [0, 0, 1, -height]], float)
            cells.append(RoomRecord(
                id=i, kind="room", name=f"hall {x},{y}", room=None, storey=0,
                outline=np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], float), zmin=0.0, zmax=height,
                planes=planes, portals=tuple(refs[i]), neighbours=tuple(sorted({r.cell for r in refs[i]})),
                contents=ContentsRef(0, 0, 0, 0, 0, 0.0),
            ))
    return Topology((), tuple(cells), (), ())


def hall_figures(sizes: Sequence[int] = (4, 8, 12, 16, 24), repeats: int = 100,
                 size: tuple[int, int] = (640, 480)) -> list[dict[str, Any]]:
    """Cells-to-cells culling microseconds in open halls looked across from a corner:
    the walk (``us_*``) and the reference walk's (``before_us_*``, :mod:`~walkstream.benchmarks.portalwalk`)
    timed alternately, frame by frame, so that both see the same load."""
    proj = perspective(60.0, size[0] / size[1], 0.1, 1000.0).astype(np.float64)
    rows = []
    for k in sizes:
        graph = PortalGraph.from_topology(hall_topology(k))
        eye = np.array([0.5, 0.5, 1.6])
        view = camera(eye, math.pi / 4, 0.0).astype(np.float64)
        us: list[float] = []
        before: list[float] = []
        pc = None
        for _ in range(repeats):
            t0 = time.perf_counter()
            pc = cull_portals(graph, 0, eye, view, proj, size)
            t1 = time.perf_counter()
            ref = cull_portals_reference(graph, 0, eye, view, proj, size)
            before.append((time.perf_counter() - t1) * 1e6)
            us.append((t1 - t0) * 1e6)
            if ref.order != pc.order or ref.vsas != pc.vsas:
                raise WalkstreamError(f"hall {k}x{k}: the walk and the reference walk disagree")
        assert pc is not None
        rows.append({"hall": f"{k}x{k}", "cells": k * k, "visible": len(pc.order), "tested": pc.tested,
                     "us_median": float(np.median(us)), "us_p95": float(np.percentile(us, 95)),
                     "before_us_median": float(np.median(before)), "before_us_p95": float(np.percentile(before, 95))})
    return rows


def _before(r: dict[str, Any]) -> str:
    """The reference walk's culling microseconds (median) beside the walk's, portal culling only."""
    b = r.get("cull_before_us", {}).get("median", 0.0)
    return f"{b:,.0f}" if b else "-"


def portals_tables(scenes: Sequence[dict[str, Any]], halls: Sequence[dict[str, Any]]) -> str:
    """The benchmark's tables as text."""
    out = []
    out.append(f"{'scene':<9}{'cells':>6}{'mode':>9}{'vis cells':>10}{'tris mean':>10}{'tris p95':>9}"
               f"{'cull us med':>12}{'p95':>7}{'before':>8}{'gl ms med':>10}{'pda ms med':>11}")
    for s in scenes:
        for m in CULLING_MODES:
            r = s["modes"][m]
            out.append(
                f"{s['scene']:<9}{s['cells']:>6}{m:>9}{r['cells']['mean']:>10.1f}{r['tris']['mean']:>10,.0f}"
                f"{r['tris']['p95']:>9,.0f}{r['cull_us']['median']:>12,.0f}{r['cull_us']['p95']:>7,.0f}"
                f"{_before(r):>8}"
                f"{r['gl_ms']['median']:>10.2f}{r['pda_ms']['median']:>11.1f}"
            )
    for s in scenes:
        if s["truth_frames"]:
            tp, tf = s["tightness"]["portals"], s["tightness"]["frustum"]
            out.append(
                f"tightness {s['scene']} ({s['truth_frames']} frames, drawn / truly visible triangles): portals mean "
                f"{tp['mean']:.2f} p95 {tp['p95']:.2f}; frustum alone mean {tf['mean']:.2f} p95 {tf['p95']:.2f}; "
                f"missed pixels {s['missed_pixels']}"
            )
    for s in scenes:
        r = s["modes"]["portals"]
        if r["gl_fog_ms"]["median"]:
            out.append(f"fog fading on gl, {s['scene']}, portal culling's frames: {r['gl_ms']['median']:.2f} ms without, "
                       f"{r['gl_fog_ms']['median']:.2f} ms with (medians, drawn back to back)")
    for s in scenes[:1]:
        out.append(f"Table 1 scenes ({s['scene']}): cells, triangles of the visible cells (paper), drawn, culling us, pda fps (paper)")
        for r in s["table1"]:
            out.append(
                f"  {r['cells']} cells  {r['cell_triangles']:>6,} ({r['paper_triangles']:,})  drawn {r['drawn']:>6,}"
                f"  {r['cull_us']:>6,.0f} us  {r['pda_fps']:>5.1f} fps ({r['paper_fps']})"
            )
    out.append("open hall, cells-to-cells culling (median of the frames; before = the reference walk, timed alternately):")
    out.append(f"  {'hall':>6} {'cells':>5} {'visible':>7} {'tests':>6} {'before us':>10} {'us':>7} {'speed-up':>8}"
               f" {'before p95':>10} {'p95':>7}")
    for h in halls:
        out.append(f"  {h['hall']:>6} {h['cells']:>5} {h['visible']:>7} {h['tested']:>6} {h['before_us_median']:>10,.0f}"
                   f" {h['us_median']:>7,.0f} {h['before_us_median'] / h['us_median']:>7.1f}x"
                   f" {h['before_us_p95']:>10,.0f} {h['us_p95']:>7,.0f}")
    return "\n".join(out)


def run_portals_bench(out: Path, presets: Sequence[str], *, frames: int, step_s: float, truth_frames: int,
                      gl: bool, log: Callable[[str], None]) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """Bake (once) and measure every preset, then the halls."""
    out.mkdir(parents=True, exist_ok=True)
    warm_up_culling()  # the compiled kernels loaded before the first timed frame
    scenes = []
    for k, p in enumerate(presets):
        db = _scene(p, out, log)
        scenes.append(portal_figures(db, frames=frames, step_s=step_s, truth_frames=truth_frames if k == 0 else 0,
                                     gl=gl, log=log))
    return scenes, hall_figures()


def replay_rows(db: Path, replay: Callable[[str, dict[str, Any], str], Any], out: Path,
                duration: str = "180s", step_at: float = 60.0) -> list[dict[str, Any]]:
    """Replays of ``db``'s tour (simulated clock): the walk at 56 kbit/s / 200 ms with the
    default cache (and without the first view's contents in the start bundle, and with
    the whole path before them, as before) and with a cache smaller than the building (and the same three with one
    contents request per cell, as before the batches), each with the default
    (``crowded``) and the paper's flush policy, and on the pda model at
    25 fps with the fog set by the budget controller (and kept fixed, to compare)
    through a tenfold per-triangle cost step at ``step_at`` seconds."""
    link = {"bandwidth": "56kbit", "rtt": "200ms", "duration": duration, "path": "tour", "kind": "interior"}
    cases: list[tuple[str, dict[str, Any]]] = [
        ("56 kbit/s, default cache", dict(link)),
        # before the first view's contents came in the start bundle (the same sitting)
        ("56 kbit/s, default cache, no 1st view", {**link, "no_start_contents": True}),
        # before the path's head came first and the whole path after the contents
        ("56 kbit/s, whole path in bundle", {**link, "path_head": 0.0}),
        ("56 kbit/s, cache 400 kB", {**link, "cache": "400kB"}),
        ("56 kbit/s, cache 600 kB", {**link, "cache": "600kB"}),
        # before the contents batch: one request per cell (the same sitting, to compare)
        ("56 kbit/s, default cache, 1 cell/req", {**link, "contents_batch": "0"}),
        ("56 kbit/s, cache 400 kB, 1 cell/req", {**link, "cache": "400kB", "contents_batch": "0"}),
        ("56 kbit/s, cache 600 kB, 1 cell/req", {**link, "cache": "600kB", "contents_batch": "0"}),
        ("56 kbit/s, paper flush (30 s)", {**link, "flush_policy": "paper"}),
        ("56 kbit/s, cache 400 kB, paper flush", {**link, "cache": "400kB", "flush_policy": "paper"}),
        ("pda 25 fps, fog by budget, cost x10", {**link, "device": "pda", "fps": 25.0, "cost_step_at_s": step_at}),
        ("pda 25 fps, fixed fog, cost x10", {**link, "device": "pda", "fps": 25.0, "cost_step_at_s": step_at,
                                              "no_fog_budget": True}),
    ]
    rows = []
    for k, (name, options) in enumerate(cases, 1):
        options["report"] = str(out / f"replay-{k:02d}")
        s = replay(str(db), options, f"bench portals: {name}").summary
        rows.append({"case": name, **{key: s.get(key) for key in (
            "perfect_frame_ratio", "time_to_first_perfect_frame_s", "redownloads", "cells_flushed", "fps_mean",
            "fps_within_10pct_ratio", "recovery_frames", "fog_m_median", "fog_m_min", "fog_tightened_frames",
            "culling_ms_median", "visible_cells_mean", "triangles_mean", "topology_bytes", "contents_bytes",
            "contents_requests", "bytes_received", "start_contents_cells")}})
    return rows


WHOLE_TOUR = "whole"
"""The ``--seed-duration`` that replays each tour to its end."""


def seed_rows(seeds: Sequence[int], replay: Callable[[str, dict[str, Any], str], Any], out: Path,
              duration: str = "30s", storeys: int = 3, log: Callable[[str], None] = lambda s: None,
              truth_every: int = 50) -> list[dict[str, Any]]:
    """Generated offices of ``seeds`` (``walkstream generate interior --storeys 3 --seed S``),
    each baked and its tour replayed for ``duration`` (``"whole"``: to the tour's end) as
    the issue measures a tour: 56
    kbit/s, 200 ms, simulated clock, ``desktop2003``, every ``truth_every``-th frame
    against the truth at 160x120 (0: no truth, whose frames cost seconds each on
    llvmpipe: a whole tour's 600 take longer than its replay; the simulated clock walks
    the same frames either way).  A row per seed: perfect frames, first perfect frame, culled pixels,
    tightness p95, bytes, the culling's median milliseconds, the cells missing from a frame
    after the first perfect one (the replay's ``late_cells``: which and why in its report),
    ``walked_s``, the seconds the replay walked, and ``cpu_ms_per_frame``, this process's CPU
    time over the replay (the client, the in-process server, the report) per frame walked."""
    rows = []
    for seed in seeds:
        src, db = out / f"seed{seed}.json", out / f"seed{seed}.db"
        if not db.exists():
            write_interior(src, InteriorPlan(storeys=storeys, seed=seed))
            log(f"bench portals: baking seed {seed}")
            bake(src, db)
        options = {"bandwidth": "56kbit", "rtt": "200ms", "path": "tour", "kind": "interior",
                   "device": "desktop2003", "truth_every": truth_every, "size": "160x120",
                   "report": str(out / f"seed{seed}-replay")}
        if duration != WHOLE_TOUR:
            options["duration"] = duration
        cpu0 = time.process_time()
        s = replay(str(db), options, f"bench portals: seed {seed}").summary
        cpu = time.process_time() - cpu0
        truth = s.get("truth") or {}
        rows.append({"seed": seed, "duration": duration, **{key: s.get(key) for key in (
            "perfect_frame_ratio", "time_to_first_perfect_frame_s", "bytes_received", "start_contents_cells",
            "culling_ms_median")}, "culled_pixels": truth.get("culled_pixels"), "tightness_p95": truth.get("tightness_p95"),
            "truth_frames": truth.get("frames"), "late_cells": (s.get("late_cells") or {}).get("cells"),
            "walked_s": s.get("duration_s"),
            "cpu_ms_per_frame": 1e3 * cpu / s["frames"] if s.get("frames") else None})
    return rows


def _or_dash(v: Any, fmt: str) -> str:
    """``v`` formatted with ``fmt``, or ``-`` when it was not measured."""
    return "-" if v is None else format(v, fmt)


def seed_table(rows: Sequence[dict[str, Any]]) -> str:
    """The generated seeds' replays as text."""
    f = _or_dash
    out = [f"{'seed':>5}{'walked':>8}{'perfect%':>9}{'1st perf s':>11}{'culled px':>10}{'truth fr':>9}"
           f"{'tight p95':>10}{'kB down':>8}{'1st view':>9}{'cull ms':>8}{'late':>5}{'cpu ms/fr':>10}"]
    for r in rows:
        pf = r["perfect_frame_ratio"]
        walked = r["duration"] if r.get("walked_s") is None else f"{r['walked_s']:.0f}s"
        out.append(f"{r['seed']:>5}{walked:>8}{f(None if pf is None else 100 * pf, '.2f'):>9}"
                   f"{f(r['time_to_first_perfect_frame_s'], '.2f'):>11}{f(r['culled_pixels'], ',d'):>10}"
                   f"{f(r['truth_frames'], 'd'):>9}{f(r['tightness_p95'], '.2f'):>10}"
                   f"{f(None if r['bytes_received'] is None else r['bytes_received'] / 1000, '.1f'):>8}"
                   f"{f(r['start_contents_cells'], 'd'):>9}{f(r['culling_ms_median'], '.2f'):>8}"
                   f"{f(r.get('late_cells'), 'd'):>5}{f(r.get('cpu_ms_per_frame'), '.1f'):>10}")
    return "\n".join(out)


def replay_table(rows: Sequence[dict[str, Any]]) -> str:
    """The replays as text."""
    f = _or_dash
    out = [f"{'case':<38}{'perfect%':>9}{'1st perf s':>11}{'topo kB':>8}{'redl':>5}{'flushed':>8}{'reqs':>6}{'kB down':>8}"
           f"{'fps':>6}{'within10%':>10}{'recover':>8}{'fog med':>8}{'fog min':>8}{'tightened':>10}"]
    for r in rows:
        pf = r["perfect_frame_ratio"]
        w10 = r["fps_within_10pct_ratio"]
        out.append(
            f"{r['case']:<38}{f(None if pf is None else 100 * pf, '.2f'):>9}{f(r['time_to_first_perfect_frame_s'], '.2f'):>11}"
            f"{f(None if r.get('topology_bytes') is None else r['topology_bytes'] / 1e3, '.1f'):>8}"
            f"{f(r['redownloads'], 'd'):>5}{f(r['cells_flushed'], 'd'):>8}{f(r.get('contents_requests'), 'd'):>6}"
            f"{f(None if r.get('bytes_received') is None else r['bytes_received'] / 1e3, '.1f'):>8}{f(r['fps_mean'], '.1f'):>6}"
            f"{f(None if w10 is None else 100 * w10, '.1f'):>10}{f(r['recovery_frames'], ''):>8}"
            f"{f(r['fog_m_median'], '.1f'):>8}{f(r['fog_m_min'], '.1f'):>8}{f(r['fog_tightened_frames'], 'd'):>10}"
        )
    return "\n".join(out)
