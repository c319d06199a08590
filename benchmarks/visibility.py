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
    the missed objects (share of the frame).

When the scene is a baked database, its stored PVS is scored too (row ``baked``).
The scene is read from the database itself (objects, cells, PVS, view distance),
so a database baked from any source works; a source file is read by the caller.
"""

from __future__ import annotations

import math
import os
import re
import statistics
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import shapely
from numpy.typing import NDArray

from walkstream.benchmarks.visref import reference_cache_key, scene_digest
from walkstream.server.bake.cells import make_cells
from walkstream.server.bake.samples import reference_points
from walkstream.server.bake.settings import BakeSettings
from walkstream.server.bake.viewcell import ViewCell
from walkstream.server.bake.visibility import VisibilityRenderer, meshes_for_scene, pvs_from_counts
from walkstream.server.bake.workers import cell_counts
from walkstream.server.sources.scene import SourceScene
from walkstream.shared.errors import InputError

if TYPE_CHECKING:
    import moderngl

from walkstream.shared.arrays import I64

__all__ = [
    "BenchInput",
    "Setting",
    "TODAY",
    "PREVIOUS",
    "DEFAULT_SETTINGS",
    "TARGETS",
    "format_table",
    "load_bench_input",
    "parse_setting",
    "pick_cells",
    "plot_visibility_benchmark",
    "scene_from_database",
    "visibility_benchmark",
]

Progress = Callable[[int, int], None]

#: Eye points of the image error keep this far from walls and the cell's border: the
#: client's camera has a 0.5 m near plane whose corners reach 0.7 m, and window sills
#: stand out 0.3 m, so a camera closer to a facade looks through it.
VIEW_MARGIN = 1.0

#: the issue's targets: misses by count, largest single miss, misses by pixels (shares),
#: bake time and PVS size as ratios to the first default
TARGETS = {
    "miss_count": 0.05,
    "miss_max": 0.0001,
    "miss_px": 0.0005,
    "time_ratio": 2.0,
    "pvs_ratio": 1.25,
}


# --------------------------------------------------------------------------- settings


@dataclass(frozen=True, slots=True)
class Setting:
    """A named way of baking a cell's PVS (only the sampling fields of ``bake`` matter)."""

    name: str
    bake: BakeSettings


_SPEC = re.compile(r"^(corners|(?:boundary|region)(\d+(?:\.\d+)?)?)-(\d+)((?:-[a-zA-Z]+\d*(?:\.\d+)?|\+[ce])*)$")


def parse_setting(spec: str) -> Setting:
    """A setting from its name: ``SAMPLING-RES[-tN][-LK][-hH][+c][+e]``.

    ``corners-64`` is the first bake (8 box corners, 64 px); ``boundary20-128`` samples
    the outline every 20 m at 128 px; ``region20-128`` the outline, a 20 m grid inside
    and both ends of the height range; ``-t2`` adds a hardly-visible threshold of 2
    pixels, ``-L2`` renders LOD2 occluders, ``-h0.25`` samples a height every 0.25 m
    of the cell's range, ``+c`` the centre too, ``+e`` the edge pass (objects thinner
    than a pixel).

    >>> s = parse_setting("boundary10-256-t4+c").bake
    >>> (s.sampling, s.spacing, s.resolution, s.threshold, s.centre, s.edge_pass)
    ('boundary', 10.0, 256, 4, True, False)
    >>> s = parse_setting("region20-128+e").bake
    >>> (s.sampling, s.spacing, s.edge_pass)
    ('region', 20.0, True)
    """
    m = _SPEC.match(spec.strip())
    if m is None:
        raise InputError(
            f"setting {spec!r}: expected SAMPLING-RES[-tN][-LK][-hH][+c], e.g. corners-64, "
            "boundary20-128-t2"
        )
    kw: dict[str, Any] = {"resolution": int(m.group(3))}
    if m.group(1) == "corners":
        kw["sampling"] = "corners"
    else:
        kw["sampling"] = "region" if m.group(1).startswith("region") else "boundary"
        if m.group(2):
            kw["spacing"] = float(m.group(2))
    for part in re.findall(r"-([a-zA-Z]+)(\d+(?:\.\d+)?)|\+([ce])", m.group(4)):
        key, value, flag = part
        if flag == "c":
            kw["centre"] = True
        elif flag == "e":
            kw["edge_pass"] = True
        elif key == "s":
            kw["split"] = float(value)
        elif key == "t":
            kw["threshold"] = int(float(value))
        elif key == "L":
            kw["occluder_lod"] = int(value)
        elif key == "h":
            kw["height_step"] = float(value)
        else:
            raise InputError(f"setting {spec!r}: unknown part -{key}{value} (t, L, h, s, +c or +e)")
    return Setting(spec.strip(), BakeSettings(**kw).check())


#: the first bake's default, the yardstick of every ratio
TODAY = parse_setting("corners-64")

#: the bake's default before region sampling (issue 12 item 2): the second yardstick
PREVIOUS = parse_setting("boundary20-128")

#: the rows ``bench visibility`` runs by default
DEFAULT_SETTINGS: tuple[str, ...] = (
    "corners-64",
    "corners-64+c",
    "corners-128",
    "corners-256",
    "boundary20-64",
    "boundary10-64",
    "boundary20-128",
    "boundary10-128",
    "boundary20-128-t1",
    "boundary20-128-t4",
    "boundary20-256",
    "boundary20-256-t4",
    "region20-128",
    "region10-128",
    "region20-128-t1",
    "region20-128-t4",
    "region20-128+e",
    "region20-128-s0.5",
)


def _same_sampling(a: BakeSettings, b: BakeSettings) -> bool:
    keys = ("sampling", "spacing", "height_step", "centre", "resolution", "occluder_lod", "threshold", "edge_pass", "split")
    return all(getattr(a, k) == getattr(b, k) for k in keys)


# --------------------------------------------------------------------------- input


@dataclass(frozen=True, slots=True)
class BenchInput:
    """What the benchmark runs on: a scene, its view cells, the view distance, a baked PVS."""

    scene: SourceScene
    cells: list[ViewCell]
    view_distance: float
    source: str
    baked: dict[int, I64] | None = None
    """Cell id -> PVS as stored in the database (None for a source file)."""
    settings: dict[str, Any] | None = None
    """The database's bake settings."""


def scene_from_database(path: str | os.PathLike[str]) -> tuple[SourceScene, list[ViewCell], dict[int, I64], dict[str, Any]]:
    """The scene, cells, stored PVS and bake settings of a scene database, from the file alone.

    Objects of kinds other than buildings and street pieces are left out.
    """
    from walkstream.server.store import SceneReader

    with SceneReader.open(path) as reader:
        meta = reader.meta
        info = reader.object_info(reader.object_ids().tolist())
        buildings = tuple(reader.building(i) for i, o in info.items() if o.kind == "building")
        streets = tuple(
            reader.street(i) for i, o in info.items() if o.kind in ("street", "crossroad", "square")
        )
        cells, baked = [], {}
        for c in reader.cells():
            cells.append(
                ViewCell(c.id, c.kind, np.asarray(c.boundary), c.zmin, c.zmax, tuple(int(n) for n in c.neighbours))
            )
            baked[c.id] = np.asarray(c.pvs, np.int64)
    scene = SourceScene(meta.name, meta.crs, meta.origin, buildings, streets)
    return scene, cells, baked, meta.settings


def load_bench_input(path: str | os.PathLike[str], *, scene: SourceScene | None = None) -> BenchInput:
    """Scene and cells from a scene database, or from a source file.

    Parameters
    ----------
    path:
        A baked scene database (its objects, cells, stored PVS and view distance are
        used; any source it was baked from), or a city source file (GeoJSON,
        OpenStreetMap: any format :func:`~walkstream.server.sources.read.read_source`
        reads), or pass the loaded ``scene``.  A source gets
        ``make_cells(scene, "auto")`` and an 800 m view distance.
    scene:
        The scene of a source file read by the caller.

    Raises
    ------
    InputError
        When the file cannot be read as either.
    """
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: no such file")
    if scene is None:
        with p.open("rb") as f:
            is_db = f.read(16) == b"SQLite format 3\x00"
        if not is_db:
            from walkstream.server.sources.read import READERS, read_source

            if not any(p.name.lower().endswith(e) for e in READERS):
                raise InputError(
                    f"{p}: neither a scene database nor a scene source ({', '.join(sorted(READERS))})"
                )
            source = read_source(p)
            if not isinstance(source, SourceScene):
                raise InputError(f"{p}: an interior; bench visibility compares the PVS of city cells")
            scene = source
    if scene is not None:
        return BenchInput(scene, make_cells(scene, "auto"), 800.0, str(p))
    sc, cells, baked, settings = scene_from_database(p)
    return BenchInput(sc, cells, float(settings.get("view_distance", 800.0)), str(p), baked, settings)


# --------------------------------------------------------------------------- cells


def _morton(q: I64) -> I64:
    """Z-order keys of integer points ``(n, 2)`` in ``[0, 2**16)``."""
    key = np.zeros(len(q), np.int64)
    for bit in range(16):
        key |= ((q[:, 0] >> bit) & 1) << (2 * bit)
        key |= ((q[:, 1] >> bit) & 1) << (2 * bit + 1)
    return key


def pick_cells(cells: Sequence[ViewCell], sample: int, *, seed: int = 0) -> list[ViewCell]:
    """``sample`` cells spread over the scene, deterministically.

    Street cells (kind ``"street"``) are preferred when there are any, else every cell
    is a candidate.  The candidates are ordered along a Z-order curve of their
    centroids and cut into ``sample`` runs of equal length; one cell is drawn from each
    run (uniformly, with a generator seeded by ``seed``), so the sample covers the
    scene evenly without favouring its border.  Returned in cell-id order.
    """
    if int(sample) < 1:
        raise InputError(f"sample: expected >= 1 cells, got {sample}")
    cand = [c for c in cells if c.kind == "street"] or list(cells)
    if not cand:
        raise InputError("the scene has no view cells to benchmark")
    if len(cand) <= int(sample):
        return sorted(cand, key=lambda c: c.id)
    xy = np.array([c.centroid for c in cand], np.float64)
    lo = xy.min(axis=0)
    span = float(max((xy.max(axis=0) - lo).max(), 1e-9))
    q = np.clip((xy - lo) / span * 65535.0, 0, 65535).astype(np.int64)
    order = np.argsort(_morton(q), kind="stable")
    rng = np.random.default_rng(seed)
    edges = np.linspace(0, len(cand), int(sample) + 1).round().astype(np.int64)
    picks = [int(order[rng.integers(a, b)]) for a, b in zip(edges[:-1], edges[1:], strict=True)]
    return sorted((cand[i] for i in picks), key=lambda c: c.id)


# --------------------------------------------------------------------------- benchmark


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
        "miss_px": missed_px / total_px if total_px else 0.0,
        "miss_max": worst,
        "miss_max_at": where,
        "missed_ref_shares": shares,
        "pvs_mean": float(np.mean([len(p) for p in pvs])) if pvs else 0.0,
        "extra_per_cell": float(np.mean([len(p - r.keys()) for p, r in zip(pvs, ref, strict=True)])),
    }


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
    if not any(_same_sampling(s.bake, TODAY.bake) for s in rows_in):
        rows_in.insert(0, TODAY)
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
    renderers: dict[tuple[int, int, bool], VisibilityRenderer] = {}
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
            key = (s.bake.occluder_lod, s.bake.resolution, s.bake.edge_pass)
            if key not in renderers:
                m, ids = (meshes2, ids2) if key[0] == 2 else meshes_for_scene(scene, key[0])
                renderers[key] = VisibilityRenderer(m, ids, resolution=key[1], view_distance=vd, ctx=gl, edge_pass=key[2])
                renderers[key].cell_counts(np.array([[0.0, 0.0, 1.7]]))  # compile, warm up
        pvs: list[list[set[int]]] = [[] for _ in rows_in]
        times: list[list[float]] = [[] for _ in rows_in]
        npts: list[list[int]] = [[] for _ in rows_in]
        for c in chosen:
            for k, s in enumerate(rows_in):
                r = renderers[(s.bake.occluder_lod, s.bake.resolution, s.bake.edge_pass)]
                best = math.inf
                for _ in range(max(1, int(repeat))):
                    t = time.perf_counter()
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

    n_obj = len(scene.buildings) + len(scene.streets)
    rows: list[dict[str, Any]] = []
    for k, s in enumerate(rows_in):
        sec = float(statistics.median(times[k]))
        rows.append(
            {"name": s.name, "sampling": s.bake.sampling, "spacing": s.bake.spacing if s.bake.sampling != "corners" else None,
             "resolution": s.bake.resolution, "lod": s.bake.occluder_lod, "threshold": s.bake.threshold,
             "centre": s.bake.centre, "points_per_cell": float(np.mean(npts[k])), "sec_per_cell": sec}
            | _score(pvs[k], ref)
            | (_view_error(shots, pvs[k]) if shots else {})
        )
    if inp.baked is not None:
        stored = [{int(i) for i in inp.baked.get(c.id, np.zeros(0, np.int64))} for c in chosen]
        rows.append({"name": "baked", "sec_per_cell": None} | _score(stored, ref) | (_view_error(shots, stored) if shots else {}))
    base = rows[next(k for k, s in enumerate(rows_in) if _same_sampling(s.bake, TODAY.bake))]
    prev = next((rows[k] for k, s in enumerate(rows_in) if _same_sampling(s.bake, PREVIOUS.bake)), None)
    for row in rows:
        sec = row["sec_per_cell"]
        row["time_ratio"] = sec / base["sec_per_cell"] if sec else None
        row["pvs_ratio"] = row["pvs_mean"] / base["pvs_mean"] if base["pvs_mean"] else None
        row["time_ratio_previous"] = sec / prev["sec_per_cell"] if sec and prev else None
        row["pvs_ratio_previous"] = row["pvs_mean"] / prev["pvs_mean"] if prev and prev["pvs_mean"] else None
        row["culled"] = 1.0 - row["pvs_mean"] / n_obj if n_obj else None
        row["meets"] = {k: (row.get(k) is not None and row[k] <= v) for k, v in TARGETS.items()}
    default = next((s.name for s in rows_in if _same_sampling(s.bake, BakeSettings())), None)
    return {
        "rows": rows,
        "default": default,
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
                rgb, img = tr.render(eye, camera(eye, float(rng.uniform(0.0, 2.0 * math.pi))))
                out.append((k, img, rgb))
        tick()
    return out


# --------------------------------------------------------------------------- output


def _pct(v: float | None, digits: int = 2) -> str:
    return "n/a" if v is None else f"{100.0 * v:.{digits}f}"


def _ratio(v: float | None) -> str:
    return "n/a" if v is None else f"{v:.2f}"


def format_table(result: dict[str, Any]) -> str:
    """The rows of :func:`visibility_benchmark` as text, with the reference and the targets."""
    ref = result["reference"]
    lines = [
        f"reference: {len(result['cells'])} cells ({ref['cells_scored']} see something), "
        f"{ref['points_per_cell']:.0f} random points/cell over the cell and its height range, "
        f"{ref['resolution']} px, LOD{ref['lod']}, no frustum culling: PVS {ref['pvs_mean']:.1f} "
        f"of {result['objects']} objects, {ref['sec_per_cell']:.1f} s/cell"
        + (f" ({ref['cached']} cells from the cache)" if ref.get("cached") else ""),
        f"image error: {result['views']} random eye points ({result['view_size'][0]}x{result['view_size'][1]}, "
        "random heading) compared with their ground truth",
        "",
        f"{'setting':<20} {'pts':>4} {'ms/cell':>8} {'time x':>6} {'x prev':>6} {'PVS':>6} {'PVS x':>5} {'x prev':>6} {'culled%':>7} "
        f"{'miss#%':>6} {'miss px%':>8} {'max obj%':>8} {'view px%':>8} {'view #%':>7} {'v>0.5%':>6}",
    ]
    for r in result["rows"]:
        mark = "  <- bake default" if r["name"] == result.get("default") else ""
        sec, tr = r.get("sec_per_cell"), r["time_ratio"]
        lines.append(
            f"{r['name']:<20} {r.get('points_per_cell', float('nan')):>4.0f} "
            f"{'n/a' if sec is None else f'{1e3 * sec:.1f}':>8} "
            f"{'n/a' if tr is None else f'{tr:.2f}':>6} {_ratio(r.get('time_ratio_previous')):>6} {r['pvs_mean']:>6.1f} "
            f"{r['pvs_ratio']:>5.2f} {_ratio(r.get('pvs_ratio_previous')):>6} {_pct(r['culled'], 1):>7} {_pct(r['miss_count'], 1):>6} "
            f"{_pct(r['miss_px'], 4):>8} {_pct(r['miss_max'], 4):>8} {_pct(r.get('view_miss_px'), 3):>8} "
            f"{_pct(r.get('view_miss_count'), 1):>7} {_pct(r.get('view_over_half'), 1):>6}{mark}"
        )
    t = TARGETS
    lines += [
        "",
        f"targets: miss# <= {100 * t['miss_count']:g} %, max obj <= {100 * t['miss_max']:g} %, "
        f"miss px <= {100 * t['miss_px']:g} %, time x <= {t['time_ratio']:g}, PVS x <= {t['pvs_ratio']:g}, "
        "culled >= 90 %",
        f"time x, PVS x: against {TODAY.name} (the first bake); x prev: against {PREVIOUS.name} "
        "(the default before region sampling), when it is a row",
        "view px%: truth pixels showing an object missing from the cell's PVS; view #%: objects "
        "shown that are missing; v>0.5%: views whose missing pixels exceed 0.5 % of the frame",
    ]
    for r in result["rows"]:
        sh = r.get("missed_ref_shares")
        if sh:
            a = 100.0 * np.array(sh)
            lines.append(
                f"missed objects against the reference, {r['name']}: {len(a)} misses, median "
                f"{np.median(a):.5f} %, p90 {np.percentile(a, 90):.5f} % of the cell's reference pixels"
            )
    for r in result["rows"]:
        s = r.get("missed_sizes")
        if s is not None and not s:
            lines.append(f"missed objects' sizes in the views, {r['name']}: nothing missed")
        elif s:
            a = 100.0 * np.array(s)
            lines.append(
                f"missed objects' sizes in the views, {r['name']}: {len(a)} misses, median "
                f"{np.median(a):.4f} %, p95 {np.percentile(a, 95):.4f} %, max {a.max():.4f} % of the frame"
            )
    return "\n".join(lines)


def _nice_ticks(lo: float, hi: float) -> list[float]:
    """A few 1-2-5 tick values covering ``lo .. hi`` (> 0) on a log axis."""
    e0, e1 = math.floor(math.log10(lo)) - 1, math.ceil(math.log10(hi)) + 1
    cand = [m * 10.0**e for e in range(e0, e1) for m in (1, 2, 5)]
    return [v for v in cand if lo / 2.5 <= v <= hi * 2.5]


def plot_visibility_benchmark(result: dict[str, Any], path: str | os.PathLike[str], *, dpi: int = 120) -> None:
    """A PNG of three panels: misses against bake time, misses against PVS size, missed objects' sizes.

    Left: pixel-weighted misses and the largest single miss (%, log) against seconds
    per cell (log) for every setting, the targets as dashed lines.  Middle: misses by
    count against the PVS size relative to the first default, the 25 % line.  Right:
    the distribution of the missed objects' sizes at the random eye points (share of
    the frame, log bins) for the first default, the bake default and the baked PVS.
    """
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure
    from matplotlib.ticker import FuncFormatter, NullFormatter

    rows = result["rows"]
    timed = [r for r in rows if r.get("sec_per_cell")]
    fig = Figure(figsize=(17, 6.0), dpi=dpi)
    ax1, ax2, ax3 = fig.subplots(1, 3)
    floor = 1e-5
    for r in timed:
        x = r["sec_per_cell"]
        special = r["name"] in (TODAY.name, result.get("default"))
        colour = "#D55E00" if r["name"] == TODAY.name else ("#009E73" if r["name"] == result.get("default") else "#0072B2")
        ax1.plot([x], [max(100 * r["miss_px"], floor)], "o", color=colour, markersize=8 if special else 6)
        ax1.plot([x], [max(100 * r["miss_max"], floor)], "^", color=colour, markersize=8 if special else 6, markerfacecolor="white")
        ax1.annotate(r["name"], (x, max(100 * r["miss_px"], floor)), xytext=(4, 3), textcoords="offset points", fontsize=7)
        ax2.plot([r["pvs_ratio"]], [100 * r["miss_count"]], "o", color=colour, markersize=8 if special else 6)
        ax2.annotate(r["name"], (r["pvs_ratio"], 100 * r["miss_count"]), xytext=(4, 3), textcoords="offset points", fontsize=7)
    base = next((r for r in timed if r["name"] == TODAY.name), None)
    if base is not None:
        ax1.axvline(TARGETS["time_ratio"] * base["sec_per_cell"], color="#888888", linestyle=":", linewidth=1.0)
        ax1.annotate("2 x the first default's time", (TARGETS["time_ratio"] * base["sec_per_cell"], 0.98), xycoords=("data", "axes fraction"), fontsize=7, rotation=90, va="top", ha="right", color="#555555")
    ax1.axhline(100 * TARGETS["miss_px"], color="#0072B2", linestyle="--", linewidth=1.0, label="target: misses by pixels")
    ax1.axhline(100 * TARGETS["miss_max"], color="#555555", linestyle="-.", linewidth=1.0, label="target: largest single miss")
    ax1.plot([], [], "o", color="#555555", label="misses by pixels (pooled)")
    ax1.plot([], [], "^", color="#555555", markerfacecolor="white", label="largest missed object (one cell)")
    ax1.set_xscale("log")
    ax1.set_yscale("log")
    # seconds per cell span less than a decade: labelled minor ticks would overlap
    ax1.xaxis.set_minor_formatter(NullFormatter())
    ax1.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    ax1.set_xticks(_nice_ticks(min(r["sec_per_cell"] for r in timed), max(r["sec_per_cell"] for r in timed)) if timed else [])
    ax1.set_xlabel("bake seconds per cell (median, log)")
    ax1.set_ylabel("% of a cell's reference pixels (log)")
    ax1.set_title("misses against bake time (red: first default, green: bake default)", fontsize=9)
    ax1.legend(fontsize=7, loc="lower left")
    ax2.axvline(TARGETS["pvs_ratio"], color="#888888", linestyle=":", linewidth=1.0)
    if base is not None and base["pvs_mean"]:
        # a PVS missing at most 5 % by count holds at least 95 % of the reference's
        # objects: where that lies against the PVS limit says whether both can be met
        need = (1.0 - TARGETS["miss_count"]) * result["reference"]["pvs_mean"] / base["pvs_mean"]
        ax2.axvline(need, color="#CC79A7", linestyle="-.", linewidth=1.0)
        ax2.annotate(
            "95 % of the reference PVS", (need, 0.98), xycoords=("data", "axes fraction"),
            fontsize=7, rotation=90, va="top", ha="right", color="#CC79A7",
        )
    ax2.axhline(100 * TARGETS["miss_count"], color="#0072B2", linestyle="--", linewidth=1.0)
    ax2.set_xlabel("mean PVS size / the first default's")
    ax2.set_ylabel("reference-visible objects missed (% by count)")
    ax2.set_title("misses by count against PVS growth (targets dashed)", fontsize=9)
    bins = np.logspace(-6, 0, 37)
    for name, colour in ((TODAY.name, "#D55E00"), (result.get("default"), "#009E73"), ("baked", "#555555")):
        r = next((x for x in rows if x["name"] == name), None)
        if r is None or not r.get("missed_sizes"):
            continue
        ax3.hist(
            np.clip(r["missed_sizes"], 1e-6, 1.0), bins=bins, histtype="step", linewidth=1.6, color=colour,
            linestyle="--" if name == "baked" else "-",
            label=f"{name}: {len(r['missed_sizes'])} misses in {result['views']} views",
        )
    ax3.set_xscale("log")
    ax3.set_xlabel("missed object's pixels / the frame's pixels (log)")
    ax3.set_ylabel("missed objects")
    ax3.set_title("sizes of the objects a PVS misses at random eye points", fontsize=9)
    if ax3.get_legend_handles_labels()[0]:
        ax3.legend(fontsize=7)
    for ax in (ax1, ax2, ax3):
        ax.grid(True, which="both", alpha=0.25)
    ref = result["reference"]
    fig.suptitle(
        f"Visibility bake against a dense reference: {len(result['cells'])} cells, "
        f"{ref['points_per_cell']:.0f} random points/cell at {ref['resolution']} px, LOD2, no culling",
        fontsize=10,
    )
    fig.tight_layout(rect=(0, 0, 1, 0.95))
    fig.savefig(os.fspath(path))
