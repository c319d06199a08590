"""The procedural city generator: determinism, layout, overlaps, party walls, loading."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import shapely

from walkstream.server.sources.citygen import (
    CRS_NAME,
    ORIGIN,
    generate_city,
    write_city,
)
from walkstream.server.sources.citysummary import city_summary
from walkstream.shared.errors import InputError

OVERLAP_M2 = 0.01


@pytest.fixture(scope="module")
def city700() -> dict[str, Any]:
    return generate_city(700, seed=1)


def local_rings(feature: dict[str, Any]) -> list[np.ndarray]:
    """Rings without the closing vertex, moved to the local frame (precise shapely areas)."""
    return [
        np.asarray(r, dtype=np.float64)[:-1] - ORIGIN for r in feature["geometry"]["coordinates"]
    ]


def polygon(feature: dict[str, Any]) -> shapely.Polygon:
    rings = local_rings(feature)
    return shapely.Polygon(rings[0], rings[1:])


def of_kind(fc: dict[str, Any], *kinds: str) -> list[dict[str, Any]]:
    return [f for f in fc["features"] if f["properties"]["kind"] in kinds]


def signed_area(r: np.ndarray) -> float:
    x, y = (r - r[0]).T
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def max_pair_overlap(a: list[shapely.Polygon], b: list[shapely.Polygon], same: bool) -> float:
    """Largest intersection area over all pairs (a[i], b[j]), i < j when ``same``."""
    aa, bb = np.array(a, dtype=object), np.array(b, dtype=object)
    i, j = shapely.STRtree(bb).query(aa, predicate="intersects")
    if same:
        keep = i < j
        i, j = i[keep], j[keep]
    if len(i) == 0:
        return 0.0
    return float(shapely.area(shapely.intersection(aa[i], bb[j])).max())


# --------------------------------------------------------------------------- inputs


def test_same_seed_is_byte_identical_and_other_seed_differs(tmp_path: Path) -> None:
    a = json.dumps(generate_city(350, seed=7), separators=(",", ":"))
    b = json.dumps(generate_city(350, seed=7), separators=(",", ":"))
    c = json.dumps(generate_city(350, seed=8), separators=(",", ":"))
    assert a == b
    assert a != c
    write_city(tmp_path / "one.geojson", 350, 7)
    write_city(tmp_path / "two.geojson", 350, 7)
    assert (tmp_path / "one.geojson").read_bytes() == (tmp_path / "two.geojson").read_bytes()


@pytest.mark.parametrize("size", [99.9, 5000.5, -350, 0, float("nan"), float("inf"), "big"])
def test_size_out_of_range_raises_input_error_naming_the_value(size: Any) -> None:
    with pytest.raises(InputError, match=re.escape(repr(size))):
        generate_city(size)


@pytest.mark.parametrize("seed", [-1, 1.5, "1", True])
def test_bad_seed_raises_input_error(seed: Any) -> None:
    with pytest.raises(InputError, match="seed"):
        generate_city(350, seed)


# --------------------------------------------------------------------------- structure


@pytest.mark.parametrize("size", [100, 350, 700, 2000])
def test_sizes_generate(size: int) -> None:
    fc = generate_city(size)
    s = city_summary(fc)
    assert s["buildings"] > 0
    assert s["crossroads"] >= 4
    assert s["streets"] >= 4
    # Every building stands on a lot, except at most one backyard shed per block.
    assert 1 <= s["lots"] and s["buildings"] <= s["lots"] + s["crossroads"]
    if size >= 300:
        assert s["squares"] >= 1
    if size == 700:
        assert 300 <= s["buildings"] <= 3000  # "hundreds": the paper's large model
    assert s["area_m2"] == pytest.approx(size * size)


def test_collection_metadata_and_coordinates(city700: dict[str, Any]) -> None:
    fc = city700
    assert fc["type"] == "FeatureCollection"
    assert fc["crs"] == {"type": "name", "properties": {"name": CRS_NAME}}
    assert fc["walkstream"]["generator"] == "city"
    assert fc["walkstream"]["size"] == 700
    assert fc["walkstream"]["seed"] == 1
    assert fc["walkstream"]["version"] == 2
    ids = [f["id"] for f in fc["features"]]
    assert len(set(ids)) == len(ids)
    for f in fc["features"]:
        assert f["type"] == "Feature"
        assert f["geometry"]["type"] == "Polygon"
        assert f["properties"]["id"] == f["id"]
        for k, ring in enumerate(f["geometry"]["coordinates"]):
            assert ring[0] == ring[-1]  # GeoJSON rings are closed
            r = np.asarray(ring)
            # Far from the origin (UTM 33N), within the city plus half a border street.
            assert np.all(r[:, 0] > ORIGIN[0] - 15) and np.all(r[:, 0] < ORIGIN[0] + 715)
            assert np.all(r[:, 1] > ORIGIN[1] - 15) and np.all(r[:, 1] < ORIGIN[1] + 715)
            assert np.allclose(r, np.round(r, 2), rtol=0, atol=1e-6)  # 1 cm grid
            area = signed_area(r[:-1] - ORIGIN)
            assert (area > 0) if k == 0 else (area < 0), (f["id"], k)  # CCW / CW


def test_building_properties(city700: dict[str, Any]) -> None:
    buildings = of_kind(city700, "building")
    assert [f["id"] for f in buildings] == [f"b{k}" for k in range(len(buildings))]
    for f in buildings:
        p = f["properties"]
        if p.get("landmark"):  # a tower or a spire: see the landmark test
            assert p["landmark"] in ("tower", "spire") and 14 <= p["floors"] <= 34
            continue
        assert isinstance(p["floors"], int) and 1 <= p["floors"] <= 9
        assert 3.0 <= p["floor_height"] <= 3.6
        assert p["height"] == pytest.approx(p["floors"] * p["floor_height"], abs=0.006)
        assert isinstance(p["style"], int)
    floors = [f["properties"]["floors"] for f in buildings]
    assert len(set(floors)) >= 5  # per-block 3-7, per-lot +-2


def test_streets_and_crossroads_properties(city700: dict[str, Any]) -> None:
    streets = of_kind(city700, "street")
    crossroads = {f["properties"]["node"]: f for f in of_kind(city700, "crossroad")}
    widths = {f["properties"]["width"] for f in streets}
    assert min(widths) >= 10 and max(widths) <= 20
    assert max(widths) >= 18  # at least one avenue
    for f in streets:
        p = f["properties"]
        assert len(p["centreline"]) == 2
        piece = polygon(f)
        for node in (p["from"], p["to"]):
            cross = crossroads[node]
            assert cross["properties"]["width"] >= p["width"]
            # The piece ends on its crossroads: they share a whole edge, as wide as the street.
            shared = piece.boundary.intersection(polygon(cross).boundary).length
            assert shared == pytest.approx(p["width"], rel=0.15)
        # The centreline runs between the two crossroads, inside the piece.
        line = shapely.LineString(np.asarray(p["centreline"]) - ORIGIN)
        assert piece.buffer(0.02).contains(line)
    for f in [*streets, *crossroads.values()]:
        poly = polygon(f)
        assert poly.is_valid
        assert poly.area == pytest.approx(poly.convex_hull.area, abs=0.05)  # convex cells


# --------------------------------------------------------------------------- shapes, overlap


def test_footprint_shapes_vary(city700: dict[str, Any]) -> None:
    shapes = city_summary(city700)["shapes"]
    assert shapes["rect"] > 0
    assert shapes["l"] > 0
    assert shapes["courtyard"] > 0
    assert shapes["irregular"] > 0
    holed = [f for f in of_kind(city700, "building") if len(f["geometry"]["coordinates"]) > 1]
    assert holed and all(polygon(f).interiors for f in holed)


def test_nothing_overlaps(city700: dict[str, Any]) -> None:
    buildings = [polygon(f) for f in of_kind(city700, "building")]
    nav = [polygon(f) for f in of_kind(city700, "street", "crossroad", "square")]
    assert all(p.is_valid for p in buildings + nav)
    assert max_pair_overlap(buildings, buildings, same=True) < OVERLAP_M2
    assert max_pair_overlap(buildings, nav, same=False) < OVERLAP_M2
    assert max_pair_overlap(nav, nav, same=True) < OVERLAP_M2


def test_navigation_space_is_tiled(city700: dict[str, Any]) -> None:
    nav = [polygon(f) for f in of_kind(city700, "street", "crossroad", "square")]
    union = shapely.union_all(nav)
    # No gaps inside the street network: one polygon whose only holes are the built
    # blocks, and whose outline is the city square grown by half a border street.
    assert union.geom_type == "Polygon"
    assert union.area == pytest.approx(sum(p.area for p in nav), abs=0.5)
    outline = shapely.Polygon(union.exterior)
    assert outline.area == pytest.approx(outline.envelope.area, rel=1e-6)
    s = city_summary(city700)
    nx = round(math.sqrt(s["crossroads"]))
    assert len(union.interiors) == (nx - 1) ** 2 - s["squares"]
    # Every building lies in one of those holes.
    blocks = [shapely.Polygon(h) for h in union.interiors]
    tree = shapely.STRtree(blocks)
    for f in of_kind(city700, "building"):
        p = polygon(f)
        hits = tree.query(p, predicate="within")
        assert len(hits) == 1, f["id"]


# --------------------------------------------------------------------------- party walls


def test_the_generator_writes_plain_footprints(city700: dict[str, Any]) -> None:
    """Party walls are found in one place, when the footprints are loaded: none in the file."""
    assert not any("neighbour_heights" in f["properties"] for f in of_kind(city700, "building"))


@pytest.fixture(scope="module")
def loaded700(city700: dict[str, Any]) -> Any:
    from walkstream.server.sources.geojson import load_geojson_dict

    return load_geojson_dict(city700)


def test_neighbour_heights_align_with_rings(city700: dict[str, Any], loaded700: Any) -> None:
    heights = [b.height for b in loaded700.buildings]
    party = taller = 0
    for b in loaded700.buildings:
        assert len(b.neighbour_heights) == len(b.rings)
        for ring, nh in zip(b.rings, b.neighbour_heights, strict=True):
            assert len(nh) == len(ring)  # one per edge (rings are open)
            for h in nh:  # the height of an actual building
                assert h == 0 or min(abs(h - x) for x in heights) < 1e-6
            party += int(np.count_nonzero(nh > 0))
            taller += int(np.count_nonzero(nh > b.height + 1e-9))
        if len(b.rings) > 1:  # a courtyard building stands alone in its block
            assert not any((h > 0).any() for h in b.neighbour_heights)
    assert party > len(loaded700.buildings)  # most lots are built wall to wall
    assert taller > 0
    assert city_summary(city700)["party_wall_edges"] == party


def test_party_walls_are_shared_and_partly_shared_edges_are_split(loaded700: Any) -> None:
    buildings = loaded700.buildings
    outlines = np.array([shapely.LinearRing(b.rings[0]) for b in buildings], dtype=object)
    tree = shapely.STRtree(outlines)
    l_shapes_with_neighbours = 0
    for k, b in enumerate(buildings):
        ring, nh = b.rings[0], np.asarray(b.neighbour_heights[0])
        mids = shapely.points((ring + np.roll(ring, -1, axis=0)) / 2)
        # An edge is a party wall exactly when another building's outline runs along it.
        near = [set(tree.query(m, predicate="dwithin", distance=0.05).tolist()) - {k} for m in mids]
        for i, hits in enumerate(near):
            assert (nh[i] > 0) == bool(hits), (b.source_id, i)
            if hits:
                assert nh[i] == pytest.approx(max(buildings[j].height for j in hits))
        if len(ring) >= 6 and nh.any():
            l_shapes_with_neighbours += 1
    assert l_shapes_with_neighbours > 0


# --------------------------------------------------------------------------- writing, loading


def test_write_city_is_compact_and_returns_its_summary(tmp_path: Path) -> None:
    path = tmp_path / "city.geojson"
    summary = write_city(path, 350, 3)
    text = path.read_text(encoding="utf-8")
    assert ", " not in text and ": " not in text
    fc = json.loads(text)
    assert summary == city_summary(fc)
    assert summary["buildings"] == len(of_kind(fc, "building"))
    assert summary["floors"]["min"] >= 1
    assert summary["floors"]["min"] <= summary["floors"]["mean"] <= summary["floors"]["max"]


def test_load_geojson_reads_every_building(tmp_path: Path) -> None:
    geojson = pytest.importorskip("walkstream.server.sources.geojson")
    path = tmp_path / "city.geojson"
    summary = write_city(path, 350, 1)
    scene = geojson.load_geojson(path)
    assert len(scene.buildings) == summary["buildings"]
    assert len(scene.streets) == summary["streets"] + summary["crossroads"] + summary["squares"]
    assert not [i for i in scene.issues if i.action == "skipped"]
    assert (
        sum(int(np.count_nonzero(h > 0)) for b in scene.buildings for h in b.neighbour_heights) > 0
    )


def test_the_demo_city_has_a_few_deterministic_landmarks(city700: dict[str, Any], loaded700: Any) -> None:
    from walkstream.server.bake.impostorsettings import DEFAULT_COMPLEX_TRIANGLES
    from walkstream.shared.buildings import predict_triangles

    marks = [f for f in city700["features"] if f["properties"].get("landmark")]
    assert 2 <= len(marks) <= 4
    assert {f["properties"]["landmark"] for f in marks} == {"tower", "spire"}
    assert city_summary(city700)["landmarks"]["tower"] + city_summary(city700)["landmarks"]["spire"] == len(marks)
    # the same seed places the same landmarks; another seed other ones
    again = [f for f in generate_city(700, 1)["features"] if f["properties"].get("landmark")]
    assert again == marks
    other = [f for f in generate_city(700, 2)["features"] if f["properties"].get("landmark")]
    assert other and other != marks
    by_source = {b.source_id: b for b in loaded700.buildings}
    for f in marks:
        b = by_source[f["id"]]
        assert b.kind in (1, 2)
        ring = b.rings[0]
        assert len(b.rings) == 1 and len(ring) == 4
        sides = np.hypot(*(np.roll(ring, -1, axis=0) - ring).T)
        assert np.allclose(sides, sides[0], atol=0.02) and 14.0 - 0.02 <= sides[0] <= 24.0 + 0.02
        # free standing: every wall a frontage, nothing touching it
        assert not (b.neighbour_heights[0] > 0).any()
        assert b.top > b.height + 10.0
        # the complex-impostor path's default threshold is passed at LOD2
        assert predict_triangles(b)[2] > DEFAULT_COMPLEX_TRIANGLES


def test_landmarks_leave_the_rest_of_the_city_as_it_was(monkeypatch: pytest.MonkeyPatch) -> None:
    from walkstream.server.sources import citylandmarks

    for size in (150, 350):
        fc = generate_city(size, 3)
        assert city_summary(fc)["landmarks"] == {"tower": 0, "spire": 0}
    with_marks = generate_city(500, 3)["features"]
    monkeypatch.setattr(citylandmarks, "landmark_count", lambda size: 0)
    without = generate_city(500, 3)["features"]
    marks = [f["id"] for f in with_marks if f["properties"].get("landmark")]
    assert len(marks) == 1
    # a landmark takes a backyard shed's place (and id) or comes after the last building
    a, b = {f["id"]: f for f in with_marks}, {f["id"]: f for f in without}
    assert set(b) <= set(a)
    differ = [k for k in a if k not in b or a[k] != b[k]]
    assert differ == marks
    if marks[0] in b:
        assert b[marks[0]]["properties"]["floors"] <= 2  # it was a shed
