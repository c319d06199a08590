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
from walkstream.shared.wire import (
    CellIndex,
    CellRecord,
    decode_cell,
    decode_cell_index,
    decode_manifest,
)

SQUARE_A = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]])
SQUARE_B = np.array([[10.0, 0.0], [20.0, 0.0], [20.0, 10.0], [10.0, 10.0]])
SQUARE_C = np.array([[20.0, 0.0], [30.0, 0.0], [30.0, 10.0], [20.0, 10.0]])


def test_inside_convex_includes_the_boundary_in_either_orientation() -> None:
    pts = [[5, 5], [10, 5], [0, 0], [10.0001, 5], [-1, 5]]
    assert inside_convex(SQUARE_A, pts).tolist() == [True, True, True, False, False]
    assert inside_convex(SQUARE_A[::-1], pts).tolist() == [True, True, True, False, False]


def _map() -> CellMap:
    m = CellMap()
    m.add_cells([1, 2, 3], [SQUARE_A, SQUARE_B, SQUARE_C], [[2], [1, 3], [2]], tile=(0, 0))
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


def test_cells_of_a_tile_are_known_until_the_tile_is_forgotten() -> None:
    m = CellMap()
    m.add_cells([1, 2], [SQUARE_A, SQUARE_B], [[2], [1, 3]], tile=(0, 0))
    m.add_cells([3], [SQUARE_C], [[2]], tile=(1, 0))
    m.update([15, 5])
    assert m.update([25, 5]) == (3, True)  # cell 3 comes with its own tile
    assert m.distance_to(3, [15, 5]) == pytest.approx(5.0)
    assert m.distance_to(99, [0, 0]) == float("inf")
    assert m.portal(2, 3).tolist() == [[20.0, 0.0], [20.0, 10.0]]
    assert m.forget_tile((1, 0)) == [3]
    assert not m.knows(3) and m.neighbours[2] == (1, 3)  # still a neighbour, by id
    assert m.update([25, 5]) == (3, False)  # outside every held cell: the last one kept
    assert m.find([25, 5]) is None


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

    rec: dict[str, object] = CellRecord(
        4, "street", np.array([1, 2, 3]), np.array([0.5, 0.25, 0.25])
    ).to_wire()
    rec.update(over)
    return msgpack.packb(rec, use_bin_type=True)  # type: ignore[no-any-return]


def test_decode_cell_checks_every_field() -> None:
    c = decode_cell(_cell_body(), "cell 4")
    assert (
        c.id == 4
        and c.pvs.tolist() == [1, 2, 3]
        and c.ach.tolist() == pytest.approx([0.5, 0.25, 0.25], abs=1e-4)
    )
    # extra (kind-specific) fields are ignored by a client that does not know them
    assert decode_cell(_cell_body(portals=[[1, 2]]), "cell 4").pvs.tolist() == [1, 2, 3]
    bad: list[dict[str, object]] = [
        {"id": "4"},
        {"id": -4},
        {"pvs": [0, [1, 1]]},  # two ids where ach has three
        {"pvs": [0, [1, 0, 1]]},  # not ascending
        {"pvs": [0, [1, "x", 3]]},
        {"pvs": [9, b"xx"]},  # unknown format
        {"pvs": [1, b"xxx"]},  # int16 blob of odd length
        {"ach": [0, [-1, 1, 1]]},
        {"ach": [0, [70000, 1, 1]]},
        {"ach": [0, [1, 1]]},
    ]
    for over in bad:
        with pytest.raises(CodecError, match="cell 4"):
            decode_cell(_cell_body(**over), "cell 4")


def _index_body(**over: object) -> bytes:
    import msgpack

    idx = CellIndex(
        (0, 1),
        [3, 7],
        ["street", "crossroad"],
        [1.5, 1.5],
        [2.0, 2.0],
        [SQUARE_A, SQUARE_B],
        [[7], [3, 9]],
    )
    rec = idx.to_wire()
    rec.update(over)
    return msgpack.packb(rec, use_bin_type=True)  # type: ignore[no-any-return]


def test_cell_index_round_trips_at_centimetres_and_checks_every_field() -> None:
    rng = np.random.default_rng(1)
    far = [SQUARE_A + rng.uniform(-1e6, 1e6, 2), SQUARE_B * 1.001 + 600000.0]
    idx = CellIndex(
        None, [3, 700], ["square", "street"], [1.0, 1.5], [2.0, 3.5], far, [[700], [3, 9, 12]]
    )
    back = decode_cell_index(msgpack_pack(idx.to_wire()), "index")
    assert (
        back.tile is None and back.ids.tolist() == [3, 700] and back.kinds == ("square", "street")
    )
    assert back.zmax.tolist() == [2.0, 3.5] and [n.tolist() for n in back.neighbours] == [
        [700],
        [3, 9, 12],
    ]
    for a, b in zip(far, back.outlines, strict=True):
        assert np.abs(a - b).max() <= 0.005 + 1e-9  # centimetres
    plain = decode_cell_index(msgpack_pack(idx.to_wire(compact=False)), "index")
    assert [o.tolist() for o in plain.outlines] == [o.tolist() for o in back.outlines]
    bad: list[dict[str, object]] = [
        {"tile": [1]},
        {"ids": [0, [3, 0]]},
        {"kinds": [0, [0, 5]]},
        {"counts": [0, [4, 2]]},
        {"counts": [0, [4]]},
        {"coords": [0, [1, 2]]},
        {"degrees": [0, [1, 1]]},
        {"adjacent": [0, [-10, 1, 1]]},
        {"anchor": [1.5, 2]},
        {"zmin": [0, [150]]},
    ]
    for over in bad:
        with pytest.raises(CodecError, match="tile 9"):
            decode_cell_index(_index_body(**over), "tile 9")


def msgpack_pack(obj: object) -> bytes:
    import msgpack

    return msgpack.packb(obj, use_bin_type=True)  # type: ignore[no-any-return]


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=400))
def test_random_bytes_never_escape_as_anything_but_codec_errors(data: bytes) -> None:
    for decode in (decode_cell, decode_manifest, decode_cell_index):
        try:
            decode(data, "fuzz")
        except CodecError:
            pass
