"""The bake's cell tasks, run in this process, in local worker processes or on a Dask cluster.

Each worker builds one :class:`~walkstream.server.bake.visibility.VisibilityRenderer`
(its own GL context) on first use and keeps it; a task takes plain arrays (cell id,
polygon, height range) and returns plain arrays (id, PVS, ACH), so it pickles.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np
import shapely
from numpy.typing import NDArray

from walkstream.server.bake.samples import bake_points, split_points
from walkstream.server.bake.settings import BakeSettings
from walkstream.server.bake.viewcell import ViewCell
from walkstream.server.bake.visibility import VisibilityRenderer, meshes_for_scene, pvs_from_counts
from walkstream.server.sources.scene import SourceScene
from walkstream.shared.errors import InputError

__all__ = ["SPLIT_ROUNDS", "cell_task", "cell_points", "cell_counts", "dask_client", "run_tasks"]

#: cells per task: big enough to amortise a task's overhead, small enough for a smooth bar
_CHUNK = 8


# ------------------------------------------------------------------ cell tasks

_WORKER: dict[str, Any] = {}


def _renderer_for(scene: SourceScene, settings: BakeSettings, key: str) -> tuple[VisibilityRenderer, Any]:
    """One renderer per process (and per scene), built on first use and kept."""
    if _WORKER.get("key") != key:
        old = _WORKER.get("renderer")
        if old is not None:
            old.release()
        meshes, ids = meshes_for_scene(scene, settings.occluder_lod)
        _WORKER["renderer"] = VisibilityRenderer(
            meshes, ids, resolution=settings.resolution, view_distance=settings.view_distance,
            edge_pass=settings.edge_pass,
        )
        _WORKER["footprints"] = shapely.STRtree(
            [shapely.Polygon(b.rings[0], b.rings[1:]) for b in scene.buildings]
        )
        _WORKER["key"] = key
    return _WORKER["renderer"], _WORKER["footprints"]


def _init_worker(scene: SourceScene, settings: BakeSettings, key: str) -> None:
    _WORKER["scene"], _WORKER["settings"], _WORKER["skey"] = scene, settings, key


def _pool_task(cells: list[tuple[int, NDArray[np.float64], float, float]]) -> list[tuple[int, NDArray[np.int64], NDArray[np.float64]]]:
    return cell_task(_WORKER["scene"], _WORKER["settings"], _WORKER["skey"], cells)


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


#: rounds of adaptive sampling (``BakeSettings.split``): each halves the gaps it splits
SPLIT_ROUNDS = 2


def cell_counts(
    renderer: VisibilityRenderer,
    settings: BakeSettings,
    polygon: NDArray[np.float64],
    zmin: float,
    zmax: float,
    footprints: Any,
) -> tuple[NDArray[np.int64], NDArray[np.int64], int]:
    """Pixels per object over a cell's sample points, as the bake counts them.

    The points of :func:`cell_points`; with ``settings.split`` (adaptive sampling),
    up to :data:`SPLIT_ROUNDS` rounds of :func:`~walkstream.server.bake.samples.split_points`
    between the points whose views differ, each new point rendered and counted too.

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
    if not settings.split:
        ids, pixels = renderer.cell_counts(pts)
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
    return keys, np.array([total[k] for k in keys.tolist()], np.int64), len(pts)


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
        ids, pixels, n = cell_counts(renderer, settings, poly, zmin, zmax, footprints)
        if n == 0:
            out.append((cid, np.zeros(0, np.int64), np.zeros(0)))
            continue
        pvs, ach = pvs_from_counts(ids, pixels, threshold=settings.threshold)
        out.append((cid, pvs, ach))
    return out


def _chunks(cells: Sequence[ViewCell], n: int) -> Iterator[list[tuple[int, NDArray[np.float64], float, float]]]:
    for i in range(0, len(cells), n):
        yield [(c.id, np.asarray(c.polygon), c.zmin, c.zmax) for c in cells[i : i + n]]


def run_tasks(
    scene: SourceScene,
    st: BakeSettings,
    key: str,
    todo: list[ViewCell],
    workers: int,
    scheduler: str | None,
) -> Iterator[list[tuple[int, NDArray[np.int64], NDArray[np.float64]]]]:
    """Render the PVS of the cells ``todo`` in chunks: here, in ``workers`` local
    processes or on the Dask ``scheduler``; yields each chunk's ``(cell id, pvs, ach)``
    as it finishes (``key`` names the bake's settings: a worker keeps its renderer while it
    stays the same)."""
    chunks = list(_chunks(todo, _CHUNK))
    if not chunks:
        return
    if scheduler:
        yield from _run_dask(scene, st, key, chunks, scheduler)
    elif workers > 1:
        import multiprocessing as mp

        # spawn: a forked child would inherit this process's GL state
        ctx = mp.get_context("spawn")
        with ctx.Pool(workers, initializer=_init_worker, initargs=(scene, st, key)) as pool:
            yield from pool.imap_unordered(_pool_task, chunks)
    else:
        try:
            for chunk in chunks:
                yield cell_task(scene, st, key, chunk)
        finally:
            r = _WORKER.pop("renderer", None)
            _WORKER.pop("key", None)
            if r is not None:
                r.release()


def dask_client(scheduler: str) -> Any:
    """A ``distributed.Client`` of the scheduler at ``tcp://HOST:PORT`` (close it when done).

    Raises
    ------
    InputError
        Dask is not installed, or the scheduler cannot be reached.
    """
    try:
        from distributed import Client
    except ImportError as exc:  # optional dependency: fail only when used
        raise InputError("--scheduler needs Dask: pip install 'dask[distributed]'") from exc
    try:
        return Client(scheduler, timeout=20)
    except OSError as exc:
        raise InputError(f"--scheduler {scheduler}: cannot reach the Dask scheduler ({exc})") from exc


def _run_dask(
    scene: SourceScene,
    st: BakeSettings,
    key: str,
    chunks: list[list[tuple[int, NDArray[np.float64], float, float]]],
    scheduler: str,
) -> Iterator[list[tuple[int, NDArray[np.int64], NDArray[np.float64]]]]:
    from distributed import as_completed

    client = dask_client(scheduler)
    try:
        # ship the scene once; every task refers to the same scattered copy
        [remote] = client.scatter([scene], broadcast=True)
        futures = [client.submit(cell_task, remote, st, key, c, pure=False) for c in chunks]
        for fut in as_completed(futures):
            yield fut.result()
    finally:
        client.close()
