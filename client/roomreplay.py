"""The replay's start and frame loop on an interior scene (what :func:`~walkstream.client.replay.replay`
runs when the manifest's kind is ``interior``).

Setup (:func:`~walkstream.client.stream.walkstart.interior_start`) asks for the interior start bundle: the path (compact),
the topology (compact: every cell's outline and every portal, in millimetres) and the
manifest in one round trip.  When that fails before the path and the topology are
in, the replay falls back to scene list, manifest and path, then the topology
(compact, unless the replay asks for nothing compressed).  Then,
frame by frame: move the eye along the path, let the
:class:`~walkstream.client.stream.rooms.RoomStreamer` locate it by the cells' planes,
find the visible cells and fetch their contents; draw the parts of the visible cells'
contents that the culling keeps (``config.culling``, :mod:`walkstream.shared.portals`),
fading into the background near the fog distance (``--fog``):
``portals`` tests each part's box against the VSAs through which its cell is seen,
the fog and the frustum; ``frustum`` the frustum and the fog; ``none`` keeps every
part.  Indoors there is one LOD per part, so no polygon budget is shared; the budget
column of the log stays 0.  The CPU time of the culling (cells and parts) and the
portals opened per frame are kept in :class:`InteriorFrames`.

Per frame, download quality is the share of the visible cells whose contents are in
memory and rewrite quality the share that is also on the GPU (the same here: decoded
contents are uploaded in the frame they are drawn), so a perfect frame is one where
everything visible has arrived.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Hashable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from walkstream.client.clock import Clock
from walkstream.client.config import ReplayConfig
from walkstream.client.content.cellmesh import CELLMESH_CONTENT
from walkstream.client.draw.budget import BudgetController
from walkstream.client.draw.present import present, save_snapshot
from walkstream.client.report.metrics import FrameLog, FrameLogBuilder
from walkstream.client.stream.rooms import RoomStreamer
from walkstream.client.truth.recorder import TruthRecorder
from walkstream.shared.camera import camera
from walkstream.shared.paths import RecordedPath
from walkstream.shared.portals import box_distance, cull_parts
from walkstream.shared.records import Mesh
from walkstream.shared.roomview import room_projection
from walkstream.shared.roomwire import Topology
from walkstream.shared.wire import Manifest

__all__ = ["InteriorFrames", "fog_for_budget", "interior_summary", "walk_interior"]


@dataclass
class InteriorFrames:
    """Per-frame figures of an interior walk beyond the frame log: culling seconds
    (cells and parts), portals opened, and the fog distance in force."""

    cull_s: list[float] = field(default_factory=list)
    portals: list[int] = field(default_factory=list)
    fog_m: list[float] = field(default_factory=list)
    budget: list[int] = field(default_factory=list)
    tightened: int = 0
    """Frames on which the visible cells did not fit the memory budget at the default
    fog, so the fog was tightened until they did (the paper's use of fog)."""

    def figures(self) -> dict[str, float]:
        """Median, p95 and max culling milliseconds per frame, and portals opened per frame."""
        if not self.cull_s:
            return {}
        ms = np.asarray(self.cull_s) * 1e3
        return {
            "culling_ms_median": float(np.median(ms)),
            "culling_ms_p95": float(np.percentile(ms, 95)),
            "culling_ms_max": float(ms.max()),
            "portals_mean": float(np.mean(self.portals)),
            "portals_max": int(np.max(self.portals)),
        }

    def series(self, log: FrameLog) -> dict[str, NDArray[np.float64]]:
        """Per frame: visible cells, portals opened, triangles, culling ms, fog m (the report's plot)."""
        return {
            "cells": np.asarray(log.pvs, np.float64),
            "portals": np.asarray(self.portals, np.float64),
            "triangles": np.asarray(log.triangles, np.float64),
            "cull_ms": 1e3 * np.asarray(self.cull_s, np.float64),
            "fog_m": np.asarray(self.fog_m, np.float64),
        }


async def walk_interior(
    config: ReplayConfig,
    clock: Clock,
    path: RecordedPath,
    streamer: RoomStreamer,
    device: Any,
    renderer: Any,
    progress: Callable[[float, float], None] | None,
    t_start: float,
    bytes_down: Callable[[], int],
    frames: InteriorFrames | None = None,
    recorder: TruthRecorder | None = None,
) -> tuple[FrameLog, list[Path], NDArray[np.bool_]]:
    """Walk ``path`` through an interior (see the module docstring).

    Returns the frame log, the snapshot files and the per-frame spike flags, like
    the city's walk; ``frames``, when given, gets the culling figures of each frame,
    ``recorder`` what the ground truth needs of every N-th.
    """
    culling = streamer.config.culling
    default_fog = streamer.config.fog_m
    # one LOD per part: the polygon budget has nothing to choose, so it sets the fog
    # distance (the nearest parts that fit the budget are drawn, the fog just beyond)
    controller = BudgetController(config.fps_target, k=config.budget_frames) if config.fog_budget else None
    stepped = False
    boxes: dict[int, tuple[NDArray[np.float64], NDArray[np.float64]]] = {}
    tick = 1.0 / config.fps
    total = path.duration if config.duration_s is None else min(config.duration_s, path.duration)
    w, h = config.size
    proj = room_projection(config.fov_deg, (w, h), streamer.config.fog_m)
    builder = FrameLogBuilder()
    snapshots: list[Path] = []
    spikes: list[bool] = []
    meshes: dict[tuple[int, int], Mesh] = {}
    t_walk0 = clock.now()
    frame = 0
    last_progress = -math.inf
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
        view = camera(eye, float(yaw), float(pitch))
        v64, p64 = view.astype(np.float64), proj
        vp = p64 @ v64
        t_cull = time.perf_counter()
        # the perfect frame is defined at the scene's default fog: the visible cells
        # (fetched, and counted in the quality) are those within it, unless they do not
        # fit the memory budget, when the fog tightens until they do
        streamer.fog_m = default_fog
        vis = streamer.tick(t, eye, vp, v64, p64, (w, h))
        vis_default = list(vis)
        fog = default_fog
        while streamer.visible_bytes(vis) > streamer.cache.budget_bytes and fog > 2.0:
            fog *= 0.8
            streamer.fog_m = fog
            vis = streamer.visible_cells(eye, vp, v64, p64, (w, h))
        if fog < default_fog and frames is not None:
            frames.tightened += 1
        loaded = {}
        for cid in vis:
            cm = streamer.mesh(cid)
            if cm is None:
                continue
            loaded[cid] = cm
            if cid not in boxes:
                b = [p.bbox for p in cm.parts]
                boxes[cid] = (np.array([x[0] for x in b]).reshape(-1, 3), np.array([x[1] for x in b]).reshape(-1, 3))
        pc = streamer.last_cull
        masks = cull_parts(
            culling, list(loaded), boxes, eye, v64, p64, (w, h),
            vsas=None if pc is None else pc.vsas, fog_m=fog,
        )
        budget = 0
        if controller is not None:
            budget = int(controller.budget)
            fog = fog_for_budget(masks, boxes, loaded, eye, budget, fog)
            for cid, mask in masks.items():
                lo, hi = boxes[cid]
                mask &= box_distance(lo, hi, eye) <= fog
        if renderer is not None:
            renderer.fog_m = fog
        if frames is not None:
            # the prefetch's prediction is streaming work, not this frame's culling
            frames.cull_s.append(time.perf_counter() - t_cull - streamer.plan_s)
            frames.portals.append(0 if pc is None else pc.portals)
            frames.fog_m.append(fog)
            frames.budget.append(budget)
        draw_keys: list[Hashable] = []
        triangles = 0
        parts = 0
        for cid, cm in loaded.items():
            if not cm.parts:
                continue
            for k, (part, ok) in enumerate(zip(cm.parts, masks[cid].tolist(), strict=True)):
                if not ok:
                    continue
                triangles += part.triangles
                parts += 1
                if renderer is not None:
                    m = meshes.get((cid, k))
                    if m is None:
                        m = meshes[(cid, k)] = part.mesh()
                    draw_keys.append(CELLMESH_CONTENT.upload(renderer, cid, k, m))
        if recorder is not None and recorder.due(frame):
            # a visible cell not yet received is not a culled one: its parts count as kept
            recorder.record(frame=frame, t=t - t_start, eye=eye, view=v64,
                            parts=[(c, k) for c, mk in masks.items() for k in np.flatnonzero(mk).tolist()],
                            waiting=[c for c in vis if c not in loaded], fog=float(streamer.fog_m))
        quality = sum(1 for c in vis_default if streamer.mesh(c) is not None) / len(vis_default) if vis_default else 0.0
        snap = config.snapshot_every and frame % config.snapshot_every == 0
        if config.cost_step_at_s is not None and not stepped and wt >= config.cost_step_at_s:
            device.cost_scale = device.cost_scale * config.cost_step_factor
            stepped = True
        frame_time, spike = present(device, renderer, draw_keys, view, proj, triangles, parts, bool(snap))
        spikes.append(spike)
        shot = save_snapshot(renderer, config.report_dir, frame) if snap else None
        if shot is not None:
            snapshots.append(shot)
        builder.append(
            t=t - t_start,
            frame_time=frame_time,
            cell=-1 if streamer.current is None else int(streamer.current),
            pvs=len(vis),
            download_quality=quality,
            rewrite_quality=quality,
            bytes_down=bytes_down(),
            budget=budget,
            triangles=triangles,
            visible=parts,
        )
        if controller is not None:
            controller.observe(frame_time, triangles)
        frame += 1
        if renderer is not None and frame % 25 == 0:
            # a flushed cell's GPU buffers go with it
            for key in [k for k in meshes if streamer.mesh(k[0]) is None]:
                renderer.forget(CELLMESH_CONTENT.gpu_key(*key))
                del meshes[key]
        if frame % 25 == 0:
            for c in [c for c in boxes if streamer.mesh(c) is None]:
                del boxes[c]
        await clock.sleep_until(t + max(frame_time, tick))
    streamer.fog_m = default_fog
    if renderer is not None:
        for key in list(meshes):
            renderer.forget(CELLMESH_CONTENT.gpu_key(*key))
    if progress is not None:
        progress(total, total)
    return builder.build(fps_cap=config.fps), snapshots, np.array(spikes, dtype=bool)


def interior_summary(
    config: ReplayConfig,
    log: FrameLog,
    streamer: RoomStreamer,
    frames: InteriorFrames,
    topology: Topology,
    cache: Any,
    setup_s: float,
    path: RecordedPath,
    manifest: Manifest | None,
) -> dict[str, Any]:
    """The interior figures of a replay's summary (beyond the frame log's and the link's)."""
    entered = {int(c) for c in np.unique(log.cell) if c >= 0}
    return {
        "kind": "interior",
        "scene_version": None if manifest is None else manifest.version,
        "path_duration_s": path.duration,
        "walk_s": float(log.t[-1] - log.t[0]) if len(log.t) else 0.0,
        "setup_s": setup_s,
        "cells_entered": len(entered),
        "cells_in_scene": len(topology.cells),
        "topology_bytes": topology.nbytes,
        "visible_cells_mean": float(np.mean(log.pvs)) if len(log.pvs) else 0.0,
        "visible_cells_max": int(np.max(log.pvs)) if len(log.pvs) else 0,
        "contents_requests": streamer.stats.requests,
        "start_contents_cells": streamer.stats.bundled,
        "contents_bytes": streamer.stats.bytes_received,
        "cells_fetched": len(streamer.stats.fetched),
        "cells_flushed": streamer.stats.flushed,
        "redownloads": streamer.stats.refetched,
        "flush_policy": streamer.config.flush_policy, "flush_after_s": streamer.config.flush_s,
        "fog_m": config.fog_m,
        "culling": config.culling,
        **frames.figures(),
        "fog_budget": config.fog_budget,
        "fog_m_median": float(np.median(frames.fog_m)) if frames.fog_m else config.fog_m,
        "fog_m_min": float(np.min(frames.fog_m)) if frames.fog_m else config.fog_m,
        "fog_tightened_frames": frames.tightened,
        "cache_bytes": config.cache_bytes,
        "cache_peak_bytes": int(cache.peak_bytes),
    }


def fog_for_budget(
    masks: dict[int, NDArray[np.bool_]],
    boxes: dict[int, tuple[NDArray[np.float64], NDArray[np.float64]]],
    loaded: dict[int, Any],
    eye: NDArray[np.float64],
    budget: int,
    fog: float,
) -> float:
    """The fog distance at which the kept parts, nearest first, fit ``budget`` triangles
    (``fog`` itself when they all fit; never below 2 m)."""
    dist: list[NDArray[np.float64]] = []
    tris: list[NDArray[np.int64]] = []
    for cid, m in masks.items():
        if not m.any():
            continue
        lo, hi = boxes[cid]
        dist.append(box_distance(lo[m], hi[m], eye))
        tris.append(np.array([p.triangles for p in loaded[cid].parts], np.int64)[m])
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
