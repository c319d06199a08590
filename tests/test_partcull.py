"""The parts culling's fast path (shared/partcull.py) against the plain forms it replaces.

:func:`~walkstream.shared.partcull.cull_parts` packs a scene's boxes once (a table checked
by identity on every frame), projects every visible box from its two corners in one batch
(:func:`~walkstream.shared.screenrects.box_rects_ckm`) into buffers reused from frame to
frame.  Each of those could go stale or alias: these tests change the boxes between frames,
keep one frame's answer across the next, and compare the rectangles with the eight-corner
projection, boxes across the clip plane and behind the eye included.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from walkstream.benchmarks.cullcpu import hall_boxes
from walkstream.benchmarks.portals import hall_topology
from walkstream.shared import partcull
from walkstream.shared.camera import camera, perspective
from walkstream.shared.partcull import cull_boxes, cull_parts, part_table
from walkstream.shared.portalgraph import PortalGraph
from walkstream.shared.portals import cull_portals
from walkstream.shared.screenrects import BOX_EDGES, box_corners_ckm, box_rects_ckm, rects_ckm

SIZE = (320, 240)
PROJ = perspective(60.0, SIZE[0] / SIZE[1], 0.1, 60.0).astype(np.float64)


def _want(cells: list[int], boxes: dict, vsas: dict, eye: np.ndarray, view: np.ndarray, fog: float) -> dict:
    return {c: cull_boxes(*boxes[c], vsas[c], eye, view, PROJ, SIZE, fog_m=fog) for c in cells if c in boxes}


def _same(got: dict, want: dict) -> bool:
    """Conservative and close: every box the exact test keeps is kept, and few more (a box
    that crosses the clip plane is tested by an unclipped superset of its rectangle)."""
    if got.keys() != want.keys() or any(np.any(want[c] & ~got[c]) for c in want):
        return False
    extra = sum(int(np.sum(got[c] & ~want[c])) for c in want)
    return extra <= 4 + 0.05 * sum(int(np.sum(want[c])) for c in want)


def test_box_rects_from_two_corners_are_the_eight_corner_rects() -> None:
    rng = np.random.default_rng(5)
    lo = rng.uniform(-6.0, 6.0, (600, 3))
    hi = lo + rng.uniform(0.0, 3.0, (600, 3))
    hi[:50, 0] = lo[:50, 0]  # flat boxes (a portal, a floor slab seen edge-on)
    lohi = np.ascontiguousarray(np.stack([lo.T, hi.T], axis=1))
    crossed = behind = 0
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the divisions by depths <= clip_m stay silent
        for i in range(12):
            eye = rng.uniform(-3.0, 3.0, 3)
            view = camera(eye, float(rng.uniform(-math.pi, math.pi)), float(rng.uniform(-0.6, 0.6))).astype(np.float64)
            want = rects_ckm(box_corners_ckm(lo, hi), BOX_EDGES, view, PROJ, SIZE, 0.03)
            got = box_rects_ckm(lohi, view, PROJ, SIZE, 0.03)
            assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1]), i
            assert np.allclose(got[2], want[2]) and np.allclose(got[3], want[3])
            crossed += int(((want[2] < 0.03) & (want[3] >= 0.03)).sum())
            behind += int((~want[1]).sum())
    assert crossed > 20 and behind > 100  # both special cases were compared


@pytest.fixture(autouse=True)
def _batch(monkeypatch: pytest.MonkeyPatch) -> None:
    """The batch path (table, buffers, two corners) even on these small halls."""
    monkeypatch.setattr(partcull, "_FEW_CELLS", 0)
    monkeypatch.setattr(partcull, "_FEW_BOXES", 0)


def test_changed_boxes_are_culled_as_they_are_now_not_as_packed() -> None:
    k = 6
    graph = PortalGraph.from_topology(hall_topology(k))
    boxes = hall_boxes(k)
    eye = np.array([0.5, 0.5, 1.6])
    view = camera(eye, math.pi / 4, 0.0).astype(np.float64)
    pc = cull_portals(graph, 0, eye, view, PROJ, SIZE)
    first = cull_parts("portals", pc.order, boxes, eye, view, PROJ, SIZE, vsas=pc.vsas)
    assert _same(first, _want(pc.order, boxes, pc.vsas, eye, view, math.inf))
    # a cell's boxes replaced (a cell loaded again), one dropped, one emptied
    far = pc.order[-1]
    lo, hi = boxes[far]
    boxes[far] = (lo[:3] + [0.0, 0.0, 40.0], hi[:3] + [0.0, 0.0, 40.0])  # lifted far out of view
    del boxes[pc.order[1]]
    boxes[pc.order[2]] = (np.zeros((0, 3)), np.zeros((0, 3)))
    got = cull_parts("portals", pc.order, boxes, eye, view, PROJ, SIZE, vsas=pc.vsas)
    assert _same(got, _want(pc.order, boxes, pc.vsas, eye, view, math.inf))
    assert len(got[far]) == 3 and not got[far].any() and first[far].any()
    assert pc.order[1] not in got and len(got[pc.order[2]]) == 0
    assert part_table(boxes, [c for c in pc.order if c in boxes]).src[far] is boxes[far]


def test_one_frames_answer_outlives_the_next_frame() -> None:
    # the batch's temporaries are reused; the answers must not be views of them
    k = 6
    graph = PortalGraph.from_topology(hall_topology(k))
    boxes = hall_boxes(k)
    frames = []
    for yaw in (0.3, 1.2):
        eye = np.array([0.5, 0.5, 1.6])
        view = camera(eye, yaw, 0.0).astype(np.float64)
        pc = cull_portals(graph, 0, eye, view, PROJ, SIZE)
        frames.append((pc, eye, view, cull_parts("portals", pc.order, boxes, eye, view, PROJ, SIZE, vsas=pc.vsas,
                                                 fog_m=12.0)))
    for pc, eye, view, got in frames:
        assert _same(got, _want(pc.order, boxes, pc.vsas, eye, view, 12.0))
    assert any(not np.array_equal(frames[0][3][c], frames[1][3][c]) for c in frames[0][3].keys() & frames[1][3].keys())


def test_cells_without_vsas_or_boxes_and_a_fog_that_leaves_every_box_out() -> None:
    boxes = hall_boxes(2)
    eye = np.array([0.5, 0.5, 1.6])
    view = camera(eye, math.pi / 4, 0.0).astype(np.float64)
    whole = [(0, 0, SIZE[0] - 1, SIZE[1] - 1)]
    vsas = {0: whole, 1: whole}
    got = cull_parts("portals", [0, 1, 2, 99], boxes, eye, view, PROJ, SIZE, vsas=vsas)
    assert sorted(got) == [0, 1, 2]  # 99 has no boxes: left out
    assert not got[2].any() and len(got[2]) == len(boxes[2][0])  # no VSA: culled whole
    assert got[0].any() and _same({c: got[c] for c in (0, 1)}, _want([0, 1], boxes, vsas, eye, view, math.inf))
    fogged = cull_parts("portals", [0, 1], boxes, eye, view, PROJ, SIZE, vsas=vsas, fog_m=1e-3)
    assert fogged.keys() == {0, 1} and not any(m.any() for m in fogged.values())
    assert _same(fogged, _want([0, 1], boxes, vsas, eye, view, 1e-3))
