"""The walk of a crossing scene: from a street through a door into the rooms and back, one frame loop.

A crossing scene holds cells of both visibility models: street cells with a PVS
(and ACH per object), room cells with portals, joined at an entrance portal (street
cell <-> doorway).  The walk runs on one link (:class:`~walkstream.client.net.link.ShapedTransport`)
with one :class:`~walkstream.client.stream.cache.Cache`: the city
:class:`~walkstream.client.stream.streamer.Streamer` keeps cell records, parameters
and geometry (its kinds), the :class:`~walkstream.client.stream.rooms.RoomStreamer`
the rooms' contents (kind ``cellmesh``, by cell id), each pinning its own kinds.

Each frame runs these steps, in order:

``locate``
    Indoors when a room cell's planes hold the eye; on the street when a street cell
    of the city's index holds it; otherwise (on the threshold) where it was.
``visible``
    By the current cell's model.  *Indoors*: the portal walk from the room cell
    (:func:`~walkstream.shared.portals.cull_portals`); when it reaches the street (the
    entrance portal leads to the street cell, which the topology holds as a
    :attr:`~walkstream.client.stream.rooms.RoomStreamer.foreign` cell) or the
    building's outside (its windows), the street cell's PVS is visible too.
    *On the street*: the current street cell's PVS; the building whose entrance this
    is stands in it as its shell (the interior's ``outside`` cell,
    :class:`~walkstream.shared.roomwire.Entrance`), never as its own parameters
    (a stand-in inside the shell), and when it does, a portal walk from the shell
    through its openings (the entrance, the windows) gives the rooms seen from the
    street, out to :data:`OUTDOOR_FOG_M`.
``wants``
    The rooms' streamer fetches the visible cells, the shell, then (prefetch) the
    interior ahead of the door: once the city's predicted route reaches the
    entrance's street cell, or the door is within
    :data:`~walkstream.client.stream.entrance.DOOR_AHEAD_S` seconds' walk, the rooms
    :mod:`~walkstream.client.stream.entrance` names, in the order the walk comes to them; the city
    streamer plans its own wants (records and objects by need time).
``build``
    Geometry the current PVS lacks is rebuilt from parameters.
``allocate``
    One budget controller, its lever chosen by the current cell's model: triangles
    outdoors (ACH allocation of the PVS objects in the frustum, after the room parts
    drawn), fog indoors (the nearest room parts that fit the budget, the fog just
    beyond, :func:`~walkstream.client.roomreplay.fog_for_budget`).
``draw`` and ``measure``
    The simulated device's frame time (or the GL renderer's), the frame log: download
    quality is the share of what the frame's model makes visible (the PVS objects
    and the visible room cells) that has arrived, rewrite quality the share also built.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable, Hashable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import httpx
import numpy as np
from numpy.typing import NDArray

from walkstream.client.clock import Clock
from walkstream.client.config import ReplayConfig
from walkstream.client.draw.allocate import allocate_ach
from walkstream.client.draw.budget import BudgetController
from walkstream.client.draw.devices import make_device
from walkstream.client.draw.present import present, save_snapshot
from walkstream.client.net.api import SceneClient
from walkstream.client.net.link import ShapedTransport
from walkstream.client.report.link import link_figures
from walkstream.client.report.metrics import FrameLog, FrameLogBuilder, summarise
from walkstream.client.roomreplay import fog_for_budget
from walkstream.client.stream.cache import Cache
from walkstream.client.stream.entrance import DOOR_AHEAD_S, door_ahead, entrance_view, seen_ahead
from walkstream.client.stream.predict import MotionPredictor
from walkstream.client.stream.rooms import RoomStreamConfig, RoomStreamer
from walkstream.client.stream.streamer import Streamer
from walkstream.client.walk.crosstruth import UNKNOWN
from walkstream.shared.camera import camera, perspective
from walkstream.shared.codec.cellmesh import CellMesh
from walkstream.shared.errors import ApiError
from walkstream.shared.frustum import frustum_cull
from walkstream.shared.paths import RecordedPath
from walkstream.shared.portals import box_distance, cull_parts
from walkstream.shared.records import Mesh
from walkstream.shared.roomwire import ContentsRef, Entrance, RoomRecord, Topology
from walkstream.shared.wire import Manifest

__all__ = [
    "OUTDOOR_FOG_M",
    "MODEL_PVS",
    "MODEL_PORTALS",
    "CrossingFrames",
    "crossing_topology",
    "walk_crossing",
    "replay_crossing",
]

OUTDOOR_FOG_M = 800.0
"""Outdoors the rooms are seen through the shell's openings out to the bake's view
distance (the city's PVS has no fog)."""

MODEL_PVS = 0
"""The frame's visible set came from the street cell's PVS."""

MODEL_PORTALS = 1
"""The frame's visible set came from the portal walk of a room cell."""

_NEAR, _FAR = 0.1, 2000.0


@dataclass
class CrossingFrames:
    """Per-frame figures of a crossing walk beyond the frame log."""

    model: list[int] = field(default_factory=list)
    """:data:`MODEL_PVS` or :data:`MODEL_PORTALS`."""
    room: list[int] = field(default_factory=list)
    """The room cell holding the eye (-1 on the street)."""
    rooms_visible: list[int] = field(default_factory=list)
    """Room cells visible (drawn or waiting)."""
    objects_visible: list[int] = field(default_factory=list)
    """City objects in the visible PVS (the stand-in left out)."""
    fog_m: list[float] = field(default_factory=list)
    loaded: dict[int, frozenset[int]] = field(default_factory=dict)
    """Frames in the entrance's doorway: the room cells whose contents were in memory."""
    prefetch_from: float | None = None
    """Walk time at which the interior's prefetch began (None: never)."""
    notes: list[tuple[int, NDArray[np.float64], NDArray[np.float64], list[tuple[int, int]], float]] = field(
        default_factory=list
    )
    """Every ``truth_every``-th frame: index, eye, view, what was drawn or waited for
    (room parts ``(cell, part)``, ``(cell, -1)`` for a visible cell not received, city
    objects ``(-1 - id, 0)``), the fog in force."""

    def switches(self, t: NDArray[np.float64]) -> list[tuple[float, str]]:
        """``(walk time, model)`` each time the visible set's model changes (the first frame's too)."""
        out: list[tuple[float, str]] = []
        last = None
        for k, m in enumerate(self.model):
            if m != last:
                out.append((float(t[k]), "pvs" if m == MODEL_PVS else "portals"))
                last = m
        return out


def crossing_topology(topology: Topology, entrances: tuple[Entrance, ...]) -> Topology:
    """The interior's topology with each entrance's street cell added as a cell of its own
    (no planes: never located by them; no contents), its one portal the entrance: the
    portal walk then passes from the doorway to the street and from the street in."""
    portals = {p[0]: p for p in topology.portals}
    extra: list[RoomRecord] = []
    for e in entrances:
        pid, kind, a, b, poly = portals[e.portal]
        door = next(r for c in topology.cells if c.id == e.doorway for r in c.portals if r.id == e.portal)
        extra.append(RoomRecord(
            id=e.street, kind="street", name="street", room=None, storey=0, outline=np.zeros((0, 2)),
            zmin=-1e9, zmax=1e9, planes=np.zeros((0, 4)), portals=(replace(door, cell=e.doorway),),
            neighbours=(e.doorway,), contents=ContentsRef(0, 0, 0, 0, 0, 0.0),
        ))
    return replace(topology, cells=(*topology.cells, *extra))


class _Objects:
    """The city objects a frame may draw: the visible PVS (the stand-in left out) as arrays."""

    def __init__(self) -> None:
        self.key: tuple[Any, ...] | None = None
        self.pvs: list[int] = []
        self.geoms: list[Any] = []
        self.ach = np.zeros(0)
        self.tri = np.zeros((0, 3), np.int64)
        self.avail = np.zeros((0, 3), bool)
        self.lo = self.hi = np.zeros((0, 3))

    def update(self, cells: list[int], city: Streamer, cache: Cache, skip: int) -> None:
        key = (tuple((c, c in city.cells) for c in cells), city.geometry_version, sum(cache.evictions.values()))
        if key == self.key:
            return
        self.key = key
        ach: dict[int, float] = {}
        for c in cells:
            rec = city.cells.get(c)
            if rec is None:
                continue
            for oid, a in zip(rec.pvs.tolist(), rec.ach.tolist(), strict=True):
                if oid != skip:
                    ach[oid] = max(a, ach.get(oid, 0.0))
        self.pvs = list(ach)
        self.geoms = [g for oid in self.pvs if (g := cache.peek("geom", oid)) is not None]
        self.ach = np.array([ach[g.id] for g in self.geoms])
        if self.geoms:
            self.tri = np.stack([g.triangles for g in self.geoms])
            self.avail = np.stack([g.available for g in self.geoms])
            self.lo = np.stack([g.bbox_min for g in self.geoms])
            self.hi = np.stack([g.bbox_max for g in self.geoms])
        else:
            self.tri = np.zeros((0, 3), np.int64)
            self.avail = np.zeros((0, 3), bool)
            self.lo = self.hi = np.zeros((0, 3))


async def walk_crossing(
    config: ReplayConfig,
    clock: Clock,
    path: RecordedPath,
    city: Streamer,
    rooms: RoomStreamer,
    cache: Cache,
    entrance: Entrance,
    device: Any,
    renderer: Any,
    progress: Callable[[float, float], None] | None,
    t_start: float,
    bytes_down: Callable[[], int],
    frames: CrossingFrames,
) -> tuple[FrameLog, list[Path], NDArray[np.bool_]]:
    """Walk ``path`` through a crossing scene (see the module docstring).

    Returns the frame log, the snapshot files and the per-frame spike flags, like the
    city's and the interior's walks; ``frames`` gets the crossing's own figures.
    """
    e = entrance
    indoor_fog = rooms.config.fog_m
    controller = BudgetController(config.fps_target, k=config.budget_frames)
    predictor = MotionPredictor()
    objects = _Objects()
    builder = FrameLogBuilder()
    snapshots: list[Path] = []
    spikes: list[bool] = []
    boxes: dict[int, tuple[NDArray[np.float64], NDArray[np.float64]]] = {}
    meshes: dict[tuple[int, int], Mesh] = {}
    w, h = config.size
    proj = perspective(config.fov_deg, w / h, _NEAR, _FAR).astype(np.float64)
    tick = 1.0 / config.fps
    total = path.duration if config.duration_s is None else min(config.duration_s, path.duration)
    every = int(config.truth_every or 0)
    t_walk0 = clock.now()
    city.walk_end = t_walk0 + total
    frame = 0
    indoors = False
    room: int | None = None
    stepped = False
    last_progress = -math.inf
    planned = -math.inf
    seen: list[int] = []
    from_entrance: list[int] | None = None
    door = np.asarray(next(p[4] for p in rooms.topology.portals if p[0] == e.portal), np.float64).mean(axis=0)
    while True:
        t = clock.now()
        wt = t - t_walk0
        if wt > total:
            break
        if progress is not None and wt - last_progress >= 1.0:
            last_progress = wt
            progress(wt, total)
        xyz, yaw, pitch = path.at(wt)
        eye = np.asarray(xyz, dtype=np.float64)
        view = camera(eye, float(yaw), float(pitch)).astype(np.float64)
        vp = proj @ view
        # -- locate: a room's planes first, then the street cells; on the threshold, where it was
        predictor.observe(wt, eye[:2])
        street = city.tick(t, eye[:2], predictor)
        room = rooms.locate(eye)
        held = room is not None and rooms.holds(room, eye)
        on_street = city.cellmap.find(eye[:2], street) is not None
        indoors = held or (indoors and not on_street)
        # -- visible set by the current cell's model; the room streamer's wants with it
        speed = float(np.linalg.norm(predictor.velocity()))
        near_door = float(np.linalg.norm(eye[:2] - door[:2])) <= max(speed, 1.0) * DOOR_AHEAD_S
        soon = rooms.config.prefetch and (near_door or e.street in city.need or street == e.street)
        if soon and frames.prefetch_from is None:
            frames.prefetch_from = wt
        ahead: list[int] = []
        if soon and not indoors:
            if t - planned >= rooms.config.replan_s:
                planned = t
                seen = seen_ahead(rooms, e, eye, view, proj, (w, h), predictor.velocity(), door)
            if from_entrance is None:
                from_entrance = entrance_view(rooms, e, door, proj, (w, h))
            ahead = [*seen, *from_entrance, *door_ahead(rooms, e)]
        pvs_cells: list[int] = []
        shown: list[int] = []
        if indoors:
            rooms.fog_m = indoor_fog
            vis = rooms.tick(t, eye, vp, view, proj, (w, h), cell=room)
            if e.street in vis or e.shell in vis:  # the street through the door or a window
                pvs_cells = list(dict.fromkeys([e.street, *([street] if street is not None else [])]))
            fog = indoor_fog
        else:
            if street is not None:
                pvs_cells = [street]
            rec = city.cells.get(street) if street is not None else None
            shows_building = rec is not None and bool(np.any(rec.pvs == e.building))
            rooms.fog_m = OUTDOOR_FOG_M
            shown = [e.shell] if shows_building else []
            vis = rooms.tick(t, eye, vp, view, proj, (w, h), cell=e.street if street == e.street else None,
                             shown=shown, ahead=ahead)
            fog = OUTDOOR_FOG_M
        room_cells = [c for c in vis if c not in rooms.foreign]
        objects.update(pvs_cells, city, cache, e.building)
        # -- build: geometry the visible PVS lacks
        if city.rewrite is not None and len(objects.geoms) < len(objects.pvs):
            city.ensure_geometry(objects.pvs)
        # -- allocate: room parts (culled by portals, fog and frustum), then the objects
        loaded: dict[int, CellMesh] = {}
        for cid in room_cells:
            cm = rooms.mesh(cid)
            if cm is None:
                continue
            loaded[cid] = cm
            if cid not in boxes:
                b = [p.bbox for p in cm.parts]
                boxes[cid] = (np.array([x[0] for x in b]).reshape(-1, 3), np.array([x[1] for x in b]).reshape(-1, 3))
        pc = rooms.last_cull
        walked = [c for c in loaded if pc is not None and c in pc.vsas]
        masks = cull_parts(rooms.config.culling, walked, boxes, eye, view, proj, (w, h),
                           vsas=None if pc is None else pc.vsas, fog_m=fog)
        # a cell drawn besides the portal walk's (the shell from the street): the frustum's test
        whole = [c for c in loaded if c not in masks or c in shown]
        for c, m in cull_parts("frustum", whole, boxes, eye, view, proj, (w, h), fog_m=fog).items():
            masks[c] = masks[c] | m if c in masks else m
        budget = int(controller.budget)
        if indoors and config.fog_budget:  # indoors the budget's lever is the fog
            fog = fog_for_budget(masks, boxes, loaded, eye, budget, fog)
            for cid, mask in masks.items():
                lo, hi = boxes[cid]
                mask &= box_distance(lo, hi, eye) <= fog
        room_tris = sum(p.triangles for cid, cm in loaded.items() for p, ok in zip(cm.parts, masks[cid].tolist(), strict=True) if ok)
        room_parts = sum(int(m.sum()) for m in masks.values())
        visible = frustum_cull(objects.lo, objects.hi, vp) if objects.geoms else np.zeros(0, bool)
        if indoors and len(visible):  # what the fog hides indoors is hidden outdoors too
            visible &= box_distance(objects.lo, objects.hi, eye) <= fog
        alloc = allocate_ach(objects.ach, objects.tri, objects.avail, visible, max(budget - room_tris, 0), reserve_floor=True)
        if config.cost_step_at_s is not None and not stepped and wt >= config.cost_step_at_s:
            device.cost_scale = device.cost_scale * config.cost_step_factor
            stepped = True
        triangles = int(alloc.triangles) + room_tris
        drawn = room_parts + int((alloc.lod >= 0).sum())
        # -- draw
        snap = config.snapshot_every and frame % config.snapshot_every == 0
        keys: list[Hashable] = []
        if renderer is not None and (snap or not device.simulated):
            renderer.fog_m = fog if indoors else _FAR
            keys = _upload(renderer, objects.geoms, alloc.lod, loaded, masks, meshes)
        frame_time, spike = present(device, renderer, keys, view, proj, triangles, drawn, bool(snap))
        spikes.append(spike)
        shot = save_snapshot(renderer, config.report_dir, frame) if snap else None
        if shot is not None:
            snapshots.append(shot)
        # -- measure
        have_obj = sum(1 for i in objects.pvs if city.has_object(i))
        have_rooms = sum(1 for c in room_cells if c in loaded)
        items = len(objects.pvs) + len(room_cells)
        dq = (have_obj + have_rooms) / items if items else 1.0
        rq = (len(objects.geoms) + have_rooms) / items if items else 1.0
        if every and frame % every == 0:
            kept = [(c, k) for c, mk in masks.items() for k in np.flatnonzero(mk).tolist()]
            kept += [(c, -1) for c in room_cells if c not in loaded]
            built = {g.id for g in objects.geoms}
            kept += [(-1 - g.id, 0) for g, lod in zip(objects.geoms, alloc.lod.tolist(), strict=True) if lod >= 0]
            kept += [(-1 - i, 0) for i in objects.pvs if i not in built]  # late, not culled
            if not indoors and (street is None or street not in city.cells):
                kept.append(UNKNOWN)
            frames.notes.append((frame, eye.copy(), view.copy(), kept, fog if indoors else OUTDOOR_FOG_M))
        if held and room == e.doorway:
            frames.loaded[frame] = frozenset(c for c in rooms.cells if rooms.mesh(c) is not None)
        frames.model.append(MODEL_PORTALS if indoors else MODEL_PVS)
        frames.room.append(room if held and room is not None else -1)
        frames.rooms_visible.append(len(room_cells))
        frames.objects_visible.append(len(objects.pvs))
        frames.fog_m.append(fog)
        builder.append(
            t=t - t_start, frame_time=frame_time,
            cell=(room if held and room is not None else -1) if indoors else (-1 if street is None else int(street)),
            pvs=items, download_quality=dq, rewrite_quality=rq, bytes_down=bytes_down(), budget=budget,
            triangles=triangles, visible=drawn,
            floor_limited=bool(alloc.floor_limited), all_lod2=bool(alloc.all_max),
        )
        controller.observe(frame_time, triangles)
        frame += 1
        if frame % 25 == 0:
            for c in [c for c in boxes if rooms.mesh(c) is None]:
                del boxes[c]
        await clock.sleep_until(t + max(frame_time, tick))
    rooms.fog_m = indoor_fog
    if progress is not None:
        progress(total, total)
    return builder.build(fps_cap=config.fps), snapshots, np.array(spikes, dtype=bool)


def _upload(
    renderer: Any,
    geoms: list[Any],
    lods: NDArray[Any],
    loaded: dict[int, CellMesh],
    masks: dict[int, NDArray[np.bool_]],
    meshes: dict[tuple[int, int], Mesh],
) -> list[Hashable]:
    """Upload what the frame draws (objects as ``(id, lod)``, room parts as ``("cell", cell, part)``)."""
    keys: list[Hashable] = []
    for g, lod in zip(geoms, lods.tolist(), strict=True):
        if lod >= 0 and g.meshes[lod] is not None:
            key: Hashable = (g.id, int(lod))
            if not renderer.has(key):
                renderer.upload(key, g.meshes[lod])
            keys.append(key)
    for cid, cm in loaded.items():
        for k, ok in enumerate(masks[cid].tolist()):
            if ok:
                key = ("cell", cid, k)
                if not renderer.has(key):
                    m = meshes.get((cid, k))
                    if m is None:
                        m = meshes[(cid, k)] = cm.parts[k].mesh()
                    renderer.upload(key, m)
                keys.append(key)
    return keys


async def replay_crossing(
    api: SceneClient,
    link: ShapedTransport,
    clock: Clock,
    config: ReplayConfig,
    path: RecordedPath,
    city: Streamer,
    cache: Cache,
    manifest_fut: asyncio.Future[Manifest],
    t_start: float,
    setup_s: float,
    progress: Callable[[float, float], None] | None,
    inner: tuple[httpx.AsyncBaseTransport, str],
) -> tuple[dict[str, Any], FrameLog, list[Path], NDArray[np.bool_]]:
    """The walk of a crossing scene on the replay's link, cache and city streamer.

    Fetches the topology and the entrances (concurrently), walks, compares with the
    ground truth after the walk (``config.truth_every``, on the unshaped transport of
    ``inner``), and returns the summary, the frame log, the snapshots and the spikes.
    """
    topology, entrances = await asyncio.gather(api.topology(), api.entrances())
    if not entrances:
        raise ApiError(f"scene {api.scene!r} is a crossing without an entrance")
    entrance = entrances[0]
    setup_s = clock.now() - t_start  # the walk starts once the rooms' topology is in too
    rooms = RoomStreamer(
        api, clock, cache, crossing_topology(topology, entrances),
        RoomStreamConfig(prefetch=config.prefetch, fog_m=config.fog_m, culling=config.culling, **config.rooms),
        foreign=[x.street for x in entrances], scheduler=city.scheduler,  # one scheduler owns the link
    )
    device = make_device(config.device, config.seed)
    renderer: Any = None
    frames = CrossingFrames()
    try:
        if not device.simulated or config.snapshot_every:
            from walkstream.client.draw.frames import FrameRenderer

            renderer = FrameRenderer(size=config.size, fov_deg=config.fov_deg, near=_NEAR)
        log, snapshots, spikes = await walk_crossing(
            config, clock, path, city, rooms, cache, entrance, device, renderer, progress, t_start,
            lambda: int(link.stats.bytes_down), frames,
        )
    finally:
        await rooms.close()
        await city.close()
        if renderer is not None:
            renderer.release()
    truth = None
    if config.truth_every:
        from walkstream.client.walk.crosstruth import crossing_truth

        with clock.busy():
            truth = await crossing_truth(
                inner[0], inner[1], api.scene or "", [c.id for c in topology.cells], entrance, frames.notes,
                config.size, config.fov_deg, clock,
            )
    manifest = manifest_fut.result() if manifest_fut.done() and not manifest_fut.cancelled() else None
    step = None
    if config.cost_step_at_s is not None and len(log.t):
        step = int(np.searchsorted(log.t - log.t[0], config.cost_step_at_s))
    summary = summarise(log, fps_target=config.fps_target, fps_cap=config.fps, t_start=0.0, cost_step=step,
                        recovery_ignore=spikes)
    summary.update(link_figures(config, link.stats, api))
    summary.update(_figures(config, log, frames, city, rooms, cache, entrance, setup_s, path, manifest))
    summary["truth"] = truth
    return summary, log, snapshots, spikes


def _figures(
    config: ReplayConfig,
    log: FrameLog,
    frames: CrossingFrames,
    city: Streamer,
    rooms: RoomStreamer,
    cache: Cache,
    e: Entrance,
    setup_s: float,
    path: RecordedPath,
    manifest: Manifest | None,
) -> dict[str, Any]:
    """The crossing's figures of a replay's summary (beyond the frame log's and the link's)."""
    wt = np.asarray(log.t, np.float64) - (float(log.t[0]) if len(log.t) else 0.0)
    room = np.asarray(frames.room)
    inside = np.flatnonzero((room >= 0) & (room != e.doorway))
    first_in = int(inside[0]) if len(inside) else None
    first_room = int(room[first_in]) if first_in is not None else None
    # the doorway's frames on the way in: each must already hold the first room's contents
    door_in = [k for k in frames.loaded if first_in is None or k < first_in]
    lacking = [k for k in door_in if first_room is not None and first_room not in frames.loaded[k]]
    door_t = float(wt[min(frames.loaded)]) if frames.loaded else None
    return {
        "kind": "crossing",
        "scene_version": None if manifest is None else manifest.version,
        "path_duration_s": path.duration,
        "walk_s": float(wt[-1]) if len(wt) else 0.0,
        "setup_s": setup_s,
        "entrance": e.to_wire(),
        "model_switches": [[round(t, 3), m] for t, m in frames.switches(wt)],
        "frames_pvs": int(sum(1 for m in frames.model if m == MODEL_PVS)),
        "frames_portals": int(sum(1 for m in frames.model if m == MODEL_PORTALS)),
        "first_room": first_room,
        "door_frames": len(door_in),
        "door_frames_without_first_room": len(lacking),
        "door_reached_s": door_t,
        "interior_prefetch_from_s": frames.prefetch_from,
        "rooms_visible_max": max(frames.rooms_visible, default=0),
        "objects_visible_max": max(frames.objects_visible, default=0),
        "fog_m_min": float(min(frames.fog_m)) if frames.fog_m else None,
        "object_requests": city.stats.object_requests,
        "objects_received": city.stats.objects_received,
        "cell_requests": city.stats.cell_requests,
        "index_requests": city.stats.tile_requests,
        "object_bytes": int(sum(city.stats.object_bytes.values())),
        "cell_bytes": int(sum(city.stats.cell_bytes.values())),
        "contents_requests": rooms.stats.requests,
        "contents_bytes": rooms.stats.bytes_received,
        "cells_fetched": len(rooms.stats.fetched),
        "contents_redownloads": rooms.stats.refetched,
        "cache_bytes": config.cache_bytes,
        "cache_peak_bytes": int(cache.peak_bytes),
        "cache_entries": cache.stats()["entries"],
    }
