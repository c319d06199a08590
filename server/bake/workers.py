"""The bake's visibility tasks: the PVS and ACH of view cells, for the one chunk runner.

The tasks run wherever :func:`~.chunks.run_chunks` sends them (this process, local
processes, a Dask cluster).  Each worker builds one :class:`~walkstream.server.bake.visibility.VisibilityRenderer`
(its own GL context) on first use and keeps it; a task takes plain arrays (cell id,
polygon, height range) and returns plain arrays (id, PVS, ACH), so it pickles.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import shapely
from numpy.typing import NDArray

from walkstream.server.bake.farband import band_renderer, merge_band_counts
from walkstream.server.bake.fieldrender import FieldRenderer
from walkstream.server.bake.idpack import meshes_for_scene
from walkstream.server.bake.pvsbudget import within_budget
from walkstream.server.bake.samples import axis_points, bake_points, split_points
from walkstream.server.bake.settings import BakeSettings
from walkstream.server.bake.viewcell import ViewCell
from walkstream.server.bake.visibility import VisibilityRenderer, pvs_from_counts
from walkstream.server.sources.scene import SourceScene

__all__ = [
    "PVS_CHUNK",
    "band_points",
    "SPLIT_ROUNDS",
    "cell_counts",
    "cell_points",
    "cell_task",
    "field_task",
    "pvs_items",
    "pvs_task",
    "release_renderer",
]

PVS_CHUNK = 8
"""Cells per task: big enough to amortise a task's overhead, small enough for a smooth bar."""


# ------------------------------------------------------------------ cell tasks

_WORKER: dict[str, Any] = {}


def _renderer_for(scene: SourceScene, settings: BakeSettings, key: str) -> tuple[FieldRenderer, Any]:
    """One renderer per process (and per scene), built on first use and kept (the
    field's :class:`~.fieldrender.FieldRenderer`: a :class:`VisibilityRenderer` with
    one more way to render many points)."""
    if _WORKER.get("key") != key:
        for name in ("band", "renderer"):
            old = _WORKER.pop(name, None)
            if old is not None:
                old.release()
        meshes, ids = meshes_for_scene(scene, settings.occluder_lod)
        _WORKER["renderer"] = FieldRenderer(
            meshes, ids, resolution=settings.resolution, view_distance=settings.view_distance,
            edge_pass=settings.edge_pass, thin_pass=settings.thin_pass,
            thin_depth=settings.thin_depth,
        )
        # the band shares the renderer's context (released before it, by whoever releases it)
        _WORKER["band"] = band_renderer(meshes, ids, settings, ctx=_WORKER["renderer"].ctx)
        _WORKER["footprints"] = shapely.STRtree(
            [shapely.Polygon(b.rings[0], b.rings[1:]) for b in scene.buildings]
        )
        _WORKER["key"] = key
    return _WORKER["renderer"], _WORKER["footprints"]


def cell_points(
    settings: BakeSettings, polygon: NDArray[np.float64], zmin: float, zmax: float, footprints: Any
) -> NDArray[np.float64]:
    """A cell's sample points under ``settings`` (:func:`~walkstream.server.bake.samples.bake_points`)."""
    return bake_points(
        polygon,
        zmin,
        zmax,
        sampling=settings.sampling,
        spacing=settings.spacing,
        height_step=settings.height_step,
        margin=settings.margin,
        centre=settings.centre,
        footprints=footprints,
    )


def band_points(
    settings: BakeSettings, pts: NDArray[np.float64], polygon: NDArray[np.float64], zmin: float, zmax: float,
    footprints: Any,
) -> NDArray[np.float64]:
    """Where the far field's band is rendered: the cube's points ``pts``, then, with
    ``settings.far_axis``, the cell's :func:`~walkstream.server.bake.samples.axis_points`."""
    if not settings.far_axis:
        return pts
    more = axis_points(polygon, zmin, zmax, spacing=settings.far_axis, height_step=settings.height_step,
                       margin=settings.margin, footprints=footprints)
    return np.vstack([pts, more]) if len(more) else pts


#: rounds of adaptive sampling (``BakeSettings.split``): each halves the gaps it splits
SPLIT_ROUNDS = 2


def cell_counts(
    renderer: VisibilityRenderer,
    settings: BakeSettings,
    polygon: NDArray[np.float64],
    zmin: float,
    zmax: float,
    footprints: Any,
    band: VisibilityRenderer | None = None,
) -> tuple[NDArray[np.int64], NDArray[np.int64], int]:
    """Pixels per object over a cell's sample points, as the bake counts them.

    The points of :func:`cell_points`; with ``settings.split`` (adaptive sampling),
    up to :data:`SPLIT_ROUNDS` rounds of :func:`~walkstream.server.bake.samples.split_points`
    between the points whose views differ, each new point rendered and counted too.

    With ``band`` (:func:`~.farband.band_renderer`), every point rendered is rendered
    again as the far field's horizon band and its counts added
    (:func:`~.farband.merge_band_counts`); with ``settings.far_axis`` the band also at
    the cell's :func:`band_points` beyond them.

    With ``settings.pvs_budget``, the counts less the objects the budget leaves out
    (:func:`~.pvsbudget.within_budget`: each point's cube and each band point's band a view).

    Returns
    -------
    ids, pixels : (k,) int64
        As :meth:`VisibilityRenderer.cell_counts`.
    points : int
        Points rendered in all.
    """
    pts = cell_points(settings, polygon, zmin, zmax, footprints)
    if len(pts) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), 0
    if settings.pvs_budget:
        # the same renders kept apart by view, for the budget (which takes no split)
        cube = renderer.each_point_counts(pts)
        far = band.each_point_counts(band_points(settings, pts, polygon, zmin, zmax, footprints)) if band is not None else []
        return *within_budget(cube, far, settings), len(pts)
    if not settings.split:
        ids, pixels = renderer.cell_counts(pts)
        if band is not None:
            bp = band_points(settings, pts, polygon, zmin, zmax, footprints)
            ids, pixels = merge_band_counts(ids, pixels, *band.cell_counts(bp), settings)
        return ids, pixels, len(pts)
    ids, pixels, seen = renderer.point_counts(pts)
    total = dict(zip(ids.tolist(), pixels.tolist(), strict=True))
    for _ in range(SPLIT_ROUNDS):
        new = split_points(
            pts, seen, polygon, differ=settings.split, max_gap=1.5 * settings.spacing,
            margin=settings.margin, footprints=footprints,
        )
        if len(new) == 0:
            break
        i2, p2, s2 = renderer.point_counts(new)
        for a, b in zip(i2.tolist(), p2.tolist(), strict=True):
            total[a] = total.get(a, 0) + b
        pts, seen = np.vstack([pts, new]), seen + s2
    keys = np.array(sorted(total), np.int64)
    counts = np.array([total[k] for k in keys.tolist()], np.int64)
    if band is not None:
        bp = band_points(settings, pts, polygon, zmin, zmax, footprints)
        keys, counts = merge_band_counts(keys, counts, *band.cell_counts(bp), settings)
    return keys, counts, len(pts)


def cell_task(
    scene: SourceScene,
    settings: BakeSettings,
    key: str,
    cells: list[tuple[int, NDArray[np.float64], float, float]],
) -> list[tuple[int, NDArray[np.int64], NDArray[np.float64]]]:
    """PVS and ACH of some cells: ``(cell id, polygon, zmin, zmax)`` in, ``(id, pvs, ach)`` out.

    Runs wherever the cells are sent (this process, a pool worker, a Dask worker).
    """
    renderer, footprints = _renderer_for(scene, settings, key)
    out = []
    for cid, poly, zmin, zmax in cells:
        ids, pixels, n = cell_counts(renderer, settings, poly, zmin, zmax, footprints, _WORKER.get("band"))
        if n == 0:
            out.append((cid, np.zeros(0, np.int64), np.zeros(0)))
            continue
        pvs, ach = pvs_from_counts(ids, pixels, threshold=settings.threshold)
        out.append((cid, pvs, ach))
    return out


def pvs_items(cells: Sequence[ViewCell]) -> list[tuple[int, NDArray[np.float64], float, float]]:
    """The work items of :func:`pvs_task`: ``(cell id, polygon, zmin, zmax)`` of each cell."""
    return [(c.id, np.asarray(c.polygon), c.zmin, c.zmax) for c in cells]


def pvs_task(
    cells: list[tuple[int, NDArray[np.float64], float, float]],
    scene: SourceScene,
    settings: BakeSettings,
    key: str,
) -> list[tuple[int, NDArray[np.int64], NDArray[np.float64]]]:
    """:func:`cell_task` with the chunk first, as :func:`~.chunks.run_chunks` calls a task."""
    return cell_task(scene, settings, key, cells)


def field_task(
    blocks: list[tuple[int, NDArray[np.float64], tuple[float, float]]],
    scene: SourceScene,
    settings: BakeSettings,
    key: str,
) -> list[tuple[int, NDArray[np.int64], NDArray[np.int32], NDArray[np.uint32]]]:
    """The dense visibility field of some blocks of points (:mod:`~.field`).

    ``(block, eyes (k, 2), heights)`` in: every eye rendered at both heights (a full
    spin up and down); ``(block, offsets (k + 1,), ids, pixels)`` out, each point's
    visible set with the pixels each object covers over its twelve images.  The
    points go to the renderer height by height, in the order they always had (a
    point's place in the framebuffer decides the rounding of its vertices, and a
    resumed field mixes blocks rendered at different times).
    """
    renderer, _ = _renderer_for(scene, settings, key)
    out = []
    for block, eyes, heights in blocks:
        k = len(eyes)
        pts = np.vstack([np.column_stack([eyes, np.full(k, z)]) for z in heights])
        per = renderer.field_counts(pts)
        offsets = np.zeros(k + 1, np.int64)
        ids_l, pix_l = [], []
        for i in range(k):
            both = [per[i + h * k] for h in range(len(heights))]
            ids = np.concatenate([b[0] for b in both])
            u, inv = np.unique(ids, return_inverse=True)
            px = np.bincount(inv.reshape(-1), weights=np.concatenate([b[1] for b in both]), minlength=len(u))
            ids_l.append(u.astype(np.int32))
            pix_l.append(np.minimum(px, 2**32 - 1).astype(np.uint32))
            offsets[i + 1] = offsets[i] + len(u)
        out.append((block, offsets, np.concatenate(ids_l) if ids_l else np.zeros(0, np.int32),
                    np.concatenate(pix_l) if pix_l else np.zeros(0, np.uint32)))
    return out


def release_renderer() -> None:
    """Free this process's renderer (its GL context) after a bake run here."""
    band = _WORKER.pop("band", None)
    if band is not None:
        band.release()
    r = _WORKER.pop("renderer", None)
    _WORKER.pop("key", None)
    if r is not None:
        r.release()
