"""Typed areas on the ground: read from OSM and GeoJSON, repaired or skipped, clipped, baked, drawn.

The traps of issue 29 on tiny synthetic sources written here: a lake with an island (a
multipolygon whose inner ring holds a building), an area crossing the scene's edge, an
area under a building (drawn below it), a relation with missing members, a
self-intersecting area.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import shapely

from walkstream.cli import main
from walkstream.client.truth.render import TruthRenderer
from walkstream.server.sources.geojson import load_geojson_dict
from walkstream.server.sources.read import read_source
from walkstream.server.store import SceneReader
from walkstream.shared.areakinds import AREA_MATERIALS
from walkstream.shared.areas import build_area
from walkstream.shared.buildings import build_lods
from walkstream.shared.camera import look_at
from walkstream.shared.codec import decode_area, decode_object, encode_area
from walkstream.shared.palette import PALETTE
from walkstream.shared.records import AreaParams
from walkstream.shared.streets import build_street

LAT0, LON0 = 60.53, 26.95


def _osm_town(tmp_path: Path) -> Path:
    """Streets, buildings, a lake with an island (and a house on it), a park crossing the
    scene's edge, parking under a building, a relation with missing members, a bow-tie."""
    nodes: dict[int, tuple[float, float]] = {}
    ways: list[tuple[int, list[int], dict[str, str]]] = []
    rels: list[tuple[int, list[tuple[str, int, str]], dict[str, str]]] = []
    nid = [1000]

    def ring(pts: list[tuple[float, float]]) -> list[int]:
        ids = []
        for x, y in pts:
            nid[0] += 1
            nodes[nid[0]] = (LAT0 + y / 111_320.0, LON0 + x / (111_320.0 * math.cos(math.radians(LAT0))))
            ids.append(nid[0])
        return ids + ids[:1]

    def sq(x0: float, y0: float, x1: float, y1: float) -> list[tuple[float, float]]:
        return [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]

    line = ring([(-60, 0), (260, 0)])[:-1]
    ways.append((1, line, {"highway": "residential"}))
    side = ring([(100, 0), (100, 150)])[:-1]
    ways.append((2, side, {"highway": "residential"}))
    ways.append((10, ring(sq(10, 10, 40, 30)), {"building": "house"}))
    ways.append((11, ring(sq(150, 10, 180, 40)), {"building": "yes"}))
    # the lake: an outer ring and an island (inner ring) with a house on it
    ways.append((20, ring(sq(120, 50, 240, 140)), {}))
    ways.append((21, ring(sq(160, 80, 200, 110)), {}))
    rels.append((500, [("way", 20, "outer"), ("way", 21, "inner")], {"type": "multipolygon", "natural": "water"}))
    ways.append((12, ring(sq(170, 88, 190, 102)), {"building": "house"}))
    # a park running far beyond the scene (clipped to it)
    ways.append((30, ring(sq(-1000, 20, 90, 200)), {"leisure": "park"}))
    # parking under building 11
    ways.append((31, ring(sq(140, 5, 190, 45)), {"amenity": "parking"}))
    # a relation whose outer way is not in the extract
    rels.append((501, [("way", 9999, "outer")], {"type": "multipolygon", "landuse": "forest"}))
    # a self-intersecting landuse (a bow-tie): repaired with make_valid
    ways.append((32, ring([(-40, -40), (0, -10), (0, -40), (-40, -10)]), {"landuse": "residential"}))
    text = ['<?xml version="1.0" encoding="UTF-8"?>', '<osm version="0.6" generator="test">']
    text += [f'  <node id="{i}" version="1" lat="{la:.8f}" lon="{lo:.8f}"/>' for i, (la, lo) in sorted(nodes.items())]
    for wid, refs, tags in sorted(ways):
        text.append(f'  <way id="{wid}" version="1">')
        text += [f'    <nd ref="{r}"/>' for r in refs]
        text += [f'    <tag k="{k}" v="{v}"/>' for k, v in tags.items()]
        text.append("  </way>")
    for rid, members, tags in rels:
        text.append(f'  <relation id="{rid}" version="1">')
        text += [f'    <member type="{t}" ref="{r}" role="{role}"/>' for t, r, role in members]
        text += [f'    <tag k="{k}" v="{v}"/>' for k, v in tags.items()]
        text.append("  </relation>")
    text.append("</osm>")
    p = tmp_path / "lake.osm"
    p.write_text("\n".join(text), encoding="utf-8")
    return p


def test_area_records_round_trip_and_build_flat_with_holes() -> None:
    a = AreaParams(7, "water", (np.array([[0, 0], [10, 0], [10, 10], [0, 10]]), np.array([[3, 3], [3, 6], [6, 6], [6, 3]])), "relation/1")
    blob = encode_area(a)
    assert len(blob) < 60
    b = decode_area(blob)
    assert isinstance(decode_object(blob), AreaParams)
    assert b.kind == "water" and len(b.rings) == 2 and b.source_id == "relation/1"
    m = build_area(b)
    assert np.allclose(m.positions[:, 2], m.positions[0, 2]) and m.positions[0, 2] < 0
    tri = m.positions[m.indices].astype(np.float64)
    area = 0.5 * np.abs(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])[:, 2]).sum()
    assert area == pytest.approx(100 - 9)  # the hole stays a hole
    assert set(m.materials.tolist()) == {AREA_MATERIALS["water"]}


def test_osm_areas_lake_island_edge_missing_members_and_repair(tmp_path: Path) -> None:
    scene = read_source(_osm_town(tmp_path), network="walk")
    assert len(scene.buildings) == 3
    kinds = {a.source_id.split(".")[0].split("#")[0]: a for a in scene.areas}
    assert set(kinds) == {"relation/500", "way/30", "way/31", "way/32"}
    first = len(scene.buildings) + len(scene.streets)
    assert [a.id for a in scene.areas] == list(range(first, first + len(scene.areas)))  # areas after streets
    lake = kinds["relation/500"]
    assert lake.kind == "water" and len(lake.rings) == 2  # the island is a hole
    lake_poly = shapely.Polygon(lake.rings[0], lake.rings[1:])
    assert lake_poly.area == pytest.approx(120 * 90 - 40 * 30, rel=0.02)
    island_house = shapely.Polygon(scene.buildings[2].rings[0])
    assert not lake_poly.intersects(island_house.centroid)  # the house stands on the island, not in the water
    park = shapely.Polygon(kinds["way/30"].rings[0])
    assert park.bounds[0] > -200  # clipped to the scene (its box grown by 50 m), not 1 km out
    issues = {i.feature_id: i for i in scene.issues}
    assert issues["relation/501"].action == "skipped" and "members missing" in issues["relation/501"].problem
    assert issues["way/30"].action == "repaired" and "clipped" in issues["way/30"].problem
    assert issues["way/32"].action == "repaired" and "make_valid" in issues["way/32"].problem
    assert any("areas skipped" in n for n in scene.notes)


def test_geojson_areas_by_tag_and_by_kind() -> None:
    def poly(rings: list[Any], fid: str, **props: Any) -> dict[str, Any]:
        return {"type": "Feature", "id": fid, "properties": props, "geometry": {"type": "Polygon", "coordinates": rings}}

    def box(x0: float, y0: float, x1: float, y1: float) -> list[list[float]]:
        return [[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]]

    fc = {
        "type": "FeatureCollection",
        "crs": {"type": "name", "properties": {"name": "EPSG:32633"}},
        "features": [
            poly([box(0, 0, 20, 20)], "b", building="yes"),
            poly([box(30, 0, 90, 60), box(40, 10, 50, 20)[::-1]], "pond", kind="water"),
            poly([box(-20, -20, 0, 0)], "lot", amenity="parking"),
            poly([box(0, 30, 10, 40)], "shop", shop="bakery"),  # no area kind: a building
        ],
    }
    scene = load_geojson_dict(fc)
    kinds = {a.source_id: a for a in scene.areas}
    assert kinds["pond"].kind == "water" and len(kinds["pond"].rings) == 2
    assert kinds["lot"].kind == "parking"
    assert len(scene.buildings) == 2


def test_an_area_under_a_building_lies_below_it_in_both_renderers(gl: Any) -> None:
    """A parking lot under a building and a street on a park: depth alone keeps them apart."""
    from walkstream.shared.records import BuildingParams, StreetParams

    b = BuildingParams(0, (np.array([[0.0, 0.0], [20.0, 0.0], [20.0, 15.0], [0.0, 15.0]]),), (np.zeros(4),), 3, 3.0)
    street = StreetParams(1, "street", np.array([[-30.0, -12.0], [50.0, -12.0], [50.0, -4.0], [-30.0, -4.0]]), 8.0)
    lot = AreaParams(2, "parking", (np.array([[-10.0, -2.0], [30.0, -2.0], [30.0, 25.0], [-10.0, 25.0]]),))
    park = AreaParams(3, "grass", (np.array([[-40.0, -40.0], [60.0, -40.0], [60.0, 40.0], [-40.0, 40.0]]),))
    meshes = {0: build_lods(b)[2], 1: build_street(street), 2: build_area(lot), 3: build_area(park)}
    view = look_at(np.array([10.0, -30.0, 12.0]), np.array([10.0, 5.0, 0.0]))
    with TruthRenderer(meshes, (160, 120), ground_z=0.0, ctx=gl) as tr:
        rgb, ids = tr.colour_frame(np.array([10.0, -30.0, 12.0]), view)
    shown = set(np.unique(ids).tolist())
    assert {1, 2, 3, 4} <= shown  # every object shows somewhere
    # the lot never shows through the building, the park never through the street or the lot:
    # the pixels of a thing lying higher are never the lower thing's, in every row
    lot_col = PALETTE[AREA_MATERIALS["parking"]].astype(int)
    assert not np.any(np.all(np.abs(rgb.astype(int) - lot_col) <= 2, axis=2) & (ids == 1))
    # and the same frame again gives the same ids (no depth fight decided by chance)
    with TruthRenderer(dict(reversed(list(meshes.items()))), (160, 120), ground_z=0.0, ctx=gl) as tr2:
        _, ids2 = tr2.colour_frame(np.array([10.0, -30.0, 12.0]), view)
    np.testing.assert_array_equal(ids, ids2)
    # where the street lies over the park, the street shows
    street_px = ids == 2
    assert street_px.sum() > 50


def test_bake_serve_and_map_areas_and_an_old_database_still_serves(tmp_path: Path) -> None:
    src = _osm_town(tmp_path)
    db = tmp_path / "lake.db"
    assert main(["bake", str(src), "-o", str(db), "--resolution", "16", "--cell-size", "30"]) == 0
    with SceneReader.open(db) as r:
        infos = r.object_info(int(i) for i in r.object_ids())
        areas = [i for i, info in infos.items() if info.kind == "area"]
        assert len(areas) == 5  # the bow-tie became two
        assert r.area(areas[0]).kind in ("water", "grass", "parking", "built")
        seen = set().union(*(set(c.pvs.tolist()) for c in r.cells()))
        assert set(areas) & seen  # areas are in PVSs where they are seen
        summary = r.summary()
        walk = sorted(r.path_names())[0]
    assert summary["objects"] == len(infos)
    png = tmp_path / "map.png"
    assert main(["inspect", str(db), "--map", str(png)]) == 0
    assert png.stat().st_size > 10_000
    # a short walk (one the bake recorded) with the truth: the areas stream as objects and
    # are drawn by both, below the horizon no sky
    rep = tmp_path / "rep"
    assert main(["replay", str(db), "--path", walk, "--duration", "6s", "--clock", "sim", "--device", "desktop2003",
                 "--truth-every", "30", "--report", str(rep), "--no-plots"]) == 0  # fmt: skip
    report = json.loads((rep / "report.json").read_text())
    truth = report.get("summary", report)["truth"]
    assert truth["frames"] >= 2
    assert truth["below_horizon"]["sky"]["max"] < 0.01
    assert truth["missing"]["culled"]["max"] == 0.0
