"""The frame step ``allocate``: what the frame draws under the budget, its lever chosen by the current cell's model.

Room parts first: the visible cells' parts culled by ``config.culling`` (against the
portal walk's visible screen areas, the fog and the frustum), a cell drawn besides the
portal walk's (an entrance's shell from the street) by the frustum.  Then one budget
controller, two levers: *indoors* the fog (one LOD per part, so the nearest parts that
fit the budget are drawn and the fog is set just beyond, :func:`fog_for_budget`), *on
the street* the triangles (the ACH allocation of the PVS objects in the frustum,
``lod_select == "distance"`` the usual distance bands instead), after the room parts
drawn; the impostors of the current cell (:mod:`.impostors`) first, two triangles and
one draw each, their buildings' geometry left out where the image stands alone and
kept at its LOD while the image blends over it (:func:`~.impostors.hold_blend_lods`);
while the budget binds, the LOD hold (:mod:`.lodhold`) holds the most the draws before
the objects took off their share and lets a LOD that just fell not rise, so
nothing flips with the budget.  The device's cost step (``cost_step_at_s``) is applied here too.
"""

from __future__ import annotations

import dataclasses
import math
import time
from typing import Any

import numpy as np
from numpy.typing import NDArray

from walkstream.client.draw.allocate import allocate_ach, allocate_distance
from walkstream.client.walk.draw import forget_cell
from walkstream.client.walk.facades import bake_facades, choose_facades, facade_avail
from walkstream.client.walk.impostors import frame_impostors, hold_blend_lods, replaced
from walkstream.client.walk.lodhold import held_share, note_lod_changes
from walkstream.client.walk.state import Frame, WalkState
from walkstream.shared.codec.cellmesh import CellMesh
from walkstream.shared.frustum import frustum_cull
from walkstream.shared.partcull import PartRects, cull_parts
from walkstream.shared.portalgraph import PortalGraph
from walkstream.shared.portals import PortalCull, box_distance
from walkstream.shared.trianglecull import refine_parts

__all__ = ["allocate", "fog_for_budget", "kept_distances", "nearest_portal_in_view"]


def allocate(w: WalkState, f: Frame) -> None:
    """Set the frame's room parts (``f.masks``), object LODs (``f.alloc``), triangles and draws."""
    cfg, rooms = w.config, w.scene.rooms
    room_tris = room_parts = 0
    if rooms is not None:
        _cull_rooms(w, f)
        room_tris = sum(int(w.part_triangles[cid][f.masks[cid]].sum()) for cid in f.loaded)
        room_parts = sum(int(m.sum()) for m in f.masks.values())
    else:
        f.budget = int(w.controller.budget) if w.controller is not None else 0
    if w.scene.streets is not None:
        o = w.objects
        seen = frustum_cull(o.lo, o.hi, f.vp) if o.geoms else np.zeros(0, bool)
        if w.indoors and len(seen):  # what the fog hides indoors is hidden outdoors too
            seen &= box_distance(o.lo, o.hi, f.eye) <= f.fog
        f.impostors = [] if w.indoors else frame_impostors(w, f)
        if f.impostors and len(seen):  # a building drawn as its image alone: no geometry
            seen &= ~replaced([g.id for g in o.geoms], f.impostors)
        # the walls' depth meshes (--wall-depth) come out of the objects' share too
        quad_tris = 2 * len(f.impostors) + sum(d.triangles - 2 for d in f.walls)
        if w.facades is not None and not w.indoors:  # the bake and last frame's facade quads come first
            quad_tris += 2 * w.facades.last_quads
            floor = int(o.tri[seen & o.avail[:, 0], 0].sum()) if len(seen) else 0
            f.facade_bake = bake_facades(w, f, f.budget - room_tris - quad_tris - floor)
            quad_tris += f.facade_bake
        avail = o.avail if w.facades is None or w.indoors else facade_avail(w)
        if cfg.lod_select == "ach":
            own = max(f.budget - room_tris - quad_tris, 0)
            # held while the budget binds: no flips with the share's swing
            share, caps = held_share(w, f, own, o.tri, avail, seen)
            f.alloc = allocate_ach(o.ach, o.tri, avail, seen, share,
                                   reserve_floor=True, greedy=cfg.lod_greedy, cap=caps)
            if f.alloc.floor_limited and share < own:  # limited by the frame's own share, not the hold
                low = np.argmax(avail, axis=1)
                drawable = seen & avail.any(axis=1)
                floor = int(o.tri[drawable, low[drawable]].sum())
                f.alloc = dataclasses.replace(f.alloc, floor_limited=floor > own)
        else:
            centre = (o.lo + o.hi) / 2.0
            dist = np.hypot(centre[:, 0] - f.eye[0], centre[:, 1] - f.eye[1])
            f.alloc = allocate_distance(dist, o.tri, avail, seen, cfg.lod_distances)
        hold_blend_lods(w, f)  # a building under its blending image keeps its LOD
        note_lod_changes(w, f)  # a LOD that just changed does not go up again for a while
    if cfg.cost_step_at_s is not None and not w.stepped and f.wt >= cfg.cost_step_at_s:
        w.device.cost_scale = w.device.cost_scale * cfg.cost_step_factor
        w.stepped = True
    lods = f.lods
    # a wall texture is a quad as an impostor is: two triangles and one draw (and its
    # depth mesh's triangles, --wall-depth)
    f.triangles = room_tris + 2 * len(f.impostors) + sum(d.triangles for d in f.walls) + (
        0 if f.alloc is None else int(f.alloc.triangles))
    f.drawn = room_parts + len(f.impostors) + len(f.walls) + int((lods >= 0).sum())
    f.triangles += f.facade_bake
    if w.facades is not None and not w.indoors:
        choose_facades(w, f)


def _cull_rooms(w: WalkState, f: Frame) -> None:
    """The visible room cells' parts to draw (``f.loaded``, ``f.masks``), the fog's lever indoors."""
    rooms = w.scene.rooms
    assert rooms is not None
    tri_s = 0.0
    boxes = w.boxes
    for cid in f.room_cells:
        cm = rooms.mesh(cid)
        if cm is None:
            continue
        f.loaded[cid] = cm
        if cid in boxes and w.boxed.get(cid) is not cm:  # a head made whole
            forget_cell(w, cid)
        if cid not in boxes:
            w.boxed[cid] = cm
            b = [p.bbox for p in cm.parts]
            boxes[cid] = (np.array([x[0] for x in b]).reshape(-1, 3), np.array([x[1] for x in b]).reshape(-1, 3))
            w.part_triangles[cid] = np.array([p.triangles for p in cm.parts], np.int64)
    pc = rooms.last_cull
    culling = rooms.config.culling
    cached = rooms.cull_cache if rooms.cull_cache is not None and rooms.cull_cache.last is not None else None
    if cached is not None:  # the guard's parts (--cull-cache), copied: the fog budget cuts them
        masks = cached.masks(f.loaded)
        walked = list(masks)
        if rooms.config.cull_cache == "frustum":  # the frame's own frustum cuts the guard's wider view
            for c, m in cull_parts("frustum", walked, boxes, f.eye, f.view, w.proj, w.size, fog_m=f.fog).items():
                masks[c] &= m
    elif pc is not None:
        walked = [c for c in f.loaded if c in pc.vsas]
    else:  # no portal walk: the chosen culling on its own ("portals" without one keeps nothing)
        walked = [] if culling == "portals" else list(f.loaded)
    rects = PartRects()  # the boxes' rectangles, made once for both tests
    if cached is None:
        masks = cull_parts(culling, walked, boxes, f.eye, f.view, w.proj, w.size,
                           vsas=None if pc is None else pc.vsas, fog_m=f.fog, rects=rects)
    if culling == "portals" and pc is not None and w.config.triangle_cull:
        # the parts the boxes kept, tested again by their triangles (never adds one)
        t_tri = time.thread_time()
        w.frames.triangle_culled += refine_parts(masks, f.loaded, pc.vsas, f.view, w.proj, w.size, rects=rects)
        tri_s = time.thread_time() - t_tri
    # a cell drawn besides the portal walk's (the shell from the street): the frustum's test
    whole = [c for c in f.loaded if c not in masks or c in f.shown]
    for c, m in (cull_parts("frustum", whole, boxes, f.eye, f.view, w.proj, w.size, fog_m=f.fog).items()
                 if whole else ()):
        masks[c] = masks[c] | m if c in masks else m
    # a head walked to whose stand-ins the culling drops, at the default fog, draws all it
    # would draw whole; any other head is waiting for its cell
    for c in walked:
        if not f.loaded[c].missing:  # a whole cell (most): no array to make
            continue
        gone = np.asarray(f.loaded[c].missing, np.int64)
        if len(gone) and c not in whole and cached is not None:
            if cached.head_clear(c, gone):
                f.heads_clear.add(c)
        elif len(gone) and c not in whole and pc is not None:
            lo, hi = boxes[c]
            if not cull_parts(culling, [c], {c: (lo[gone], hi[gone])}, f.eye, f.view, w.proj, w.size,
                              vsas=pc.vsas, fog_m=rooms.config.fog_m)[c].any():
                f.heads_clear.add(c)
    lever = w.controller is not None and (w.scene.streets is not None or w.config.fog_budget)
    f.budget = int(w.controller.budget) if lever and w.controller is not None else 0
    if w.indoors and w.config.fog_budget:  # indoors the budget's lever is the fog
        # the kept parts' distances, once: the fog is chosen on them and then cuts them
        kept = kept_distances(masks, boxes, f.eye)
        f.fog = fog_for_budget(masks, boxes, f.loaded, f.eye, f.budget, f.fog, w.part_triangles, kept=kept)
        for cid, (idx, d) in kept.items():
            masks[cid][idx[d > f.fog]] = False
        if pc is not None and f.fog < nearest_portal_in_view(rooms.graph, pc, f.eye):
            w.frames.fog_below_portal += 1
    f.masks = masks
    w.frames.cull_s.append(time.thread_time() - f.t_cull - rooms.plan_s)
    w.frames.triangle_s.append(tri_s)
    w.frames.walk_s.append(rooms.walk_s)
    w.frames.portals.append(0 if pc is None else pc.portals)


def nearest_portal_in_view(graph: PortalGraph, pc: PortalCull, eye: NDArray[np.float64]) -> float:
    """The distance from ``eye`` to the nearest portal of the walk's first cell that the
    portal walk looked through (``inf`` when it looked through none): a fog nearer than
    this hides every room beyond the viewer's own."""
    if not pc.order or pc.order[0] not in graph.index:
        return math.inf
    i = graph.index[pc.order[0]]
    rows = np.arange(int(graph.start[i]), int(graph.start[i + 1]))
    if not len(rows):
        return math.inf
    seen = np.array([int(graph.ids[t]) in pc.vsas for t in graph.target[rows].tolist()], bool)
    if not seen.any():
        return math.inf
    return float(box_distance(graph.lo[rows[seen]], graph.hi[rows[seen]], eye).min())


def kept_distances(
    masks: dict[int, NDArray[np.bool_]],
    boxes: dict[int, tuple[NDArray[np.float64], NDArray[np.float64]]],
    eye: NDArray[np.float64],
) -> dict[int, tuple[NDArray[np.int64], NDArray[np.float64]]]:
    """Per cell with a kept part, the kept parts' indices ``(k,)`` into ``masks[cid]`` and
    their boxes' distances ``(k,)`` from ``eye`` ``(3,)`` (:func:`box_distance`), in the
    cells' order: what the fog is chosen on (:func:`fog_for_budget`) and then cuts."""
    picks = [(cid, np.flatnonzero(m)) for cid, m in masks.items()]
    picks = [(cid, idx) for cid, idx in picks if len(idx)]
    if not picks:
        return {}
    # every cell's kept boxes in one batch (a box's distance is its own row's)
    d = box_distance(np.concatenate([boxes[cid][0][idx] for cid, idx in picks]),
                     np.concatenate([boxes[cid][1][idx] for cid, idx in picks]), eye)
    ends = np.cumsum([len(idx) for _, idx in picks]).tolist()
    return {cid: (idx, d[end - len(idx):end]) for (cid, idx), end in zip(picks, ends, strict=True)}


def fog_for_budget(
    masks: dict[int, NDArray[np.bool_]],
    boxes: dict[int, tuple[NDArray[np.float64], NDArray[np.float64]]],
    loaded: dict[int, CellMesh] | dict[int, Any],
    eye: NDArray[np.float64],
    budget: int,
    fog: float,
    part_triangles: dict[int, NDArray[np.int64]] | None = None,
    *,
    kept: dict[int, tuple[NDArray[np.int64], NDArray[np.float64]]] | None = None,
) -> float:
    """The fog distance at which the kept parts, nearest first, fit ``budget`` triangles
    (``fog`` itself when they all fit; never below 2 m); ``part_triangles``: each cell's
    triangles per part, when the caller keeps them (else counted here); ``kept``: the
    kept parts' indices and distances (:func:`kept_distances`), when the caller has them."""
    if kept is None:
        kept = kept_distances(masks, boxes, eye)
    dist: list[NDArray[np.float64]] = []
    tris: list[NDArray[np.int64]] = []
    for cid, (idx, d) in kept.items():
        dist.append(d)
        counts = part_triangles.get(cid) if part_triangles is not None else None
        if counts is None:
            counts = np.array([p.triangles for p in loaded[cid].parts], np.int64)
        tris.append(counts[idx])
    if not dist:
        return fog
    d = np.concatenate(dist)
    n = np.concatenate(tris)
    order = np.argsort(d, kind="stable")
    total = np.cumsum(n[order])
    if total[-1] <= budget:
        return fog
    k = int(np.searchsorted(total, budget, side="right"))  # parts 0..k-1 fit
    return max(2.0, min(fog, float(d[order[k]]) - 1e-6))
