"""Error against run time of the visibility bake (``walkstream bench visibility``).

The bake samples a cell's visibility from a few points (the 8 corners of a box fitted
to the cell, optionally its centre too) at one cube-face resolution with one building
LOD as occluder geometry.  This module measures what each such setting misses against
a dense reference on a sample of cells, and how long it takes:

* the reference renders many viewpoints spread through each sampled cell
  (:func:`~walkstream.server.bake.samples.dense_points`: ``ref_points`` ground positions times
  ``ref_levels`` heights, by default 66 points, more than 8 times the 8 corners) at
  twice the highest resolution (capped at 512) with the finest LOD (2) as occluder;
* every setting (resolution x centre point x occluder LOD) renders the same cells the
  way the bake does (:func:`~walkstream.server.bake.samples.sample_points` then
  :meth:`VisibilityRenderer.cell_counts`) and is timed per cell;
* a setting's miss rate is the share of reference-visible objects absent from its PVS
  (mean over cells), its pixel-weighted miss rate the reference pixels of the missed
  objects over all reference pixels (pooled over cells);
* the default is the cheapest setting whose pixel-weighted miss rate is at most 1 %.

All renderers share one GL context; each is built once per (LOD, resolution), used for
both centre options and released.  Building (mesh upload) time is reported apart from
the per-cell render time.
"""

from __future__ import annotations

import os
import statistics
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import shapely

from walkstream.server.bake.cells import make_cells
from walkstream.server.bake.samples import dense_points, sample_points
from walkstream.server.bake.viewcell import ViewCell
from walkstream.server.bake.visibility import VisibilityRenderer, meshes_for_scene
from walkstream.server.sources.scene import SourceScene
from walkstream.shared.errors import InputError

if TYPE_CHECKING:
    import moderngl

from walkstream.shared.arrays import I64

__all__ = [
    "BenchInput",
    "MAX_MISS_RATE_PX",
    "format_table",
    "load_bench_input",
    "pick_cells",
    "plot_visibility_benchmark",
    "setting_label",
    "visibility_benchmark",
]

#: The default setting is the cheapest one whose pixel-weighted miss rate is at most this.
MAX_MISS_RATE_PX = 0.01

Progress = Callable[[int, int], None]


# --------------------------------------------------------------------------- input


@dataclass(frozen=True, slots=True)
class BenchInput:
    """What the benchmark runs on: a scene, its view cells and the bake's view distance."""

    scene: SourceScene
    cells: list[ViewCell]
    view_distance: float
    source: str


def load_bench_input(
    path: str | os.PathLike[str], *, source: str | os.PathLike[str] | None = None
) -> BenchInput:
    """Scene and cells from a scene database or directly from a GeoJSON source.

    Parameters
    ----------
    path:
        A ``.geojson``/``.json`` source (cells made with ``make_cells(scene, "auto")``,
        view distance 800 m) or a baked scene database, whose cells, view distance and
        ``--bbox`` clip are used; its scene is rebuilt from the source file recorded in
        the database's settings (``settings["source"]``) or from ``source``.
    source:
        The GeoJSON the database was baked from, when the database does not record it
        (or it has moved).

    Raises
    ------
    InputError
        When the source is unknown, cannot be read, or no longer matches the database.
    """
    from walkstream.server.sources.geojson import load_geojson

    p = Path(path)
    if p.suffix.lower() in (".geojson", ".json"):
        scene = load_geojson(p)
        return BenchInput(scene, make_cells(scene, "auto"), 800.0, str(p))

    from walkstream.server.store import SceneReader

    with SceneReader.open(p) as reader:
        settings = reader.meta.settings
        db_ids = np.sort(reader.object_ids())
        db_cells = list(reader.cells())
    src = source if source is not None else settings.get("source")
    if not src:
        raise InputError(
            f"{p}: the database does not record its source file; pass --source FILE.geojson"
        )
    src_path = Path(src)
    if not src_path.is_file():
        raise InputError(
            f"{p}: source file {str(src_path)!r} not found; pass --source FILE.geojson"
        )
    scene = load_geojson(src_path)
    bbox = settings.get("bbox")
    if bbox is not None:
        from walkstream.server.sources.clip import clip_scene

        scene = clip_scene(scene, tuple(float(v) for v in bbox))  # type: ignore[arg-type]
    scene_ids = np.sort(
        np.array([b.id for b in scene.buildings] + [s.id for s in scene.streets], np.int64)
    )
    if not np.array_equal(scene_ids, db_ids):
        raise InputError(
            f"{p}: the objects of {str(src_path)!r} do not match the database "
            f"({len(scene_ids)} vs {len(db_ids)} objects); was it baked from another file?"
        )
    cells = [
        ViewCell(
            c.id,
            c.kind,
            np.asarray(c.boundary),
            c.zmin,
            c.zmax,
            tuple(int(n) for n in c.neighbours),
        )
        for c in db_cells
    ]
    view_distance = float(settings.get("view_distance", 800.0))
    return BenchInput(scene, cells, view_distance, str(src_path))


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


# ------------------------------------------------------------------------- benchmark


def _as_dict(ids: I64, pixels: I64) -> dict[int, int]:
    return {int(i): int(n) for i, n in zip(ids, pixels, strict=True) if n > 0}


def visibility_benchmark(
    scene: SourceScene,
    cells: list[ViewCell],
    *,
    sample: int = 12,
    seed: int = 0,
    resolutions: Sequence[int] = (64, 128, 256),
    centres: Sequence[bool] = (False, True),
    lods: Sequence[int] = (0, 1, 2),
    view_distance: float = 800.0,
    ref_points: int = 22,
    ref_levels: int = 3,
    ref_resolution: int | None = None,
    margin: float = 0.3,
    ctx: moderngl.Context | None = None,
    progress: Progress | None = None,
) -> dict[str, Any]:
    """Miss rate against a dense reference and render time of every visibility setting.

    Parameters
    ----------
    scene:
        The scene (its object ids are the ids of the PVS).
    cells:
        Its view cells; ``sample`` of them are benchmarked (:func:`pick_cells`).
    sample, seed:
        How many cells, and the seed that picks them (and jitters the reference points).
    resolutions, centres, lods:
        The settings: every combination of cube-face resolution (pixels), sampling the
        cell centre too (``True``) or the 8 corners only, and building LOD as occluder.
    view_distance:
        Far plane, metres (the bake's view distance).
    ref_points, ref_levels:
        Reference viewpoints per cell: ``ref_points`` positions spread through the
        cell's free space times ``ref_levels`` heights over its height range (default
        22 x 3 = 66, more than 8 times the 8 corner points).
    ref_resolution:
        Cube-face resolution of the reference; default twice the highest resolution,
        capped at 512.
    margin:
        Distance of every viewpoint from the cell border and from footprints, metres.
    ctx:
        OpenGL context for all renderers; by default one is made and released.
    progress:
        Called with ``(renders done, renders total)``; one render is one cell of the
        reference or of one setting.

    Returns
    -------
    dict
        ``settings``: one dict per setting with ``resolution``, ``centre``, ``lod``,
        ``sec_per_cell`` (median over cells of ``cell_counts``), ``cells_per_sec``,
        ``upload_seconds`` (building the renderer), ``points_per_cell``,
        ``miss_rate``, ``miss_rate_px``, ``extra_per_cell`` and ``pvs_mean``;
        ``reference``: ``resolution``, ``lod``, ``points_per_cell`` (mean),
        ``pvs_mean``, ``pixels_per_cell`` (mean), ``sec_per_cell``,
        ``upload_seconds``, ``cells`` (the sampled cell ids), ``cells_scored`` (cells
        whose reference sees something) and ``objects``;
        ``default``: the cheapest setting (lowest ``sec_per_cell``) with
        ``miss_rate_px <= 0.01``, or None;
        ``seconds``: wall time of the whole benchmark.

    Raises
    ------
    InputError
        On empty or out-of-range options.
    RenderError
        When OpenGL fails.
    """
    from walkstream.shared.gl import create_context

    t_start = time.perf_counter()
    resolutions = [int(r) for r in resolutions]
    centres = [bool(c) for c in centres]
    lods = [int(lod) for lod in lods]
    if not resolutions or not centres or not lods:
        raise InputError("visibility_benchmark: resolutions, centres and lods must not be empty")
    if min(resolutions) < 1:
        raise InputError(f"visibility_benchmark: resolutions must be >= 1, got {resolutions}")
    if any(lod not in (0, 1, 2) for lod in lods):
        raise InputError(f"visibility_benchmark: lods must be 0, 1 or 2, got {lods}")
    if int(ref_points) < 1 or int(ref_levels) < 1:
        raise InputError(
            f"visibility_benchmark: ref_points and ref_levels must be >= 1, got "
            f"{ref_points}, {ref_levels}"
        )
    ref_res = int(ref_resolution) if ref_resolution is not None else min(2 * max(resolutions), 512)
    chosen = pick_cells(cells, sample, seed=seed)
    footprints = shapely.STRtree(
        [shapely.Polygon(b.rings[0], b.rings[1:]) for b in scene.buildings]
    )
    n_settings = len(resolutions) * len(centres) * len(lods)
    total = len(chosen) * (1 + n_settings)
    done = 0

    def tick() -> None:
        nonlocal done
        done += 1
        if progress is not None:
            progress(done, total)

    if progress is not None:
        progress(0, total)
    own_ctx = ctx is None
    gl = create_context() if ctx is None else ctx
    try:
        # -- the dense reference ----------------------------------------------------
        ref_pts = [
            dense_points(
                c.polygon,
                c.zmin,
                c.zmax,
                int(ref_points),
                levels=int(ref_levels),
                margin=margin,
                footprints=footprints,
                seed=seed + c.id,
            )
            for c in chosen
        ]
        meshes, ids = meshes_for_scene(scene, 2)
        t = time.perf_counter()
        ref_r = VisibilityRenderer(
            meshes, ids, resolution=ref_res, view_distance=view_distance, ctx=gl
        )
        ref_upload = time.perf_counter() - t
        ref: list[dict[int, int]] = []
        ref_times: list[float] = []
        try:
            ref_r.cell_counts(np.zeros((1, 3)) + [0.0, 0.0, 1.7])  # warm-up (shader compile)
            for pts in ref_pts:
                t = time.perf_counter()
                ref.append(_as_dict(*ref_r.cell_counts(pts)))
                ref_times.append(time.perf_counter() - t)
                tick()
        finally:
            ref_r.release()
        scored = [k for k, r in enumerate(ref) if r]
        ref_px_total = sum(sum(ref[k].values()) for k in scored)

        # -- the settings ------------------------------------------------------------
        points = {
            centre: [
                sample_points(
                    c.polygon, c.zmin, c.zmax, margin=margin, centre=centre, footprints=footprints
                )
                for c in chosen
            ]
            for centre in centres
        }
        rows: list[dict[str, Any]] = []
        for lod in lods:
            meshes, ids = meshes_for_scene(scene, lod)
            for res in resolutions:
                t = time.perf_counter()
                r = VisibilityRenderer(
                    meshes, ids, resolution=res, view_distance=view_distance, ctx=gl
                )
                upload = time.perf_counter() - t
                try:
                    r.cell_counts(np.zeros((1, 3)) + [0.0, 0.0, 1.7])  # warm-up
                    for centre in centres:
                        times: list[float] = []
                        pvs: list[set[int]] = []
                        for pts in points[centre]:
                            t = time.perf_counter()
                            seen, _pixels = r.cell_counts(pts)
                            times.append(time.perf_counter() - t)
                            pvs.append({int(i) for i in seen})
                            tick()
                        rows.append(
                            _score(res, centre, lod, times, upload, pvs, ref, scored, ref_px_total)
                            | {"points_per_cell": float(np.mean([len(p) for p in points[centre]]))}
                        )
                finally:
                    r.release()
    finally:
        if own_ctx:
            gl.release()

    rows.sort(key=lambda s: (s["resolution"], s["lod"], s["centre"]))
    ok = [s for s in rows if s["miss_rate_px"] <= MAX_MISS_RATE_PX]
    default = min(ok, key=lambda s: s["sec_per_cell"]) if ok else None
    reference = {
        "resolution": ref_res,
        "lod": 2,
        "points_per_cell": float(np.mean([len(p) for p in ref_pts])),
        "pvs_mean": float(np.mean([len(r) for r in ref])),
        "pixels_per_cell": float(np.mean([sum(r.values()) for r in ref])),
        "sec_per_cell": float(statistics.median(ref_times)),
        "upload_seconds": ref_upload,
        "cells": [c.id for c in chosen],
        "cells_scored": len(scored),
        "objects": len(scene.buildings) + len(scene.streets),
    }
    return {
        "settings": rows,
        "reference": reference,
        "default": default,
        "seconds": time.perf_counter() - t_start,
    }


def _score(
    res: int,
    centre: bool,
    lod: int,
    times: list[float],
    upload: float,
    pvs: list[set[int]],
    ref: list[dict[int, int]],
    scored: list[int],
    ref_px_total: int,
) -> dict[str, Any]:
    """One result row: timing and the errors of ``pvs`` against ``ref`` (per cell)."""
    miss = []
    missed_px = 0
    for k in scored:
        missed = ref[k].keys() - pvs[k]
        miss.append(len(missed) / len(ref[k]))
        missed_px += sum(ref[k][i] for i in missed)
    sec = float(statistics.median(times))
    return {
        "resolution": res,
        "centre": centre,
        "lod": lod,
        "sec_per_cell": sec,
        "cells_per_sec": 1.0 / sec if sec > 0 else float("inf"),
        "upload_seconds": upload,
        "miss_rate": float(np.mean(miss)) if miss else 0.0,
        "miss_rate_px": missed_px / ref_px_total if ref_px_total else 0.0,
        "extra_per_cell": float(np.mean([len(p - ref[k].keys()) for k, p in enumerate(pvs)])),
        "pvs_mean": float(np.mean([len(p) for p in pvs])),
    }


# --------------------------------------------------------------------------- output


def setting_label(s: dict[str, Any]) -> str:
    """Short name of a setting, e.g. ``"128 L0 +c"`` (``+c``: the centre is sampled too)."""
    return f"{s['resolution']} L{s['lod']}" + (" +c" if s["centre"] else "")


def _is_default(result: dict[str, Any], s: dict[str, Any]) -> bool:
    d = result.get("default")
    return d is not None and all(d[k] == s[k] for k in ("resolution", "centre", "lod"))


def format_table(result: dict[str, Any]) -> str:
    """A text table of every setting of :func:`visibility_benchmark`'s result, and the default."""
    ref = result["reference"]
    lines = [
        f"reference: {len(ref['cells'])} cells ({ref['cells_scored']} see something), "
        f"{ref['points_per_cell']:.0f} points/cell at {ref['resolution']} px, LOD{ref['lod']}: "
        f"PVS {ref['pvs_mean']:.1f} of {ref['objects']} objects, "
        f"{ref['sec_per_cell']:.2f} s/cell",
        "",
        f"{'setting':<11} {'res':>4} {'LOD':>3} {'centre':>6} {'pts':>4} {'ms/cell':>8} "
        f"{'cells/s':>8} {'upload s':>8} {'miss %':>7} {'miss px %':>9} {'extra':>6} {'PVS':>6}",
    ]
    for s in result["settings"]:
        mark = "  <- default" if _is_default(result, s) else ""
        lines.append(
            f"{setting_label(s):<11} {s['resolution']:>4} {s['lod']:>3} "
            f"{'yes' if s['centre'] else 'no':>6} {s['points_per_cell']:>4.0f} "
            f"{1e3 * s['sec_per_cell']:>8.1f} {s['cells_per_sec']:>8.1f} "
            f"{s['upload_seconds']:>8.2f} {100 * s['miss_rate']:>7.2f} "
            f"{100 * s['miss_rate_px']:>9.3f} {s['extra_per_cell']:>6.2f} {s['pvs_mean']:>6.1f}{mark}"
        )
    lines.append("")
    d = result.get("default")
    if d is None:
        lines.append(
            f"default: none (no setting has a pixel-weighted miss rate <= {100 * MAX_MISS_RATE_PX:g} %)"
        )
    else:
        lines.append(
            f"default: {setting_label(d)} (resolution {d['resolution']}, LOD{d['lod']} occluders, "
            f"{'corners and centre' if d['centre'] else 'corners only'}): "
            f"{1e3 * d['sec_per_cell']:.1f} ms/cell, pixel-weighted miss rate "
            f"{100 * d['miss_rate_px']:.3f} %"
        )
    return "\n".join(lines)


def plot_visibility_benchmark(
    result: dict[str, Any], path: str | os.PathLike[str], *, dpi: int = 130
) -> None:
    """Write a PNG: seconds per cell (log x) against pixel-weighted miss rate (%) per setting.

    Both axes are logarithmic (a miss rate of 0 is drawn on the floor of the plot).
    Colour is the resolution, marker shape the occluder LOD, a hollow marker a setting
    that samples the centre too; each point is labelled (e.g. ``"128 L0 +c"``), the
    1 % line is drawn and the default setting is ringed in red.
    """
    import matplotlib
    import matplotlib.ticker

    matplotlib.use("Agg")
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    rows = result["settings"]
    fig = Figure(figsize=(10, 6.5), dpi=dpi)
    ax = fig.add_subplot(1, 1, 1)
    res_values = sorted({s["resolution"] for s in rows})
    palette = ["#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd", "#8c564b", "#17becf"]
    colour = {r: palette[i % len(palette)] for i, r in enumerate(res_values)}
    shape = {0: "o", 1: "s", 2: "^"}
    # Log y so that rates far below the 1 % line stay apart; a rate of 0 sits on the floor.
    limit = 100 * MAX_MISS_RATE_PX
    pct = [100 * s["miss_rate_px"] for s in rows]
    positive = [v for v in pct if v > 0]
    floor = min(positive + [limit]) / 3.0
    for s, v in zip(rows, pct, strict=True):
        x, y = s["sec_per_cell"], max(v, floor)
        c = colour[s["resolution"]]
        ax.plot(
            [x],
            [y],
            linestyle="none",
            marker=shape.get(s["lod"], "D"),
            markersize=8,
            markeredgecolor=c,
            markeredgewidth=1.6,
            markerfacecolor="white" if s["centre"] else c,
        )
        ax.annotate(
            setting_label(s),
            (x, y),
            xytext=(5, -11 if s["centre"] else 5),
            textcoords="offset points",
            fontsize=7.5,
            color="#333333",
        )
        if _is_default(result, s):
            ax.plot(
                [x],
                [y],
                linestyle="none",
                marker="o",
                markersize=17,
                markerfacecolor="none",
                markeredgecolor="red",
                markeredgewidth=2.0,
            )
    ax.axhline(limit, color="red", linestyle="--", linewidth=1.0)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_ylim(floor / 1.6, max(pct + [limit]) * 2.0)
    x_all = [s["sec_per_cell"] for s in rows]
    ax.set_xlim(min(x_all) / 1.4, max(x_all) * 1.6)
    ax.yaxis.set_major_formatter(matplotlib.ticker.FuncFormatter(lambda v, _pos: f"{v:g}"))
    ax.set_xlabel("render seconds per cell (median over cells, log scale)")
    ax.set_ylabel(
        "pixel-weighted miss rate (%, log scale"
        + (", 0 on the floor)" if len(positive) < len(pct) else ")")
    )
    ax.grid(True, which="both", alpha=0.25)
    handles = [
        Line2D([], [], linestyle="none", marker="o", color=colour[r], label=f"{r} px/face")
        for r in res_values
    ]
    handles += [
        Line2D(
            [],
            [],
            linestyle="none",
            marker=shape.get(lod, "D"),
            color="#555555",
            label=f"LOD{lod} occluders",
        )
        for lod in sorted({s["lod"] for s in rows})
    ]
    handles += [
        Line2D(
            [],
            [],
            linestyle="none",
            marker="o",
            markerfacecolor="white",
            color="#555555",
            label="corners + centre (+c)",
        ),
        Line2D([], [], color="red", linestyle="--", label=f"{100 * MAX_MISS_RATE_PX:g} % limit"),
        Line2D(
            [],
            [],
            linestyle="none",
            marker="o",
            markersize=11,
            markerfacecolor="none",
            markeredgecolor="red",
            markeredgewidth=2.0,
            label="default",
        ),
    ]
    ax.legend(handles=handles, fontsize=8, loc="upper left", framealpha=0.9)
    ref = result["reference"]
    d = result.get("default")
    ax.set_title(
        f"Visibility: error vs run time on {len(ref['cells'])} cells; reference "
        f"{ref['points_per_cell']:.0f} points/cell at {ref['resolution']} px, LOD{ref['lod']}\n"
        + (f"default: {setting_label(d)}" if d is not None else "default: none under the limit"),
        fontsize=10,
    )
    fig.tight_layout()
    fig.savefig(os.fspath(path))
