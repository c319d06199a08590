"""The driver's impostor step: plan a city's images from the stored PVS, make the missing ones, list them per cell.

Called by the one driver (:func:`~.driver.drive`) once every PVS cell is done:

1. the plan (:func:`~.impostorplan.plan_impostors`) from the cells' stored PVS,
   the same on every run, so image ids are the same on resume;
2. the images not yet in the work file rendered and encoded in chunks by the one
   chunk runner (:func:`~.chunks.run_chunks` over
   :func:`~.impostorrender.impostor_task`), each committed as it comes (a kill loses
   only the images in flight);
3. each cell's list of impostors written (cheap; on resume again).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from typing import Any

from walkstream.server.bake.chunks import run_chunks
from walkstream.server.bake.impostorplan import plan_impostors
from walkstream.server.bake.impostorrender import impostor_task, release_impostor_renderer
from walkstream.server.bake.plan import ImpostorCells, Say
from walkstream.server.bake.viewcell import ViewCell
from walkstream.server.store import SceneWriter
from walkstream.shared.codec.image import IMAGE_MEDIA

__all__ = ["IMAGE_CHUNK", "bake_impostors"]

IMAGE_CHUNK = 64
"""Images per task: a renderer's start (LOD2 of every building) is paid once per process."""


def bake_impostors(
    writer: SceneWriter,
    imp: ImpostorCells,
    cells: Sequence[ViewCell],
    *,
    workers: int = 1,
    scheduler: str | None = None,
    progress: Callable[[int, int], None] | None = None,
    say: Say = lambda _msg: None,
) -> dict[str, Any]:
    """Bake the impostor images of ``cells`` into ``writer`` (see the module docstring).

    Returns
    -------
    dict
        ``impostor_cells`` (cells with at least one impostor), ``impostor_pairs``
        (cell-object pairs drawn as impostors), ``impostor_far``,
        ``impostor_complex``, ``impostor_too_near`` (far or complex pairs no bin
        level serves: geometry), ``impostor_resumed`` (images found done),
        ``impostor_seconds`` (this step's wall time).
    """
    t0 = time.perf_counter()
    st = imp.settings
    plan = plan_impostors(cells, writer.stored_pvs(), imp.boxes, imp.tris2, st)
    done = writer.done_impostors()
    todo = [job for job in plan.jobs if job[0] not in done]
    say(f"impostors: {len(plan.jobs)} images for {sum(len(v) for v in plan.cells.values())} cell-object pairs "
        f"({len(plan.jobs) - len(todo)} already baked)")
    media = IMAGE_MEDIA[st.codec]
    for results in run_chunks(
        impostor_task, todo, (imp.scene, imp.key, st.codec, st.quality, st.sampling,
                        (st.projection, math.radians(st.error_deg), st.distance)), size=IMAGE_CHUNK, workers=workers,
        scheduler=scheduler, progress=progress, done=len(plan.jobs) - len(todo), total=len(plan.jobs),
        release=release_impostor_renderer,
    ):
        for (image, oid, level, ia, ie, size), data in results:
            writer.add_impostor(image, oid, (level, ia, ie), size, media, data)
    writer.set_cell_impostors((cid, [r.to_row() for r in rows]) for cid, rows in sorted(plan.cells.items()) if rows)
    return {
        "impostor_cells": sum(1 for rows in plan.cells.values() if rows),
        "impostor_pairs": sum(len(rows) for rows in plan.cells.values()),
        "impostor_far": plan.far,
        "impostor_complex": plan.complex,
        "impostor_too_near": plan.too_near,
        "impostor_resumed": len(plan.jobs) - len(todo),
        "impostor_seconds": time.perf_counter() - t0,
    }
