"""The one bake driver: a planned scene's cells baked by their kind into one database, resumable.

:func:`drive` takes a :class:`~.plan.BakePlan` (a city, an interior or a crossing of
both) and

1. opens the work file (:meth:`~walkstream.server.store.SceneWriter.create`); a work
   file left by a killed bake with the same header is resumed;
2. with field cells (sections, or street and grid cells with ``--sampling field``),
   renders the dense visibility field (each block kept as it comes, so a killed bake
   resumes with the blocks done) and grows the cells from it or gives the cells
   their PVS (written after the tables);
3. writes the plan's tables (objects, cells, viewpoints, rooms, portals, stairs,
   entrances; on resume again, as upserts that keep every stored PVS);
4. bakes the room cells' contents, unless a resumed work file has them all: clipped
   in chunks by the one chunk runner (:func:`~.chunks.run_chunks`), placed, encoded;
5. bakes the PVS of the PVS cells not yet done, in chunks by the same runner, each
   cell committed as it comes (a kill loses only the cells in flight);
6. with impostors (``--impostors``), plans the PVS cells' images, makes those not
   yet stored in chunks by the same runner and lists them per cell
   (:func:`~.impostors.bake_impostors`); with virtual walls (``--virtual-walls``),
   makes the wall textures not yet stored likewise and writes the wall sides
   (:func:`~.walls.bake_walls`; a city's rings around its cells whose PVS is large
   and their cut PVS, :func:`~.walls.bake_ring_walls`);
7. records the default walks and seals the database.

So every scene kind resumes alike, to the same version an uninterrupted bake gets.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from walkstream.server.bake.chunks import run_chunks
from walkstream.server.bake.field import bake_field, field_folder
from walkstream.server.bake.impostors import bake_impostors
from walkstream.server.bake.interior import room_contents, write_contents
from walkstream.server.bake.plan import BakePlan, settings_key
from walkstream.server.bake.wallplan import whole_crossing
from walkstream.server.bake.walls import bake_ring_walls, bake_walls
from walkstream.server.bake.workers import PVS_CHUNK, pvs_items, pvs_task, release_renderer
from walkstream.server.store import SceneReader, SceneWriter
from walkstream.shared.errors import InputError

__all__ = ["drive"]


def drive(
    plan: BakePlan,
    output: str | os.PathLike[str],
    *,
    workers: int = 1,
    scheduler: str | None = None,
    progress: Callable[[int, int], None] | None = None,
    log: Callable[[str], None] | None = None,
    max_cells: int | None = None,
    started: float | None = None,
    stage: Callable[[str, str], None] | None = None,
    resume: bool = True,
) -> dict[str, Any]:
    """Bake ``plan`` into the database ``output`` (replaced atomically on success).

    Parameters
    ----------
    plan:
        The scene (:mod:`~.plan`).
    output:
        The database to write.
    workers, scheduler:
        Local processes, or a Dask scheduler ``tcp://HOST:PORT``, for the chunks.
    progress:
        Called with ``(done, total)`` of the step running: field points, room
        contents, PVS cells, impostor images, wall textures.
    stage:
        Called with ``(step, unit)`` as each of those steps starts (``("visibility
        field", "point")``, ``("PVS", "cell")``, ...), so that a progress bar names
        what ``progress`` counts.
    log:
        Called with one-line messages about the stages.
    max_cells:
        Stop after this many new PVS cells (or about as many new field points)
        without finishing the database (for tests of interruption and resume; the
        work file stays for the next run).
    started:
        ``time.perf_counter()`` when the bake began (reading the sources counts);
        default now.
    resume:
        Reuse a matching work file (default) or start over.

    Returns
    -------
    dict
        The database summary (``SceneReader.summary``), the plan's summary,
        ``resumed_cells`` (PVS cells found done in a resumed work file), with
        room cells ``contents_encode_s``, with impostors the figures of
        :func:`~.impostors.bake_impostors`; empty when ``max_cells`` stopped it early.
    """
    if workers < 1:
        raise InputError(f"--workers: expected >= 1, got {workers}")
    say = log or (lambda _msg: None)
    step = stage or (lambda _step, _unit: None)
    t0 = time.perf_counter() if started is None else started
    out = Path(output)
    writer = SceneWriter.create(
        out, name=plan.name, crs=plan.crs, origin=plan.origin, grammar_text=plan.grammar_text,
        grammar_version=plan.grammar_version, features=plan.features, settings=plan.settings, resume=resume,
    )
    pvs, rooms = plan.pvs, plan.rooms
    pvs_cells = pvs.cells if pvs is not None else []
    extra: dict[str, Any] = {}
    try:
        done = writer.done_cells() if writer.resumed else set()
        grown: list[tuple[int, Any, Any]] = []
        if plan.field is not None:
            fc = plan.field
            step("visibility field", "point")
            sets = bake_field(fc.lattice, fc.scene, fc.settings, fc.key, field_folder(out, fc.key), workers=workers,
                              scheduler=scheduler, progress=progress, max_points=max_cells)
            if sets is None:
                writer.close()
                return {}
            grown = fc.grow(sets)  # the cells the tables and the walks are made of
        # on resume too: every write is an upsert that keeps a cell's stored PVS, so a
        # bake killed while it wrote the tables resumes as well
        plan.write_tables(writer)
        resumed = len([c for c in pvs_cells if c.id in done])
        if writer.resumed:
            say(f"resuming: {resumed} of {len(pvs_cells)} cells already baked")
        if rooms is not None:
            ids = {c.id + rooms.offset for c in rooms.layout.cells}
            encode_s = 0.0
            if not ids <= done:
                step("room contents", "cell")
                found = room_contents(rooms.scene, rooms.layout, workers=workers, scheduler=scheduler,
                                      progress=progress)
                if rooms.wall_plan is not None:  # objects across a virtual wall: whole, as geometry
                    found = whole_crossing(found, rooms.scene, rooms.layout, rooms.wall_plan.crossing)
                parts = rooms.place(found)
                encode_s = write_contents(writer, rooms.layout, parts, offset=rooms.offset,
                                          cellmesh_version=rooms.cellmesh_version)
            extra["contents_encode_s"] = encode_s
        for cid, ids_, ach in grown:
            writer.set_pvs(cid, ids_, ach)
        todo = [c for c in pvs_cells if c.id not in done]
        if max_cells is not None:
            todo = todo[:max_cells]
        finished = resumed
        if pvs is not None:
            step("PVS", "cell")
            for results in run_chunks(
                pvs_task, pvs_items(todo), (pvs.scene, pvs.settings, pvs.key), size=PVS_CHUNK, workers=workers,
                scheduler=scheduler, progress=progress, done=resumed, total=len(pvs_cells),
                release=release_renderer,
            ):
                for cid, ids_, ach in results:
                    writer.set_pvs(cid, ids_, ach)
                    finished += 1
        if max_cells is not None and finished < len(pvs_cells):
            writer.close()
            return {}
        imp_cells = pvs_cells or (plan.field.cells if plan.field is not None else [])
        if plan.impostors is not None and imp_cells:
            step("impostor images", "image")
            extra.update(bake_impostors(writer, plan.impostors, imp_cells, workers=workers, scheduler=scheduler,
                                        progress=progress, say=say))
        if plan.rings is not None and imp_cells:
            step("wall textures", "texture")
            extra.update(bake_ring_walls(writer, plan.rings, imp_cells, workers=workers, scheduler=scheduler,
                                         progress=progress, say=say))
        if rooms is not None and rooms.walls is not None and rooms.wall_plan is not None:
            step("wall textures", "texture")
            extra.update(bake_walls(writer, rooms.scene, rooms.wall_plan, rooms.walls, settings_key(plan.settings),
                                    workers=workers, scheduler=scheduler, progress=progress, say=say))
        # the default walks: made from the cells alone, so a resumed bake records the
        # same ones (INSERT OR REPLACE) just before sealing the file
        for path, line in plan.walks(say):
            writer.add_path(path.name, path.to_msgpack())
            say(line)
        writer.finish(time.perf_counter() - t0)
    finally:
        writer.close()
    with SceneReader.open(out) as reader:
        summary = reader.summary()
    summary.update(plan.summary)
    summary.update(extra)
    summary["resumed_cells"] = resumed
    return summary

