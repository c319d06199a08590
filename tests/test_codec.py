"""Round trips and hostile input for the wire/storage codecs (walkstream.shared.codec)."""

from __future__ import annotations

import time

import msgpack
import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from walkstream.shared.codec import (
    ACH_UNITS,
    decode_building,
    decode_ids,
    decode_object,
    decode_polygon,
    decode_pvs,
    decode_street,
    decode_varints,
    encode_building,
    encode_ids,
    encode_polygon,
    encode_pvs,
    encode_street,
    encode_varints,
    pvs_size,
    quantise_ach,
    unpack_bounded,
)
from walkstream.shared.errors import CodecError
from walkstream.shared.records import BuildingParams, StreetParams

# 5 mm quantisation plus float64 rounding at ten million metres
TOL = 0.005 + 1e-6

# ---------------------------------------------------------------------------
# strategies
# ---------------------------------------------------------------------------

coord = st.floats(-1e7, 1e7, allow_nan=False, allow_infinity=False)
offset = st.floats(-300.0, 300.0, allow_nan=False, allow_infinity=False)
height = st.one_of(st.just(0.0), st.just(0.0), st.floats(0.0, 300.0, allow_nan=False))


@st.composite
def rings_near(draw: st.DrawFn, min_rings: int = 1, max_rings: int = 3) -> list[np.ndarray]:
    """Rings of 3-40 vertices within a few hundred metres of a possibly far anchor."""
    cx, cy = draw(coord), draw(coord)
    n_rings = draw(st.integers(min_rings, max_rings))
    rings = []
    for _ in range(n_rings):
        n = draw(st.integers(3, 40))
        d = draw(st.lists(st.tuples(offset, offset), min_size=n, max_size=n))
        rings.append(np.array(d) + [cx, cy])
    return rings


@st.composite
def buildings(draw: st.DrawFn) -> BuildingParams:
    rings = draw(rings_near())
    nbs = [np.array(draw(st.lists(height, min_size=len(r), max_size=len(r)))) for r in rings]
    return BuildingParams(
        id=draw(st.integers(0, 2**63 - 1)),
        rings=tuple(rings),
        neighbour_heights=tuple(nbs),
        floors=draw(st.integers(1, 300)),
        floor_height=draw(st.floats(0.01, 20.0)),
        style=draw(st.integers(-(2**63), 2**63 - 1)),
        source_id=draw(st.text(max_size=30)),
    )


@st.composite
def streets(draw: st.DrawFn) -> StreetParams:
    (ring,) = draw(rings_near(1, 1))
    return StreetParams(
        id=draw(st.integers(0, 2**40)),
        kind=draw(st.sampled_from(["street", "crossroad", "square"])),
        ring=ring,
        width=draw(st.floats(0.0, 80.0)),
        source_id=draw(st.text(max_size=10)),
    )


def typical_building(x0: float = 1203.41, y0: float = 5071.22) -> BuildingParams:
    """An L-shaped 8-vertex building of ~13 x 15 m with two party walls."""
    ring = np.array(
        [[0, 0], [12.49, 0.58], [12.89, 8.88], [7.59, 9.08], [7.79, 14.48], [0.49, 14.78],
         [0.19, 8.18], [-0.21, 3.78]]
    ) + [x0, y0]  # fmt: skip
    nb = np.array([0, 0, 12.5, 12.5, 0, 0, 9.0, 0])
    return BuildingParams(4711, (ring,), (nb,), floors=5, floor_height=3.1, style=3)


# ---------------------------------------------------------------------------
# buildings and streets
# ---------------------------------------------------------------------------


def assert_building_close(a: BuildingParams, b: BuildingParams) -> None:
    assert a.id == b.id and a.floors == b.floors and a.style == b.style
    assert a.source_id == b.source_id
    assert len(a.rings) == len(b.rings)
    for ra, rb, ha, hb in zip(
        a.rings, b.rings, a.neighbour_heights, b.neighbour_heights, strict=True
    ):
        assert ra.shape == rb.shape and ha.shape == hb.shape
        if not np.allclose(rb, ra, rtol=0, atol=TOL):
            # a sliver whose signed area changes sign under rounding comes back
            # reversed by BuildingParams; edge i then runs the other way
            ra, ha = ra[::-1], np.roll(ha[::-1], -1)
        np.testing.assert_allclose(rb, ra, rtol=0, atol=TOL)
        np.testing.assert_allclose(hb, ha, rtol=0, atol=TOL)
    assert abs(a.floor_height - b.floor_height) <= TOL


@given(buildings())
def test_building_round_trip(b: BuildingParams) -> None:
    data = encode_building(b)
    back = decode_building(data)
    assert_building_close(b, back)
    # quantised values are a fixed point: re-encoding gives the same bytes
    assert encode_building(back) == data
    assert isinstance(decode_object(data), BuildingParams)


@given(streets())
def test_street_round_trip(s: StreetParams) -> None:
    data = encode_street(s)
    back = decode_street(data)
    assert (back.id, back.kind, back.source_id) == (s.id, s.kind, s.source_id)
    np.testing.assert_allclose(back.ring, s.ring, rtol=0, atol=TOL)
    assert abs(back.width - s.width) <= TOL
    assert encode_street(back) == data
    assert isinstance(decode_object(data), StreetParams)


def test_sliver_flipped_by_rounding_keeps_its_edges() -> None:
    ring = np.array([[0.0, 0.0], [2.0, 0.0051], [1.0, 0.0049]])  # CCW by 0.0047 m2
    b = BuildingParams(1, (ring,), (np.array([1.0, 2.0, 3.0]),), 1, 3.0)
    back = decode_building(encode_building(b))
    np.testing.assert_allclose(back.rings[0], np.array([[1.0, 0.0], [2.0, 0.01], [0.0, 0.0]]))
    np.testing.assert_array_equal(back.neighbour_heights[0], [2.0, 1.0, 3.0])
    assert_building_close(b, back)


def test_far_coordinates_stay_exact_to_the_centimetre() -> None:
    b = typical_building(6_543_210.37, 5_432_109.91)  # UTM-like metres
    back = decode_building(encode_building(b))
    np.testing.assert_allclose(back.rings[0], np.round(b.rings[0] * 100) / 100, rtol=0, atol=1e-8)


def test_typical_building_is_compact() -> None:
    b = typical_building()
    assert len(encode_building(b)) <= 60
    no_party = BuildingParams(1, b.rings, (np.zeros(8),), floors=4, floor_height=3.0)
    assert len(encode_building(no_party)) <= 50


def test_source_id_can_be_dropped() -> None:
    b = BuildingParams(1, (np.eye(3)[:, :2],), (np.zeros(3),), 1, 3.0, source_id="way/123456789")
    assert len(encode_building(b, with_source_id=False)) + 13 == len(encode_building(b))
    assert decode_building(encode_building(b, with_source_id=False)).source_id == ""


def test_street_with_empty_ring() -> None:
    s = StreetParams(3, "square", np.zeros((0, 2)), 5.0)
    back = decode_street(encode_street(s))
    assert back.ring.shape == (0, 2) and back.kind == "square"


def test_wrong_record_type_is_refused() -> None:
    street = encode_street(StreetParams(3, "street", np.eye(3)[:, :2], 5.0))
    with pytest.raises(CodecError, match="building params"):
        decode_building(street)
    with pytest.raises(CodecError, match="street params"):
        decode_street(encode_building(typical_building()))


def test_non_finite_coordinates_are_refused() -> None:
    b = BuildingParams(1, (np.array([[0, 0], [1, 0], [np.nan, 1]]),), (np.zeros(3),), 1, 3.0)
    with pytest.raises(CodecError, match="building 1"):
        encode_building(b)


# ---------------------------------------------------------------------------
# PVS and ACH
# ---------------------------------------------------------------------------


@st.composite
def pvs_inputs(draw: st.DrawFn) -> tuple[np.ndarray, np.ndarray]:
    ids = draw(st.lists(st.integers(0, 2**63 - 1), unique=True, max_size=300))
    ach = draw(
        st.lists(
            st.one_of(st.just(0.0), st.floats(0.0, 1e12), st.floats(1e-300, 1e-3)),
            min_size=len(ids),
            max_size=len(ids),
        )
    )
    a = np.array(ach, dtype=np.float64)
    assume(len(ids) == 0 or a.sum() > 0)
    return np.array(ids, dtype=np.int64), a


@given(pvs_inputs())
def test_pvs_round_trip(inp: tuple[np.ndarray, np.ndarray]) -> None:
    ids, ach = inp
    data = encode_pvs(ids, ach)
    got_ids, got_ach = decode_pvs(data)
    order = np.argsort(ids)
    assert got_ids.dtype == np.int64 and got_ach.dtype == np.float64
    np.testing.assert_array_equal(got_ids, ids[order])
    assert pvs_size(data) == len(ids)
    if len(ids) == 0:
        assert len(got_ach) == 0
        return
    units = np.rint(got_ach * ACH_UNITS).astype(np.int64)
    assert units.sum() == ACH_UNITS
    assert abs(got_ach.sum() - 1.0) < 1e-12
    # everything seen keeps at least one unit; nothing unseen gets one
    sorted_ach = ach[order]
    assert (units[sorted_ach > 0] >= 1).all()
    assert (units[sorted_ach == 0] == 0).all()
    # largest remainder: within one unit of the exact share, unless the minimum-one
    # rule had to take units back (then within the number of bumped objects)
    exact = sorted_ach / sorted_ach.sum() * ACH_UNITS
    bumped = int(((exact < 1) & (sorted_ach > 0)).sum())
    assert np.abs(units - exact).max() < 1 + bumped


def test_quantise_ach_is_largest_remainder() -> None:
    np.testing.assert_array_equal(quantise_ach([1, 1, 1]), [21845, 21845, 21845])
    u = quantise_ach([2, 1, 1])
    assert u.sum() == ACH_UNITS and u.tolist() == [32767, 16384, 16384]  # remainders .5, .75, .75
    # one dominant object and many barely-seen ones: each of those keeps a unit
    u = quantise_ach([1e9] + [1.0] * 1000)
    assert u.sum() == ACH_UNITS and (u[1:] == 1).all() and u[0] == ACH_UNITS - 1000


def test_quantise_ach_refuses_nonsense() -> None:
    for bad in ([0.0, 0.0], [-1.0, 2.0], [np.nan, 1.0], [np.inf]):
        with pytest.raises(CodecError, match="ACH"):
            quantise_ach(bad)
    with pytest.raises(CodecError, match="visible objects"):
        quantise_ach(np.ones(ACH_UNITS + 1))


def test_empty_pvs() -> None:
    data = encode_pvs(np.zeros(0, np.int64), np.zeros(0))
    ids, ach = decode_pvs(data)
    assert ids.shape == (0,) and ach.shape == (0,) and pvs_size(data) == 0
    assert encode_pvs([], []) == data


def test_pvs_refuses_bad_input() -> None:
    with pytest.raises(CodecError, match="repeat"):
        encode_pvs([3, 3], [1.0, 1.0])
    with pytest.raises(CodecError, match="non-negative"):
        encode_pvs([-1], [1.0])
    with pytest.raises(CodecError, match="2 ids but 1"):
        encode_pvs([1, 2], [1.0])


def test_pvs_of_200_objects_is_compact() -> None:
    rng = np.random.default_rng(7)
    ids = rng.choice(20_000, 200, replace=False)
    ach = rng.pareto(1.5, 200) + 1e-3
    assert len(encode_pvs(ids, ach)) < 600


# ---------------------------------------------------------------------------
# varints, id sets, polygons
# ---------------------------------------------------------------------------


@given(st.lists(st.integers(0, 2**64 - 1), max_size=200))
def test_varints_round_trip(values: list[int]) -> None:
    a = np.array(values, dtype=np.uint64)
    np.testing.assert_array_equal(decode_varints(encode_varints(a)), a)


def test_varint_known_bytes() -> None:
    assert encode_varints([0, 1, 127, 128, 300]) == bytes([0, 1, 127, 0x80, 1, 0xAC, 2])
    assert encode_varints(np.array([2**64 - 1], np.uint64)) == b"\xff" * 9 + b"\x01"


@pytest.mark.parametrize(
    "data, match",
    [
        (b"\x80", "truncated"),
        (b"\x80\x00", "shortest"),
        (b"\xff" * 9 + b"\x02", "64 bits"),
        (b"\xff" * 11 + b"\x01", "longer than 10"),
    ],
)
def test_bad_varints(data: bytes, match: str) -> None:
    with pytest.raises(CodecError, match=match):
        decode_varints(data)


@given(st.sets(st.integers(0, 2**63 - 1), max_size=100))
def test_ids_round_trip(ids: set[int]) -> None:
    data = encode_ids(np.array(sorted(ids), dtype=np.int64)[::-1])
    np.testing.assert_array_equal(decode_ids(data), sorted(ids))


@given(st.lists(st.tuples(coord, coord), min_size=3, max_size=50))
def test_polygon_round_trip(pts: list[tuple[float, float]]) -> None:
    p = np.array(pts)
    np.testing.assert_array_equal(decode_polygon(encode_polygon(p)), p)


# ---------------------------------------------------------------------------
# hostile bytes
# ---------------------------------------------------------------------------

DECODERS = [
    decode_building,
    decode_street,
    decode_object,
    decode_pvs,
    decode_ids,
    decode_polygon,
    decode_varints,
    pvs_size,
]


def valid_samples() -> list[bytes]:
    rng = np.random.default_rng(1)
    b = typical_building()
    holed = BuildingParams(
        9,
        (b.rings[0], b.rings[0][::-1] * 0.5 + 600),
        (np.zeros(8), np.full(8, 7.0)),
        floors=2,
        floor_height=2.8,
        source_id="x",
    )
    return [
        encode_building(b),
        encode_building(holed),
        encode_street(StreetParams(5, "crossroad", b.rings[0], 12.0)),
        encode_pvs(rng.choice(5000, 50, replace=False), rng.random(50)),
        encode_ids([4, 9, 1000]),
        encode_polygon(b.rings[0]),
    ]


@settings(max_examples=300)
@given(st.binary(max_size=200))
def test_random_bytes_never_crash(data: bytes) -> None:
    for decode in DECODERS:
        try:
            decode(data)
        except CodecError:
            pass


@settings(max_examples=200)
@given(st.data())
def test_mutated_records_never_crash(data: st.DataObject) -> None:
    sample = bytearray(data.draw(st.sampled_from(valid_samples())))
    for _ in range(data.draw(st.integers(1, 4))):
        i = data.draw(st.integers(0, len(sample) - 1))
        sample[i] = data.draw(st.integers(0, 255))
    for decode in DECODERS:
        try:
            decode(bytes(sample))
        except CodecError:
            pass


@pytest.mark.parametrize("k", range(6))
def test_truncated_records_raise(k: int) -> None:
    sample = valid_samples()[k]
    decoder = [
        decode_building,
        decode_building,
        decode_street,
        decode_pvs,
        decode_ids,
        decode_polygon,
    ][k]
    decoder(sample)  # whole: fine
    for n in range(len(sample)):
        if decoder is decode_ids and (n == 0 or sample[n - 1] < 0x80):
            continue  # a prefix of an id set that ends on a varint boundary is a smaller set
        with pytest.raises(CodecError):
            decoder(sample[:n])


HUGE = [
    b"\xdd\xff\xff\xff\xff",  # array32 of 4 G items
    b"\xdc\xff\xff",  # array16 of 65535 items, no items present
    b"\xdb\xff\xff\xff\xff",  # str32 of 4 GB
    b"\xc6\xff\xff\xff\xff",  # bin32 of 4 GB
    b"\xdf\xff\xff\xff\xff",  # map32
    b"\xc9\xff\xff\xff\xff\x01",  # ext32
    b"\x91" * 200_000,  # deep nesting
    b"\x9b\x23" + b"\xdd\xff\xff\xff\xff",  # building header then a huge array
    msgpack.packb([35, 1, 0, 0, 2**20, b"", [], 1, 300, 0, ""]),  # a million vertices, no data
    msgpack.packb([35, 1, 0, 0, [3] * 60000, b"", [], 1, 300, 0, ""]),
    msgpack.packb([35, 1, 0, 0, 3, [0, 0, 0, 0], [0, 2**62, 1, 2**62], 1, 300, 0, ""]),
    b"\x01\xff\xff\xff\xff\xff\xff\xff\x7f",  # PVS declaring 2**56 objects
    b"\x01" + b"\xff" * 1000,  # an unterminated varint
]


@pytest.mark.parametrize("data", HUGE, ids=range(len(HUGE)))
def test_huge_declarations_raise_quickly(data: bytes) -> None:
    t0 = time.perf_counter()
    for decode in DECODERS:
        try:
            decode(data)
        except CodecError as exc:
            assert str(exc)
        else:
            # plain varints decode whatever is there; pvs_size only peeks at the count
            assert decode in (decode_varints, decode_ids, pvs_size)
    assert time.perf_counter() - t0 < 2.0


def test_errors_name_what_was_decoded() -> None:
    with pytest.raises(CodecError, match=r"^object 17: not valid msgpack"):
        decode_building(b"\xc1", "object 17")
    with pytest.raises(CodecError, match=r"^cell 3 pvs: format 7"):
        decode_pvs(b"\x07\x00", "cell 3 pvs")
    with pytest.raises(CodecError, match="expected bytes"):
        decode_building("text")  # type: ignore[arg-type]
    with pytest.raises(CodecError, match="trailing"):
        unpack_bounded(b"\x01\x02", "x")
    with pytest.raises(CodecError, match="limit"):
        unpack_bounded(b"\x00" * 100, "x", max_bytes=10)


def test_booleans_are_not_integers() -> None:
    rec = msgpack.unpackb(encode_building(typical_building()))
    rec[7] = True  # floors
    with pytest.raises(CodecError, match="floors"):
        decode_building(msgpack.packb(rec))
