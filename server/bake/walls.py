"""The virtual walls' step of the one bake driver: the wall textures not yet stored, then every wall side.

What the walls are, where they stand and what each side needs is planned in
:mod:`~walkstream.server.bake.wallplan` (an interior's) and
:mod:`~walkstream.server.bake.ringwalls` (a city's rings); a texture is rendered and encoded by
:func:`~walkstream.server.bake.wallrender.wall_task`, in chunks of the one chunk
runner, so a killed bake resumes texture by texture.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from walkstream.server.bake.chunks import run_chunks
from walkstream.server.bake.plan import RingCells
from walkstream.server.bake.ringwalls import plan_ring_walls
from walkstream.server.bake.viewcell import ViewCell
from walkstream.server.bake.wallplan import WALL_CHUNK, WallPlan, WallSettings
from walkstream.server.bake.wallrender import release_wall_renderer, wall_task
from walkstream.server.sources.interior import InteriorScene
from walkstream.server.sources.scene import SourceScene
from walkstream.server.store import SceneWriter
from walkstream.shared.codec.image import IMAGE_MEDIA

__all__ = ["bake_ring_walls", "bake_walls"]


def bake_walls(
    writer: SceneWriter,
    scene: InteriorScene | SourceScene,
    plan: WallPlan,
    settings: WallSettings,
    key: str,
    *,
    workers: int = 1,
    scheduler: str | None = None,
    progress: Callable[[int, int], None] | None = None,
    say: Callable[[str], None] = lambda _msg: None,
) -> dict[str, Any]:
    """Make the wall textures not yet stored and write every side (see :mod:`~.wallplan`).

    Returns
    -------
    dict
        ``wall_sides``, ``wall_textures``, ``wall_crossing`` (objects kept whole across
        a wall), ``wall_resumed`` (textures found done), ``wall_texture_bytes``,
        ``wall_seconds`` (this step's wall time).
    """
    t0 = time.perf_counter()
    done = writer.done_wall_textures()
    todo = [j for j in plan.jobs if j[0] not in done]
    say(f"virtual walls: {len(plan.sides)} wall sides, {len(plan.jobs)} textures "
        f"({len(plan.jobs) - len(todo)} already baked)")
    media = IMAGE_MEDIA[settings.codec]
    for results in run_chunks(
        wall_task, todo, (scene, key, settings.codec, settings.quality, settings.depth_grid), size=WALL_CHUNK, workers=workers, scheduler=scheduler,
        progress=progress, done=len(plan.jobs) - len(todo), total=len(plan.jobs), release=release_wall_renderer,
    ):
        for (tid, row, zone, width, _ex), (height, data) in results:
            writer.add_wall_texture(tid, int(row[0]), int(row[1]), zone, width, height, media, data)
    writer.set_wall_sides([s.to_row() for s in plan.sides])
    return {
        "wall_sides": len(plan.sides),
        "wall_textures": len(plan.jobs),
        "wall_crossing": sum(len(v) for v in plan.crossing.values()),
        "wall_resumed": len(plan.jobs) - len(todo),
        "wall_texture_bytes": writer.wall_texture_bytes(),
        "wall_seconds": time.perf_counter() - t0,
    }


def bake_ring_walls(
    writer: SceneWriter,
    rings: RingCells,
    cells: Sequence[ViewCell],
    *,
    workers: int = 1,
    scheduler: str | None = None,
    progress: Callable[[int, int], None] | None = None,
    say: Callable[[str], None] = lambda _msg: None,
) -> dict[str, Any]:
    """A city's rings (:mod:`~.ringwalls`): planned from the stored PVS, their textures
    made as an interior's (:func:`bake_walls`), then each ringed cell's PVS cut to what
    stays geometry.  The cut comes last, so a bake killed while it rendered resumes
    from the full PVS to the same plan.

    Returns
    -------
    dict
        As :func:`bake_walls`, and ``ring_cells`` (cells with a ring), ``ring_removed``
        (cell-object pairs taken out of the geometry PVS), ``ring_radius_median`` (m).
    """
    st = rings.settings.outdoors()
    plan = plan_ring_walls(cells, writer.stored_pvs(), rings.boxes, st, view_distance=rings.view_distance)
    say(f"virtual walls: rings around {len(plan.kept)} of {len(cells)} cells, "
        f"{plan.removed} cell-object pairs carried by their textures")
    out = bake_walls(writer, rings.scene, plan.walls, st, rings.key, workers=workers,
                     scheduler=scheduler, progress=progress, say=say)
    full = writer.stored_pvs()
    for cid, ids in sorted(plan.kept.items()):
        # what the ring carries, kept apart (all before the first cut): the client draws
        # it as geometry while a texture of the ring in view has not arrived
        whole = full.get(cid, np.zeros(0, np.int64))
        far = np.setdiff1d(whole, ids)
        cover, total = writer.stored_coverage(cid, far), float(writer.stored_coverage(cid, whole).sum())
        writer.set_ring_far(cid, far, cover, float(cover.sum()) / total if total > 0.0 else 0.0)
    for cid, ids in sorted(plan.kept.items()):
        writer.set_pvs(cid, ids, writer.stored_coverage(cid, ids))
    out.update({
        "ring_cells": len(plan.kept),
        "ring_removed": plan.removed,
        "ring_radius_median": float(np.median(list(plan.radius.values()))) if plan.radius else 0.0,
    })
    return out
