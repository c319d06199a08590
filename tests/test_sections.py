"""Sections from a dense visibility field (Brosnan et al.): the growth rules, the bake, the walk.

The rules are tested on a synthetic field (no rendering): a lattice with a building
in it and made-up visible sets.  The bake, the map and a replay on a small generated
city with a coarse field at a low resolution.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import httpx
import numpy as np
import pytest
import shapely

from walkstream.cli import main
from walkstream.client.config import ReplayConfig
from walkstream.client.net.link import LinkProfile
from walkstream.client.replay import run_replay
from walkstream.client.stream.cellmap import CellMap, portal_between
from walkstream.client.stream.plan import plan_needs
from walkstream.client.stream.route import predict_route
from walkstream.server.bake import BakeSettings, bake
from walkstream.server.bake.cells import make_cells
from walkstream.server.bake.field import (
    FieldLattice,
    PointSets,
    bake_field,
    field_folder,
    field_lattice,
    points_meeting,
)
from walkstream.server.bake.sections import grow_sections, section_points, section_pvs
from walkstream.server.bake.sectionsize import sections_for_area
from walkstream.server.service.main import create_app
from walkstream.server.sources.citygen import write_city
from walkstream.server.sources.read import read_source
from walkstream.server.store import SceneReader
from walkstream.shared.cells import CellLocator
from walkstream.shared.paths import RecordedPath

# --------------------------------------------------------------------- synthetic field


def _field() -> tuple[FieldLattice, PointSets]:
    """A 12 x 8 lattice (2 m) with a 4 x 3 building in it; two 'streets' (rows 0-2 and
    rows 6-7) that see different objects, joined by a column on the west."""
    ny, nx = 8, 12
    r, c = np.divmod(np.arange(nx * ny), nx)
    building = (r >= 3) & (r <= 5) & (c >= 3) & (c <= 6)
    index = np.flatnonzero(~building)
    sets: list[list[int]] = []
    for k in index.tolist():
        rr, cc = divmod(k, nx)
        s = {0, 1} | ({2, 3} if rr <= 2 else {4, 5} if rr >= 6 else {2, 4})
        if cc >= 8:
            s.add(6 + cc)  # the east sees a new object every column
        sets.append(sorted(s))
    offsets = np.concatenate([[0], np.cumsum([len(s) for s in sets])]).astype(np.int64)
    ids = np.array([i for s in sets for i in s], np.int64)
    xy = np.stack([c[index] * 2.0, r[index] * 2.0], axis=1)
    lat = FieldLattice((0.0, 0.0), 2.0, (ny, nx), index.astype(np.int64), xy, (1.7, 2.0))
    return lat, PointSets(offsets, ids, np.ones(len(ids), np.int64))


def _set(sets: PointSets, k: int) -> set[int]:
    return set(sets.of(k)[0].tolist())


@pytest.mark.parametrize(("redundancy", "min_size"), [(0, 0.0), (2, 16.0), (5, 64.0), (100, 400.0)])
def test_growth_rules_on_a_synthetic_field(redundancy: int, min_size: float) -> None:
    lat, sets = _field()
    secs = grow_sections(lat, sets, redundancy=redundancy, min_size=min_size)
    grid = lat.grid()
    covered = np.zeros(len(lat), bool)
    for s in secs:
        pts = section_points(s, grid)
        covered[pts] = True
        union = set().union(*(_set(sets, int(k)) for k in pts))
        pvs, ach = section_pvs(s, grid, sets)
        assert set(pvs.tolist()) == union  # the PVS is the union of its points' sets
        assert ach.sum() == pytest.approx(1.0)
        seed = _set(sets, s.seed)
        i0, j0, i1, j1 = s.inner
        inner = grid[j0 : j1 + 1, i0 : i1 + 1]
        assert (inner >= 0).all()  # no gaps in the inner rectangle
        assert all(_set(sets, int(k)) <= seed for k in inner.ravel())  # the subset rule
        assert len(union - seed) == s.redundancy <= redundancy
        if not s.relaxed:
            assert s.points * lat.spacing**2 >= min_size
    assert covered.all()  # every field point lies in a section


def test_a_row_of_building_alone_does_not_join_two_streets() -> None:
    lat, sets = _field()
    grid = lat.grid()
    for s in grow_sections(lat, sets, redundancy=0, min_size=0.0):
        pts = section_points(s, grid)
        rows = {int(k) // 12 for k in lat.index[pts].tolist()}
        assert not (min(rows) <= 2 and max(rows) >= 6 and s.i0 >= 3)  # only via the west column


def test_overlaps_only_where_they_add_points() -> None:
    lat, sets = _field()
    grid = lat.grid()
    secs = grow_sections(lat, sets, redundancy=3, min_size=0.0)
    seen = np.zeros(len(lat), bool)
    for s in secs:
        pts = section_points(s, grid)
        assert not seen[pts].all()  # every section brings a point no earlier one has
        seen[pts] = True


# --------------------------------------------------------------------- the bake

# the default R (from the field): the bake below is the default's path
FAST = BakeSettings(cells="sections", resolution=32, field_spacing=6.0)


@pytest.fixture(scope="module")
def city(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("sections") / "city.geojson"
    write_city(path, 150, 2)
    return path


@pytest.fixture(scope="module")
def baked(city: Path, gl_ctx: object) -> tuple[Path, dict]:
    out = city.parent / "sections.db"
    return out, bake(city, out, settings=FAST)


@pytest.mark.gl
def test_the_bake_covers_every_free_point_and_unions_the_field(city: Path, baked: tuple[Path, dict]) -> None:
    db, summary = baked
    assert summary["schema_version"] == 3 and summary["cells"] == summary["sections"] > 1
    scene = read_source(city)
    free = field_lattice(scene, FAST.field_spacing, (1.7, 2.0), margin=FAST.margin)
    # the default cover: the field points whose squares meet the walkable (street) cells
    streets = shapely.union_all([shapely.Polygon(c.polygon) for c in make_cells(scene, "auto")])
    walkable = points_meeting(free, streets)
    assert 0 < walkable.sum() < len(free)  # the free space inside the blocks is left out
    lat = free.subset(walkable)
    # no sample inside a building: every eye lies outside every footprint
    foot = shapely.union_all([shapely.Polygon(b.rings[0], b.rings[1:]) for b in scene.buildings])
    assert not shapely.contains_xy(foot, lat.eyes[:, 0], lat.eyes[:, 1]).any()
    with SceneReader.open(db) as r:
        cells = list(r.cells())
        assert {c.kind for c in cells} == {"section"} and "section_cells" in r.meta.features
        loc = CellLocator.of_kinds([c.id for c in cells], [c.kind for c in cells], [c.boundary for c in cells],
                                   [[c.zmin, c.zmax] for c in cells])
        # every field point (its lattice position and where it was rendered) lies in a section
        assert (loc.locate_many(lat.xy()) >= 0).all() and (loc.locate_many(lat.eyes) >= 0).all()
        folders = list(Path(str(db) + ".field").iterdir())
        assert len(folders) == 1
        blocks = sorted(folders[0].glob("*.npz"))
        ids = [np.load(b)["ids"] for b in blocks]
        offs = [np.load(b)["offsets"] for b in blocks]
        sets = [set(i[o[k] : o[k + 1]].tolist()) for i, o in zip(ids, offs, strict=True) for k in range(len(o) - 1)]
        assert len(sets) == len(lat)  # only the walkable points were rendered
        xy = lat.xy()
        for c in cells:
            lo, hi = c.boundary.min(axis=0), c.boundary.max(axis=0)
            inside = np.flatnonzero(((xy >= lo) & (xy <= hi)).all(axis=1))
            assert set(c.pvs.tolist()) == set().union(*(sets[k] for k in inside.tolist()))
            if len(c.pvs):
                assert c.ach.sum() == pytest.approx(1.0)
        # sections that share an edge are neighbours
        for c in cells:
            for n in c.neighbours:
                assert c.id in cells[n].neighbours
        assert r.viewpoints() and all(v.name.startswith("start") and v.cell is not None for v in r.viewpoints())


@pytest.mark.gl
def test_a_field_resumes_after_a_kill(city: Path, baked: tuple[Path, dict], tmp_path: Path) -> None:
    db, summary = baked
    out = tmp_path / "again.db"
    assert bake(city, out, settings=FAST, max_cells=64, name="sections") == {}
    folder = next(Path(str(out) + ".field").iterdir())
    assert 0 < len(list(folder.glob("*.npz"))) < len(list(next(Path(str(db) + ".field").iterdir()).glob("*.npz")))
    again = bake(city, out, settings=FAST, name="sections")  # the same scene: the same version
    assert again["version"] == summary["version"]
    assert field_folder(out, folder.name) == folder


@pytest.mark.gl
def test_a_replay_on_sections_locates_every_frame_and_prefetches_neighbours(baked: tuple[Path, dict]) -> None:
    db, _ = baked
    cfg = ReplayConfig(link=LinkProfile(56_000.0, 56_000.0, 0.2), device="desktop2003", path="SE", duration_s=10.0)
    app = create_app([db])
    try:
        res = run_replay(httpx.ASGITransport(app=app), "http://walkstream.test", cfg)
    finally:
        app.state.scenes.close()
    with SceneReader.open(db) as r:
        cells = {c.id: c for c in r.cells()}
        se = RecordedPath.from_msgpack(r.path_blob("SE"), "SE")
    cell = np.asarray(res.log.cell)
    assert (cell >= 0).all() and set(cell.tolist()) <= set(cells)
    # the prefetch follows the sections' adjacency: the cells ahead are planned from the index
    m = CellMap()
    m.add_cells(list(cells), [c.boundary for c in cells.values()], [c.neighbours for c in cells.values()],
                [c.kind for c in cells.values()])
    xy = np.asarray(se.xyz)[0, :2]
    m.update(xy)
    assert m.current is not None
    needs = plan_needs(m, None, xy, np.array([1.4, 0.0]), None, reach_m=300.0, reach_records_m=400.0,
                       turn_m=10.0, min_speed=1.0)
    assert set(cells[m.current].neighbours) <= set(needs.records)


@pytest.mark.gl
def test_the_map_draws_the_sections(baked: tuple[Path, dict], tmp_path: Path) -> None:
    db, _ = baked
    assert main(["inspect", str(db), "--map", str(tmp_path / "map.png")]) == 0
    assert (tmp_path / "map.png").stat().st_size > 10_000


@pytest.mark.parametrize(("flag", "value", "says"), [("--field-spacing", "0", "--field-spacing"),
                                                      ("--redundancy", "-1", "--redundancy"),
                                                      ("--min-size", "-5", "--min-size"),
                                                      ("--section-cover", "everywhere", "--section-cover")])
def test_bad_section_flags_get_one_line(city: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                        flag: str, value: str, says: str) -> None:
    assert main(["bake", str(city), "-o", str(tmp_path / "x.db"), "--cells", "sections", flag, value]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and says in err[0]


def test_a_walkable_cover_keeps_the_points_whose_square_meets_the_cells() -> None:
    # a 10 x 10 m street; a lattice every 2 m over 0..20 (squares from -1 to 21)
    street = shapely.box(0.0, 0.0, 10.0, 10.0)
    r, c = np.divmod(np.arange(121), 11)
    for angle in (0.0, np.radians(30.0)):
        xy = np.stack([c * 2.0, r * 2.0], axis=1).astype(np.float64)
        lat = FieldLattice((0.0, 0.0), 2.0, (11, 11), np.arange(121, dtype=np.int64), xy, (1.7, 2.0), float(angle))
        got = points_meeting(lat, street)
        squares = [shapely.Polygon(lat.to_scene(np.array([[x - 1, y - 1], [x + 1, y - 1], [x + 1, y + 1], [x - 1, y + 1]])))
                   for x, y in xy]
        want = np.array([shapely.intersection(q, street).area > 1e-6 for q in squares])
        assert (got == want).all() and 0 < got.sum() < 121
        sub = lat.subset(got)
        assert len(sub) == got.sum() and (sub.grid() >= 0).sum() == got.sum() and sub.angle == lat.angle
    # a square that only touches the street at its edge is not kept: (12, 0), its square from x 11
    edge = FieldLattice((0.0, 0.0), 2.0, (1, 7), np.array([5, 6]), np.array([[10.0, 0.0], [12.0, 0.0]]), (1.7, 2.0))
    assert points_meeting(edge, shapely.box(0.0, 0.0, 11.0, 10.0)).tolist() == [True, False]


def test_locating_in_an_overlap_keeps_the_section_the_viewer_is_in() -> None:
    a = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 4.0], [0.0, 4.0]])
    b = np.array([[6.0, 0.0], [20.0, 0.0], [20.0, 4.0], [6.0, 4.0]])  # overlaps a over x 6..10
    m = CellMap()
    m.add_cells([0, 1], [a, b], [[1], [0]], ["section", "section"])
    assert m.update([2.0, 2.0]) == (0, True) and m.update([8.0, 2.0]) == (0, True)  # into the overlap: still 0
    assert m.update([15.0, 2.0]) == (1, True) and m.update([8.0, 2.0]) == (1, True)  # back: still 1
    # the service answers the lowest id in an overlap, deterministically
    loc = CellLocator.of_kinds([0, 1], ["section", "section"], [a, b], [[1.5, 2.0], [1.5, 2.0]])
    assert loc.locate(8.0, 2.0) == 0 and loc.locate(15.0, 2.0) == 1


def test_the_route_into_an_overlapping_section_crosses_where_the_viewer_is() -> None:
    # a street going north (x 0..20) and a wide section across it overlapping its north
    # end (y 40..60 of the street): the way in is where the viewer goes, not a far corner
    street = np.array([[0.0, 0.0], [20.0, 0.0], [20.0, 60.0], [0.0, 60.0]])
    across = np.array([[-150.0, 40.0], [150.0, 40.0], [150.0, 90.0], [-150.0, 90.0]])
    seg = portal_between(street, across)
    assert np.allclose(seg[:, 1], 50.0) and np.allclose(sorted(seg[:, 0]), [0.0, 20.0])  # the overlap's long axis
    assert np.allclose(portal_between(across, street), seg)
    m = CellMap()
    m.add_cells([0, 1], [street, across], [[1], [0]], ["section", "section"])
    m.update([10.0, 30.0])
    route = predict_route(m, 0, [10.0, 30.0], [0.0, 1.0], 100.0, 20.0)
    assert {s.cell: s.distance_m for s in route.steps}[1] == pytest.approx(20.0)
    # cells sharing an edge, or only a corner, keep their portal
    a = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [0.0, 1.0]])
    assert portal_between(a, a + [2.0, 0.5]).tolist() == [[2.0, 0.5], [2.0, 1.0]]
    assert portal_between(a, a + [2.0, 1.0]).tolist() == [[2.0, 1.0], [2.0, 1.0]]


# --------------------------------------------------------------------- aligned sections


def _turned_city(path: Path, degrees: float) -> Path:
    """The small generated city turned by ``degrees`` about its corner."""
    import math

    from walkstream.server.sources.citygen import generate_city

    d = generate_city(150, 2)
    a = math.radians(degrees)
    x0, y0 = 600000.0, 5340000.0

    def turn(c: object) -> object:
        if isinstance(c, list) and c and isinstance(c[0], (int, float)):
            x, y = float(c[0]) - x0, float(c[1]) - y0  # type: ignore[arg-type]
            return [x0 + math.cos(a) * x - math.sin(a) * y, y0 + math.sin(a) * x + math.cos(a) * y]
        return [turn(v) for v in c] if isinstance(c, list) else c

    for f in d["features"]:
        f["geometry"]["coordinates"] = turn(f["geometry"]["coordinates"])
    path.write_text(json.dumps(d))
    return path


def test_street_angle_finds_a_turned_grid(tmp_path: Path) -> None:
    from walkstream.server.bake.sectionplan import street_angle

    # the generated city's streets bend by a degree or so; a grid's streets and cross
    # streets count alike: modulo 90 degrees
    base = np.degrees(street_angle(read_source(_turned_city(tmp_path / "c0.geojson", 0.0))))
    assert min(base, 90.0 - base) < 1.0
    for deg in (30.0, 75.0):
        got = np.degrees(street_angle(read_source(_turned_city(tmp_path / f"c{deg:g}.geojson", deg))))
        assert (got - deg - base) % 90.0 == pytest.approx(0.0, abs=1e-3) or (got - deg - base) % 90.0 > 90.0 - 1e-3


@pytest.mark.gl
def test_aligned_sections_are_turned_rectangles_that_cover_the_field(tmp_path: Path) -> None:
    src = _turned_city(tmp_path / "turned.geojson", 30.0)
    db = tmp_path / "aligned.db"
    st = BakeSettings(cells="sections", resolution=16, field_spacing=10.0, redundancy=8, section_shape="aligned",
                      section_cover="free")
    summary = bake(src, db, settings=st)
    assert summary["cells"] == summary["sections"] > 1 and summary["redundancy"] == 8  # given: not from the field
    scene = read_source(src)
    from walkstream.server.bake.sectionplan import street_angle

    angle = street_angle(scene)
    lat = field_lattice(scene, 10.0, (1.7, 2.0), margin=st.margin, angle=angle)
    assert lat.angle == pytest.approx(np.radians(30.0), abs=np.radians(1.0))
    foot = shapely.union_all([shapely.Polygon(b.rings[0], b.rings[1:]) for b in scene.buildings])
    assert not shapely.contains_xy(foot, lat.eyes[:, 0], lat.eyes[:, 1]).any()  # no sample in a building
    with SceneReader.open(db) as r:
        cells = list(r.cells())
        assert r.meta.settings["section_shape"] == "aligned"
        loc = CellLocator.of_kinds([c.id for c in cells], [c.kind for c in cells], [c.boundary for c in cells],
                                   [[c.zmin, c.zmax] for c in cells])
        # every field point, where it stands and where it was rendered, lies in a section
        assert (loc.locate_many(lat.xy()) >= 0).all() and (loc.locate_many(lat.eyes) >= 0).all()
        for c in cells:
            ring = np.asarray(c.boundary)
            assert len(ring) == 4
            e = np.roll(ring, -1, axis=0) - ring
            # a rectangle whose sides run at the street angle (or across it)
            assert np.allclose(np.sum(e * np.roll(e, -1, axis=0), axis=1), 0.0, atol=1e-6)
            assert np.degrees(np.arctan2(e[0, 1], e[0, 0])) % 90.0 == pytest.approx(np.degrees(angle) % 90.0, abs=1e-6)
        for c in cells:
            for n in c.neighbours:
                assert c.id in cells[n].neighbours
    assert main(["inspect", str(db), "--map", str(tmp_path / "map.png")]) == 0


def test_a_bad_section_shape_gets_one_line(city: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bake", str(city), "-o", str(tmp_path / "x.db"), "--cells", "sections", "--section-shape", "round"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--section-shape" in err[0]


def test_the_bench_table_and_plot_show_every_kind_cover_and_where_the_bytes_go(tmp_path: Path) -> None:
    from walkstream.benchmarks.sections import format_sections_table, plot_sections_trade

    def walk(b: float, o: float, c: float, i: float) -> dict[str, float | None]:
        return {"km": 0.8, "perfect_frame_ratio": 0.998, "first_perfect_s": 1.5, "bytes_per_km": b,
                "cells_per_km": 20.0, "object_bytes_per_km": o, "cell_bytes_per_km": c, "index_bytes_per_km": i,
                "overfetch_ratio": 0.25}

    def row(kind: str, cover: str | None, r: int | None) -> dict[str, object]:
        return {"cells_kind": kind, "cover": cover, "redundancy": r, "min_size": None if r is None else 64.0,
                "cells": 100, "pvs_mean": 80.0, "section_redundancy_mean": None if r is None else 30.0,
                "bake_seconds": 10.0, "walks": {"SE": walk(60_000.0 + (r or 0), 40_000.0, 12_000.0, 8_000.0)}}

    rows = [row("street", None, None), row("grid", None, None), row("sections", "walkable", 64), row("sections", "free", 64)]
    lines = format_sections_table(rows).splitlines()
    assert "records" in lines[0] and "index" in lines[0] and "cover" in lines[0]
    assert [ln.split()[:2] for ln in lines[2:]] == [["street", "-"], ["grid", "-"], ["sections", "walkable"], ["sections", "free"]]
    assert "40,000" in lines[4] and "12,000" in lines[4] and "60,064" in lines[4]
    plot_sections_trade(rows, tmp_path / "trade.png")
    assert (tmp_path / "trade.png").stat().st_size > 10_000


def test_bench_sections_refuses_a_bad_bbox_in_one_line(city: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "sections", str(city), "--bbox", "1,2,3", "--out", str(tmp_path / "b")]) != 0
    err = capsys.readouterr().err
    assert "--bbox" in err and "Traceback" not in err
    assert not (tmp_path / "b" / "street.db").exists()


def test_a_reused_database_keeps_the_redundancy_its_bake_measured(small_city_db: Path, tmp_path: Path) -> None:
    import shutil

    from walkstream.benchmarks.sections import _bake, _previous_rows

    db = tmp_path / "sections-R64-M64.db"
    shutil.copy(small_city_db, db)
    st = BakeSettings(cells="sections")
    # no figures kept: the table shows "-"
    assert _bake(tmp_path / "unused.geojson", db, st, True, 1).get("section_redundancy_mean") is None
    # a database of an older run: its row in the last bench_sections.json (named by R, M, cover)
    (tmp_path / "bench_sections.json").write_text(json.dumps([
        {"cells_kind": "sections", "cover": "walkable", "redundancy": 64, "min_size": 64.0, "section_redundancy_mean": 37.5},
        {"cells_kind": "sections", "cover": "free", "redundancy": 64, "min_size": 64.0, "section_redundancy_mean": 99.0},
    ]))
    prev = _previous_rows(tmp_path)
    assert set(prev) == {"sections-R64-M64.db", "sections-R64-M64-free.db"}
    s = _bake(tmp_path / "unused.geojson", db, st, True, 1, prev.get(db.name))
    assert s["section_redundancy_mean"] == 37.5 and s["cells"] > 0
    # the figures the bake kept beside the database win
    (tmp_path / "sections-R64-M64.db.figures.json").write_text(json.dumps({"section_redundancy_mean": 12.25}))
    assert _bake(tmp_path / "unused.geojson", db, st, True, 1, prev.get(db.name))["section_redundancy_mean"] == 12.25


def test_points_on_one_spot_of_the_trade_plot_share_one_label(tmp_path: Path) -> None:
    from walkstream.benchmarks.sections import plot_sections_trade, trade_labels

    def row(r: int, pvs: float, kb: float, red: float | None, m: float = 64.0) -> dict[str, object]:
        return {"cells_kind": "sections", "cover": "walkable", "redundancy": r, "min_size": m, "cells": 10,
                "pvs_mean": pvs, "section_redundancy_mean": red, "bake_seconds": 1.0,
                "walks": {"drive": {"bytes_per_km": kb * 1000, "cells_per_km": 5.0}}}

    # Kouvola's clip on the drive: R 128 and R 256 a quarter of the PVS range apart, 0.05 kB/km
    rows = [row(32, 127.7, 38.1, 35.0), row(64, 159.2, 19.0, 73.0), row(128, 255.7, 9.09, 178.0),
            row(256, 306.0, 9.04, 214.0)]
    labels = trade_labels(rows, "drive")
    assert [lab for _, _, lab in labels] == ["R32 M64 (redundancy 35)", "R64 M64 (redundancy 73)",
                                             "R128, R256 M64 (redundancy 178, 214)"]
    assert labels[2][:2] == (255.7, 9.09)
    # one redundancy where they agree, none where it was not measured
    rows[3]["section_redundancy_mean"] = 178.0
    assert trade_labels(rows, "drive")[2][2] == "R128, R256 M64 (redundancy 178)"
    rows[2]["section_redundancy_mean"] = rows[3]["section_redundancy_mean"] = None
    assert trade_labels(rows, "drive")[2][2] == "R128, R256 M64"
    # another M on the same spot: whole labels side by side
    rows[3] = row(256, 306.0, 9.04, 214.0, m=128.0)
    assert trade_labels(rows, "drive")[2][2] == "R128 M64; R256 M128 (redundancy 214)"
    # far apart in kB/km: two labels, even at one PVS
    assert len(trade_labels([row(128, 300.0, 9.0, 1.0), row(256, 300.0, 30.0, 1.0)], "drive")) == 2
    assert trade_labels(rows, "SE") == []
    plot_sections_trade(rows, tmp_path / "trade.png")
    assert (tmp_path / "trade.png").stat().st_size > 10_000


# --------------------------------------------------------------------- R from the field


def _target(lat: FieldLattice, sets: PointSets, area: float) -> int:
    coarsest = len(grow_sections(lat, sets, redundancy=10_000, min_size=0.0))
    return max(math.ceil(len(lat) * lat.spacing**2 / area), coarsest)


def test_the_default_redundancy_is_the_smallest_that_reaches_the_sections_area() -> None:
    lat, sets = _field()  # 84 points of 4 m², 336 m²
    chosen = []
    for area in (4.0, 12.0, 30.0, 80.0, 400.0):
        r, secs = sections_for_area(lat, sets, min_size=0.0, area=area)
        target = _target(lat, sets, area)
        assert len(secs) <= target  # sections of the area on average (or the coarsest partition)
        if r > 0:  # and no smaller R reaches it (the bracket is exact below 32 objects)
            assert len(grow_sections(lat, sets, redundancy=r - 1, min_size=0.0)) > target
        assert secs == grow_sections(lat, sets, redundancy=r, min_size=0.0)  # the sections of that R
        chosen.append(r)
    assert chosen == sorted(chosen) and chosen[0] == 0 < chosen[-1]  # bigger sections, more redundancy
    assert sections_for_area(lat.subset(np.zeros(len(lat), bool)), PointSets(np.zeros(1, np.int64),
                             np.zeros(0, np.int64), np.zeros(0, np.int64)), min_size=0.0) == (0, [])
    with pytest.raises(ValueError, match="section area"):
        sections_for_area(lat, sets, min_size=0.0, area=0.0)


def test_the_default_redundancy_is_stored_as_from_the_field() -> None:
    st = BakeSettings(cells="sections").check()
    assert st.redundancy is None and st.record()["redundancy"] is None
    assert BakeSettings(cells="sections", redundancy=12).check().record()["redundancy"] == 12


@pytest.mark.gl
def test_a_bake_without_redundancy_takes_r_from_its_field(city: Path, baked: tuple[Path, dict]) -> None:
    db, summary = baked  # baked without a redundancy
    scene = read_source(city)
    free = field_lattice(scene, FAST.field_spacing, (1.7, 2.0), margin=FAST.margin)
    lat = free.subset(points_meeting(free, shapely.union_all([shapely.Polygon(c.polygon)
                                                              for c in make_cells(scene, "auto")])))
    folder = next(Path(str(db) + ".field").iterdir())
    sets = bake_field(lat, scene, FAST, folder.name, folder)  # all blocks on disk: loaded, not rendered
    assert sets is not None
    r, secs = sections_for_area(lat, sets, min_size=FAST.min_size)
    assert summary["redundancy"] == r and summary["sections"] == len(secs) > 1
    assert len(secs) <= max(math.ceil(len(lat) * FAST.field_spacing**2 / 2400.0),
                            len(grow_sections(lat, sets, redundancy=10_000, min_size=FAST.min_size)))
    with SceneReader.open(db) as reader:
        assert reader.meta.settings["redundancy"] is None  # the header says: from the field


def test_bench_sections_takes_auto_and_refuses_a_bad_redundancy(capsys: pytest.CaptureFixture[str]) -> None:
    from walkstream.cmd_bench import _redundancy_arg

    assert _redundancy_arg("auto") is None and _redundancy_arg("64") == 64
    with pytest.raises(SystemExit):
        main(["bench", "sections", "--redundancy", "lots"])
    err = capsys.readouterr().err
    assert "--redundancy" in err and "lots" in err and "Traceback" not in err
