"""What the visibility bake misses, against its price (``walkstream bench visibility``).

The bake samples each view cell from a few points (:mod:`walkstream.server.bake.samples`)
at one cube-face resolution.  This benchmark measures, on a sample of cells spread over
the scene, what every *setting* of that sampling misses and what it costs, side by
side in one run:

reference
    Per cell :func:`~walkstream.server.bake.samples.reference_points` (default 64)
    viewpoints spread over the whole cell and its height range, drawn at random
    independently of where the bake samples, rendered at 512 px per cube face with
    every object at LOD2 and *no* frustum culling (every object within the view
    distance drawn in every face).  An object is reference-visible when it covers a
    pixel.
settings
    Each setting (sampling scheme, spacing, resolution, occluder LOD, hardly-visible
    threshold; :func:`parse_setting`) computes the cells' PVS exactly as the bake does
    (:func:`~walkstream.server.bake.workers.cell_counts`: the points, then
    :meth:`~walkstream.server.bake.visibility.VisibilityRenderer.cell_counts` and
    :func:`~walkstream.server.bake.visibility.pvs_from_counts`).  The settings take
    turns cell by cell, so a slower machine moment hits them all alike; each renders
    a cell ``repeat`` times and keeps the fastest; a setting's time is the median
    over cells of those seconds and its ``time x`` the ratio to the first default
    (``corners-64``) measured in the same run.
misses by count
    Mean over cells of the share of reference-visible objects absent from the PVS.
misses by pixels
    Reference pixels of the missed objects over all reference pixels (pooled).
largest miss
    The largest share of one cell's reference pixels that a single missed object
    covers (the worst over the cells): "a building seen clearly from part of the cell
    and never downloaded there".
image error at random eye points
    ``views`` per sampled cell: a random eye in the cell (at a random eye height),
    random heading, level, the client's camera (640 x 480, 60 degrees); the ground
    truth of that camera (:class:`~walkstream.client.truth.render.TruthRenderer`:
    every object within the view distance at LOD2) compared with what the cell's
    PVS would show (:func:`~walkstream.client.truth.compare.compare_frame`, cause
    ``pvs``): the share of the truth's object pixels showing an object missing from
    the PVS, the share of the objects it shows that are missing, and the sizes of
    the missed objects (share of the frame); and the share of views whose missing
    pixels exceed 0.01 % of the frame (``view_over_hundredth``, the per-frame figure
    at random eye points) and their mean.  ``view_need``: the per-frame figure's floor
    at those eye points (:func:`view_need`), against ``corners-64``'s PVS.

least PVS
    The floor the PVS bound meets (:func:`least_pvs`): per cell, the reference-visible
    objects less the least-seen ones that both miss targets allow leaving out.  When it
    is over the PVS target, no sampling can meet the miss targets and the PVS target
    together on these cells.

When the scene is a baked database, its stored PVS is scored too (row ``baked``).
The scene and the sample of cells come from :mod:`walkstream.benchmarks.visinput`, the
settings and targets from :mod:`walkstream.benchmarks.vissettings`, the reference's
cache from :mod:`walkstream.benchmarks.visref`; the table and the plot are drawn by
:mod:`walkstream.benchmarks.visreport`.
"""

from __future__ import annotations

import math
import os
import statistics
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import shapely
from numpy.typing import NDArray

from walkstream.benchmarks.pvsmisses import OVER_SHARE, frame_need
from walkstream.benchmarks.visinput import BenchInput, pick_cells
from walkstream.benchmarks.visref import reference_cache_key, scene_digest
from walkstream.benchmarks.vissettings import (
    DEFAULT_SETTINGS,
    PREVIOUS,
    TARGETS,
    TODAY,
    Setting,
    bake_default,
    parse_setting,
    same_sampling,
)
from walkstream.server.bake.field import FieldLattice
from walkstream.server.bake.fieldsampling import cell_field_counts, sampling_lattice
from walkstream.server.bake.idpack import meshes_for_scene
from walkstream.server.bake.samples import reference_points
from walkstream.server.bake.settings import BakeSettings
from walkstream.server.bake.viewcell import ViewCell
from walkstream.server.bake.visibility import VisibilityRenderer, pvs_from_counts
from walkstream.server.bake.workers import cell_counts
from walkstream.server.sources.scene import SourceScene
from walkstream.shared.errors import InputError

if TYPE_CHECKING:
    import moderngl

__all__ = ["VIEW_MARGIN", "least_pvs", "view_need", "visibility_benchmark"]

Progress = Callable[[int, int], None]

#: Eye points of the image error keep this far from walls and the cell's border: the
#: client's camera has a 0.5 m near plane whose corners reach 0.7 m, and window sills
#: stand out 0.3 m, so a camera closer to a facade looks through it.
VIEW_MARGIN = 1.0



def _score(pvs: list[set[int]], ref: list[dict[int, int]]) -> dict[str, Any]:
    """Misses of one setting's PVS (per cell) against the reference (per cell)."""
    count, missed_px, total_px, worst, where = [], 0, 0, 0.0, None
    shares: list[float] = []
    for k, (p, r) in enumerate(zip(pvs, ref, strict=True)):
        if not r:
            continue
        tot = sum(r.values())
        missed = [j for j in r if j not in p]
        shares += [r[j] / tot for j in missed]
        count.append(len(missed) / len(r))
        missed_px += sum(r[j] for j in missed)
        total_px += tot
        for j in missed:
            if r[j] / tot > worst:
                worst, where = r[j] / tot, (k, j)
    return {
        "miss_count": float(np.mean(count)) if count else 0.0,
        "missed": len(shares),
        "miss_px": missed_px / total_px if total_px else 0.0,
        "miss_max": worst,
        "miss_max_at": where,
        "missed_ref_shares": shares,
        "pvs_mean": float(np.mean([len(p) for p in pvs])) if pvs else 0.0,
        "extra_per_cell": float(np.mean([len(p - r.keys()) for p, r in zip(pvs, ref, strict=True)])),
    }


def least_pvs(ref: list[dict[int, int]], miss_px: float, miss_max: float) -> list[set[int]]:
    """The smallest PVS per cell that still meets the miss targets against the reference.

    Leaving objects out of a cell's PVS costs their reference pixels.  The targets allow
    ``miss_px`` of all the cells' reference pixels (pooled, as :func:`_score` counts them)
    and no single object above ``miss_max`` of its own cell's pixels, so the most objects
    that can be left out are the fewest pixels first: the objects under ``miss_max``,
    taken over all cells in ascending order of pixels while their sum stays within the
    budget.  No sampling, however placed, can meet both targets with a smaller mean PVS
    against this reference: it is the floor the PVS bound (``pvs_ratio``) meets.
    """
    total = sum(sum(r.values()) for r in ref)
    budget = miss_px * total
    cands = sorted(
        (px, k, j) for k, r in enumerate(ref) for j, px in r.items()
        if r and px <= miss_max * sum(r.values())
    )
    out = [set(r) for r in ref]
    spent = 0
    for px, k, j in cands:
        if spent + px > budget:
            break
        spent += px
        out[k].discard(j)
    return out


def view_need(
    views: list[tuple[int, NDArray[np.uint32], NDArray[np.uint8]]], cells: int
) -> tuple[list[set[int]], list[set[int]]]:
    """Per cell, what its PVS must hold to keep every view of it within :data:`OVER_SHARE`.

    Returns ``(need, must)``.  ``must``: the objects that alone cover more than
    :data:`OVER_SHARE` of some view, a floor no PVS that keeps every view within the
    share goes under.  ``need``: at each view the objects it shows less its least-seen
    ones while they stay within the share together, their union per cell, an estimate
    of the whole need (each view choosing alone: a PVS chosen for all of a cell's views
    at once could hold a little less).  More views only add to both.
    """
    need: list[set[int]] = [set() for _ in range(cells)]
    must: list[set[int]] = [set() for _ in range(cells)]
    for k, ids, _ in views:
        tid = ids.astype(np.int64).reshape(-1) - 1
        n_ids, m_ids = frame_need(*np.unique(tid[tid >= 0], return_counts=True), float(tid.size))
        need[k].update(n_ids.tolist())
        must[k].update(m_ids.tolist())
    return need, must


def _view_error(views: list[tuple[int, NDArray[np.uint32], NDArray[np.uint8]]], pvs: list[set[int]]) -> dict[str, Any]:
    """The image error of one setting's PVS at the random eye points (see the module docs)."""
    from walkstream.client.truth.compare import compare_frame

    obj_px, miss_px, counts, frame_share, sizes = 0, 0, [], [], []
    for k, ids, rgb in views:
        p = np.fromiter(pvs[k], np.int64, len(pvs[k]))
        tid = ids.astype(np.int64) - 1
        shows = np.where(np.isin(tid, p), ids, 0).astype(np.uint32)
        err = compare_frame(ids, rgb, shows, rgb, pvs=p, received=p, built=p, drawn={int(i): 2 for i in p})
        per = np.bincount(tid[tid >= 0])
        seen = np.flatnonzero(per)
        missed = seen[~np.isin(seen, p)]
        obj_px += int(per.sum())
        miss_px += int(err.missing[0])
        counts.append(len(missed) / len(seen) if len(seen) else 0.0)
        frame_share.append(err.missing[0] / err.pixels)
        sizes += (per[missed] / err.pixels).tolist()
    fs = np.array(frame_share) if frame_share else np.zeros(1)
    return {
        "view_over_hundredth": float(np.mean(fs > OVER_SHARE)),
        "view_frame_mean": float(fs.mean()),
        "view_miss_px": miss_px / obj_px if obj_px else 0.0,
        "view_miss_count": float(np.mean(counts)) if counts else 0.0,
        "view_frame_p95": float(np.percentile(fs, 95)),
        "view_frame_max": float(fs.max()),
        "view_over_half": float(np.mean(fs > 0.005)),
        "missed_sizes": sizes,
    }


def visibility_benchmark(
    inp: BenchInput,
    *,
    settings: Sequence[str | Setting] = DEFAULT_SETTINGS,
    sample: int = 12,
    seed: int = 0,
    ref_points: int = 64,
    ref_resolution: int = 512,
    views: int = 4,
    view_size: tuple[int, int] = (640, 480),
    repeat: int = 3,
    ctx: moderngl.Context | None = None,
    progress: Progress | None = None,
    cache: str | os.PathLike[str] | None = None,
) -> dict[str, Any]:
    """Misses against the dense reference, image error at random eye points, and time, per setting.

    Parameters
    ----------
    inp:
        The scene (:func:`load_bench_input`).
    settings:
        Names (:func:`parse_setting`) or settings; ``corners-64`` (the yardstick of the
        ratios) is added first when missing.
    sample, seed:
        How many cells (:func:`pick_cells`) and the seed of everything random.
    ref_points, ref_resolution:
        Reference viewpoints per cell and their cube-face resolution.
    views, view_size:
        Random eye points per cell and the frame size for the image error (0: none);
        the eyes keep :data:`VIEW_MARGIN` from walls and the cell's border.
    repeat:
        Each setting renders each cell this many times and keeps the fastest (other
        work on the machine only ever slows a render down).
    ctx:
        OpenGL context for every renderer; by default one is made and released.
    progress:
        Called with ``(cells done, cells total)``: the reference, then the settings,
        then the views, each a pass over the cells.
    cache:
        Folder of reference counts kept between runs
        (:func:`~walkstream.benchmarks.visref.reference_cache_key`:
        the scene's LOD2 meshes, the cell, the points and the resolution decide it);
        None: none kept.  The reference is by far the slowest part of a run.

    Returns
    -------
    dict
        ``rows`` (one dict per setting, then ``baked`` for a database: the figures of
        the module docs, ``sec_per_cell``, ``time_ratio``, ``pvs_ratio``,
        ``points_per_cell``, ``culled`` = 1 - PVS / objects, ``meets`` per target),
        ``reference`` (points, resolution, PVS and pixels per cell, seconds), ``cells``,
        ``default`` (the name of the row that matches the bake's default, or None),
        ``objects``, ``seconds``.
    """
    from walkstream.shared.gl import create_context

    t_start = time.perf_counter()
    rows_in = [s if isinstance(s, Setting) else parse_setting(s) for s in settings]
    if not any(same_sampling(s.bake, TODAY.bake) for s in rows_in):
        rows_in.insert(0, TODAY)
    dflt = bake_default()
    if not any(same_sampling(s.bake, dflt.bake) for s in rows_in):
        rows_in.insert(1, dflt)
    if int(ref_points) < 1 or int(ref_resolution) < 8 or int(views) < 0:
        raise InputError(
            f"visibility_benchmark: expected ref_points >= 1, ref_resolution >= 8, views >= 0, got "
            f"{ref_points}, {ref_resolution}, {views}"
        )
    scene, vd = inp.scene, inp.view_distance
    chosen = pick_cells(inp.cells, sample, seed=seed)
    footprints = shapely.STRtree([shapely.Polygon(b.rings[0], b.rings[1:]) for b in scene.buildings])
    total = len(chosen) * (3 if views else 2)
    done = 0

    def tick() -> None:
        nonlocal done
        done += 1
        if progress is not None:
            progress(done, total)

    if progress is not None:
        progress(0, total)
    own = ctx is None
    gl = create_context() if ctx is None else ctx
    renderers: dict[tuple[int, int, bool, float, bool], VisibilityRenderer] = {}
    try:
        meshes2, ids2 = meshes_for_scene(scene, 2)
        # -- the reference ---------------------------------------------------------
        ref_r: VisibilityRenderer | None = None
        ref: list[dict[int, int]] = []
        ref_times, ref_pts, ref_cached = [], [], 0
        scene_key = scene_digest(meshes2, ids2) if cache is not None else ""
        try:
            for c in chosen:
                pts = reference_points(c.polygon, c.zmin, c.zmax, int(ref_points), footprints=footprints, seed=seed * 7919 + 100_003 + c.id)
                ref_pts.append(len(pts))
                file = None
                if cache is not None:
                    file = Path(cache) / f"{reference_cache_key(scene_key, pts, int(ref_resolution), vd)}.npz"
                    if file.is_file():
                        with np.load(file) as z:
                            i, px, sec = z["ids"], z["pixels"], float(z["seconds"])
                        ref_cached += 1
                        ref_times.append(sec)
                        ref.append({int(a): int(b) for a, b in zip(i, px, strict=True)})
                        tick()
                        continue
                if ref_r is None:
                    ref_r = VisibilityRenderer(meshes2, ids2, resolution=int(ref_resolution), view_distance=vd, ctx=gl, frustum_cull=False)
                t = time.perf_counter()
                i, px = ref_r.cell_counts(pts)
                ref_times.append(time.perf_counter() - t)
                if file is not None:
                    file.parent.mkdir(parents=True, exist_ok=True)
                    tmp = file.with_suffix(".tmp.npz")
                    np.savez(tmp, ids=i, pixels=px, seconds=ref_times[-1])
                    os.replace(tmp, file)  # a run stopped halfway leaves no half-written entry
                ref.append({int(a): int(b) for a, b in zip(i, px, strict=True)})
                tick()
        finally:
            if ref_r is not None:
                ref_r.release()
        # -- the settings, taking turns cell by cell --------------------------------
        for s in rows_in:
            key = (s.bake.occluder_lod, s.bake.resolution, s.bake.edge_pass, s.bake.thin_pass, s.bake.thin_depth)
            if key not in renderers:
                m, ids = (meshes2, ids2) if key[0] == 2 else meshes_for_scene(scene, key[0])
                renderers[key] = VisibilityRenderer(m, ids, resolution=key[1], view_distance=vd, ctx=gl, edge_pass=key[2], thin_pass=key[3], thin_depth=key[4])
                renderers[key].cell_counts(np.array([[0.0, 0.0, 1.7]]))  # compile, warm up
        # the field settings: the lattice of the whole scene's cells, as the bake lays it
        lattices: dict[str, FieldLattice] = {}
        for s in rows_in:
            if s.bake.sampling == "field":
                lattices[s.name] = sampling_lattice(inp.cells, list(footprints.geometries), s.bake.field_spacing,
                                                    margin=s.bake.margin)
        pvs: list[list[set[int]]] = [[] for _ in rows_in]
        times: list[list[float]] = [[] for _ in rows_in]
        npts: list[list[int]] = [[] for _ in rows_in]
        for c in chosen:
            for k, s in enumerate(rows_in):
                r = renderers[(s.bake.occluder_lod, s.bake.resolution, s.bake.edge_pass, s.bake.thin_pass, s.bake.thin_depth)]
                best = math.inf
                for _ in range(max(1, int(repeat))):
                    t = time.perf_counter()
                    if s.bake.sampling == "field":
                        ci, cp, n_pts = cell_field_counts(r, lattices[s.name], np.asarray(c.polygon))
                    else:
                        ci, cp, n_pts = cell_counts(r, s.bake, np.asarray(c.polygon), c.zmin, c.zmax, footprints)
                    got = pvs_from_counts(ci, cp, threshold=s.bake.threshold)[0]
                    best = min(best, time.perf_counter() - t)
                times[k].append(best)
                npts[k].append(n_pts)
                pvs[k].append({int(i) for i in got})
            tick()
        # -- the image error at random eye points ----------------------------------
        shots = _views(scene, chosen, int(views), view_size, vd, footprints, seed, gl, tick) if views else []
    finally:
        for r in renderers.values():
            r.release()
        if own:
            gl.release()

    n_obj = len(scene.buildings) + len(scene.streets) + len(scene.areas)
    rows: list[dict[str, Any]] = []
    for k, s in enumerate(rows_in):
        sec = float(statistics.median(times[k]))
        rows.append(
            {"name": s.name, "sampling": s.bake.sampling, "spacing": s.bake.spacing if s.bake.sampling != "corners" else None,
             "resolution": s.bake.resolution, "lod": s.bake.occluder_lod, "threshold": s.bake.threshold,
             "centre": s.bake.centre, "points_per_cell": float(np.mean(npts[k])), "sec_per_cell": sec}
            | ({"field_spacing": s.bake.field_spacing, "field_points": len(lattices[s.name]),
                "field_points_per_cell": len(lattices[s.name]) / len(inp.cells)} if s.name in lattices else {})
            | _score(pvs[k], ref)
            | (_view_error(shots, pvs[k]) if shots else {})
        )
    floor = least_pvs(ref, TARGETS["miss_px"], TARGETS["miss_max"])
    rows.append({"name": "least PVS", "sec_per_cell": None} | _score(floor, ref) | (_view_error(shots, floor) if shots else {}))
    need, must = view_need(shots, len(chosen)) if shots else (None, None)
    if inp.baked is not None:
        stored = [{int(i) for i in inp.baked.get(c.id, np.zeros(0, np.int64))} for c in chosen]
        rows.append({"name": "baked", "sec_per_cell": None} | _score(stored, ref) | (_view_error(shots, stored) if shots else {}))
    base = rows[next(k for k, s in enumerate(rows_in) if same_sampling(s.bake, TODAY.bake))]
    base_d = rows[next(k for k, s in enumerate(rows_in) if same_sampling(s.bake, dflt.bake))]
    prev = next((rows[k] for k, s in enumerate(rows_in) if same_sampling(s.bake, PREVIOUS.bake)), None)
    for row in rows:
        sec = row["sec_per_cell"]
        row["time_ratio"] = sec / base["sec_per_cell"] if sec else None
        row["time_ratio_default"] = sec / base_d["sec_per_cell"] if sec else None
        if row.get("field_points_per_cell") and row.get("points_per_cell"):
            # the bake renders a field point once for every cell its square meets
            row["bake_sec_per_cell"] = sec * row["field_points_per_cell"] / row["points_per_cell"]
            row["bake_time_ratio_default"] = row["bake_sec_per_cell"] / base_d["sec_per_cell"]
        row["pvs_ratio"] = row["pvs_mean"] / base["pvs_mean"] if base["pvs_mean"] else None
        row["time_ratio_previous"] = sec / prev["sec_per_cell"] if sec and prev else None
        row["pvs_ratio_previous"] = row["pvs_mean"] / prev["pvs_mean"] if prev and prev["pvs_mean"] else None
        row["culled"] = 1.0 - row["pvs_mean"] / n_obj if n_obj else None
        row["meets"] = {k: (row.get(k) is not None and row[k] <= v) for k, v in TARGETS.items()}
    default = next((s.name for s in rows_in if same_sampling(s.bake, BakeSettings())), None)
    return {
        "rows": rows,
        "default": default,
        "cells_total": len(inp.cells),
        "cells": [c.id for c in chosen],
        "objects": n_obj,
        "source": inp.source,
        "reference": {
            "points_per_cell": float(np.mean(ref_pts)),
            "resolution": int(ref_resolution),
            "lod": 2,
            "frustum_culling": False,
            "pvs_mean": float(np.mean([len(r) for r in ref])),
            "pixels_per_cell": float(np.mean([sum(r.values()) for r in ref])),
            "sec_per_cell": float(statistics.median(ref_times)),
            "cells_scored": sum(1 for r in ref if r),
            "cached": ref_cached,
        },
        "views": len(shots),
        "view_size": list(view_size),
        "view_need": None if need is None or must is None else {
            "pvs_mean": float(np.mean([len(n) for n in need])),
            "pvs_ratio": float(np.mean([len(n) for n in need])) / base["pvs_mean"] if base["pvs_mean"] else None,
            "must_mean": float(np.mean([len(n) for n in must])),
            "must_ratio": float(np.mean([len(n) for n in must])) / base["pvs_mean"] if base["pvs_mean"] else None,
        },
        "seconds": time.perf_counter() - t_start,
    }


def _views(
    scene: SourceScene,
    cells: list[ViewCell],
    per_cell: int,
    size: tuple[int, int],
    view_distance: float,
    footprints: shapely.STRtree,
    seed: int,
    gl: moderngl.Context,
    tick: Callable[[], None],
) -> list[tuple[int, NDArray[np.uint32], NDArray[np.uint8]]]:
    """Truth frames at random eye points: ``(cell index, ids, rgb)`` per view."""
    from walkstream.client.truth.render import TruthRenderer
    from walkstream.shared.camera import camera

    meshes, ids = meshes_for_scene(scene, 2)
    lo = np.array([m.positions[:, :2].min(axis=0) if len(m.positions) else (np.inf, np.inf) for m in meshes], np.float64).reshape(-1, 2)
    hi = np.array([m.positions[:, :2].max(axis=0) if len(m.positions) else (-np.inf, -np.inf) for m in meshes], np.float64).reshape(-1, 2)
    rng = np.random.default_rng([int(seed), 0xE7E])
    out = []
    for k, c in enumerate(cells):
        eyes = reference_points(
            c.polygon, c.zmin, c.zmax, per_cell, margin=VIEW_MARGIN, footprints=footprints,
            seed=seed * 7919 + 500_009 + c.id,
        )
        # one truth per cell, of the objects within the view distance of the cell's box:
        # a whole city at LOD2 (3 GB for the Vienna blocks) is more than one GL buffer holds
        poly = np.asarray(c.polygon, np.float64)
        gap = np.maximum(np.maximum(lo - poly.max(axis=0), poly.min(axis=0) - hi), 0.0)
        near = np.flatnonzero(np.einsum("nk,nk->n", gap, gap) <= view_distance**2)
        with TruthRenderer({int(ids[i]): meshes[i] for i in near}, size, view_distance=view_distance, ctx=gl) as tr:
            for eye in eyes:
                rgb, img = tr.colour_frame(eye, camera(eye, float(rng.uniform(0.0, 2.0 * math.pi))))
                out.append((k, img, rgb))
        tick()
    return out
