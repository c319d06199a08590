"""The recorded path format: round trips, interpolation, validation, compactness."""

from __future__ import annotations

import json
import math

import msgpack
import numpy as np
import pytest

from walkstream.shared.errors import CodecError, InputError
from walkstream.shared.paths import (
    COLUMNS,
    FORMAT,
    MAX_SAMPLES,
    RecordedPath,
    direction,
    wrap_angle,
)


def simple(**kw: object) -> RecordedPath:
    args: dict[str, object] = {
        "name": "p",
        "t": [0.0, 10.0, 20.0],
        "xyz": [[0.0, 0.0, 1.7], [10.0, 0.0, 1.7], [10.0, 10.0, 1.7]],
        "yaw": [0.0, 0.0, math.pi / 2],
        "pitch": [0.0, 0.0, 0.0],
        "speed_kmh": 3.6,
    }
    args.update(kw)
    return RecordedPath(**args)  # type: ignore[arg-type]


def blob(**kw: object) -> bytes:
    d = simple().to_dict()
    d.update(kw)
    return bytes(msgpack.packb(d))


CITY_WALK = np.array(
    [[0, 0], [120, 0], [120, 95], [260, 95], [260, -40], [400, -40], [400, 200], [330, 200]],
    dtype=np.float64,
)


# --------------------------------------------------------------------------- round trips


def test_msgpack_round_trip_is_float32_close_and_then_exact() -> None:
    p = RecordedPath.from_polyline("walk", CITY_WALK, 15.0)
    q = RecordedPath.from_msgpack(p.to_msgpack())
    assert q.name == "walk" and q.speed_kmh == 15.0 and len(q) == len(p)
    np.testing.assert_allclose(q.table(), p.table(), atol=1e-3)
    assert RecordedPath.from_msgpack(q.to_msgpack()) == q  # stable after one trip


def test_exact_values_round_trip_exactly_and_unpack_to_the_documented_map() -> None:
    xyz = [[0.0, 0.0, 1.75], [10.0, 0.0, 1.75], [10.0, 10.0, 1.75]]
    p = simple(xyz=xyz, yaw=[0.0, 0.5, 1.25])
    data = msgpack.unpackb(p.to_msgpack())
    assert data["format"] == FORMAT and data["version"] == 1
    assert data["columns"] == list(COLUMNS) and data["speed_kmh"] == 3.6
    assert data["samples"][1] == [10, 10, 0, 1.75, 0.5, 0]
    assert RecordedPath.from_msgpack(p.to_msgpack()) == p
    # 1.7 m is not exact in float32: stored as the nearest float32
    assert RecordedPath.from_msgpack(simple().to_msgpack()).xyz[0, 2] == pytest.approx(
        1.7, abs=1e-6
    )


def test_times_that_float32_would_merge_are_kept_as_float64() -> None:
    p = simple(t=[0.0, 1000.0, 1000.00001])
    q = RecordedPath.from_msgpack(p.to_msgpack())
    assert q == p


def test_json_round_trip_and_speed_none() -> None:
    p = RecordedPath.from_polyline("walk", CITY_WALK, 5.0)
    text = p.to_json()
    assert json.loads(text)["samples"][0] == [0, 0, 0, 1.7, 0, 0]
    q = RecordedPath.from_json(text)
    np.testing.assert_allclose(q.table(), p.table(), atol=1e-5)
    r = RecordedPath.from_json(simple(speed_kmh=None).to_json(indent=False))
    assert r.speed_kmh is None
    np.testing.assert_allclose(r.table(), simple().table(), atol=1e-6)


def test_arrays_are_read_only_and_equality_compares_values() -> None:
    p = simple()
    with pytest.raises(ValueError):
        p.xyz[0, 0] = 5.0
    assert p == simple() and p != simple(name="q") and p != simple(speed_kmh=None)


def test_extra_keys_are_ignored() -> None:
    assert RecordedPath.from_msgpack(blob(comment="made by hand")) == simple()


# --------------------------------------------------------------------------- sampling


def test_sample_interpolates_linearly_and_clamps() -> None:
    p = simple()
    xyz, yaw, pitch = p.sample([-5.0, 0.0, 5.0, 15.0, 20.0, 99.0])
    np.testing.assert_allclose(
        xyz[:, :2], [[0, 0], [0, 0], [5, 0], [10, 5], [10, 10], [10, 10]], atol=1e-12
    )
    np.testing.assert_allclose(yaw, [0, 0, 0, math.pi / 4, math.pi / 2, math.pi / 2])
    assert (pitch == 0).all() and (xyz[:, 2] == 1.7).all()
    pos, y, pt = p.at(15.0)
    assert pos.shape == (3,) and pos[1] == pytest.approx(5.0)
    assert y == pytest.approx(math.pi / 4) and pt == 0.0
    assert p.sample(np.zeros((2, 2)))[0].shape == (4, 3)


def test_yaw_takes_the_shorter_arc_across_pi() -> None:
    p = simple(yaw=[3.0, -3.0, -3.0])
    _, yaw, _ = p.sample([5.0])
    # halfway from 3.0 to -3.0 the short way is through pi, not through 0
    assert abs(abs(float(yaw[0])) - math.pi) < 1e-9
    assert ((yaw >= -math.pi) & (yaw < math.pi)).all()


def test_pitch_interpolates() -> None:
    p = simple(pitch=[0.0, 0.2, -0.2])
    assert p.at(5.0)[2] == pytest.approx(0.1) and p.at(15.0)[2] == pytest.approx(0.0)


def test_direction_gives_unit_view_vectors() -> None:
    d = direction([0.0, math.pi / 2, 0.0], [0.0, 0.0, math.pi / 2])
    np.testing.assert_allclose(d, [[1, 0, 0], [0, 1, 0], [0, 0, 1]], atol=1e-12)
    many = direction(np.linspace(-4, 4, 50), 0.3)
    np.testing.assert_allclose(np.linalg.norm(many, axis=1), 1.0)
    assert wrap_angle(3 * math.pi) == pytest.approx(-math.pi)


# --------------------------------------------------------------------------- from_polyline


def test_from_polyline_times_by_distance_and_faces_the_motion() -> None:
    p = RecordedPath.from_polyline("L", [[0, 0], [100, 0], [100, 100]], 36.0, turn_seconds=1.0)
    assert p.length_m() == pytest.approx(200.0)
    assert p.duration == pytest.approx(20.0)  # 10 m/s, a walked turn adds no time
    assert p.speed_kmh == 36.0 and (p.xyz[:, 2] == 1.7).all()
    _, yaw, _ = p.sample([2.0, 18.0])
    np.testing.assert_allclose(yaw, [0.0, math.pi / 2], atol=1e-12)
    # the corner is a key point, and the turn has key points before and after it
    assert any(np.allclose(x, [100, 0]) for x in p.xyz[:, :2])
    assert len(p) == 5


def yaw_rate(p: RecordedPath, dt: float = 0.01) -> float:
    ts = np.arange(0.0, p.duration, dt)
    _, yaw, _ = p.sample(ts)
    return float(np.abs(wrap_angle(np.diff(yaw))).max() / dt)


def test_corners_turn_the_view_smoothly() -> None:
    p = RecordedPath.from_polyline("walk", CITY_WALK, 5.0, turn_seconds=1.0)
    assert yaw_rate(p) <= (math.pi / 2) * 1.05  # 90 degrees a second, never a snap


def test_a_u_turn_stops_and_turns_left_on_the_spot() -> None:
    p = RecordedPath.from_polyline("u", [[0, 0], [50, 0], [20, 0]], 3.6, turn_seconds=1.0)
    assert p.length_m() == pytest.approx(80.0)
    assert p.duration == pytest.approx(80.0 + 2.0)  # 2 s to turn 180 degrees
    pos, yaw, _ = p.at(51.0)  # halfway through the turn
    np.testing.assert_allclose(pos[:2], [50, 0])
    assert yaw == pytest.approx(math.pi / 2)
    _, yaw_back, _ = p.at(60.0)
    assert abs(yaw_back) == pytest.approx(math.pi)
    assert yaw_rate(p) <= (math.pi / 2) * 1.05


def test_from_polyline_drops_repeats_and_straight_vertices() -> None:
    p = RecordedPath.from_polyline("s", [[0, 0], [0, 0], [5, 0], [10, 0], [10, 0.0000001]], 5.0)
    assert len(p) == 2


def test_short_legs_still_give_strictly_increasing_times() -> None:
    zig = np.cumsum(np.tile([[0.01, 0.0], [0.0, 0.01]], (200, 1)), axis=0)
    p = RecordedPath.from_polyline("zig", np.vstack([[0, 0], zig]), 50.0, turn_seconds=2.0)
    assert (np.diff(p.t) > 0).all()
    assert (np.diff(RecordedPath.from_msgpack(p.to_msgpack()).t) > 0).all()


@pytest.mark.parametrize(
    ("xy", "kw", "message"),
    [
        ([[0, 0]], {}, "at least 2 distinct"),
        ([[0, 0], [0, 0]], {}, "at least 2 distinct"),
        ([[0, 0], [np.nan, 1]], {}, "point 1 is not finite"),
        ([0, 1, 2], {}, "(n, 2)"),
        ([[0, 0], [1, 1]], {"speed_kmh": 0.0}, "speed_kmh"),
        ([[0, 0], [1, 1]], {"speed_kmh": -3.0}, "speed_kmh"),
        ([[0, 0], [1, 1]], {"turn_seconds": 0.0}, "turn_seconds"),
        ([[0, 0], [1, 1]], {"eye_height": math.inf}, "eye_height"),
    ],
)
def test_from_polyline_refuses_bad_input(xy: object, kw: dict[str, float], message: str) -> None:
    args: dict[str, object] = {"speed_kmh": 5.0} | kw
    with pytest.raises(InputError, match=message.replace("(", r"\(").replace(")", r"\)")):
        RecordedPath.from_polyline("bad", xy, **args)  # type: ignore[arg-type]


def test_key_points_keep_a_street_walk_compact() -> None:
    # a 3.5-minute walk at 15 km/h with six corners
    p = RecordedPath.from_polyline("SE", CITY_WALK * 1.3, 15.0)
    assert p.duration >= 180
    assert len(p.to_msgpack()) < 1000


# --------------------------------------------------------------------------- validation


@pytest.mark.parametrize(
    ("kw", "message"),
    [
        ({"t": [0.0, 10.0, np.nan]}, r"samples\[2\]: t is not finite"),
        ({"xyz": [[0, 0, 1.7], [np.inf, 0, 1.7], [1, 1, 1.7]]}, r"samples\[1\]: x is not finite"),
        ({"t": [0.0, 10.0, 10.0]}, r"samples\[2\]: t must increase strictly"),
        ({"t": [1.0, 10.0, 20.0]}, r"samples\[0\]: t must be 0"),
        ({"t": [0.0], "xyz": [[0, 0, 0]], "yaw": [0.0], "pitch": [0.0]}, "at least 2 samples"),
        ({"xyz": [[0, 0], [1, 1], [2, 2]]}, "xyz: expected shape"),
        ({"yaw": [0.0, 1.0]}, "yaw: expected 3 values"),
        ({"speed_kmh": 0.0}, "speed_kmh"),
        ({"speed_kmh": math.nan}, "speed_kmh"),
        ({"name": ""}, "name"),
        ({"name": "a\nb"}, "control characters"),
    ],
)
def test_constructor_refuses_bad_paths(kw: dict[str, object], message: str) -> None:
    with pytest.raises(InputError, match=message):
        simple(**kw)


ROW = [1.0, 0.0, 0.0, 1.7, 0.0, 0.0]


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (b"", "no bytes"),
        (b"\xc1", "not valid msgpack"),
        (blob() + b"\x00", "trailing bytes"),
        (msgpack.packb([1, 2]), "expected a map"),
        (blob(format="other"), "format"),
        (blob(version=2), "version: 2 is not supported"),
        (blob(version="1"), "version: expected an integer"),
        (blob(version=True), "version: expected an integer"),
        (blob(name=5), "name"),
        (blob(speed_kmh=0), "speed_kmh"),
        (blob(speed_kmh="fast"), "speed_kmh: expected a number"),
        (blob(columns=["t", "x", "y", "z", "yaw"]), "columns"),
        (blob(samples={"a": 1}), "samples: expected a list"),
        (blob(samples=[[0, 0, 0, 1.7, 0, 0], 5]), r"samples\[1\]: expected 6 numbers, got int"),
        (blob(samples=[[0, 0, 0, 1.7, 0, 0], ROW[:5]]), r"samples\[1\]: expected 6 numbers, got 5"),
        (
            blob(samples=[[0, 0, 0, 1.7, 0, 0], [1, 0, True, 0, 0, 0]]),
            r"samples\[1\]: y: expected a number",
        ),
        (
            blob(samples=[[0, 0, 0, 1.7, 0, 0], [1, 0, "0", 0, 0, 0]]),
            r"samples\[1\]: y: expected a number",
        ),
        (
            blob(samples=[[0, 0, 0, 1.7, 0, 0], [1, 0, 0, 0, math.nan, 0]]),
            r"samples\[1\]: yaw is not finite",
        ),
        (blob(samples=[[0, 0, 0, 1.7, 0, 0], ROW, ROW]), r"samples\[2\]: t must increase"),
        (blob(samples=[ROW, [2.0, 0, 0, 0, 0, 0]]), r"samples\[0\]: t must be 0"),
        (blob(samples=[[0, 0, 0, 1.7, 0, 0]]), "at least 2 samples"),
    ],
)
def test_from_msgpack_names_what_is_wrong(data: bytes, message: str) -> None:
    with pytest.raises(CodecError, match=message):
        RecordedPath.from_msgpack(data, "path 'p'")


def test_from_msgpack_is_bounded() -> None:
    with pytest.raises(CodecError, match="more than the limit"):
        RecordedPath.from_msgpack(b"\x00" * (64 << 20))
    many = [[float(i), 0, 0, 0, 0, 0] for i in range(MAX_SAMPLES + 1)]
    with pytest.raises(CodecError):
        RecordedPath.from_msgpack(blob(samples=many))
    missing = simple().to_dict()
    del missing["name"]
    with pytest.raises(CodecError, match="name: missing"):
        RecordedPath.from_msgpack(msgpack.packb(missing))


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("{", "not JSON"),
        ('"just a string"', "expected a map"),
        (
            json.dumps(simple().to_dict()).replace("[10, 10, 0", "[10, NaN, 0"),
            r"samples\[1\]: x is not finite",
        ),
        (
            json.dumps(simple().to_dict()).replace("[10, 10, 0", "[10, " + "9" * 400 + ", 0"),
            "a number is out of range",
        ),
    ],
)
def test_from_json_names_what_is_wrong(text: str, message: str) -> None:
    with pytest.raises(CodecError, match=message):
        RecordedPath.from_json(text)
