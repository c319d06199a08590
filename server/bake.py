"""The bake: a scene source becomes a scene database.

Load the source (GeoJSON footprints or a generated city), cut the navigation space
into view cells, store every object's compact parameters, then render each cell's
object-ID cube maps to find its PVS and ACH.  Cells are independent tasks: they run
in this process, in ``workers`` local processes, or on a Dask cluster; in every case
this process alone writes the database, so a kill loses at most the cells in flight
and the next bake with the same settings resumes from the cells already stored.
"""

from __future__ import annotations

import hashlib
import os
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import shapely
from numpy.typing import NDArray

from walkstream.server.cells import ViewCell, make_cells, viewpoints
from walkstream.server.pathgen import default_paths
from walkstream.server.sources.geojson import load_geojson
from walkstream.server.sources.scene import SourceScene
from walkstream.server.store import CellRow, ObjectRow, SceneReader, SceneWriter
from walkstream.server.visibility import (
    VisibilityRenderer,
    meshes_for_scene,
    pvs_from_counts,
    sample_points,
)
from walkstream.shared.buildings import default_grammar, default_grammar_text, predict_triangles
from walkstream.shared.errors import InputError

__all__ = ["BakeSettings", "bake", "clip_scene", "DEFAULT_RESOLUTION", "DEFAULT_OCCLUDER_LOD"]

#: chosen with ``walkstream bench visibility`` (cheapest setting whose
#: pixel-weighted miss rate against the dense reference is at most 1 %)
DEFAULT_RESOLUTION = 64
DEFAULT_OCCLUDER_LOD = 0

#: cells per task: big enough to amortise a task's overhead, small enough for a smooth bar
_CHUNK = 8


@dataclass(frozen=True, slots=True)
class BakeSettings:
    """Everything that decides a bake's result (and so whether a resume is valid)."""

    cells: str = "auto"
    cell_size: float = 40.0
    max_length: float = 40.0
    view_distance: float = 800.0
    bbox: tuple[float, float, float, float] | None = None
    resolution: int = DEFAULT_RESOLUTION
    occluder_lod: int = DEFAULT_OCCLUDER_LOD
    centre: bool = False
    threshold: int = 0
    margin: float = 0.3

    def check(self) -> BakeSettings:
        """Raise InputError naming the first bad setting."""
        if self.cells not in ("auto", "street", "grid"):
            raise InputError(f"--cells: expected street, grid or auto, got {self.cells!r}")
        for name in ("cell_size", "max_length", "view_distance", "margin"):
            v = float(getattr(self, name))
            if not (np.isfinite(v) and v > 0):
                raise InputError(f"{name.replace('_', '-')}: expected a positive number, got {v}")
        if self.resolution < 8 or self.resolution > 2048:
            raise InputError(f"resolution: expected 8..2048 pixels, got {self.resolution}")
        if self.occluder_lod not in (0, 1, 2):
            raise InputError(f"occluder LOD: expected 0, 1 or 2, got {self.occluder_lod}")
        if self.threshold < 0:
            raise InputError(f"threshold: expected >= 0 pixels, got {self.threshold}")
        if self.bbox is not None:
            x0, y0, x1, y1 = self.bbox
            if not (all(np.isfinite(self.bbox)) and x1 > x0 and y1 > y0):
                raise InputError(f"--bbox: expected MINX,MINY,MAXX,MAXY with MIN < MAX, got {self.bbox}")
        return self


def clip_scene(scene: SourceScene, bbox: tuple[float, float, float, float]) -> SourceScene:
    """Keep the objects whose footprint centre lies in ``bbox`` (scene-local metres).

    Ids are renumbered densely (buildings first) so PVS id lists stay compact.
    """
    box = shapely.box(*bbox)

    def inside(ring: NDArray[np.float64]) -> bool:
        c = ring.mean(axis=0)
        return bool(shapely.contains_xy(box, c[0], c[1]))

    buildings = [b for b in scene.buildings if inside(b.rings[0])]
    streets = [s for s in scene.streets if inside(s.ring)]
    if not buildings and not streets:
        raise InputError(f"--bbox {bbox}: no object of the scene lies inside it")
    buildings = [replace(b, id=i) for i, b in enumerate(buildings)]
    streets = [replace(s, id=len(buildings) + i) for i, s in enumerate(streets)]
    return replace(scene, buildings=tuple(buildings), streets=tuple(streets))


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
            meshes, ids, resolution=settings.resolution, view_distance=settings.view_distance
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
        pts = sample_points(poly, zmin, zmax, margin=settings.margin, centre=settings.centre, footprints=footprints)
        if len(pts) == 0:
            out.append((cid, np.zeros(0, np.int64), np.zeros(0)))
            continue
        ids, pixels = renderer.cell_counts(pts)
        pvs, ach = pvs_from_counts(ids, pixels, threshold=settings.threshold)
        out.append((cid, pvs, ach))
    return out


def _chunks(cells: Sequence[ViewCell], n: int) -> Iterator[list[tuple[int, NDArray[np.float64], float, float]]]:
    for i in range(0, len(cells), n):
        yield [(c.id, np.asarray(c.polygon), c.zmin, c.zmax) for c in cells[i : i + n]]


# ------------------------------------------------------------------ the bake


def _file_digest(path: Path) -> str:
    h = hashlib.sha256()
    with path.open("rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()[:16]


def bake(
    source: str | os.PathLike[str],
    output: str | os.PathLike[str],
    *,
    settings: BakeSettings | None = None,
    name: str | None = None,
    workers: int = 1,
    scheduler: str | None = None,
    progress: Callable[[int, int], None] | None = None,
    log: Callable[[str], None] | None = None,
    max_cells: int | None = None,
) -> dict[str, Any]:
    """Bake ``source`` (GeoJSON) into the scene database ``output``.

    Parameters
    ----------
    source, output:
        Input GeoJSON file and the database to write (replaced atomically on success).
    settings:
        Cells, view distance, resolution, occluder LOD, ... (defaults: :class:`BakeSettings`).
    name:
        Scene name (default: the database file's stem).
    workers:
        Local processes rendering cells (each makes its own GL context).
    scheduler:
        ``tcp://HOST:PORT`` of a Dask distributed scheduler to send the cell tasks to.
    progress:
        Called with ``(cells done, cells total)`` as cells finish.
    log:
        Called with one-line messages about the stages.
    max_cells:
        Stop after this many new cells without finishing the database (for tests of
        interruption and resume; the work file stays for the next run).

    Returns
    -------
    dict
        The database summary (``SceneReader.summary``) plus ``bake_seconds``,
        ``resumed_cells`` and ``source``; empty when ``max_cells`` stopped it early.
    """
    st = (settings or BakeSettings()).check()
    if workers < 1:
        raise InputError(f"--workers: expected >= 1, got {workers}")
    src = Path(source)
    out = Path(output)
    say = log or (lambda _msg: None)
    t0 = time.perf_counter()

    scene = load_geojson(src)
    if st.bbox is not None:
        scene = clip_scene(scene, st.bbox)
    cells = make_cells(
        scene, st.cells, max_length=st.max_length, cell_size=st.cell_size, bbox=st.bbox
    )
    if not cells:
        raise InputError(f"{src}: no view cell could be made (no free space?)")
    kind = "grid" if cells[0].kind == "grid" else "street"
    features = ["buildings"] + (["streets"] if scene.streets else []) + [f"{kind}_cells"]
    say(f"{src.name}: {len(scene.buildings)} buildings, {len(scene.streets)} street pieces, {len(cells)} {kind} cells")

    grammar = default_grammar()
    settings_dict = asdict(st) | {"source": str(src), "source_digest": _file_digest(src)}
    writer = SceneWriter.create(
        out,
        name=name or out.stem,
        crs=scene.crs,
        origin=scene.origin,
        grammar_text=default_grammar_text(),
        grammar_version=grammar.id,
        features=features,
        settings=settings_dict,
    )
    try:
        done = writer.done_cells() if writer.resumed else set()
        if not writer.resumed:
            rows = [
                ObjectRow.of(b, tris=predict_triangles(b, grammar), bbox=_building_box(b))
                for b in scene.buildings
            ]
            rows += [ObjectRow.of(s, tris=(len(s.ring) - 2,) * 3) for s in scene.streets]
            writer.add_objects(rows)
            writer.add_cells(
                CellRow(c.id, c.kind, np.asarray(c.polygon), c.zmin, c.zmax, np.asarray(c.neighbours, np.int64))
                for c in cells
            )
            for vp in viewpoints(cells, scene):
                writer.add_viewpoint(vp.name, vp.x, vp.y, vp.z, vp.yaw, vp.cell)
        else:
            say(f"resuming: {len(done)} of {len(cells)} cells already baked")
        todo = [c for c in cells if c.id not in done]
        if max_cells is not None:
            todo = todo[:max_cells]
        key = hashlib.sha256(repr(sorted(settings_dict.items())).encode()).hexdigest()[:16]
        finished = len(done)
        if progress:
            progress(finished, len(cells))
        for results in _run_tasks(scene, st, key, todo, workers, scheduler):
            for cid, pvs, ach in results:
                writer.set_pvs(cid, pvs, ach)
                finished += 1
            if progress:
                progress(finished, len(cells))
        if max_cells is not None and finished < len(cells):
            writer.close()
            return {}
        # the default recorded paths: made from the cells alone, so a resumed bake
        # records the same ones (INSERT OR REPLACE) just before sealing the file
        for path in default_paths(cells, footprints=[b.rings[0] for b in scene.buildings]):
            writer.add_path(path.name, path.to_msgpack())
            say(f"recorded path {path.name}: {path.duration:.0f} s, {path.length_m():.0f} m at {path.speed_kmh:g} km/h")
        seconds = time.perf_counter() - t0
        writer.finish(seconds)
    finally:
        writer.close()
    reader = SceneReader.open(out)
    try:
        summary = reader.summary()
    finally:
        reader.close()
    summary["resumed_cells"] = len(done)
    summary["source"] = str(src)
    return summary


def _building_box(b: Any) -> tuple[float, float, float, float, float, float]:
    lo, hi = b.rings[0].min(axis=0), b.rings[0].max(axis=0)
    # the grammar builds a parapet above the eaves and ledges just outside the walls
    return (float(lo[0]) - 0.5, float(lo[1]) - 0.5, 0.0, float(hi[0]) + 0.5, float(hi[1]) + 0.5, b.height + 1.0)


def _run_tasks(
    scene: SourceScene,
    st: BakeSettings,
    key: str,
    todo: list[ViewCell],
    workers: int,
    scheduler: str | None,
) -> Iterator[list[tuple[int, NDArray[np.int64], NDArray[np.float64]]]]:
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


def _run_dask(
    scene: SourceScene,
    st: BakeSettings,
    key: str,
    chunks: list[list[tuple[int, NDArray[np.float64], float, float]]],
    scheduler: str,
) -> Iterator[list[tuple[int, NDArray[np.int64], NDArray[np.float64]]]]:
    try:
        from distributed import Client, as_completed
    except ImportError as exc:  # optional dependency: fail only when used
        raise InputError("--scheduler needs Dask: pip install 'dask[distributed]'") from exc
    try:
        client = Client(scheduler, timeout=20)
    except OSError as exc:
        raise InputError(f"--scheduler {scheduler}: cannot reach the Dask scheduler ({exc})") from exc
    try:
        # ship the scene once; every task refers to the same scattered copy
        [remote] = client.scatter([scene], broadcast=True)
        futures = [client.submit(cell_task, remote, st, key, c, pure=False) for c in chunks]
        for fut in as_completed(futures):
            yield fut.result()
    finally:
        client.close()
