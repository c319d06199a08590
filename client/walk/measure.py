"""The frame step ``measure``: the frame log, the walk's per-frame figures, the notes for the ground truth.

Download quality is the share of what the frame's model makes visible (the PVS
objects and the visible room cells, at the rooms' default fog) that has arrived,
rewrite quality the share also built; a frame whose visible set is not known yet
counts :attr:`~walkstream.client.walk.scene.WalkScene.unknown_quality`.  The frame's
time goes to the budget controller.

Everything the ground truth needs is noted here, in the one
:class:`~walkstream.client.truth.recorder.TruthRecorder`, and compared after the walk
(:func:`compare_truth`): every city object and every room part at full detail.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import httpx
import numpy as np
from numpy.typing import NDArray

from walkstream.client.clock import Clock
from walkstream.client.draw.quads import quads_of
from walkstream.client.report.framelog import FrameLog
from walkstream.client.report.metrics import first_perfect_index
from walkstream.client.stream.cache import Cache
from walkstream.client.truth.recorder import TruthResult
from walkstream.client.truth.seam import SeamWall
from walkstream.client.walk.figures import MODEL_PORTALS, MODEL_PVS
from walkstream.client.walk.state import Frame, WalkState
from walkstream.client.walk.visible import OUTDOOR_FOG_M
from walkstream.client.walk.walls import wall_quads
from walkstream.shared.codec.cellmesh import CellMesh
from walkstream.shared.frustum import frustum_cull
from walkstream.shared.roomwire import Topology

__all__ = ["measure", "note_truth", "compare_truth", "unseen_stand_ins"]


def _whole_enough(mesh: CellMesh | None, cid: int, f: Frame) -> bool:
    """Whether a visible cell's contents serve the frame: in memory, whole or a head
    whose missing pieces the frame's culling drops (:attr:`Frame.heads_clear`)."""
    return mesh is not None and (not mesh.missing or cid in f.heads_clear)


def measure(w: WalkState, f: Frame) -> None:
    """Log the frame, its figures and its truth notes; feed the controller."""
    scene, city, rooms = w.scene, w.scene.streets, w.scene.rooms
    o = w.objects
    # a missing object whose box (a stand-in, known before it) the frustum drops is not waited for
    unseen = unseen_stand_ins(o.pvs, city.start_feed.stand_ins, w.scene.cache, f.vp) if city is not None else set()
    have_obj = sum(1 for i in o.pvs if i not in unseen and city.has_object(i)) if city is not None else 0
    waiting = [c for c in f.default_room_cells if rooms is not None and not _whole_enough(rooms.mesh(c), c, f)]
    have_rooms = len(f.default_room_cells) - len(waiting)
    if rooms is not None:
        rooms.note_missing(f.t, waiting)
    # outdoors with rings of walls: the textures of the ring in view are content too
    have_walls = f.wall_due - f.wall_missing
    items = len(o.pvs) - len(unseen) + len(f.default_room_cells) + f.wall_due
    known = (f.room is not None) if w.indoors else (city is not None and f.street is not None and f.street in city.cells)
    empty = 1.0 if known else scene.unknown_quality
    dq = (have_obj + have_rooms + have_walls) / items if items else empty
    rq = (len(o.geoms) + have_rooms + have_walls) / items if items else empty
    note_truth(w, f)
    fr = w.frames
    if rooms is not None:
        e = scene.entrance
        if e is not None and f.held and f.room == e.doorway:
            fr.loaded[w.frame] = frozenset(c for c in rooms.cells if rooms.mesh(c) is not None)
        fr.model.append(MODEL_PORTALS if w.indoors else MODEL_PVS)
        fr.room.append(f.room if f.held and f.room is not None else -1)
        fr.rooms_visible.append(len(f.room_cells))
        fr.objects_visible.append(len(o.pvs))
        fr.fog_m.append(f.fog)
        fr.budget.append(f.budget)
    if w.scene.wall_images is not None:
        fr.walls.append(len(f.walls))
        fr.walls_closed.append(sum(1 for d in f.walls if d.alpha >= 1.0))
        fr.wall_bytes.append(sum({d.image: d.nbytes for d in f.walls}.values()))
        if not w.indoors and city is not None:
            fr.far_field.append(int(f.ring_far))
            fr.texture_missing.append(int(f.wall_missing))
    if not w.indoors and city is not None:  # objects drawn as geometry: no quad counted (walls, facades, impostors)
        fr.geometry.append(int((f.lods >= 0).sum()))
        lods = np.asarray(f.lods, np.int64)  # none without an allocation
        fr.note_lods(f.t - w.t_start, np.fromiter((g.id for g in o.geoms[:len(lods)]), np.int64, len(lods)), lods)
    if w.facades is not None and not w.indoors:
        fr.facades.append(len(f.facades))
        fr.facade_quads.append(len(f.facade_quads))
        fr.facade_bake.append(f.facade_bake)
        fr.facade_bytes.append(sum(s.nbytes for s in f.facades))
        fr.facade_swaps.append(w.facades.swapped)
    if w.scene.images is not None:
        fr.impostors.append(len(f.impostors))
        fr.texture_bytes.append(sum({d.image: d.nbytes for d in f.impostors}.values()))
    if w.indoors:  # the room held, or kept on a threshold where no street cell takes over
        cell = f.room if f.room is not None and (f.held or city is None) else -1
    else:
        cell = -1 if f.street is None else int(f.street)
    alloc = f.alloc
    f.perfect = cell >= 0 and min(dq, rq) >= 1.0 - 1e-9  # as the frame log counts it
    w.builder.append(
        t=f.t - w.t_start, frame_time=f.frame_time, cell=cell, pvs=len(o.pvs) + len(f.room_cells),
        download_quality=dq, rewrite_quality=rq, bytes_down=w.bytes_down(), budget=f.budget,
        triangles=f.triangles, visible=f.drawn,
        floor_limited=alloc is not None and bool(alloc.floor_limited),
        all_lod2=alloc is not None and bool(alloc.all_max),
    )
    if w.controller is not None:
        # on the fog's lever a frame under its budget (facing a wall) times the device's
        # jitter, not its triangles (client/draw/budget.py, "Noise or cost")
        w.controller.observe(f.frame_time, f.triangles,
                             under_budget_is_noise=w.indoors and w.config.fog_budget)


def unseen_stand_ins(pvs: list[int], boxes: dict[int, tuple[NDArray[np.float64], NDArray[np.float64]]],
                     cache: Cache, vp: NDArray[np.float64]) -> set[int]:
    """The objects of ``pvs`` not rebuilt yet whose stand-in box in ``boxes`` (``lo``,
    ``hi`` (3,) each) the frustum of ``vp`` ``(4, 4)`` drops: the frame draws none of
    them, whole or not (:mod:`~walkstream.shared.codec.objectboxes`)."""
    if not boxes:
        return set()
    ids = [i for i in pvs if i in boxes and cache.peek("geom", i) is None]
    if not ids:
        return set()
    lo = np.stack([boxes[i][0] for i in ids])
    hi = np.stack([boxes[i][1] for i in ids])
    keep = frustum_cull(lo, hi, vp)
    return {i for i, k in zip(ids, keep.tolist(), strict=True) if not k}


def note_truth(w: WalkState, f: Frame) -> None:
    """Note the frame for the ground truth when it is due (``truth_every``): the city
    objects drawn (with their LOD) and the visible set's, the room parts drawn, the
    visible cells still waiting for their contents, the fog in force."""
    rec = w.recorder
    if rec is None or not rec.due(w.frame):
        return
    city, rooms = w.scene.streets, w.scene.rooms
    parts = [(c, k) for c, mk in f.masks.items() for k in np.flatnonzero(mk).tolist()]
    waiting = [c for c in f.room_cells if not _whole_enough(f.loaded.get(c), c, f)]
    t = f.t - w.t_start
    if rooms is None:  # streets only: the city's figures (late and missed pixels by cause)
        assert city is not None
        cache = w.scene.cache
        cell = city.cells.get(f.street) if f.street is not None else None
        rec.record(
            frame=w.frame, t=t, eye=f.eye, view=f.view.astype(np.float32), cell=f.street,
            pvs=None if cell is None else cell.pvs,
            received=cache.ids(city.kind) + cache.ids("geom"), built=cache.ids("geom"),
            geoms=w.objects.geoms, lods=f.lods, impostors=_quads(w, f), facades=f.facade_quads,
            wall_quads=[] if w.scene.wall_images is None else wall_quads(f.walls, w.scene.wall_images.image),
        )
    elif city is None:  # rooms only: at the fog the frame was drawn at (the budget's lever)
        rec.record(frame=w.frame, t=t, eye=f.eye, view=f.view, parts=parts, waiting=waiting, fog=float(f.fog),
                   walls=[d.corners for d in f.walls if d.alpha >= 1.0],
                   wall_quads=[] if w.scene.wall_images is None else wall_quads(f.walls, w.scene.wall_images.image),
                   seam_walls=[SeamWall(d.portal, d.side, d.image, d.mix_image, d.mix, d.alpha, d.corners, d.warps)
                               for d in f.walls])
    else:
        # outdoors before the street cell's record: no visible set known, nothing culled
        unknown = not w.indoors and (f.street is None or f.street not in city.cells)
        o = w.objects
        rec.record(
            frame=w.frame, t=t, eye=f.eye, view=f.view, geoms=o.geoms, lods=f.lods,
            pvs=None if unknown else o.pvs, built=[g.id for g in o.geoms], parts=parts, waiting=waiting,
            fog=f.fog if w.indoors else OUTDOOR_FOG_M,
        )


async def compare_truth(
    w: WalkState,
    log: FrameLog,
    inner: tuple[httpx.AsyncBaseTransport, str],
    scene_name: str,
    topology: Topology | None,
    clock: Clock,
    progress: Callable[[int, int], None] | None,
) -> TruthResult | None:
    """After the walk (the streamers closed; ``clock.busy()``: no simulated time passes),
    compare the noted frames with the ground truth on the unshaped transport ``inner``.

    The entrance's building is left out of the truth (its parameters are a stand-in
    inside the rooms' shell, which stands for it), and the contents of an interior kept
    in its own frame are placed as the rooms' streamer placed them.
    """
    if w.recorder is None:
        return None
    e = w.scene.entrance
    first = first_perfect_index(log)
    with clock.busy():
        return await w.recorder.finish(
            inner[0], inner[1], scene_name, clock=clock,
            cells=[] if topology is None else [c.id for c in topology.cells],
            leave_out=[] if e is None else [e.building],
            placements=() if w.scene.rooms is None else w.scene.rooms.placements,
            t_first_perfect=None if first is None else float(log.t[first]), progress=progress,
        )


def _quads(w: WalkState, f: Frame) -> list[tuple[int, Any]]:
    """``(object id, quad)`` of the frame's impostors whose images are held."""
    lane = w.scene.images
    if lane is None or not f.impostors:
        return []
    return [(d.object, q) for d in f.impostors for q in quads_of([d], lane.image)]
