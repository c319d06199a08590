"""Why an interior frame was not perfect: each late cell's wait and its cause."""

from __future__ import annotations

from walkstream.client.stream.roomlate import CAUSES, LateCells


def test_each_late_cell_gets_the_cause_of_its_wait() -> None:
    late = LateCells()
    late.wanted(1.0, [1, 2])  # 1 and 2 wanted early
    late.asked(1.0, [1], [500])  # 1 asked at once
    late.missing(2.0, [1, 2, 3], busy_bytes=900.0)  # 3 shows unforeseen, 2 is still queued
    late.asked(2.5, [2, 3], [300, 700])
    late.missing(2.5, [2, 3], busy_bytes=1000.0)
    for c in (1, 2):
        late.arrived(3.0, c)
    late.wanted(3.0, [4])
    late.arrived(3.5, 4)  # never missing: no late cell
    f = late.figures(t0=1.0)
    assert f["cells"] == 3
    assert f["cell_frames_by_cause"] == {"unforeseen": 2, "queued": 2, "on the link": 1}
    worst = {w["cell"]: w for w in f["worst"]}
    assert set(worst) == {1, 2, 3}
    assert worst[1]["cause"] == "on the link" and worst[1]["busy_bytes"] == 900
    assert worst[2]["cause"] == "queued" and worst[2]["asked_s"] == 1.5 and worst[2]["arrived_s"] == 2.0
    assert worst[3]["cause"] == "unforeseen" and worst[3]["arrived_s"] is None and worst[3]["bytes"] == 700
    # the worst (most frames missing) first, then by when wanted
    assert [w["cell"] for w in f["worst"]] == [2, 3, 1]
    assert tuple(f["cell_frames_by_cause"]) == CAUSES


def test_a_cell_fetched_again_is_a_new_wait() -> None:
    late = LateCells()
    late.wanted(0.0, [7])
    late.missing(1.0, [7], 0.0)
    late.arrived(2.0, 7)
    late.wanted(10.0, [7])  # evicted, wanted again: asked in time, never missing
    late.asked(10.0, [7], [100])
    late.arrived(10.5, 7)
    f = late.figures()
    assert f["cells"] == 1 and f["worst"][0]["wanted_s"] == 0.0 and f["worst"][0]["frames"] == 1


def test_the_start_up_before_the_first_perfect_frame_is_left_out() -> None:
    late = LateCells()
    late.wanted(0.0, [1, 2])
    late.missing(0.0, [1, 2], 0.0)  # the start-up: both missing
    late.arrived(0.5, 1)
    late.missing(1.0, [2], 300.0)  # after the first perfect frame (at 0.5 s), 2 still missing
    late.arrived(1.2, 2)
    f = late.figures(from_s=0.5)
    assert f["cells"] == 1 and f["worst"][0]["cell"] == 2 and f["worst"][0]["frames"] == 1
    assert f["worst"][0]["missing_s"] == 1.0 and f["worst"][0]["cause"] == "queued"
    assert late.figures()["cells"] == 2


def test_a_cell_dropped_from_the_wants_is_wanted_anew() -> None:
    late = LateCells()
    late.wanted(1.0, [5])
    late.wanted(1.5, [])  # the prediction turned away: 5 is no longer wanted
    late.wanted(3.0, [5])
    late.missing(3.2, [5], 0.0)
    late.arrived(4.0, 5)
    w = late.figures()["worst"][0]
    assert w["wanted_s"] == 3.0 and w["cause"] == "queued"
