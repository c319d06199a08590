"""Routes through the view cells, the default paths, GeoJSON import and storing paths."""

from __future__ import annotations

import argparse
import json
import math
import sqlite3
from functools import lru_cache
from pathlib import Path

import numpy as np
import pyproj
import pytest
import shapely
from scenes import PATH_NAME, build_city_db
from teamdata import team_data

import walkstream.server.store.edit
from walkstream.cmd_path import add_path_parser
from walkstream.server.bake.cells import make_cells
from walkstream.server.bake.navgraph import CellGraph
from walkstream.server.bake.viewcell import ViewCell, cell_locator
from walkstream.server.bake.walks import default_paths
from walkstream.server.paths.importline import CLIP_GAP, import_linestring, import_path
from walkstream.server.paths.record import record_path
from walkstream.server.sources.citygen import generate_city
from walkstream.server.sources.geojson import load_geojson_dict
from walkstream.server.sources.geojsonlines import read_linestring
from walkstream.server.sources.scene import SourceScene
from walkstream.server.store import CellRow, SceneReader, SceneWriter, write_path
from walkstream.shared.errors import (
    InputError,
    RouteError,
    SourceError,
    StoreError,
    WalkstreamError,
)
from walkstream.shared.paths import RecordedPath


@lru_cache(maxsize=4)
def city(
    size: float = 700.0, seed: int = 1, mode: str = "auto"
) -> tuple[SourceScene, list[ViewCell]]:
    scene = load_geojson_dict(generate_city(size, seed), name="city")
    return scene, make_cells(scene, mode)


@lru_cache(maxsize=4)
def graph(size: float = 700.0, seed: int = 1, mode: str = "auto") -> CellGraph:
    return CellGraph(city(size, seed, mode)[1])


@lru_cache(maxsize=4)
def defaults(size: float = 700.0, mode: str = "auto") -> dict[str, RecordedPath]:
    scene, cells = city(size, 1, mode)
    paths = default_paths(cells, footprints=[b.rings[0] for b in scene.buildings])
    return {p.name: p for p in paths}


def cells_along(cells: list[ViewCell], xy: np.ndarray, step: float = 0.5) -> np.ndarray:
    """Cell ids of points every ``step`` metres along a polyline (-1 outside)."""
    pts = [xy[0]]
    for a, b in zip(xy[:-1], xy[1:], strict=True):
        n = max(1, math.ceil(float(np.hypot(*(b - a))) / step))
        pts.extend(a + (b - a) * np.arange(1, n + 1)[:, None] / n)
    return cell_locator(cells).locate_many(np.array(pts))


def cells_of(cells: list[ViewCell], p: RecordedPath, n: int = 4000) -> np.ndarray:
    xyz, _, _ = p.sample(np.linspace(0.0, p.duration, n))
    return cell_locator(cells).locate_many(xyz[:, :2])


def to_lonlat(scene: SourceScene, xy: np.ndarray) -> list[list[float]]:
    tr = pyproj.Transformer.from_crs(scene.crs, "OGC:CRS84", always_xy=True)
    lon, lat = tr.transform(xy[:, 0] + scene.origin[0], xy[:, 1] + scene.origin[1])
    return [[float(a), float(b)] for a, b in zip(lon, lat, strict=True)]


# --------------------------------------------------------------------------- the graph


def test_portals_lie_on_both_cells_and_point_from_a_to_b() -> None:
    g = graph()
    assert len(g.portal_cells) > len(g.cells)
    mids = [shapely.Point(m) for m in g.portal_mid]
    for (a, b), m, n in zip(g.portal_cells, mids, g.portal_normal, strict=True):
        assert g.polys[a].distance(m) < 1e-3 and g.polys[b].distance(m) < 1e-3
        probe = np.asarray(m.coords[0]) + 0.05 * n
        assert g.polys[b].distance(shapely.Point(probe)) < 1e-9
    widths = np.hypot(*(g.portal_ends[:, 1] - g.portal_ends[:, 0]).T)
    assert (widths >= 0.5).all()


def test_routes_stay_inside_the_cells_and_out_of_buildings() -> None:
    scene, cells = city()
    g = graph()
    rng = np.random.default_rng(7)
    centres = np.array([c.centroid for c in cells])
    blocks = shapely.union_all([shapely.Polygon(b.rings[0]) for b in scene.buildings])
    for _ in range(12):
        i, j = rng.choice(len(cells), 2, replace=False)
        r = g.plan(centres[i], centres[j])
        np.testing.assert_allclose(r.xy[0], centres[i])
        np.testing.assert_allclose(r.xy[-1], centres[j])
        ids = cells_along(cells, r.xy)
        assert (ids >= 0).all()
        assert r.cells[0] == cells[i].id and r.cells[-1] == cells[j].id
        assert not shapely.LineString(r.xy).crosses(blocks)
        assert r.length >= float(np.hypot(*(centres[j] - centres[i]))) - 1e-9


def test_route_prefers_one_street_to_a_staircase() -> None:
    g = graph()
    # two crossroads on the same east-west street, 350 m apart
    r = g.plan((-265.0, 3.0), (90.0, 3.0))
    assert len(r.xy) <= 6
    assert r.length < 1.02 * 355.0


def test_route_within_one_cell_is_a_straight_line() -> None:
    g = graph()
    c = g.cells[0]
    a = np.asarray(c.centroid)
    b = 0.5 * (a + c.polygon[0])
    r = g.plan(a, b)
    assert len(r.xy) == 2 and r.cells == (c.id,)


def test_via_points_are_passed_in_order() -> None:
    _, cells = city()
    g = graph()
    via = np.array([[-265.0, 200.0], [90.0, -100.0]])
    r = g.plan((0.0, 3.0), (270.0, 265.0), via=via)
    for v in via:
        assert np.hypot(*(r.xy - v).T).min() < 1e-9
    k = [int(np.argmin(np.hypot(*(r.xy - v).T))) for v in via]
    assert k[0] < k[1]
    assert (cells_along(cells, r.xy) >= 0).all()


@pytest.mark.parametrize(
    ("kw", "message"),
    [
        ({"from_xy": (5000.0, 0.0)}, r"from \(5000.0, 0.0\) is outside every view cell"),
        ({"to_xy": (0.0, -5000.0)}, r"to \(0.0, -5000.0\) is outside every view cell"),
        ({"via": [(1e4, 1e4)]}, r"via 1 \(10000.0, 10000.0\) is outside"),
        ({"from_xy": (math.nan, 0.0)}, "from: expected finite X,Y"),
    ],
)
def test_route_errors_name_the_bad_point(kw: dict[str, object], message: str) -> None:
    args: dict[str, object] = {"from_xy": (0.0, 3.0), "to_xy": (270.0, 265.0)} | kw
    with pytest.raises(RouteError, match=message):
        graph().plan(**args)  # type: ignore[arg-type]


def test_route_between_unconnected_cells_is_refused() -> None:
    square = np.array([[0, 0], [10, 0], [10, 10], [0, 10]], dtype=np.float64)
    cells = [
        ViewCell(0, "grid", square, 1.5, 2.0, (1,)),
        ViewCell(1, "grid", square + (10, 0), 1.5, 2.0, (0,)),
        ViewCell(2, "grid", square + (50, 0), 1.5, 2.0, ()),
    ]
    g = CellGraph(cells)
    assert len(g.route((5, 5), (15, 5))) == 2
    with pytest.raises(
        RouteError,
        match=r"from \(5.0, 5.0\) in cell 0 to to \(55.0, 5.0\) in cell 2: the cells are not connected",
    ):
        g.route((5, 5), (55, 5))
    with pytest.raises(InputError, match="at least one view cell"):
        CellGraph([])


# --------------------------------------------------------------------------- default paths


def test_default_paths_on_the_default_city() -> None:
    _, cells = city()
    paths = defaults()
    assert list(paths) == ["SE", "SM", "drive"]
    for p in paths.values():
        ids = cells_of(cells, p)
        assert (ids >= 0).all(), p.name


def test_se_is_a_street_walk_of_three_minutes_that_fits_a_56k_link() -> None:
    _, cells = city()
    se = defaults()["SE"]
    assert se.speed_kmh == 15.0
    assert se.duration >= 180.0 and se.length_m() >= 750.0
    assert len(se.to_msgpack()) < 2048
    assert (se.xyz[:, 2] == 1.7).all()
    ids = cells_of(cells, se)
    assert {cells[i].kind for i in ids} <= {"street", "crossroad"}
    runs = [ids[0]] + [b for a, b in zip(ids[:-1], ids[1:], strict=True) if a != b]
    assert len(runs) == len(set(runs))  # no street walked twice
    # moving at 15 km/h the whole way (no stops on a street walk)
    xyz, _, _ = se.sample(np.arange(0.0, se.duration, 1.0))
    speeds = np.hypot(*np.diff(xyz[:, :2], axis=0).T) * 3.6
    assert np.median(speeds) == pytest.approx(15.0, rel=1e-6)


def test_sm_turns_back_then_crosses_a_square_from_side_to_side() -> None:
    _, cells = city()
    sm = defaults()["SM"]
    assert sm.speed_kmh == pytest.approx(5.0)
    # a U-turn: standing key points whose view turns by half a circle, with the
    # walk before and after going in opposite directions
    still = np.flatnonzero(np.all(np.diff(sm.xyz, axis=0) == 0, axis=1))
    assert len(still) >= 2
    k = int(still[0])
    before = sm.xyz[k] - sm.xyz[k - 1]
    after = sm.xyz[k + len(still) + 1] - sm.xyz[k + len(still)]
    assert float(before @ after) / (np.linalg.norm(before) * np.linalg.norm(after)) < -0.99
    assert np.linalg.norm(before) > 20.0  # tens of metres out, then back
    # then into a square and out on the other side
    xyz, _, _ = sm.sample(np.linspace(0, sm.duration, 4000))
    ids = cell_locator(cells).locate_many(xyz[:, :2])
    sq = np.flatnonzero([cells[i].kind == "square" for i in ids])
    assert len(sq) and sq[0] > np.flatnonzero(ids == ids[0]).max() - 1
    assert (np.diff(sq) == 1).all()  # one crossing
    first, last = xyz[sq[0], :2], xyz[sq[-1], :2]
    assert float(np.hypot(*(last - first))) > 40.0
    assert sq[-1] < len(ids) - 1 and cells[ids[-1]].kind != "square"  # left the square


def test_drive_is_fast_low_and_long() -> None:
    _, cells = city()
    drive = defaults()["drive"]
    assert drive.speed_kmh == 50.0
    assert (drive.xyz[:, 2] == 1.2).all()
    assert drive.length_m() >= 2000.0
    assert drive.duration == pytest.approx(drive.length_m() / (50 / 3.6), rel=0.05)
    assert {cells[i].kind for i in cells_of(cells, drive)} <= {"street", "crossroad"}


def test_default_paths_are_deterministic_and_work_on_small_and_grid_scenes() -> None:
    scene, cells = city()
    again = default_paths(cells, footprints=[b.rings[0] for b in scene.buildings])
    assert [p.to_msgpack() for p in again] == [p.to_msgpack() for p in defaults().values()]
    small = defaults(200.0)
    # a 200 m city is too small for 200 s without repeating: SE is its longest route
    assert set(small) == {"SE", "SM", "drive"} and 40 <= small["SE"].duration < 180
    grid = defaults(400.0, "grid")
    assert set(grid) == {"SE", "SM", "drive"}
    _, gcells = city(400.0, 1, "grid")
    for p in grid.values():
        assert (cells_of(gcells, p) >= 0).all()
    assert grid["SE"].duration >= 180


def test_default_paths_need_two_connected_cells() -> None:
    square = np.array([[0, 0], [10, 0], [10, 10], [0, 10]], dtype=np.float64)
    assert default_paths([ViewCell(0, "grid", square, 1.5, 2.0, ())]) == []


# --------------------------------------------------------------------------- GeoJSON


LOCAL_LINE = np.array([[-265.0, -200.0], [-265.0, 3.0], [90.0, 3.0], [90.0, 100.0]])


def test_import_a_lon_lat_line_string_and_its_wrappers() -> None:
    scene, cells = city()
    coords = to_lonlat(scene, LOCAL_LINE)
    geom = {"type": "LineString", "coordinates": coords}
    variants = [
        geom,
        {"type": "Feature", "properties": {}, "geometry": geom},
        {
            "type": "FeatureCollection",
            "features": [
                {
                    "type": "Feature",
                    "properties": {},
                    "geometry": {"type": "Point", "coordinates": coords[0]},
                },
                {"type": "Feature", "properties": {}, "geometry": geom},
            ],
        },
        {"type": "MultiLineString", "coordinates": [coords[:2], coords[1:]]},
    ]
    for obj in variants:
        xy = read_linestring(obj, scene.crs, scene.origin)
        np.testing.assert_allclose(xy, LOCAL_LINE, atol=0.01)
    path, inside = import_linestring(geom, scene.crs, scene.origin, 5.0, "line", cells=cells)
    assert path.length_m() == pytest.approx(655.0, abs=0.1)
    assert inside == pytest.approx(655.0, abs=0.1)
    assert path.duration == pytest.approx(655.0 / (5 / 3.6), abs=0.5)


def test_import_a_projected_line_with_a_declared_crs(tmp_path: Path) -> None:
    scene, _ = city()
    proj = (LOCAL_LINE + np.array(scene.origin)).tolist()
    obj = {
        "type": "FeatureCollection",
        "crs": {"type": "name", "properties": {"name": scene.crs}},
        "features": [
            {
                "type": "Feature",
                "properties": {},
                "geometry": {"type": "LineString", "coordinates": proj},
            }
        ],
    }
    f = tmp_path / "line.geojson"
    f.write_text(json.dumps(obj))
    np.testing.assert_allclose(read_linestring(f, scene.crs, scene.origin), LOCAL_LINE, atol=1e-6)


def test_clip_keeps_the_longest_stretch_inside_the_cells() -> None:
    scene, cells = city()
    g = graph()
    # in from far outside, along a street, out again, and a short piece inside
    line = np.array([[-600.0, 3.0], [90.0, 3.0], [90.0, 600.0], [-265.0, 600.0], [-265.0, 200.0]])
    geom = {"type": "LineString", "coordinates": to_lonlat(scene, line)}
    full, inside = import_linestring(geom, scene.crs, scene.origin, 5.0, "l", cells=g)
    assert full.length_m() == pytest.approx(690 + 597 + 355 + 400, abs=0.5)
    assert inside is not None and 690 + 250 < inside < 690 + 597 + 400
    clipped, inside2 = import_linestring(geom, scene.crs, scene.origin, 5.0, "l", clip_to=g)
    assert inside2 == pytest.approx(inside)
    xyz = clipped.xyz[:, :2]
    assert xyz[0, 0] == pytest.approx(-356.0, abs=1.0)  # the western edge of the cells
    assert xyz[-1, 1] < 600.0 and xyz[-1, 0] == pytest.approx(90.0, abs=0.01)
    assert (cells_of(cells, clipped) >= 0).all()
    outside = {"type": "LineString", "coordinates": to_lonlat(scene, line[:1] + [[0, 0], [0, 50]])}
    with pytest.raises(RouteError, match="entirely outside"):
        import_linestring(outside, scene.crs, scene.origin, 5.0, "l", clip_to=g)


def line(coords: object) -> dict[str, object]:
    return {"type": "LineString", "coordinates": coords}


@pytest.mark.parametrize(
    ("obj", "message"),
    [
        ({"type": "Point", "coordinates": [16.0, 48.0]}, "expected a GeoJSON LineString"),
        ([1, 2], "expected a GeoJSON object"),
        ("[1, 2]", "cannot read file"),
        ({"type": "Feature", "geometry": None}, "not a LineString"),
        ({"type": "FeatureCollection", "features": []}, "exactly one LineString feature, found 0"),
        (
            {
                "type": "FeatureCollection",
                "features": [{"type": "Feature", "geometry": line([[16, 48], [16.1, 48]])}] * 2,
            },
            "found 2",
        ),
        ({"type": "FeatureCollection"}, "no 'features' list"),
        (line("abc"), "malformed coordinates"),
        (line([[16.0, 48.0], [16.0, math.nan]]), "NaN or infinite"),
        (
            line([[16.0, 48.0], [16.0, 95.0]]),
            r"position 1 \(16.0, 95.0\) is outside the lon/lat range",
        ),
        (line([[16.0, 48.0], [16.0, 48.0]]), "fewer than 2 distinct positions"),
        (
            {"type": "MultiLineString", "coordinates": [[[16, 48], [16.1, 48]], [[16]]]},
            r"\(part 1\): malformed",
        ),
        (
            line([[16, 48], [16.1, 48]])
            | {"crs": {"type": "name", "properties": {"name": "EPSG:999999"}}},
            "unknown CRS",
        ),
        (line([[16, 48], [16.1, 48]]) | {"crs": "EPSG:4326"}, "unsupported 'crs' member"),
    ],
)
def test_bad_geojson_is_refused_with_the_reason(obj: object, message: str) -> None:
    with pytest.raises(SourceError, match=message):
        read_linestring(obj, "EPSG:32633", (600000.0, 5300000.0))  # type: ignore[arg-type]


def test_bad_geojson_files(tmp_path: Path) -> None:
    with pytest.raises(SourceError, match="cannot read file"):
        read_linestring(tmp_path / "missing.geojson", "EPSG:32633", (0, 0))
    bad = tmp_path / "bad.geojson"
    bad.write_text('{"type": "LineString", ')
    with pytest.raises(SourceError, match="not JSON"):
        read_linestring(bad, "EPSG:32633", (0, 0))
    bad.write_bytes(b"\xff\xfe\x00")
    with pytest.raises(SourceError, match="not UTF-8"):
        read_linestring(bad, "EPSG:32633", (0, 0))
    with pytest.raises(InputError, match="not projected"):
        read_linestring(line([[16, 48], [16.1, 48]]), "EPSG:4326", (0, 0))


# --------------------------------------------------------------------------- storing


@pytest.fixture
def db(tmp_path: Path) -> Path:
    return build_city_db(tmp_path / "city.db", size=300.0).path


def paths_in(db: Path) -> dict[str, bytes]:
    with SceneReader.open(db) as r:
        return {n: r.path_blob(n) for n in r.path_names()}


def test_record_path_makes_a_new_version_and_keeps_other_paths(db: Path) -> None:
    with SceneReader.open(db) as r:
        old = r.version
        cells = list(r.cells())
    start, end = cells[0].boundary.mean(axis=0), cells[-1].boundary.mean(axis=0)
    before = paths_in(db)
    path, version = record_path(db, "mine", start, end, 5.0)
    assert version != old
    after = paths_in(db)
    assert after[PATH_NAME] == before[PATH_NAME] and set(after) == {PATH_NAME, "mine"}
    stored = RecordedPath.from_msgpack(after["mine"])
    np.testing.assert_allclose(stored.table(), path.table(), atol=1e-3)
    with SceneReader.open(db) as r:
        assert r.version == version
    # the name is taken: refused unless replace
    with pytest.raises(StoreError, match="exists already"):
        record_path(db, "mine", end, start, 5.0)
    _, v3 = record_path(db, "mine", end, start, 5.0, replace=True)
    assert v3 != version
    assert np.allclose(RecordedPath.from_msgpack(paths_in(db)["mine"]).xyz[0, :2], end, atol=1e-3)


def test_a_failed_write_leaves_the_file_intact(db: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    before = db.read_bytes()
    with pytest.raises(RouteError):
        record_path(db, "far", (0.0, 0.0), (1e5, 0.0), 5.0)
    assert db.read_bytes() == before

    def broken(conn: sqlite3.Connection) -> str:
        raise sqlite3.DatabaseError("disk I/O error")

    monkeypatch.setattr(walkstream.server.store.edit, "content_version", broken)
    with SceneReader.open(db) as r:
        start = next(iter(r.cells())).boundary.mean(axis=0)
    with pytest.raises(StoreError, match="cannot write path"):
        record_path(db, "x", start, start + 0.5, 5.0)
    assert db.read_bytes() == before
    assert sorted(p.name for p in db.parent.iterdir()) == ["city.db", "city.db.lock"]


def test_write_path_keeps_every_other_path(db: Path) -> None:
    for name in ("a", "b"):
        write_path(db, name, RecordedPath.from_polyline(name, [[0, 0], [1, 0]], 5).to_msgpack())
    assert set(paths_in(db)) == {PATH_NAME, "a", "b"}


def test_import_path_into_a_scene(db: Path, tmp_path: Path) -> None:
    scene = load_geojson_dict(generate_city(300.0, 1), name="city")
    with SceneReader.open(db) as r:
        meta = r.meta
        start = next(iter(r.cells())).boundary.mean(axis=0)
    assert meta.crs == scene.crs and meta.origin == scene.origin
    far = start + np.array([1000.0, 0.0])
    f = tmp_path / "walk.geojson"
    f.write_text(json.dumps(line(to_lonlat(scene, np.array([start, start + (0, 30), far])))))
    path, version, inside = import_path(db, "walk", f, 4.0)
    assert 30 < inside < 130 and path.length_m() > 1000
    clipped, _, inside2 = import_path(db, "walk", f, 4.0, clip=True, replace=True)
    # the stretch inside, possibly bridging a gap of at most CLIP_GAP metres
    assert inside2 == pytest.approx(inside)
    assert inside - 1 <= clipped.length_m() <= inside + CLIP_GAP
    f.write_text(json.dumps(line(to_lonlat(scene, np.array([far, far + 50])))))
    with pytest.raises(RouteError, match="no part of the line lies inside"):
        import_path(db, "walk2", f, 4.0)


# --------------------------------------------------------------------------- Vienna


@pytest.fixture(scope="module")
def vienna_db(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[ViewCell]]:
    blocks = team_data("vienna", "blocks.geojson")
    from walkstream.server.sources.clip import clip_scene
    from walkstream.server.sources.geojson import load_geojson

    bbox = (-800.0, -900.0, 600.0, 1100.0)  # the part of the city the walk goes through
    scene = clip_scene(load_geojson(blocks), bbox)
    cells = make_cells(scene, "grid", bbox=bbox)
    path = tmp_path_factory.mktemp("vienna") / "vienna.db"
    with SceneWriter.create(
        path,
        name="vienna",
        crs=scene.crs,
        origin=scene.origin,
        grammar_text="",
        grammar_version="none",
        features=["grid_cells"],
        settings={"bbox": bbox},
    ) as w:
        w.add_cells(
            CellRow(c.id, c.kind, c.polygon, c.zmin, c.zmax, np.array(c.neighbours, np.int64))
            for c in cells
        )
        for c in cells:
            w.set_pvs(c.id, np.zeros(0, np.int64), np.zeros(0))
        for p in default_paths(cells, footprints=[b.rings[0] for b in scene.buildings]):
            w.add_path(p.name, p.to_msgpack())
        w.finish(0.0)
    return path, cells


def test_vienna_walk_imports_into_the_baked_part_of_vienna(
    vienna_db: tuple[Path, list[ViewCell]],
) -> None:
    db, cells = vienna_db
    assert set(paths_in(db)) == {"SE", "SM", "drive"}
    walk = team_data("vienna", "walk.geojson")
    path, _, inside = import_path(db, "vienna", walk, 5.0)
    assert path.length_m() == pytest.approx(5535.0, abs=25.0)  # "a 5.5 km walk"
    assert 0.8 * path.length_m() < inside <= path.length_m()
    assert (cells_of(cells, path) >= 0).mean() > 0.8
    clipped, _, _ = import_path(db, "vienna", walk, 5.0, clip=True, replace=True)
    assert 3000.0 < clipped.length_m() < path.length_m()
    xyz, _, _ = clipped.sample([0.0, clipped.duration])
    assert (cell_locator(cells).locate_many(xyz[:, :2]) >= 0).all()


# --------------------------------------------------------------------------- the CLI


def cli(*argv: str) -> int:
    p = argparse.ArgumentParser(prog="walkstream")
    add_path_parser(p.add_subparsers(dest="command", required=True))
    args = p.parse_args(["path", *argv])
    return int(args.func(args))


def test_path_commands(db: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with SceneReader.open(db) as r:
        cells = list(r.cells())
    a, b = (cells[k].boundary.mean(axis=0) for k in (0, -1))
    assert a[0] < 0  # a negative X after a space is a value, not an option
    assert (
        cli(
            "record",
            str(db),
            "r1",
            "--from",
            f"{a[0]},{a[1]}",
            f"--to={b[0]},{b[1]}",
            "--speed",
            "5",
        )
        == 0
    )
    out = capsys.readouterr().out
    assert "recorded path 'r1'" in out and "scene version" in out
    assert cli("list", str(db), "--json") == 0
    listed = json.loads(capsys.readouterr().out)
    by_name = {p["name"]: p for p in listed["paths"]}
    assert set(by_name) == {PATH_NAME, "r1"} and by_name["r1"]["speed_kmh"] == 5.0
    assert by_name["r1"]["key_points"] >= 2 and by_name["r1"]["length_m"] > 0
    assert cli("list", str(db)) == 0
    assert "r1" in capsys.readouterr().out
    out_json = tmp_path / "r1.json"
    assert cli("export", str(db), "r1", "-o", str(out_json)) == 0
    exported = RecordedPath.from_json(out_json.read_text())
    assert exported.name == "r1" and exported.duration == pytest.approx(
        by_name["r1"]["duration_s"], abs=0.01
    )
    with pytest.raises(WalkstreamError, match="--from: expected X,Y"):
        cli("record", str(db), "r2", "--from", "1;2", "--to", "0,0", "--speed", "5")
    with pytest.raises(WalkstreamError, match="--speed"):
        cli("record", str(db), "r2", "--from", "1,2", "--to", "0,0", "--speed", "0")
    with pytest.raises(WalkstreamError, match="exists already"):
        cli(
            "record",
            str(db),
            "r1",
            "--from",
            f"{a[0]},{a[1]}",
            "--to",
            f"{b[0]},{b[1]}",
            "--speed",
            "5",
        )
    with pytest.raises(WalkstreamError, match="no recorded path"):
        cli("export", str(db), "nope", "-o", str(out_json))


# --------------------------------------------------------------------------- the bake


@pytest.mark.gl
def test_a_resumed_bake_ends_with_the_default_paths(tmp_path: Path, gl: object) -> None:
    from walkstream.server.bake import BakeSettings, bake
    from walkstream.server.sources.citygen import write_city

    src = tmp_path / "city.geojson"
    write_city(src, 150, 2)
    out = tmp_path / "city.db"
    st = BakeSettings(resolution=16)
    assert bake(src, out, settings=st, max_cells=3) == {}
    summary = bake(src, out, settings=st)
    assert summary["resumed_cells"] == 3 and summary["paths"] == 3
    with SceneReader.open(out) as r:
        assert r.path_names() == ["SE", "SM", "drive"]
        stored = [r.path_blob(n) for n in r.path_names()]
        # made from the cells alone: the stored cells give the same paths again
        again = default_paths(r.cells())
    assert stored == [p.to_msgpack() for p in again]
    se = RecordedPath.from_msgpack(stored[0])
    assert se.duration > 30.0 and len(stored[0]) < 2048  # a 150 m city: its longest route
