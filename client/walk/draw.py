"""The frame steps ``upload`` and ``draw``: what the frame draws onto the renderer, and the frame shown.

The simulated device's frame time comes from its cost model (the renderer draws only
when a snapshot is due), the ``gl`` device's from the real draw
(:func:`~walkstream.client.draw.present.present`), or from a recorded frame schedule
(``--frame-times``: a replay repeated exactly).  Objects are uploaded as
``(id, lod)``, room parts under their content kind's key
(:data:`~walkstream.client.content.cellmesh.CELLMESH_CONTENT`); the frame's impostors
(:mod:`walkstream.client.walk.impostors`) go to the renderer as textured quads
(:mod:`walkstream.client.draw.quads`), drawn over the meshes, after the facade
textures of the boxes (:mod:`walkstream.client.walk.facades`).
"""

from __future__ import annotations

from collections.abc import Hashable

from walkstream.client.content.cellmesh import CELLMESH_CONTENT
from walkstream.client.draw.present import present, save_snapshot
from walkstream.client.draw.quads import quads_of
from walkstream.client.walk.scene import STREET_FAR_M
from walkstream.client.walk.state import Frame, WalkState
from walkstream.client.walk.walls import wall_quads

__all__ = ["upload", "draw", "forget_flushed", "forget_cell"]


def upload(w: WalkState, f: Frame) -> None:
    """Upload what the frame draws (when it is drawn: a real device, or a snapshot due)."""
    snap = w.config.snapshot_every
    f.snap = bool(snap and w.frame % snap == 0)
    r = w.renderer
    if r is None or not (f.snap or not w.device.simulated):
        return
    if w.scene.rooms is not None:
        r.fog_m = f.fog if w.indoors else STREET_FAR_M
    keys: list[Hashable] = []
    for g, lod in zip(w.objects.geoms, f.lods.tolist(), strict=True):
        if lod >= 0 and g.meshes[lod] is not None:
            key: Hashable = (g.id, int(lod))
            if not r.has(key):
                r.upload(key, g.meshes[lod])
            keys.append(key)
    for cid, cm in f.loaded.items():
        for k, ok in enumerate(f.masks[cid].tolist()):
            if ok and cm.parts[k].triangles:  # a head's stand-in has none
                m = w.meshes.get((cid, k))
                if m is None:
                    m = w.meshes[(cid, k)] = cm.parts[k].mesh()
                keys.append(CELLMESH_CONTENT.upload(r, cid, k, m))
    f.keys = keys
    lane, walls = w.scene.images, w.scene.wall_images
    if hasattr(r, "impostors") and (lane is not None or walls is not None or w.facades is not None):
        # over the meshes: the quads (the boxes' facades first, then the images)
        r.impostors = list(f.facade_quads) + ([] if lane is None else quads_of(f.impostors, lane.image)) + (
            [] if walls is None else wall_quads(f.walls, walls.image))


def draw(w: WalkState, f: Frame) -> None:
    """Show the frame: its time on the device, the device's stall, the snapshot."""
    f.frame_time, spike = present(w.device, w.renderer, f.keys, f.view, w.proj, f.triangles, f.drawn, f.snap)
    schedule = w.config.frame_times
    if schedule is not None and w.frame < len(schedule):  # a recorded schedule: the walk repeats
        f.frame_time = schedule[w.frame]
    w.spikes.append(spike)
    shot = save_snapshot(w.renderer, w.config.report_dir, w.frame) if f.snap else None
    if shot is not None:
        w.snapshots.append(shot)


def forget_flushed(w: WalkState) -> None:
    """Forget what the frame loop keeps of room cells whose contents were flushed (boxes,
    meshes, GPU buffers)."""
    rooms = w.scene.rooms
    if rooms is None:
        return
    for c in [c for c in w.boxes if rooms.mesh(c) is None]:
        forget_cell(w, c)


def forget_cell(w: WalkState, cid: int) -> None:
    """Forget what the frame loop made of room cell ``cid``'s contents (boxes, meshes,
    GPU buffers): flushed, or a head replaced by the whole cell."""
    for key in [k for k in w.meshes if k[0] == cid]:
        if w.renderer is not None:
            w.renderer.forget(CELLMESH_CONTENT.gpu_key(*key))
        del w.meshes[key]
    w.boxes.pop(cid, None)
    w.part_triangles.pop(cid, None)
    w.boxed.pop(cid, None)
