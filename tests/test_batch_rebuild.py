"""Many buildings per call: the batched rebuild makes the meshes the one-by-one path makes."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pytest
from teamdata import team_data

from walkstream.server.sources.citygen import generate_city
from walkstream.server.sources.geojson import load_geojson, load_geojson_dict
from walkstream.shared.buildings import (
    build_lod,
    build_lod_batch,
    build_lods,
    build_lods_batch,
    default_grammar_text,
    derive_building,
    edge_frames,
    frame_batch,
)
from walkstream.shared.errors import DerivationLimitError, InputError
from walkstream.shared.lsystem.batch import derive_batch
from walkstream.shared.lsystem.derive import derive
from walkstream.shared.lsystem.grammar import parse_grammar
from walkstream.shared.records import BuildingParams, Mesh


def assert_same(single: Sequence[Mesh], batch: Sequence[Mesh]) -> None:
    """Same triangles in the same order, positions within 1e-6 m, same normals and materials."""
    assert len(single) == len(batch)
    for k, (a, b) in enumerate(zip(single, batch, strict=True)):
        assert b.indices.shape == a.indices.shape, k
        assert (b.indices == a.indices).all(), k
        assert b.positions.shape == a.positions.shape, k
        if len(a.positions):
            assert np.abs(b.positions.astype(np.float64) - a.positions).max() <= 1e-6, k
        assert (b.normals == a.normals).all(), k
        assert (b.materials == a.materials).all(), k
        assert not b.positions.flags.writeable


@pytest.fixture(scope="module")
def city() -> list[BuildingParams]:
    return list(load_geojson_dict(generate_city(300, 3), name="city").buildings)


@pytest.fixture(scope="module")
def vienna() -> list[BuildingParams]:
    return list(load_geojson(team_data("vienna", "blocks.geojson")).buildings)


@pytest.mark.parametrize("lod", [0, 1, 2])
def test_city_batch_equals_one_by_one(city: list[BuildingParams], lod: int) -> None:
    assert any(len(b.rings) > 1 for b in city)  # courtyards are in the batch
    assert any((np.concatenate(b.neighbour_heights) > 0).any() for b in city)  # party walls too
    assert_same([build_lod(b, lod) for b in city], build_lod_batch(city, lod))


def test_city_batches_of_any_size_and_all_lods(city: list[BuildingParams]) -> None:
    few = city[:23]
    want = [build_lods(b) for b in few]
    for size in (1, 5, 23):
        got = [m for i in range(0, len(few), size) for m in build_lods_batch(few[i : i + size])]
        for lod in range(3):
            assert_same([w[lod] for w in want], [g[lod] for g in got])


@pytest.mark.parametrize("lod, step", [(0, 6), (1, 12), (2, 40)])
def test_vienna_batch_equals_one_by_one(vienna: list[BuildingParams], lod: int, step: int) -> None:
    # every step-th block, plus every block with a courtyard and the most complex footprints
    edges = np.array([sum(len(r) for r in b.rings) for b in vienna])
    pick = set(range(0, len(vienna), step)) | {k for k, b in enumerate(vienna) if len(b.rings) > 1}
    pick |= set(np.argsort(edges)[-10:].tolist())
    some = [vienna[k] for k in sorted(pick)]
    assert any(len(b.rings) > 1 for b in some)
    assert_same([build_lod(b, lod) for b in some], build_lod_batch(some, lod))


def test_frame_batch_matches_edge_frames(city: list[BuildingParams]) -> None:
    few = city[:12]
    batch = frame_batch(few)
    for k, b in enumerate(few):
        one = edge_frames(b)
        e0, e1 = batch.edge_start[k], batch.edge_start[k + 1]
        t0, t1 = batch.tri_start[k], batch.tri_start[k + 1]
        for name in ("origin", "direction", "normal", "length"):
            assert (getattr(batch.frames, name)[e0:e1] == getattr(one, name)).all(), name
        assert (batch.frames.cap_xy[batch.cap_start[k] : batch.cap_start[k + 1]] == one.cap_xy).all()
        assert (batch.frames.cap_tris[t0:t1] == one.cap_tris).all()


def test_module_order_does_not_depend_on_the_other_members_of_the_batch() -> None:
    # A's second production fires only for some owners; alone, B would be seen before C
    # (or C before B) depending on which came first: both engines go in grammar order
    g = parse_grammar(
        "grammar t 1\nglobal X\n"
        "A(n) : n > X -> C(n) B(n)\n"
        "A(n) -> B(n)\n"
        "B(n) -> Quad(0, n, 0, n + 1, 1, 0, 1)\n"
        "C(n) -> Quad(0, n, 1, n + 1, 2, 0, 2)\n"
    )
    seeds = [np.array([[1.0], [5.0]]), np.array([[5.0], [1.0]]), np.array([[0.0]])]
    xs = [2.0, 0.0, 3.0]
    mods, owners = derive_batch(
        g,
        {"A": np.concatenate(seeds)},
        {"A": np.repeat(np.arange(3), [len(s) for s in seeds])},
        {"X": np.array(xs)},
        3,
    )
    for k, (s, x) in enumerate(zip(seeds, xs, strict=True)):
        alone = derive(g, {"A": s}, {"X": x})
        assert (mods["Quad"][owners["Quad"] == k] == alone["Quad"]).all()


def test_a_building_over_the_limits_is_named_as_one_by_one(city: list[BuildingParams]) -> None:
    # limits that only the biggest building of the city goes over
    sizes = [sum(len(v) for v in derive_building(b, 2).values()) for b in city]
    tall = city[int(np.argmax(sizes))]
    assert max(sizes) > 600 and max(sizes[:2]) < 500
    g = parse_grammar(default_grammar_text().replace("modules 400000", "modules 600"))
    with pytest.raises(DerivationLimitError) as one:
        build_lod(tall, 2, g)
    with pytest.raises(DerivationLimitError) as many:
        build_lod_batch([city[0], tall, city[1]], 2, g)
    assert str(many.value) == str(one.value)
    # the others alone still build, and the same as one by one
    assert_same([build_lod(city[0], 2, g)], build_lod_batch([city[0]], 2, g))


def test_empty_batch_and_bad_lod(city: list[BuildingParams]) -> None:
    assert build_lod_batch([], 2) == []
    assert build_lods_batch([]) == []
    with pytest.raises(InputError, match="lod: expected one of"):
        build_lod_batch(city[:2], 3)
