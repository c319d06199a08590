"""The culling's CPU benchmark (benchmarks/cullcpu.py) and the faster parts culling it measures.

:func:`~walkstream.shared.partcull.cull_parts` culls every visible cell's boxes in one
batch, coordinate-major, and takes the frustum's near and far planes as depths (its
side planes cannot cull a box whose rectangle meets a VSA).  It must keep every box
the plain per-cell test keeps (:func:`~walkstream.shared.partcull.cull_boxes`: the box
rectangles against the cell's VSAs, then the six-plane frustum test), and few more (a
box that crosses the clip plane is tested by an unclipped superset of its rectangle), on each
of its paths (a batch of two corners' sums or of eight corners' product, a few
cells'), with a fog that leaves some boxes out, and with boxes that hold the eye or
cross the clip plane.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from walkstream.benchmarks.cullcpu import HALL_PARTS, hall_boxes
from walkstream.benchmarks.portals import hall_topology
from walkstream.cli import main
from walkstream.shared import partcull
from walkstream.shared.camera import camera, perspective
from walkstream.shared.partcull import cull_boxes, cull_parts
from walkstream.shared.portalgraph import PortalGraph
from walkstream.shared.portals import cull_portals

SIZE = (320, 240)


# the batch with the two corners' sums, the batch with the eight corners' product, a few cells' path
@pytest.mark.parametrize(("few_cells", "few_boxes"), [(0, 0), (0, 10**6), (10**6, 0)])
@pytest.mark.parametrize(("seed", "fog"), [(400, math.inf), (97, math.inf), (97, 18.0)])
def test_parts_culled_at_once_keep_what_the_plain_box_test_keeps(
    seed: int, fog: float, few_cells: int, few_boxes: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(partcull, "_FEW_CELLS", few_cells)
    monkeypatch.setattr(partcull, "_FEW_BOXES", few_boxes)
    k = 8
    graph = PortalGraph.from_topology(hall_topology(k))
    boxes = hall_boxes(k)
    proj = perspective(60.0, SIZE[0] / SIZE[1], 0.1, 30.0).astype(np.float64)
    rng = np.random.default_rng(seed)
    kept_some = dropped_some = extra = 0
    for i in range(8):
        # a corner looking across, then eyes anywhere, low (in the furniture) and high
        eye = np.array([0.5, 0.5, 1.6]) if i == 0 else np.array([*rng.uniform(0.2, 4.0 * k - 0.2, 2),
                                                                 rng.choice([0.3, 1.6, 2.9])])
        start = int(np.floor(eye[1] / 4.0) * k + np.floor(eye[0] / 4.0))
        view = camera(eye, math.pi / 4 if i == 0 else float(rng.uniform(-math.pi, math.pi)),
                      float(rng.uniform(-0.5, 0.5))).astype(np.float64)
        pc = cull_portals(graph, start, eye, view, proj, SIZE, fog_m=fog)
        got = cull_parts("portals", pc.order, boxes, eye, view, proj, SIZE, vsas=pc.vsas, fog_m=fog)
        assert got.keys() == set(pc.order)
        for c in pc.order:
            lo, hi = boxes[c]
            want = cull_boxes(lo, hi, pc.vsas[c], eye, view, proj, SIZE, fog_m=fog)
            # conservative: every box the exact test keeps (a box crossing the clip plane
            # is tested by an unclipped superset of its rectangle, so a few more may stay)
            assert not np.any(want & ~got[c]), (i, c)
            extra += int(np.sum(got[c] & ~want))
            kept_some += int(want.sum())
            dropped_some += int((~want).sum())
        if i == 0:
            assert len(pc.order) > 20 and sum(len(boxes[c][0]) for c in pc.order) > 300  # a batch of hundreds
    assert kept_some > 100 and dropped_some > 100  # both outcomes were compared
    assert extra <= 0.05 * kept_some


def test_hall_boxes_lie_in_their_cells() -> None:
    boxes = hall_boxes(3)
    assert sorted(boxes) == list(range(9))
    for c, (lo, hi) in boxes.items():
        x0, y0 = (c % 3) * 4.0, (c // 3) * 4.0
        assert lo.shape == hi.shape == (HALL_PARTS, 3) and np.all(hi > lo)
        assert np.all(lo[:, :2] >= (x0, y0)) and np.all(hi[:, :2] <= (x0 + 4.0, y0 + 4.0))


def test_bench_portals_cull_from_the_cli(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "portals", "--cull", "--cull-frames", "3", "--out", str(tmp_path), "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)["culling_cpu"]
    assert [r["scene"] for r in rows] == ["hall 16x16", "hall walk"]
    r = rows[0]
    assert r["frames"] == 6 and 200 <= r["visible_median"] <= r["visible_max"] <= 256
    for part in ("walk", "parts", "total"):
        assert 0 < r["now"][part]["median"] <= r["now"][part]["p99"]
    assert r["now"]["total"]["median"] >= r["now"]["walk"]["median"]
    # a revision that does not exist: one line, no traceback
    assert main(["bench", "portals", "--cull", "--cull-frames", "1", "--cull-against", "no-such-revision",
                 "--out", str(tmp_path)]) != 0
    err = capsys.readouterr().err
    assert "no-such-revision" in err and "Traceback" not in err


def test_bench_portals_cull_cache_from_the_cli(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # the culling reused frame to frame against each frame culled anew: the cache's misses
    # counted (the first frame of each pass makes a guard), and it kept every part the
    # other kept (the bench raises otherwise)
    assert main(["bench", "portals", "--cull", "--cull-cache", "--cull-frames", "10", "--out", str(tmp_path),
                 "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)["culling_cpu"]
    assert [r["scene"] for r in rows] == ["hall 16x16", "hall walk"]
    for r in rows:
        assert r["against"] == "anew" and 1 <= r["misses"] < r["frames"] // 2 and r["frames"] == 20
        assert 0 < r["now"]["total"]["median"] <= r["now"]["total"]["p99"]
        assert 0 < r["then"]["total"]["median"] <= r["then"]["total"]["p99"]


def test_bench_portals_cull_against_a_revision_times_both_in_turn(tmp_path: Path,
                                                                  capsys: pytest.CaptureFixture[str]) -> None:
    # HEAD's culling loaded beside today's: both columns over the same frames, each going
    # first on every other frame, and the parts compared on every frame (the same code
    # in a checkout without local changes to the culling; the bench raises otherwise)
    root = Path(__file__).resolve().parents[1]
    if not (root / ".git").exists():
        pytest.skip("not a git checkout: no revision to load")
    assert main(["bench", "portals", "--cull", "--cull-frames", "1", "--cull-against", "HEAD",
                 "--out", str(tmp_path), "--json"]) == 0
    r = json.loads(capsys.readouterr().out)["culling_cpu"][0]
    assert r["against"] == "HEAD" and r["frames"] == 2
    for who in ("now", "then"):
        for part in ("walk", "parts", "total"):
            assert 0 < r[who][part]["median"] <= r[who][part]["p99"]
