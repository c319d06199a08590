"""Tests for server.sources.geojson (GeoJSON footprints -> SourceScene)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from teamdata import team_data

from walkstream.server.sources.geojson import load_geojson, load_geojson_dict
from walkstream.server.sources.heights import default_floors, parse_length
from walkstream.server.sources.scene import FeatureIssue, SourceScene
from walkstream.shared.errors import InputError, SourceError

UTM33 = "EPSG:32633"


# ------------------------------------------------------------------------ helpers


def square(x0: float, y0: float, size: float = 10.0) -> list[list[float]]:
    """Closed counter-clockwise GeoJSON ring."""
    return [[x0, y0], [x0 + size, y0], [x0 + size, y0 + size], [x0, y0 + size], [x0, y0]]


def poly(rings: list[Any], fid: Any = None, gtype: str = "Polygon", **props: Any) -> dict[str, Any]:
    feat: dict[str, Any] = {
        "type": "Feature",
        "properties": props,
        "geometry": {"type": gtype, "coordinates": rings},
    }
    if fid is not None:
        feat["id"] = fid
    return feat


def fc(*features: dict[str, Any], crs: str | None = UTM33) -> dict[str, Any]:
    obj: dict[str, Any] = {"type": "FeatureCollection", "features": list(features)}
    if crs is not None:
        obj["crs"] = {"type": "name", "properties": {"name": crs}}
    return obj


def signed_area(r: np.ndarray) -> float:
    x, y = r[:, 0], r[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def issues_of(scene: SourceScene, fid: str) -> list[FeatureIssue]:
    return [i for i in scene.issues if i.feature_id == fid]


def only_issue(scene: SourceScene, fid: str) -> FeatureIssue:
    found = issues_of(scene, fid)
    assert len(found) == 1, scene.issues
    return found[0]


# ------------------------------------------------------------------ basic loading


def test_two_adjacent_buildings_share_a_party_wall() -> None:
    scene = load_geojson_dict(
        fc(
            poly([square(500000, 5000000)], "a", height=12),
            poly([square(500010, 5000000)], "b", height=21),
        )
    )
    assert scene.crs == UTM33
    assert scene.origin == (500010.0, 5000005.0)
    a, b = scene.buildings
    assert (a.id, b.id) == (0, 1) and (a.source_id, b.source_id) == ("a", "b")
    np.testing.assert_array_equal(a.rings[0], [[-10, -5], [0, -5], [0, 5], [-10, 5]])
    np.testing.assert_array_equal(a.neighbour_heights[0], [0, 21, 0, 0])
    np.testing.assert_array_equal(b.neighbour_heights[0], [0, 0, 0, 12])
    assert scene.issues == ()
    assert all(r.dtype == np.float64 for bl in scene.buildings for r in bl.rings)


def test_partly_shared_wall_is_split() -> None:
    small = [[500010, 5000000], [500020, 5000000], [500020, 5000005], [500010, 5000005]]
    scene = load_geojson_dict(
        fc(poly([square(500000, 5000000)], "a", height=12), poly([small], "b", height=6))
    )
    a = scene.buildings[0]
    assert len(a.rings[0]) == 5
    np.testing.assert_array_equal(a.neighbour_heights[0], [0, 6, 0, 0, 0])


def test_clockwise_input_is_normalised() -> None:
    outer_cw = square(0, 0, 30)[::-1]
    hole_ccw = square(10, 10, 10)
    scene = load_geojson_dict(fc(poly([outer_cw, hole_ccw], "c")))
    (b,) = scene.buildings
    assert signed_area(b.rings[0]) == pytest.approx(900.0)
    assert signed_area(b.rings[1]) == pytest.approx(-100.0)
    assert scene.issues == ()


def test_collinear_duplicate_and_closing_vertices_are_removed() -> None:
    ring = [
        [0, 0], [5, 0], [10, 0], [10, 0.0004], [10, 10], [10, 10], [3, 10], [0, 10], [0, 0],
    ]  # fmt: skip
    scene = load_geojson_dict(fc(poly([ring], "r")))
    np.testing.assert_allclose(
        scene.buildings[0].rings[0] + scene.origin, [[0, 0], [10, 0], [10, 10], [0, 10]]
    )


def test_footprint_with_hole() -> None:
    scene = load_geojson_dict(fc(poly([square(0, 0, 30), square(10, 10, 10)[::-1]], "h")))
    (b,) = scene.buildings
    assert len(b.rings) == 2 and len(b.neighbour_heights) == 2
    np.testing.assert_allclose(
        sorted(map(tuple, b.rings[1] + scene.origin)), [(10, 10), (10, 20), (20, 10), (20, 20)]
    )


def test_degenerate_hole_is_dropped_and_reported() -> None:
    sliver = [[10, 10], [20, 10], [15, 10.0000001], [10, 10]]
    scene = load_geojson_dict(fc(poly([square(0, 0, 30), sliver], "h")))
    (b,) = scene.buildings
    assert len(b.rings) == 1
    issue = only_issue(scene, "h")
    assert issue.action == "repaired" and "hole" in issue.problem


def test_multipolygon_parts_become_buildings() -> None:
    scene = load_geojson_dict(
        fc(poly([[square(0, 0)], [square(50, 0)]], "m", gtype="MultiPolygon", height=9))
    )
    assert [b.source_id for b in scene.buildings] == ["m#0", "m#1"]
    assert all(b.height == pytest.approx(9.0) for b in scene.buildings)
    # Both parts share one default style seed (crc32 of the feature id).
    assert scene.buildings[0].style == scene.buildings[1].style


def test_feature_id_fallbacks() -> None:
    scene = load_geojson_dict(
        fc(
            poly([square(0, 0)], 7),
            poly([square(20, 0)], None, id="p"),
            poly([square(40, 0)], None, **{"@id": "way/1"}),
            poly([square(60, 0)]),
            poly([square(80, 0)], 0),
        )
    )
    assert [b.source_id for b in scene.buildings] == ["7", "p", "way/1", "3", "0"]


def test_style_property_and_default_seed() -> None:
    scene = load_geojson_dict(fc(poly([square(0, 0)], "a", style=42), poly([square(20, 0)], "b")))
    assert scene.buildings[0].style == 42
    assert 0 <= scene.buildings[1].style <= 0x7FFFFFFF


# ------------------------------------------------------------------------ heights


@pytest.mark.parametrize(
    ("text", "metres"),
    [
        (12, 12.0),
        (12.5, 12.5),
        ("12", 12.0),
        ("12 m", 12.0),
        ("12.5m", 12.5),
        ("12,5", 12.5),
        ("40 ft", 40 * 0.3048),
        ("40'", 40 * 0.3048),
        ("40 feet", 40 * 0.3048),
        ("tall", None),
        ("", None),
        (True, None),
        (None, None),
        ([12], None),
    ],
)
def test_parse_length(text: Any, metres: float | None) -> None:
    got = parse_length(text)
    assert got == (None if metres is None else pytest.approx(metres))


def load_one(**props: Any) -> tuple[SourceScene, Any]:
    scene = load_geojson_dict(fc(poly([square(0, 0)], "f", **props)))
    return scene, scene.buildings[0]


def test_height_string_in_metres() -> None:
    scene, b = load_one(height="12 m")
    assert b.floors == 4 and b.floor_height == pytest.approx(3.0) and b.height == pytest.approx(12)
    assert scene.issues == ()


def test_height_in_feet_and_decimal_comma() -> None:
    assert load_one(height="40 ft")[1].height == pytest.approx(12.192)
    assert load_one(**{"building:height": "12,5"})[1].height == pytest.approx(12.5)
    assert load_one(est_height=30.0)[1].height == pytest.approx(30.0)


def test_levels_string() -> None:
    scene, b = load_one(**{"building:levels": "5"})
    assert b.floors == 5 and b.floor_height == pytest.approx(3.2)
    assert scene.issues == ()


def test_levels_with_floor_height_and_with_height() -> None:
    assert load_one(levels=3, floor_height="4 m")[1].height == pytest.approx(12.0)
    _, b = load_one(floors=4, height=14)
    assert b.floors == 4 and b.floor_height == pytest.approx(3.5)


def test_default_rule_without_height() -> None:
    _, b = load_one()
    assert b.floors == default_floors("f") and 4 <= b.floors <= 6
    assert b.floor_height == pytest.approx(3.2)
    scene = load_geojson_dict(fc(poly([square(0, 0)], "f")), default_floor_height=2.5)
    assert scene.buildings[0].floor_height == 2.5


@pytest.mark.parametrize(
    "props",
    [
        {"building:levels": -3},
        {"building:levels": "-2"},
        {"levels": 0},
        {"floors": "many"},
        {"height": -5},
        {"height": float("nan")},
        {"height": "tall"},
        {"height": "0 m"},
    ],
)
def test_bad_height_or_floors_repaired_with_default_rule(props: dict[str, Any]) -> None:
    scene, b = load_one(**props)
    assert b.floors == default_floors("f") and b.floor_height == pytest.approx(3.2)
    issue = only_issue(scene, "f")
    assert issue.action == "repaired"
    assert "default rule" in issue.problem and next(iter(props)) in issue.problem


def test_bad_height_falls_back_to_good_floors() -> None:
    scene, b = load_one(height="n/a", **{"building:levels": 3})
    assert b.floors == 3
    assert only_issue(scene, "f").action == "repaired"


# ------------------------------------------------------------------- bad features


def bad_collection() -> dict[str, Any]:
    bowtie = [[0, 0], [10, 10], [10, 0], [0, 10], [0, 0]]
    return fc(
        poly([square(0, 0)], "good", height=10),
        poly([[[100, 0], [110, 0], [float("nan"), 5], [100, 5], [100, 0]]], "nan"),
        poly([[[200, 0], [210, 0], [200, 0]]], "twopoint"),
        poly([[[300, 0], [310, 0], [320, 0], [300, 0]]], "flat"),
        poly([[[400, 0], [400.05, 0], [400.05, 0.05], [400, 0.05], [400, 0]]], "tiny"),
        poly([[[p[0] + 500, p[1]] for p in bowtie]], "bowtie"),
        {
            "type": "Feature",
            "id": "pt",
            "properties": {},
            "geometry": {"type": "Point", "coordinates": [0, 0]},
        },
        {"type": "Feature", "id": "nogeom", "properties": {}, "geometry": None},
        poly([square(600, 0)], "neg", **{"building:levels": -2}),
    )


def test_bad_features_are_reported_with_their_action() -> None:
    scene = load_geojson_dict(bad_collection())
    by_id = {i.feature_id: i for i in scene.issues}
    expected = {
        "nan": ("skipped", "NaN"),
        "twopoint": ("skipped", "fewer than 3 distinct points"),
        "flat": ("skipped", "area"),
        "tiny": ("skipped", "area"),
        "bowtie": ("repaired", "make_valid"),
        "pt": ("skipped", "Point"),
        "nogeom": ("skipped", "no geometry"),
        "neg": ("repaired", "building:levels"),
    }
    assert set(by_id) == set(expected)
    for fid, (action, words) in expected.items():
        assert by_id[fid].action == action, by_id[fid]
        assert words in by_id[fid].problem, by_id[fid]
    ids = [b.source_id for b in scene.buildings]
    assert ids == ["good", "bowtie#0", "bowtie#1", "neg"]
    # The bow-tie becomes its two triangles, 25 m² each.
    for b in scene.buildings[1:3]:
        assert signed_area(b.rings[0]) == pytest.approx(25.0)
    assert [b.id for b in scene.buildings] == [0, 1, 2, 3]


def test_unknown_line_feature_is_skipped_not_fatal() -> None:
    scene = load_geojson_dict(
        fc(
            poly([square(0, 0)], "b"),
            {"type": "Feature", "id": "route", "properties": {},
             "geometry": {"type": "LineString", "coordinates": [[0, 20], [50, 20]]}},
        )
    )  # fmt: skip
    assert len(scene.buildings) == 1 and scene.streets == ()
    assert only_issue(scene, "route").action == "skipped"


# ------------------------------------------------------------------------ streets


def line(coords: list[list[float]], fid: str, **props: Any) -> dict[str, Any]:
    return {
        "type": "Feature",
        "id": fid,
        "properties": props,
        "geometry": {"type": "LineString", "coordinates": coords},
    }


def test_streets_crossroads_and_squares() -> None:
    scene = load_geojson_dict(
        fc(
            poly([square(0, 0)], "b"),
            line([[0, -10], [100, -10]], "s1", kind="street", width=8),
            line([[0, -40], [50, -40], [50, -90]], "s2", highway="residential"),
            poly([square(200, 0, 20)], "x", kind="crossroad", width="12 m"),
            poly([square(300, 0, 40)], "sq", kind="square"),
        )
    )
    assert len(scene.buildings) == 1
    by_id = {s.source_id: s for s in scene.streets}
    assert set(by_id) == {"s1", "s2", "x", "sq"}
    assert sorted(s.id for s in scene.streets) == [1, 2, 3, 4]
    s1 = by_id["s1"]
    assert s1.kind == "street" and s1.width == 8.0
    # 100 x 8 with rounded ends (half octagons of radius 4 reach 4 m past each end)
    assert 800.0 < signed_area(s1.ring) < 800.0 + np.pi * 16
    np.testing.assert_allclose(np.ptp(s1.ring, axis=0), [108.0, 8.0])
    s2 = by_id["s2"]
    assert s2.width == 6.0  # highway=residential without width: the class table
    # an L of 50 + 50 m at 6 m wide (the inner corner overlaps, the ends are rounded)
    assert 550.0 < signed_area(s2.ring) < 650.0
    assert by_id["x"].kind == "crossroad" and by_id["x"].width == 12.0
    assert by_id["sq"].kind == "square" and signed_area(by_id["sq"].ring) == pytest.approx(1600)
    assert scene.issues == ()


# ---------------------------------------------------------------- CRS and origin


def test_far_projected_coordinates_keep_millimetre_precision() -> None:
    ring = [[3.123456, 1.987654], [17.5, 2.25], [18.0001, 13.333], [2.5, 14.75]]
    near = load_geojson_dict(fc(poly([ring + ring[:1]], "n")))
    far_ring = [[x + 600000.0, y + 5000000.0] for x, y in ring]
    far = load_geojson_dict(
        fc(poly([far_ring + far_ring[:1]], "n"), crs="urn:ogc:def:crs:EPSG::32633")
    )
    assert far.crs == UTM33
    assert far.origin[0] - near.origin[0] == 600000.0
    assert far.origin[1] - near.origin[1] == 5000000.0
    assert np.abs(far.buildings[0].rings[0]).max() < 10.0
    np.testing.assert_allclose(far.buildings[0].rings[0], near.buildings[0].rings[0], atol=1e-3)
    assert all(float(o).is_integer() for o in far.origin)


def lonlat_square(lon: float, lat: float, metres: float) -> list[list[float]]:
    dlat = metres / 111_132.0
    dlon = metres / (111_320.0 * math.cos(math.radians(lat)))
    return [[lon, lat], [lon + dlon, lat], [lon + dlon, lat + dlat], [lon, lat + dlat], [lon, lat]]


@pytest.mark.parametrize("crs", [None, "urn:ogc:def:crs:OGC:1.3:CRS84", "EPSG:4326"])
def test_lonlat_is_projected_to_utm(crs: str | None) -> None:
    scene = load_geojson_dict(
        fc(
            poly([lonlat_square(16.37, 48.21, 20.0)], "a"),
            poly([lonlat_square(16.38, 48.20, 20.0)], "b"),
            crs=crs,
        )
    )
    assert scene.crs == UTM33
    ox, oy = scene.origin
    assert ox.is_integer() and oy.is_integer()
    assert 590_000 < ox < 610_000 and 5_330_000 < oy < 5_350_000
    for b in scene.buildings:
        # Edge lengths, not the bounding box: the UTM grid is turned about 1 degree
        # from true north here (meridian convergence).
        r = b.rings[0]
        sides = np.hypot(*(np.roll(r, -1, axis=0) - r).T)
        np.testing.assert_allclose(sides, 20.0, rtol=0.005)
        assert np.abs(r).max() < 1000.0


def test_southern_hemisphere_zone() -> None:
    scene = load_geojson_dict(fc(poly([lonlat_square(151.2, -33.87, 15.0)], "syd"), crs=None))
    assert scene.crs == "EPSG:32756"


# ------------------------------------------------------------------ fatal errors


def test_not_json(tmp_path: Path) -> None:
    p = tmp_path / "broken.geojson"
    p.write_text("{ not json", encoding="utf-8")
    with pytest.raises(SourceError, match=r"broken\.geojson.*not JSON"):
        load_geojson(p)


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(SourceError, match=r"nothere\.geojson"):
        load_geojson(tmp_path / "nothere.geojson")


def test_not_a_feature_collection(tmp_path: Path) -> None:
    p = tmp_path / "feature.geojson"
    p.write_text(json.dumps(poly([square(0, 0)], "a")), encoding="utf-8")
    with pytest.raises(SourceError, match=r"feature\.geojson.*not a GeoJSON FeatureCollection"):
        load_geojson(p)


def test_no_usable_feature(tmp_path: Path) -> None:
    p = tmp_path / "empty.geojson"
    p.write_text(json.dumps(fc(poly([[[0, 0], [1, 0], [0, 0]]], "x"))), encoding="utf-8")
    with pytest.raises(SourceError, match=r"empty\.geojson.*no usable feature"):
        load_geojson(p)
    with pytest.raises(SourceError, match="no usable feature"):
        load_geojson_dict(fc())


def test_projected_coordinates_without_crs_member() -> None:
    with pytest.raises(SourceError, match="lon/lat range"):
        load_geojson_dict(fc(poly([square(600000, 5000000)], "a"), crs=None))


def test_bad_crs_member() -> None:
    with pytest.raises(SourceError, match="unknown CRS"):
        load_geojson_dict(fc(poly([square(0, 0)], "a"), crs="EPSG:999999"))
    with pytest.raises(SourceError, match="not in metres"):
        load_geojson_dict(fc(poly([square(0, 0)], "a"), crs="EPSG:2263"))


def test_bad_arguments() -> None:
    with pytest.raises(InputError):
        load_geojson_dict(fc(poly([square(0, 0)], "a")), default_floor_height=0)
    with pytest.raises(InputError):
        load_geojson_dict(fc(poly([square(0, 0)], "a")), tol=-1)


def test_load_from_file_names_the_scene(tmp_path: Path) -> None:
    p = tmp_path / "block.geojson"
    p.write_text(json.dumps(bad_collection()), encoding="utf-8")
    scene = load_geojson(p)
    assert scene.name == "block"
    assert len(scene.buildings) == 4
    assert load_geojson(p, name="x").name == "x"


# ------------------------------------------------------------------------- Vienna


def test_vienna_blocks() -> None:
    vienna = team_data("vienna", "blocks.geojson")
    scene = load_geojson(vienna)  # its speed is a benchmark's (bench city), not a test's
    assert scene.name == "blocks" and scene.crs == UTM33
    skipped = sum(i.action == "skipped" for i in scene.issues)
    repaired = sum(i.action == "repaired" for i in scene.issues)
    # 3,727 Polygons and one MultiPolygon; every feature gives at least one building
    # unless it was skipped.
    assert abs(len(scene.buildings) + skipped - 3728) <= 5, (
        len(scene.buildings),
        skipped,
        repaired,
    )
    assert len(scene.buildings) > 3700
    ids = [b.id for b in scene.buildings]
    assert ids == list(range(len(ids)))
    assert all(4 <= b.floors <= 6 for b in scene.buildings)  # default rule: no heights
    # The blocks span about 6.5 km x 8.7 km around the local origin, in metres.
    allpts = np.concatenate([b.rings[0] for b in scene.buildings])
    extent = np.ptp(allpts, axis=0)
    assert 5_500 < extent[0] < 7_500 and 7_500 < extent[1] < 10_000
    assert np.abs(allpts.mean(axis=0)).max() < 2_000


def test_cleaning_many_polygons_at_once_is_cleaning_each_alone() -> None:
    """clean_and_repair_all (whole-array GEOS checks) gives each polygon the parts and the
    issues, in the same order, that clean_and_repair gives it alone: a valid square, a
    bow-tie exterior (split by make_valid), a degenerate hole, a sliver skipped, and a
    multipolygon's two parts (one a bow-tie) whose issues share one feature index."""
    import copy

    from walkstream.server.sources.features import IssueLog, PolyFeature
    from walkstream.server.sources.rings import clean_and_repair, clean_and_repair_all

    def poly(index: int, uid: str, *rings: list[list[float]], part: bool = False) -> PolyFeature:
        arrays = [np.asarray(r, np.float64) for r in rings]
        return PolyFeature(index, uid.split("#")[0], uid, part, None, {}, arrays, [a.copy() for a in arrays])

    square = [[0, 0], [10, 0], [10, 10], [0, 10], [0, 0]]
    bowtie = [[20, 0], [30, 10], [30, 0], [20, 10]]
    polys = [
        poly(0, "a", square),
        poly(1, "b", bowtie),
        poly(2, "c", square, [[2, 2], [2, 2.001], [2.001, 2]]),  # hole of no area
        poly(3, "d", [[0, 0], [10, 0], [10, 0.0001], [0, 0.0001]]),  # 0.001 m²: skipped
        poly(4, "e#0", bowtie, part=True),
        poly(4, "e#1", [[0, 0], [10, 0], [10, 10], [10, 10], [0, 10]], part=True),
    ]
    alone_log, all_log = IssueLog(), IssueLog()
    alone = [clean_and_repair(p, alone_log) for p in copy.deepcopy(polys)]
    together = clean_and_repair_all(copy.deepcopy(polys), all_log)

    def parts(found: list[list[Any]]) -> list[list[tuple[str, list[bytes]]]]:
        return [[(c.source_id, [r.tobytes() for r in c.rings]) for c in p] for p in found]

    assert parts(together) == parts(alone)
    assert [len(p) for p in together] == [1, 2, 1, 0, 2, 1]
    assert all_log.items == alone_log.items  # the same issues in the same order
    assert [i.feature_id for i in all_log.sorted()] == ["b", "c", "d", "e#0"]
