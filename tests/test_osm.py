"""Real cities: OpenStreetMap and GeoJSON street networks, street cells on them, no traceback.

Small networks are made here (junctions, a roundabout, a bridge, a courtyard); the
three real extracts of ../shared/data/osm are read as they are.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pyproj
import pytest
import shapely
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from teamdata import team_data

from walkstream.cli import main
from walkstream.server.bake.navgraph import CellGraph
from walkstream.server.bake.streetcells import MIN_CELL_AREA, street_cells
from walkstream.server.bake.viewcell import ViewCell, cell_polygons
from walkstream.server.paths.importline import import_linestring
from walkstream.server.sources.clip import clip_scene
from walkstream.server.sources.geojson import load_geojson_dict
from walkstream.server.sources.network import NetLine, street_network
from walkstream.server.sources.osm import load_osm
from walkstream.server.sources.read import read_source
from walkstream.server.sources.scene import SourceScene
from walkstream.shared.arrays import F64
from walkstream.shared.errors import InputError, RouteError, SourceError, WalkstreamError
from walkstream.shared.records import BuildingParams, StreetParams

UTM = "EPSG:32633"
#: Snap-rounding grid (metres) of the checks' overlays: robust where float overlay is not.
GRID = 1e-6


# --------------------------------------------------------------------------- helpers


def line(coords: list[list[float]], fid: str, **props: Any) -> dict[str, Any]:
    return {"type": "Feature", "id": fid, "properties": props,
            "geometry": {"type": "LineString", "coordinates": coords}}  # fmt: skip


def poly(rings: list[list[list[float]]], fid: str, **props: Any) -> dict[str, Any]:
    return {"type": "Feature", "id": fid, "properties": props,
            "geometry": {"type": "Polygon", "coordinates": rings}}  # fmt: skip


def box(x0: float, y0: float, x1: float, y1: float) -> list[list[float]]:
    return [[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]]


def fc(*features: dict[str, Any], crs: str | None = UTM) -> dict[str, Any]:
    obj: dict[str, Any] = {"type": "FeatureCollection", "features": list(features)}
    if crs:
        obj["crs"] = {"type": "name", "properties": {"name": crs}}
    return obj


def _area(g: shapely.Geometry) -> float:
    return float(shapely.area(g))


def assert_cells_ok(cells: list[ViewCell], scene: SourceScene) -> None:
    """Convex, disjoint, outside every footprint (passages aside), symmetric neighbours.

    Overlays are snap-rounded (``grid_size``): in floating point, GEOS's overlay can
    return nonsense where edges nearly coincide (shapely#1871, JTS#1000), and cells
    that share a cut edge are exactly that (two disjoint triangles with a common edge
    "intersect" in the whole of one of them).
    """
    polys = cell_polygons(cells)
    for c, p in zip(cells, polys, strict=True):
        assert p.is_valid and abs(p.convex_hull.area - p.area) <= 1e-6 * max(p.area, 1.0), c.id
        for n in c.neighbours:
            assert c.id in cells[n].neighbours
    i, j = shapely.STRtree(polys).query(polys, predicate="intersects")
    keep = i < j
    over = shapely.area(shapely.intersection(polys[i[keep]], polys[j[keep]], grid_size=GRID))
    assert over.max(initial=0) < 1e-3, over.max(initial=0)
    # the snapped overlaps agree with the areas: the union is the sum of the cells
    union = shapely.union_all(polys, grid_size=GRID)
    assert union.area == pytest.approx(float(shapely.area(polys).sum()), rel=1e-6, abs=1e-3)
    fps = [shapely.Polygon(b.rings[0], b.rings[1:]) for b in scene.buildings]
    passages = shapely.union_all(
        [shapely.Polygon(s.ring) for s in scene.streets if s.id in scene.passages]
    )
    if fps:
        fp = shapely.union_all(fps, grid_size=GRID)
        inside = _area(shapely.intersection(union, fp, grid_size=GRID))
        allowed = _area(shapely.intersection(passages, fp, grid_size=GRID))
        assert inside <= allowed + 1e-3


def crossroads(scene: SourceScene) -> list[StreetParams]:
    return [s for s in scene.streets if s.kind == "crossroad"]


def at(scene: SourceScene, x: float, y: float) -> tuple[float, float]:
    """Local coordinates of a point given in the source's CRS."""
    return x - scene.origin[0], y - scene.origin[1]


def contains(scene: SourceScene, s: StreetParams, x: float, y: float) -> bool:
    return bool(shapely.Polygon(s.ring).covers(shapely.Point(*at(scene, x, y))))


# --------------------------------------------------------------------------- networks


def test_t_junction_five_way_junction_and_dead_end() -> None:
    scene = load_geojson_dict(
        fc(
            line([[0, 0], [200, 0]], "main", highway="residential"),
            line([[100, 0], [100, 80]], "side", highway="residential"),  # T at (100, 0)
            line([[-100, 0], [0, 0]], "w", highway="residential"),  # 5-way at (0, 0)
            line([[0, 0], [0, 80]], "n", highway="residential"),
            line([[0, 0], [0, -80]], "s", highway="residential"),
            line([[0, 0], [-60, -60]], "sw", highway="footway"),
            line([[150, 0], [150, -50]], "dead", highway="service"),  # a T and a dead end
        )
    )
    cross = crossroads(scene)
    assert len(cross) == 3
    five = [c for c in cross if contains(scene, c, 0, 0)]
    assert len(five) == 1
    assert any(contains(scene, c, 100, 0) for c in cross) and any(contains(scene, c, 150, 0) for c in cross)
    # the dead end is a street piece, not a junction
    assert not any(contains(scene, c, 150, -50) for c in cross)
    cells = street_cells(scene, max_length=30.0)
    assert_cells_ok(cells, scene)
    g = CellGraph(cells)
    assert len(g.components(np.ones(len(g), bool))) == 1
    # five streets leave the 5-way junction: its cells touch five different street pieces
    o = at(scene, 0, 0)
    five_cells = [c for c in cells if c.kind == "crossroad" and shapely.Polygon(c.polygon).distance(shapely.Point(o)) < 5]
    around = {n for c in five_cells for n in c.neighbours if cells[n].kind == "street"}
    directions = {
        round(math.atan2(cells[n].centroid[1] - o[1], cells[n].centroid[0] - o[0]) / (math.pi / 8))
        for n in around
    }
    assert len(directions) >= 5


def test_roundabout_keeps_its_island() -> None:
    t = np.linspace(0, 2 * math.pi, 25)
    ring = np.column_stack([20 * np.cos(t), 20 * np.sin(t)]).tolist()
    ring[-1] = ring[0]
    arms = [line([[20 * math.cos(a), 20 * math.sin(a)], [80 * math.cos(a), 80 * math.sin(a)]], f"arm{k}", highway="tertiary")
            for k, a in enumerate(np.linspace(0, 2 * math.pi, 4, endpoint=False))]  # fmt: skip
    # the arms meet the ring at ring vertices (0, 90, 180, 270 degrees are vertices of 24)
    scene = load_geojson_dict(fc(line(ring, "rb", highway="tertiary", junction="roundabout"), *arms))
    assert len(crossroads(scene)) == 4
    cells = street_cells(scene)
    assert_cells_ok(cells, scene)
    locate = CellGraph(cells).locator
    assert locate.locate(*at(scene, 0.0, 0.0)) is None  # the island is not street
    assert locate.locate(*at(scene, 20.0 * math.cos(0.4), 20.0 * math.sin(0.4))) is not None


def test_bridge_on_another_layer_is_left_out_and_not_noded() -> None:
    scene = load_geojson_dict(
        fc(
            line([[-100, 0], [100, 0]], "road", highway="residential"),
            line([[0, -100], [0, 100]], "bridge", highway="residential", bridge="yes", layer="1"),
            line([[-100, 50], [100, 50]], "tunnel", highway="residential", tunnel="yes"),
        )
    )
    assert crossroads(scene) == []
    assert {s.source_id for s in scene.streets} == {"road"}
    assert any("1 ways on layer 1" in n and "1 tunnels" in n for n in scene.notes)


def test_pedestrian_area_with_a_hole_and_landuse() -> None:
    outer, hole = box(0, 0, 60, 40), box(20, 10, 40, 30)[::-1]
    scene = load_geojson_dict(
        fc(
            poly([outer, hole], "plaza", highway="pedestrian", area="yes"),
            poly([box(100, 0, 200, 100)], "park", leisure="park"),
            poly([box(300, 0, 400, 100)], "field", landuse="meadow"),
            poly([box(70, 0, 80, 10)], "b", building="yes"),
        )
    )
    assert len(scene.buildings) == 1  # the park and the field are not buildings: typed areas
    # the park is kept; the field lies beyond the scene's box (its objects' box grown by 50 m)
    assert [(a.source_id, a.kind) for a in scene.areas] == [("park", "grass")]
    squares = [s for s in scene.streets if s.kind == "square"]
    assert len(squares) >= 2
    area = sum(shapely.Polygon(s.ring).area for s in squares)
    assert area == pytest.approx(60 * 40 - 20 * 20)
    cells = street_cells(scene)
    assert_cells_ok(cells, scene)
    assert CellGraph(cells).locator.locate(*at(scene, 30.0, 20.0)) is None  # the hole stays a hole


def test_footway_in_a_courtyard_and_streets_crossing_footprints() -> None:
    block = [box(0, 0, 100, 100), box(30, 30, 70, 70)[::-1]]
    scene = load_geojson_dict(
        fc(
            poly(block, "block", building="apartments"),
            line([[35, 50], [65, 50]], "yard", highway="footway"),
            line([[-50, -3], [150, -3]], "street", highway="residential"),  # overlaps the block
            line([[-20, -3], [-20, 120]], "other", highway="residential"),
        )
    )
    assert scene.buildings[0].floors == 5  # apartments without levels: the type default
    cells = street_cells(scene)
    assert_cells_ok(cells, scene)
    g = CellGraph(cells)
    assert len(g.components(np.ones(len(g), bool))) == 2
    with pytest.raises(RouteError, match="not connected"):
        g.plan(at(scene, 50.0, 50.0), at(scene, -20.0, 60.0))


def test_parallel_sidewalk_merges_into_the_road() -> None:
    scene = load_geojson_dict(
        fc(
            line([[0, 0], [200, 0]], "road", highway="secondary"),  # 8 m wide
            line([[0, 6], [200, 6]], "walk", highway="footway"),  # 2 m, a 1 m gap
        )
    )
    (piece,) = [s for s in scene.streets]
    assert piece.source_id == "road"
    assert shapely.Polygon(piece.ring).covers(shapely.Point(at(scene, 100, 6.5)))


def test_web_mercator_is_reprojected_and_lengths_come_out_right() -> None:
    merc = pyproj.Transformer.from_crs("EPSG:4326", "EPSG:3857", always_xy=True)
    lon0, lat0, lon1, lat1 = 24.93, 60.17, 24.95, 60.17
    a, b = merc.transform(lon0, lat0), merc.transform(lon1, lat1)
    true_m = pyproj.Geod(ellps="WGS84").inv(lon0, lat0, lon1, lat1)[2]
    assert b[0] - a[0] == pytest.approx(true_m / math.cos(math.radians(lat0)), rel=0.01)
    bx = [[a[0] + 200, a[1] + 20], [a[0] + 300, a[1] + 20], [a[0] + 300, a[1] + 80], [a[0] + 200, a[1] + 80]]
    scene = load_geojson_dict(
        fc(
            {"type": "Feature", "id": "mp", "properties": {"building": "yes"},
             "geometry": {"type": "MultiPolygon", "coordinates": [[bx + bx[:1]]]}},  # fmt: skip
            line([list(a), list(b)], "street", highway="residential", width="6"),
            crs="EPSG:3857",
        )
    )
    assert scene.crs == "EPSG:32635"
    (piece,) = scene.streets
    length = float(np.ptp(np.asarray(piece.ring) @ np.array([1.0, 0.0]))) - 6.0  # less the round ends
    assert length == pytest.approx(true_m, rel=0.002)
    cells = street_cells(scene)  # used to end in a traceback from shapely.polygons
    assert_cells_ok(cells, scene)


def test_empty_network_and_bbox_outside(tmp_path: Path) -> None:
    scene = load_geojson_dict(fc(poly([box(0, 0, 10, 10)], "b"), line([[0, 0], [1, 0]], "m", highway="motorway")))
    assert scene.streets == ()
    with pytest.raises(InputError, match="--cells grid"):
        street_cells(scene)
    with pytest.raises(InputError, match="no object of the scene lies inside"):
        clip_scene(scene, (500.0, 500.0, 600.0, 600.0))


def test_bbox_clips_objects_that_cross_it() -> None:
    scene = load_geojson_dict(
        fc(poly([box(0, 0, 40, 20)], "b"), line([[-100, -10], [100, -10]], "s", highway="residential"))
    )
    x0 = float(scene.buildings[0].rings[0][:, 0].min())
    clipped = clip_scene(scene, (x0 + 10, -100.0, 1000.0, 100.0))
    (b,) = clipped.buildings
    assert shapely.Polygon(b.rings[0]).area == pytest.approx(30 * 20)
    assert all(np.asarray(s.ring)[:, 0].min() >= x0 + 10 - 1e-9 for s in clipped.streets)


# --------------------------------------------------------------------------- property test

_coord = st.floats(-60, 60, allow_nan=False, width=32)
_way = st.lists(st.tuples(_coord, _coord), min_size=1, max_size=5)
_PERTURB = ("duplicate", "zero", "self-cross", "touch", "wall")


def _perturbed(
    ways: list[list[tuple[float, float]]], widths: list[float], offset: float, perturb: set[str], ring: F64
) -> list[NetLine]:
    """The random ways, plus the perturbations the issue lists."""
    lines = [NetLine(f"w{k}", np.asarray(w, np.float64) + offset, widths[k]) for k, w in enumerate(ways)]
    w0 = np.asarray(ways[0], np.float64) + offset
    if "duplicate" in perturb:  # the first way twice, once with its last node repeated
        lines.append(NetLine("dup", np.vstack([w0, w0[-1:]]), widths[0]))
    if "zero" in perturb:  # a way of one node repeated, and a one-node way
        lines += [NetLine("zero", w0[:1].repeat(2, axis=0), 4.0), NetLine("one", w0[:1].copy(), 4.0)]
    if "self-cross" in perturb:  # a figure of eight through the middle
        eight = np.array([[-30, -30], [30, 30], [30, -30], [-30, 30], [-30, -25]], np.float64)
        lines.append(NetLine("eight", eight + offset, 4.0))
    if "touch" in perturb and len(w0) >= 2 and np.hypot(*(w0[1] - w0[0])) > 1.0:
        # a way whose end lies on the inside of another's segment, with no shared node,
        # and one that only touches the first way's last node
        mid = (w0[0] + w0[1]) / 2.0
        d = (w0[1] - w0[0]) / np.hypot(*(w0[1] - w0[0]))
        lines.append(NetLine("touch", np.array([mid, mid + 25.0 * np.array([-d[1], d[0]])]), 2.0))
        lines.append(NetLine("end", np.array([w0[-1], w0[-1] + [17.0, -9.0]]), 2.0))
    if "wall" in perturb:  # a way along the building's edge
        lines.append(NetLine("wall", ring[:2].copy(), 3.0))
    return lines


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    ways=st.lists(_way, min_size=1, max_size=6),
    widths=st.lists(st.sampled_from([2.0, 4.0, 7.0]), min_size=6, max_size=6),
    offset=st.sampled_from([0.0, 612_345.678, 5_000_000.0]),
    perturb=st.sets(st.sampled_from(_PERTURB)),
)
def test_cells_of_random_networks(
    ways: list[list[tuple[float, float]]], widths: list[float], offset: float, perturb: set[str]
) -> None:
    """Random, perturbed networks: valid cells covering the street space, or our own error."""
    ring = np.array([[0, 0], [20, 0], [20, 15], [0, 15]], np.float64) + offset
    building = shapely.Polygon(ring)
    lines = _perturbed(ways, widths, offset, perturb, ring)
    buildings = (BuildingParams(id=0, rings=(ring,), neighbour_heights=(np.zeros(4),), floors=2, floor_height=3.0),)
    try:
        net = street_network(lines)
        streets = tuple(
            StreetParams(id=1 + k, kind=p.kind, ring=p.ring, width=p.width, source_id=p.source_id)
            for k, p in enumerate(net.pieces)
        )
        scene = SourceScene("h", UTM, (0.0, 0.0), buildings, streets)
        cells = street_cells(scene, max_length=25.0)
    except WalkstreamError:
        # only a network with no street space outside the building may fail
        assert not net.pieces or _area(
            shapely.difference(shapely.union_all([shapely.Polygon(p.ring) for p in net.pieces]), building, grid_size=GRID)
        ) < 1.0
        return
    assert_cells_ok(cells, scene)
    # the documented street space: every way buffered by half its width (as the
    # network does it: quad_segs=2), less the footprint
    ok = [ln for ln in lines if len(np.unique(np.round(ln.xy, 3), axis=0)) >= 2]
    buffered = shapely.union_all(
        [shapely.buffer(shapely.LineString(ln.xy), ln.width / 2, quad_segs=2) for ln in ok], grid_size=GRID
    )
    space = shapely.difference(buffered, building, grid_size=GRID)
    pieces = shapely.union_all([shapely.Polygon(s.ring) for s in streets], grid_size=GRID)
    covered = shapely.union_all(cell_polygons(cells), grid_size=GRID)
    # cells cover the buffered network within 1 % (plus the parts under MIN_CELL_AREA
    # dropped around the building's corners), and never leave the street pieces
    assert _area(shapely.difference(space, covered, grid_size=GRID)) <= 0.01 * space.area + 4 * MIN_CELL_AREA
    assert _area(shapely.difference(covered, pieces, grid_size=GRID)) <= 1e-3


# --------------------------------------------------------------------------- OpenStreetMap


def _osm(tmp_path: Path) -> Path:
    """A tiny OSM XML town near Kouvola: buildings, streets, a passage, broken ways."""
    lat0, lon0 = 60.53, 26.95
    nodes: dict[int, tuple[float, float]] = {}

    def node(nid: int, x: float, y: float) -> int:
        nodes[nid] = (lat0 + y / 111_320.0, lon0 + x / (111_320.0 * math.cos(math.radians(lat0))))
        return nid

    ways = []

    def way(wid: int, refs: list[int], **tags: str) -> None:
        ways.append((wid, refs, tags))

    for k, (x, y) in enumerate([(0, 0), (20, 0), (20, 15), (0, 15)]):
        node(1 + k, x, y)
    way(1, [1, 2, 3, 4, 1], building="house")
    for k, (x, y) in enumerate([(40, 0), (60, 0), (60, 15), (40, 15)]):
        node(11 + k, x, y)
    way(2, [11, 12, 13, 14, 11], building="apartments", **{"building:levels": "3", "roof:levels": "1"})
    for k, (x, y) in enumerate([(80, 0), (95, 0), (95, 15), (80, 15)]):
        node(21 + k, x, y)
    way(3, [21, 22, 23, 24, 21], building="yes", height="12")
    way(4, [21, 22, 999, 21], building="garage")  # a node missing from the extract
    node(31, -50, -10), node(32, 30, -10), node(33, 120, -10), node(34, 30, -60)
    way(10, [31, 32, 33], highway="residential", name="Main")
    way(11, [32, 34], highway="footway")
    node(35, 10, -10), node(36, 10, 25), node(37, 10, 40)
    way(12, [35, 36, 37], highway="footway", tunnel="building_passage")
    way(13, [33, 998, 997], highway="service")  # cut at the border: one located node left
    node(41, 120, 60), node(42, 150, 60)
    way(14, [33, 41, 996, 42], highway="residential")  # two located stretches
    node(51, -40, -80), node(52, 130, -80)
    way(15, [51, 52], highway="motorway")
    for k, (x, y) in enumerate([(-40, 20), (-20, 20), (-20, 40), (-40, 40)]):
        node(61 + k, x, y)
    way(16, [61, 62, 63, 64, 61], landuse="grass")
    text = ['<?xml version="1.0" encoding="UTF-8"?>', '<osm version="0.6" generator="test">']
    text += [f'  <node id="{i}" version="1" lat="{la:.8f}" lon="{lo:.8f}"/>' for i, (la, lo) in sorted(nodes.items())]
    for wid, refs, tags in ways:
        text.append(f'  <way id="{wid}" version="1">')
        text += [f'    <nd ref="{r}"/>' for r in refs]
        text += [f'    <tag k="{k}" v="{v}"/>' for k, v in tags.items()]
        text.append("  </way>")
    text.append("</osm>")
    p = tmp_path / "town.osm"
    p.write_text("\n".join(text), encoding="utf-8")
    return p


def test_osm_xml_buildings_streets_passages_and_cut_ways(tmp_path: Path) -> None:
    scene = read_source(_osm(tmp_path), network="walk")
    assert scene.crs == "EPSG:32635" and scene.name == "town"
    floors = {b.source_id: b.floors for b in scene.buildings}
    assert floors == {"way/1": 2, "way/2": 4, "way/3": 4}  # house default, 3 + 1 roof, 12 m
    issues = {i.feature_id: i for i in scene.issues}
    assert issues["way/4"].action == "skipped" and "missing" in issues["way/4"].problem
    assert issues["way/13"].action == "skipped"
    assert issues["way/14"].action == "repaired"
    # its located stretch (nodes 33-41) is street space, merged into way/10's piece
    # through node 33 (degree 2: no junction)
    to = pyproj.Transformer.from_crs("EPSG:4326", scene.crs, always_xy=True)
    lon, lat = 26.95 + 120.0 / (111_320.0 * math.cos(math.radians(60.53))), 60.53 + 25.0 / 111_320.0
    mid = shapely.Point(np.subtract(to.transform(lon, lat), scene.origin))
    assert any(shapely.Polygon(s.ring).contains(mid) for s in scene.streets)
    assert not any(s.source_id.startswith("way/15") for s in scene.streets)  # motorway: not walk
    assert any("1 highway ways cut" in n or "highway ways cut" in n for n in scene.notes)
    assert len(scene.passages) == 1
    cells = street_cells(scene)
    assert_cells_ok(cells, scene)
    house = shapely.Polygon(scene.buildings[0].rings[0])
    assert shapely.area(shapely.intersection(shapely.union_all(cell_polygons(cells)), house)) > 10
    drive = read_source(_osm(tmp_path), network="drive")
    assert any(s.source_id.startswith("way/15") for s in drive.streets)
    assert not drive.passages


def test_gpx_track_is_imported(tmp_path: Path) -> None:
    scene = read_source(_osm(tmp_path))
    cells = street_cells(scene)
    lat0, lon0 = 60.53, 26.95
    pts = [(lat0 - 10 / 111_320.0, lon0 + x / (111_320.0 * math.cos(math.radians(lat0)))) for x in (-40, 0, 60, 110)]
    gpx = tmp_path / "walk.gpx"
    gpx.write_text(
        '<?xml version="1.0"?><gpx version="1.1" creator="test" xmlns="http://www.topografix.com/GPX/1/1">'
        "<trk><trkseg>" + "".join(f'<trkpt lat="{la}" lon="{lo}"/>' for la, lo in pts) + "</trkseg></trk></gpx>",
        encoding="utf-8",
    )
    path, inside = import_linestring(gpx, scene.crs, scene.origin, 5.0, "gpx", cells=cells)
    assert path.length_m() == pytest.approx(150.0, rel=0.01)
    assert inside is not None and inside > 140.0
    bad = tmp_path / "bad.gpx"
    bad.write_text("<gpx><trk>", encoding="utf-8")
    with pytest.raises(SourceError, match="bad.gpx: not GPX"):
        import_linestring(bad, scene.crs, scene.origin, 5.0, "gpx")


def test_bad_sources_are_one_line_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    junk = tmp_path / "junk.osm"
    junk.write_text("<osm><node id='1' lat='x'", encoding="utf-8")
    with pytest.raises(SourceError, match="junk.osm"):
        load_osm(junk)
    with pytest.raises(SourceError, match="unknown source format"):
        read_source(tmp_path / "x.shp")
    for bad in (junk, tmp_path / "none.osm.pbf"):
        assert main(["bake", str(bad), "-o", str(tmp_path / "x.db")]) == 2
        err = capsys.readouterr().err
        errors = [ln for ln in err.splitlines() if "walkstream: error:" in ln]
        assert len(errors) == 1 and "Traceback" not in err and bad.name in errors[0]


def test_the_three_extracts() -> None:
    kv = load_osm(team_data("osm", "kouvola.osm.pbf"))
    assert 2100 < len(kv.buildings) <= 2219
    assert any("highway ways cut" in n for n in kv.notes)
    assert sum(i.feature_id.startswith("way/") and i.action == "skipped" for i in kv.issues) >= 40
    village = load_osm(team_data("osm", "village-10.068_48.135.osm"))
    assert any(i.feature_id == "relation/318560" for i in village.issues)
    oak = load_osm(team_data("osm", "west-oakland.osm"))
    assert len(oak.buildings) == 23 and oak.crs == "EPSG:32610"
    cells = street_cells(oak)
    assert_cells_ok(cells, oak)
    box_ll = (-122.3026, 37.8061, -122.2982, 37.8092)  # its <bounds>
    clipped = clip_scene(oak, box_ll, "lonlat")
    assert 0 < len(clipped.streets) < len(oak.streets)


def test_bake_serve_record_and_replay_a_real_city(tmp_path: Path, gl: object) -> None:
    """The traceback case end to end: EPSG:3857 MultiPolygons and highways, baked with street cells."""
    merc = pyproj.Transformer.from_crs("EPSG:4326", "EPSG:3857", always_xy=True)
    x0, y0 = merc.transform(26.95, 60.53)
    feats = []
    for k in range(4):
        bx = box(x0 + 60 * k + 5, y0 + 8, x0 + 60 * k + 45, y0 + 50)
        feats.append({"type": "Feature", "id": f"b{k}", "properties": {"building": "house"},
                      "geometry": {"type": "MultiPolygon", "coordinates": [[bx]]}})  # fmt: skip
    feats.append(line([[x0 - 20, y0], [x0 + 260, y0]], "main", highway="residential"))
    feats.append(line([[x0 + 50, y0], [x0 + 50, y0 + 120]], "side", highway="residential"))
    feats.append(line([[x0 + 170, y0 - 60], [x0 + 170, y0 + 120]], "cross", highway="tertiary"))
    src = tmp_path / "city.geojson"
    src.write_text(json.dumps(fc(*feats, crs="EPSG:3857")), encoding="utf-8")
    db = tmp_path / "city.db"
    assert main(["bake", str(src), "-o", str(db), "--resolution", "16", "--cell-size", "30"]) == 0
    from walkstream.server.store import SceneReader

    with SceneReader.open(db) as r:
        g = CellGraph(r.cells())
    part = np.asarray(g.components(np.ones(len(g), bool))[0])  # the largest connected part
    a = int(part[0])
    far = int(part[np.argmax(np.hypot(*(g.centroids[part] - g.centroids[a]).T))])
    start, end = g.centroids[a], g.centroids[far]
    assert main(["path", "record", str(db), "mine", f"--from={start[0]},{start[1]}",
                 f"--to={end[0]},{end[1]}", "--speed", "5"]) == 0  # fmt: skip
    png = tmp_path / "map.png"
    assert main(["inspect", str(db), "--map", str(png)]) == 0
    assert png.stat().st_size > 10_000
    rep = tmp_path / "rep"
    assert main(["replay", str(db), "--path", "mine", "--duration", "10s", "--device", "pda", "--report", str(rep), "--no-plots"]) == 0
    assert (rep / "report.json").exists()


def test_locate_record_and_replay_over_http_on_a_real_network(tmp_path: Path) -> None:
    """A real OSM extract baked with street cells, served on a real socket: locate, record, replay."""
    import httpx
    from liveserver import serve_in_thread

    from walkstream.server.service.main import create_app
    from walkstream.server.store import SceneReader

    db = tmp_path / "village.db"
    src = team_data("osm", "village-10.068_48.135.osm")
    assert main(["bake", str(src), "-o", str(db), "--resolution", "16", "--cell-size", "30"]) == 0
    with SceneReader.open(db) as r:
        infos = list(r.cells())
    # real networks give cells that are not quads (the traceback case of shapely.polygons)
    assert len({len(c.boundary) for c in infos}) > 1
    polys = shapely.polygons([shapely.linearrings(c.boundary) for c in infos])
    inner = shapely.point_on_surface(polys)
    # a path routed along the real network, between the far ends of its largest part
    g = CellGraph(infos)
    big = max(g.components(np.ones(len(g), bool)), key=len)
    a = int(big[0])
    b = int(max(big, key=lambda k: float(np.hypot(*(g.centroids[k] - g.centroids[a])))))
    (sx, sy), (ex, ey) = inner[a].coords[0], inner[b].coords[0]
    assert main(["path", "record", str(db), "mine", f"--from={sx},{sy}", f"--to={ex},{ey}", "--speed", "5"]) == 0
    app = create_app([db])
    try:
        with serve_in_thread(app) as url, httpx.Client(base_url=url, timeout=30) as http:
            listed = http.get("/v1/scenes", headers={"Accept": "application/json"}).json()
            scene = listed[0]["name"]
            for c, p in zip(infos, inner, strict=True):
                got = http.get(f"/v1/scenes/{scene}/locate", params={"x": p.x, "y": p.y},
                               headers={"Accept": "application/json"})  # fmt: skip
                assert got.status_code == 200 and got.json() == {"cell": c.id}, (c.id, got.text)
            x0, y0, x1, y1 = shapely.total_bounds(polys)
            far = http.get(f"/v1/scenes/{scene}/locate", params={"x": x1 + 500.0, "y": y1 + 500.0},
                           headers={"Accept": "application/json"})  # fmt: skip
            assert far.json()["cell"] is None
            rep = tmp_path / "rep"
            argv = ["replay", url, "--path", "mine", "--duration", "10s", "--device", "pda", "--report", str(rep), "--no-plots"]
            assert main(argv) == 0
    finally:
        app.state.scenes.close()
    report = json.loads((rep / "report.json").read_text(encoding="utf-8"))
    # the walk crossed cells of the real network and fetched them over the socket
    assert report["frames"] > 0 and report["cells_entered"] >= 2 and report["cells_received"] >= 2
    assert report["perfect_frames"] > 0 and report["bytes_received"] > 0


def test_the_build_commands_read_openstreetmap_too(capsys: pytest.CaptureFixture[str]) -> None:
    village = team_data("osm", "village-10.068_48.135.osm")
    # buildings stats (and bench rebuild, bench visibility) take any city source the bake reads
    assert main(["buildings", "stats", str(village), "--json"]) == 0
    stats = json.loads(capsys.readouterr().out)
    assert stats["buildings"] > 0
