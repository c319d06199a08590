"""The bake, end to end: load the source, cut cells, store objects, render each cell's PVS, record walks."""

from __future__ import annotations

import hashlib
import os
import time
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from walkstream.server.bake.cells import make_cells
from walkstream.server.bake.digest import file_digest
from walkstream.server.bake.interior import bake_interior
from walkstream.server.bake.objectrows import object_rows
from walkstream.server.bake.settings import BakeSettings
from walkstream.server.bake.viewpoints import viewpoints
from walkstream.server.bake.walks import default_paths
from walkstream.server.bake.workers import run_tasks
from walkstream.server.sources.clip import clip_scene, local_bbox
from walkstream.server.sources.interior import InteriorScene
from walkstream.server.sources.read import read_source
from walkstream.server.store import CellRow, SceneReader, SceneWriter
from walkstream.shared.buildings import default_grammar, default_grammar_text
from walkstream.shared.errors import InputError

__all__ = ["bake"]


# ------------------------------------------------------------------ the bake


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
    interior: str | os.PathLike[str] | None = None,
    building: str | None = None,
) -> dict[str, Any]:
    """Bake ``source`` (GeoJSON, OpenStreetMap, an IFC model or an interior file) into ``output``.

    The reader is chosen by the file's ending (:func:`~walkstream.server.sources.read.read_source`);
    an interior goes to :func:`~walkstream.server.bake.interior.bake_interior`.

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
    interior, building:
        An interior to place in one of the city's buildings (an object or feature
        id, or ``auto``), joined to the street at its entrance: a crossing scene
        (:func:`~walkstream.server.bake.crossing.bake_crossing`).

    Returns
    -------
    dict
        The database summary (``SceneReader.summary``) plus ``bake_seconds``,
        ``resumed_cells`` and ``source``; empty when ``max_cells`` stopped it early.
    """
    if interior is not None:
        from walkstream.server.bake.crossing import bake_crossing

        return bake_crossing(
            source, interior, output, building=building, settings=settings, name=name, workers=workers,
            scheduler=scheduler, progress=progress, log=log,
        )
    st = (settings or BakeSettings()).check()
    if workers < 1:
        raise InputError(f"--workers: expected >= 1, got {workers}")
    src = Path(source)
    out = Path(output)
    say = log or (lambda _msg: None)
    t0 = time.perf_counter()

    scene = read_source(src, network=st.network)
    if isinstance(scene, InteriorScene):
        return bake_interior(
            scene, src, out, name=name, workers=workers, scheduler=scheduler, progress=progress,
            log=log, import_seconds=time.perf_counter() - t0,
        )
    for note in scene.notes:
        say(f"{src.name}: {note}")
    bbox = st.bbox
    if bbox is not None:
        bbox = local_bbox(scene, bbox, st.bbox_crs)
        scene = clip_scene(scene, bbox)
    if st.cells == "auto" and not scene.streets:
        say(f"{src.name}: no street network (after filtering): grid cells")
    cells = make_cells(
        scene, st.cells, max_length=st.max_length, cell_size=st.cell_size, bbox=bbox
    )
    if not cells:
        raise InputError(f"{src}: no view cell could be made (no free space?)")
    kind = "grid" if cells[0].kind == "grid" else "street"
    features = ["buildings"] + (["streets"] if scene.streets else []) + [f"{kind}_cells"]
    say(f"{src.name}: {len(scene.buildings)} buildings, {len(scene.streets)} street pieces, {len(cells)} {kind} cells")

    grammar = default_grammar()
    settings_dict = asdict(st) | {"source": str(src), "source_digest": file_digest(src)}
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
            writer.add_objects(object_rows(scene, grammar))
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
        for results in run_tasks(scene, st, key, todo, workers, scheduler):
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
        for path in default_paths(cells, footprints=[b.rings[0] for b in scene.buildings], say=say):
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
    summary["source_issues"] = len(scene.issues)
    if scene.notes:
        summary["source_notes"] = " | ".join(scene.notes)
    return summary

