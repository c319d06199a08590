"""Pieces of the streaming client: cell tracking, motion prediction, API decoding."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from walkstream.client.stream.cellmap import CellMap
from walkstream.client.stream.predict import MotionPredictor
from walkstream.shared.cells import inside_convex
from walkstream.shared.errors import CodecError
from walkstream.shared.wire import decode_cell, decode_manifest

SQUARE_A = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]])
SQUARE_B = np.array([[10.0, 0.0], [20.0, 0.0], [20.0, 10.0], [10.0, 10.0]])
SQUARE_C = np.array([[20.0, 0.0], [30.0, 0.0], [30.0, 10.0], [20.0, 10.0]])


def test_inside_convex_includes_the_boundary_in_either_orientation() -> None:
    pts = [[5, 5], [10, 5], [0, 0], [10.0001, 5], [-1, 5]]
    assert inside_convex(SQUARE_A, pts).tolist() == [True, True, True, False, False]
    assert inside_convex(SQUARE_A[::-1], pts).tolist() == [True, True, True, False, False]


def _map() -> CellMap:
    m = CellMap()
    m.add_record(1, SQUARE_A, {2: SQUARE_B})
    m.add_record(2, SQUARE_B, {1: SQUARE_A, 3: SQUARE_C})
    return m


def test_a_viewer_on_a_boundary_stays_in_the_cell_it_was_in() -> None:
    m = _map()
    assert m.update([5, 5]) == (1, True)
    assert m.update([10, 5]) == (1, True)  # on the shared edge: still cell 1
    assert m.update([15, 5]) == (2, True)
    assert m.update([10, 5]) == (2, True)  # back on the edge from the other side
    fresh = _map()
    assert fresh.update([10, 5]) == (1, True)  # no history: the lowest id


def test_a_viewer_outside_every_cell_keeps_the_last_one() -> None:
    m = _map()
    m.update([15, 5])
    assert m.update([15, 50]) == (2, False)
    assert m.current == 2
    empty = CellMap()
    assert empty.update([1, 1]) == (None, False)


def test_neighbour_outlines_are_known_before_their_records() -> None:
    m = _map()
    m.update([15, 5])
    assert m.update([25, 5]) == (3, True)  # cell 3 only known as cell 2's neighbour
    assert m.distance_to(3, [15, 5]) == pytest.approx(5.0)
    assert m.distance_to(99, [0, 0]) == float("inf")


def test_find_along_follows_a_track_without_flicker() -> None:
    m = _map()
    track = np.array([[5, 5], [10, 5], [12, 5], [20, 5], [25, 5], [40, 5]])
    assert m.find_along(track, 1) == [1, 1, 2, 2, 3, None]


def test_predictor_uses_velocity_over_time_not_per_frame() -> None:
    p = MotionPredictor(window_s=1.0)
    # 4 m/s along x with uneven frame spacing and a jittered frame
    ts = np.cumsum([0.0, 0.04, 0.01, 0.09, 0.04, 0.2, 0.04, 0.04, 0.3, 0.04])
    for t in ts:
        p.observe(float(t), [4.0 * t + (0.05 if t == ts[5] else 0.0), 2.0])
    v = p.velocity()
    assert v[0] == pytest.approx(4.0, rel=0.05) and abs(v[1]) < 1e-9
    ahead = p.predict([0.0, 2.0])
    assert ahead[1, 0] - ahead[0, 0] == pytest.approx(8.0, rel=0.05)


def test_predictor_sees_a_stop_and_forgets_old_motion() -> None:
    p = MotionPredictor(window_s=1.0)
    for k in range(20):
        p.observe(k * 0.1, [k * 0.5, 0.0])
    for k in range(20, 40):
        p.observe(k * 0.1, [10.0, 0.0])
    assert p.speed() < 1e-6
    with pytest.raises(ValueError):
        p.observe(0.0, [0.0, 0.0])


def _cell_body(**over: object) -> bytes:
    import msgpack

    rec: dict[str, object] = {
        "id": 4,
        "kind": "street",
        "boundary": SQUARE_A.tolist(),
        "zmin": 1.5,
        "zmax": 2.0,
        "neighbours": [{"id": 5, "boundary": SQUARE_B.tolist()}],
        "pvs": [1, 2, 3],
        "ach": [0.5, 0.25, 0.25],
    }
    rec.update(over)
    return msgpack.packb(rec)  # type: ignore[no-any-return]


def test_decode_cell_checks_every_field() -> None:
    c = decode_cell(_cell_body(), "cell 4")
    assert c.id == 4 and c.pvs.tolist() == [1, 2, 3] and list(c.neighbours) == [5]
    bad: list[dict[str, object]] = [
        {"id": "4"},
        {"boundary": [[0, 0], [1, 1]]},
        {"boundary": [[0, 0], [1, float("nan")], [1, 1]]},
        {"pvs": [1, 2]},
        {"pvs": [1, "x", 3]},
        {"ach": [-1.0, 1.0, 1.0]},
        {"neighbours": [{"id": 5}]},
        {"neighbours": [7]},
    ]
    for over in bad:
        with pytest.raises(CodecError, match="cell 4"):
            decode_cell(_cell_body(**over), "cell 4")


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=400))
def test_random_bytes_never_escape_as_anything_but_codec_errors(data: bytes) -> None:
    for decode in (decode_cell, decode_manifest):
        try:
            decode(data, "fuzz")
        except CodecError:
            pass
