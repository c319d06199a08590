"""One frame loop for every scene: a pipeline of named steps, each timed.

A city scene is a scene with street cells only, an interior one with room cells
only, a crossing one with both (:class:`~walkstream.client.walk.scene.WalkScene`);
the loop asks each frame which model the current cell has, never the scene's kind.
Each frame, at the clock's tick (``fps``), the viewer moves along the path and these
steps run in order, each a module of this package and a phase of
:class:`~walkstream.client.draw.phases.FramePhases` (``phases.csv``, ``phases.png``):

``locate`` (:mod:`.locate`)
    Which cell holds the eye: a street cell (PVS) or a room cell (portals).
``wants`` (:mod:`.wants`)
    What the walk asks for beyond the streamers' own plans (the interior ahead of an entrance).
``visible`` (:mod:`.visible`)
    The visible set by the current cell's model: the street cell's PVS or the portal walk.
``build`` (:mod:`.build`)
    Rebuilds the visible PVS lacks (room contents are decoded as they arrive).
``allocate`` (:mod:`.allocate`)
    One budget controller, its lever by the model: triangles outdoors, fog indoors.
``upload``, ``draw`` (:mod:`.draw`)
    The frame's meshes onto the renderer; the frame shown (a simulated device's cost
    model or the real draw), the snapshot.
``measure`` (:mod:`.measure`)
    The frame log, the walk's figures, the ground truth's notes, the controller fed.

A frame that finished before the next tick waits for it; one that took longer is
shown late and the next starts at once.  Under the real clock the wait first bakes
facade pictures while it lasts (:func:`~walkstream.client.walk.facades.bake_in_slack`).  Under the simulated clock the same code runs
on virtual time.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from walkstream.client.content.cellmesh import CELLMESH_CONTENT
from walkstream.client.draw.phases import FramePhases
from walkstream.client.report.framelog import FrameLog
from walkstream.client.walk.allocate import allocate
from walkstream.client.walk.build import build
from walkstream.client.walk.draw import draw, forget_flushed, upload
from walkstream.client.walk.facades import bake_in_slack
from walkstream.client.walk.locate import locate
from walkstream.client.walk.measure import measure
from walkstream.client.walk.state import Frame, WalkState
from walkstream.client.walk.visible import visible
from walkstream.client.walk.wants import wants
from walkstream.shared.camera import camera

__all__ = ["STEPS", "walk"]

STEPS: tuple[tuple[str, Callable[[WalkState, Frame], None]], ...] = (
    ("locate", locate),
    ("wants", wants),
    ("visible", visible),
    ("build", build),
    ("allocate", allocate),
    ("upload", upload),
    ("draw", draw),
    ("measure", measure),
)
"""The frame's steps in order, each with its phase name."""

FORGET_EVERY = 25
"""Frames between two passes forgetting what the loop keeps of flushed room cells."""


async def walk(
    w: WalkState, phases: FramePhases, progress: Callable[[float, float], None] | None = None
) -> tuple[FrameLog, list[Path], NDArray[np.bool_]]:
    """Walk ``w.path`` through ``w.scene`` (see the module docstring).

    Returns the frame log, the snapshot files and the per-frame spike flags (the
    simulated device's stalls); ``w.frames`` gets the walk's own figures and ``phases``
    each step's seconds.
    """
    cfg, clock, scene = w.config, w.clock, w.scene
    tick = 1.0 / cfg.fps

    def walk_span() -> float:
        # while only the path's head is in, the walk's end is not known yet
        end = math.inf if w.path_pending else w.path.duration
        return end if cfg.duration_s is None else min(cfg.duration_s, end)

    total = walk_span()
    t_walk0 = clock.now()
    if scene.streets is not None:
        scene.streets.walk_end = t_walk0 + total
    rooms = scene.rooms
    if rooms is not None:
        w.indoor_fog = rooms.config.fog_m
    w.indoors = scene.starts_indoors
    e = scene.entrance
    if e is not None and rooms is not None:
        w.door = np.asarray(next(p[4] for p in rooms.topology.portals if p[0] == e.portal), np.float64).mean(axis=0)
    last_progress = -math.inf
    # a walker stands at the start until its first view is complete (at most start_hold_s):
    # indoors and, when the start bundle brings the first view first (cfg.street_hold), on the street
    holding = cfg.start_hold_s > 0 and ((rooms is not None and scene.streets is None)
                                        or (scene.streets is not None and rooms is None and scene.streets.start_feed.first_view))
    hold_end = t_walk0 + cfg.start_hold_s
    while True:
        t = clock.now()
        wt = t - t_walk0
        if holding and t < hold_end:
            w.frames.start_hold_s += wt
            t_walk0, wt = t, 0.0
            if scene.streets is not None:  # the walk ends later by the time it stood
                scene.streets.walk_end = t_walk0 + total
        holding = holding and t < hold_end
        if w.path_pending and wt > w.path.duration:
            # the whole path is still on its way: the walker waits at the head's end
            w.frames.path_wait_s += wt - w.path.duration
            t_walk0 += wt - w.path.duration
            wt = w.path.duration
        total = walk_span()
        if wt > total:
            break
        phases.begin()
        if progress is not None and wt - last_progress >= 1.0:
            last_progress = wt
            progress(wt, total if math.isfinite(total) else w.path.duration)
        xyz, yaw, pitch = w.path.at(wt)
        eye = np.asarray(xyz, dtype=np.float64)
        view = camera(eye, float(yaw), float(pitch)).astype(np.float64)
        f = Frame(t=t, wt=wt, eye=eye, view=view, vp=w.proj @ view)
        for name, step in STEPS:
            step(w, f)
            phases.mark(name)
            if name == "draw" and w.renderer is not None and (f.snap or not w.device.simulated):
                phases.move("draw", "finish", w.renderer.last_finish_s)
        # the walk leads within seconds into the cells still on the link (the start bundle's
        # other cells, the first prefetch; on the street the bundle's): the walker waits for them too
        # (on a city baked with walls not the parts for the later poses: they come while it walks)
        busy = rooms.busy() if rooms is not None else scene.streets is not None and scene.streets.start_feed.holding
        holding = holding and not (f.perfect and not busy)
        w.frame += 1
        if w.frame % FORGET_EVERY == 0:
            forget_flushed(w)
        phases.end()
        if w.facades is not None and not clock.simulated:  # facade pictures in the frame's slack
            bake_in_slack(w, t + tick - clock.now())
        await clock.sleep_until(t + max(f.frame_time, tick))
    if rooms is not None:
        rooms.fog_m = w.indoor_fog
        if w.renderer is not None:
            for key in list(w.meshes):
                w.renderer.forget(CELLMESH_CONTENT.gpu_key(*key))
    if progress is not None:
        progress(total, total)  # finite: the loop ends only once the whole path is in
    return w.builder.build(fps_cap=cfg.fps), w.snapshots, np.array(w.spikes, dtype=bool)
