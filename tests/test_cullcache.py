"""The culling reused frame to frame (shared/cullcache.py): never hides what a frame sees.

Without GL: over pose sequences (turning on the spot, walking, walking while turning) in
the bench's open hall, every part the frame's own culling keeps is kept by the cache on
every frame, hits and misses alike; pose sequences where a cached answer would be wrong
(a turn past the guard towards a door, a step past its reach towards a door, another
cell, a cell's boxes replaced) are misses and find what the frame sees.  With GL: at the
doors of a generated office, frames within a guard made a turn and a step earlier show no
culled pixel against the id truth.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from portalscene import SIZE, PortalScene
from test_portals import _corridor

from walkstream.benchmarks.cullcpu import hall_boxes
from walkstream.benchmarks.portals import hall_topology
from walkstream.client.truth.culled import check_kept
from walkstream.shared.camera import camera, perspective
from walkstream.shared.cullcache import CullCache
from walkstream.shared.partcull import cull_parts
from walkstream.shared.portalgraph import PortalGraph
from walkstream.shared.portals import cull_portals

VIEW = (320, 240)
PROJ = perspective(60.0, VIEW[0] / VIEW[1], 0.1, 100.0).astype(np.float64)


def _exact(graph: PortalGraph, start: int, eye: np.ndarray, view: np.ndarray, boxes: Any, size: tuple[int, int] = VIEW,
           proj: np.ndarray = PROJ) -> dict[int, np.ndarray]:
    pc = cull_portals(graph, start, eye, view, proj, size)
    return cull_parts("portals", pc.order, boxes, eye, view, proj, size, vsas=pc.vsas)


def _dropped(cached: dict[int, np.ndarray], exact: dict[int, np.ndarray]) -> int:
    """Parts the frame's own culling keeps and the cache does not."""
    return sum(int(m.sum()) if c not in cached else int((m & ~cached[c]).sum()) for c, m in exact.items())


def _hall() -> tuple[PortalGraph, Any]:
    return PortalGraph.from_topology(hall_topology(6)), hall_boxes(6)


def test_turning_walking_and_both_keep_every_part_the_frame_keeps() -> None:
    graph, boxes = _hall()
    for name, step, turn in (("turn", 0.0, 1.0), ("walk", 0.056, 0.0), ("both", 0.056, 0.7)):
        cache = CullCache(graph)
        for i in range(60):
            eye = np.array([0.5, 0.5, 1.6]) + i * step * np.array([math.sqrt(0.5), math.sqrt(0.5), 0.0])
            view = camera(eye, math.radians(20.0 + turn * i), 0.05 * math.sin(i / 7)).astype(np.float64)
            start = int(eye[1] // 4) * 6 + int(eye[0] // 4)
            got = cache.cull(start, eye, view, PROJ, VIEW, boxes)
            assert _dropped(got.masks, _exact(graph, start, eye, view, boxes)) == 0, (name, i)
        # the next guard, made a quarter a frame ahead of the pose five frames on, is ready
        # before the walk or the turn leaves the last one: a miss at the start only (7-10
        # misses without making ahead)
        assert cache.misses == 1, name
        # most frames reuse a guard; the first is always a miss
        assert cache.misses >= 1 and cache.hits >= 50, (name, cache.hits, cache.misses)


def test_the_masks_handed_out_cannot_be_changed_in_place() -> None:
    graph, boxes = _hall()
    eye = np.array([0.5, 0.5, 1.6])
    got = CullCache(graph).cull(0, eye, camera(eye, 0.6).astype(np.float64), PROJ, VIEW, boxes)
    with pytest.raises(ValueError):
        next(iter(got.masks.values()))[0] = True


def test_a_turn_past_the_guard_towards_a_door_is_a_miss_and_sees_through_it() -> None:
    # a corridor of three rooms along x: looking along -y the door at x = 4 is out of view;
    # turned to +x it shows room 1 behind it, which a stale answer would lack
    graph = PortalGraph.from_topology(_corridor(3))
    boxes = {c: (np.array([[4.0 * c + 1, -1.0, 0.0]]), np.array([[4.0 * c + 2, 1.0, 2.0]])) for c in range(3)}
    cache = CullCache(graph, turn_deg=10.0)
    eye = np.array([2.0, 0.0, 1.0])
    first = cache.cull(0, eye, camera(eye, -math.pi / 2).astype(np.float64), PROJ, VIEW, boxes)
    assert first.fresh and 1 not in first.order
    small = cache.cull(0, eye, camera(eye, -math.pi / 2 + math.radians(8.0)).astype(np.float64), PROJ, VIEW, boxes)
    assert not small.fresh  # within the guard: reused
    view = camera(eye, 0.0).astype(np.float64)
    turned = cache.cull(0, eye, view, PROJ, VIEW, boxes)
    assert turned.fresh and 1 in turned.order and turned.masks[1].all()
    assert _dropped(turned.masks, _exact(graph, 0, eye, view, boxes)) == 0


def test_a_step_past_the_reach_another_cell_or_new_boxes_is_a_miss() -> None:
    graph = PortalGraph.from_topology(_corridor(3))
    boxes = {c: (np.array([[4.0 * c + 1, -1.0, 0.0]]), np.array([[4.0 * c + 2, 1.0, 2.0]])) for c in range(3)}
    cache = CullCache(graph, move_m=0.3)
    # facing the wall beside the door from close by: the door's cell is beyond the view's edge
    eye = np.array([3.0, 1.9, 1.0])
    view = camera(eye, math.radians(40.0)).astype(np.float64)
    assert cache.cull(0, eye, view, PROJ, VIEW, boxes).fresh
    near = eye + np.array([0.1, 0.0, 0.0])
    assert not cache.cull(0, near, camera(near, math.radians(40.0)).astype(np.float64), PROJ, VIEW, boxes).fresh
    # a step back and to the side, past the guard's reach: the door comes into view
    back = np.array([2.0, 0.5, 1.0])
    bview = camera(back, math.radians(10.0)).astype(np.float64)
    got = cache.cull(0, back, bview, PROJ, VIEW, boxes)
    assert got.fresh and _dropped(got.masks, _exact(graph, 0, back, bview, boxes)) == 0 and 1 in got.order
    assert not cache.cull(0, back, bview, PROJ, VIEW, boxes).fresh
    # the same pose from another cell (the eye on the door's plane), or a cell's boxes
    # replaced (loaded anew): the guard is not used
    assert cache.cull(1, back, bview, PROJ, VIEW, boxes).fresh
    assert not cache.cull(1, back, bview, PROJ, VIEW, boxes).fresh
    boxes[2] = (boxes[2][0] + 0.0, boxes[2][1] + 0.5)
    assert cache.cull(1, back, bview, PROJ, VIEW, boxes).fresh


def test_another_fog_viewport_or_projection_is_a_miss() -> None:
    graph, boxes = _hall()
    cache = CullCache(graph)
    eye = np.array([0.5, 0.5, 1.6])
    view = camera(eye, 0.6).astype(np.float64)
    cache.cull(0, eye, view, PROJ, VIEW, boxes)
    assert not cache.cull(0, eye, view, PROJ, VIEW, boxes).fresh
    assert cache.cull(0, eye, view, PROJ, VIEW, boxes, fog_m=12.0).fresh
    assert cache.cull(0, eye, view, PROJ, (160, 120), boxes).fresh
    wide = perspective(75.0, VIEW[0] / VIEW[1], 0.1, 100.0).astype(np.float64)
    got = cache.cull(0, eye, view, wide, VIEW, boxes)
    assert got.fresh and _dropped(got.masks, _exact(graph, 0, eye, view, boxes, proj=wide)) == 0


@pytest.mark.gl
def test_frames_within_a_guard_show_no_culled_pixel_at_the_doors(office_db: Path, gl_ctx: Any) -> None:
    """The guard made at a door a turn and a step before; the frame then culled by it
    (a hit) and compared with the id truth of the whole building."""
    scene = PortalScene(office_db, gl_ctx)
    try:
        frames = hits = 0
        for k, (eye, yaw, pitch) in enumerate(scene.poses()):
            if k % 6:
                continue  # a sixth of the door poses keeps the test to a few seconds
            res = scene.frame(eye, yaw, pitch)
            if res is None:
                continue
            _, start, _ = res
            cache = CullCache(scene.graph, turn_deg=10.0, move_m=0.3)
            # the guard: a step of 0.25 m back along the view, turned 9 degrees away
            fwd = np.array([math.cos(yaw), math.sin(yaw), 0.0])
            before = eye - 0.2 * fwd
            sign = 1.0 if k % 2 else -1.0
            cache.cull(start, before, camera(before, yaw + sign * math.radians(9.0), pitch).astype(np.float64),
                       scene.proj, SIZE, scene.boxes)
            view = camera(eye, yaw, pitch).astype(np.float64)
            got = cache.cull(start, eye, view, scene.proj, SIZE, scene.boxes)
            hits += not got.fresh
            kept = [(c, i) for c, m in got.masks.items() for i in np.flatnonzero(m).tolist()]
            chk = check_kept(scene.truth, kept, eye, view)
            frames += 1
            assert chk.missed_pixels - chk.pinholes == 0, (eye.tolist(), yaw, chk.missed_pixels)
        assert frames >= 10 and hits >= 0.8 * frames, (frames, hits)
    finally:
        scene.release()


@pytest.mark.gl
def test_a_walk_along_the_tour_frame_by_frame_shows_no_culled_pixel(office_db: Path, gl_ctx: Any) -> None:
    """25 frames a second along the office's tour, every frame culled through one cache
    (most reuse a guard), every 6th compared with the id truth."""
    from walkstream.server.store import SceneReader
    from walkstream.shared.paths import RecordedPath
    from walkstream.shared.roomview import cell_of

    with SceneReader.open(office_db) as r:
        tour = RecordedPath.from_msgpack(r.path_blob("tour"))
    scene = PortalScene(office_db, gl_ctx)
    try:
        cache = CullCache(scene.graph)
        compared = 0
        for i, t in enumerate(np.arange(0.0, min(8.0, tour.duration), 1.0 / 25.0).tolist()):
            xyz, yaw, pitch = tour.at(t)
            eye = np.asarray(xyz, np.float64)
            hit = np.flatnonzero(cell_of(scene.planes, eye))
            if not len(hit):
                continue
            view = camera(eye, float(yaw), float(pitch)).astype(np.float64)
            got = cache.cull(int(scene.ids[hit[0]]), eye, view, scene.proj, SIZE, scene.boxes)
            if i % 6:
                continue
            kept = [(c, k) for c, m in got.masks.items() for k in np.flatnonzero(m).tolist()]
            chk = check_kept(scene.truth, kept, eye, view)
            compared += 1
            assert chk.missed_pixels - chk.pinholes == 0, (t, chk.missed_pixels)
        assert compared >= 25 and cache.hits >= 2 * cache.misses, (compared, cache.hits, cache.misses)
    finally:
        scene.release()


def test_a_replay_with_the_cull_cache_culls_no_pixel_the_truth_shows(office_db: Path, tmp_path: Path) -> None:
    """``replay --cull-cache``: the walk's culling reused frame to frame, and the truth
    still finds no culled pixel (the default, culled anew, in test_portals.py)."""
    import json

    from walkstream.cli import main

    rep = tmp_path / "cached"
    assert main(["replay", str(office_db), "--path", "tour", "--duration", "3", "--truth-every", "25",
                 "--size", "160x120", "--report", str(rep), "--cull-cache", "--no-plots"]) == 0
    s = json.loads((rep / "report.json").read_text())
    s = s.get("summary", s)
    assert s["truth"]["frames"] >= 3 and s["truth"]["culled_pixels"] == 0, s["truth"]
    # the cache served most frames: a walk at a steady pace misses where it starts and at turns
    assert s["cull_cache_hits"] > s["cull_cache_misses"] > 0, s


def test_the_cull_cache_is_an_opt_in_of_the_replay() -> None:
    import argparse

    from walkstream.cmd_replay import add_replay_arguments, config_from_args
    from walkstream.shared.errors import InputError

    parser = argparse.ArgumentParser()
    add_replay_arguments(parser)
    parser.add_argument("--report", default="report")
    got = [config_from_args(parser.parse_args(a)).rooms["cull_cache"]
           for a in ([], ["--cull-cache"], ["--cull-cache", "frustum"])]
    assert got == ["", "guard", "frustum"]
    with pytest.raises(SystemExit):  # a bad choice is refused by the parser, in one line
        parser.parse_args(["--cull-cache", "walls"])
    assert config_from_args(parser.parse_args([])).rooms["cull_guard"] == (0.3, 10.0)
    assert config_from_args(parser.parse_args(["--cull-guard", "0.1,3"])).rooms["cull_guard"] == (0.1, 3.0)
    for bad in ("0.1", "x,3", "0,3", "0.1,90", "nan,3"):
        with pytest.raises(InputError, match="--cull-guard"):
            config_from_args(parser.parse_args(["--cull-guard", bad]))
