"""Street and grid cells sampled from the dense visibility field (``--sampling field``).

The lattice and the cells' field points are tested on hand-made cells and a building
(no rendering); the bake, its resume after a kill, a grid reaching past the city's
edge and the flags on a small generated city with a coarse field at a low resolution.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import shapely

from walkstream.cli import main
from walkstream.server.bake import BakeSettings, bake
from walkstream.server.bake.field import (
    FIELD_HEIGHTS,
    FieldLattice,
    PointSets,
    built_space,
    lattice_from,
)
from walkstream.server.bake.fieldsampling import (
    cell_field_points,
    cells_region,
    field_cell_pvs,
    sampling_lattice,
)
from walkstream.server.bake.viewcell import ViewCell
from walkstream.server.sources.citygen import write_city
from walkstream.server.sources.read import read_source
from walkstream.server.store import SceneReader


def _cell(cid: int, x0: float, y0: float, x1: float, y1: float, nb: tuple[int, ...] = ()) -> ViewCell:
    return ViewCell(cid, "grid", np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]]), 1.5, 2.0, nb)


# two cells sharing the edge x = 10; a building (8..9 x 2..6) in the west one
WEST, EAST = _cell(0, 0.0, 0.0, 10.0, 8.0, (1,)), _cell(1, 10.0, 0.0, 20.0, 8.0, (0,))
HOUSE = shapely.box(6.0, 2.0, 9.0, 6.0)


def _lattice(spacing: float = 2.0) -> FieldLattice:
    return sampling_lattice([WEST, EAST], [HOUSE], spacing, margin=0.3)


def test_a_point_on_the_shared_edge_belongs_to_both_cells() -> None:
    lat = _lattice()
    assert lat.origin == (0.0, 0.0) and lat.spacing == 2.0  # anchored at whole spacings
    xy = lat.xy()
    west, east = cell_field_points(lat, WEST.polygon), cell_field_points(lat, EAST.polygon)
    on_edge = set(np.flatnonzero(np.isclose(xy[:, 0], 10.0)).tolist())
    assert on_edge and on_edge <= set(west.tolist()) & set(east.tolist())
    # a square that only touches the outline does not make a point the cell's
    assert not np.isclose(xy[west, 0], 12.0).any() and not np.isclose(xy[east, 0], 8.0).any()
    # the outline points: the lattice row on y = 0 and y = 8 (squares half inside)
    assert np.isclose(xy[west, 1], 0.0).any() and np.isclose(xy[west, 1], 8.0).any()
    # the squares of a cell's field points cover its free space
    h = lat.spacing / 2
    cover = shapely.union_all([shapely.box(x - h, y - h, x + h, y + h) for x, y in xy[west]])
    free = shapely.difference(shapely.Polygon(WEST.polygon), built_space([HOUSE], 0.3))
    assert shapely.difference(free, cover).area < 1e-9


def test_no_point_is_rendered_inside_a_building() -> None:
    lat = _lattice()
    grown = built_space([HOUSE], 0.3)
    assert not shapely.contains_xy(grown, lat.eyes[:, 0], lat.eyes[:, 1]).any()
    # a lattice point inside the building whose square reaches free space is rendered
    # at a point of that free space, inside the cells
    xy = lat.xy()
    moved = np.flatnonzero(shapely.contains_xy(grown, xy[:, 0], xy[:, 1]))
    assert len(moved) and (np.abs(lat.eyes[moved] - xy[moved]) <= 1.0 + 1e-9).all()
    region = cells_region([WEST, EAST])
    assert shapely.intersects_xy(region, lat.eyes[:, 0], lat.eyes[:, 1]).all()
    # lattice points (8, 4): deep enough in the building that its square is all built -> no field point
    deep = lattice_from(built_space([shapely.box(5.0, 1.0, 11.0, 7.0)], 0.3), 2.0, FIELD_HEIGHTS,
                        within=region)
    assert not np.any(np.all(np.isclose(deep.xy(), [8.0, 4.0]), axis=1))


def test_a_cell_wholly_in_a_building_gets_an_empty_pvs() -> None:
    inside = _cell(2, 6.5, 2.5, 8.5, 5.5)
    block = shapely.box(5.0, 1.0, 10.0, 7.0)  # covers the cell and every square meeting it
    assert len(sampling_lattice([inside], [block], 2.0, margin=0.3)) == 0  # no free field point at all
    lat = sampling_lattice([WEST, EAST, inside], [block], 2.0, margin=0.3)
    sets = PointSets(np.arange(len(lat) + 1, dtype=np.int64), np.zeros(len(lat), np.int64), np.ones(len(lat), np.int64))
    res = {cid: pvs for cid, pvs, _ in field_cell_pvs(lat, sets, [WEST, EAST, inside])}
    assert len(res[0]) == len(res[1]) == 1 and len(res[2]) == 0  # no sample there, no PVS (no error)


def test_the_pvs_is_the_union_with_pixels_summed() -> None:
    lat = _lattice()
    n = len(lat)
    # point k sees object k % 5 (3 px) and object 9 (1 px)
    offsets = np.arange(0, 2 * n + 1, 2, dtype=np.int64)
    ids = np.column_stack([np.arange(n) % 5, np.full(n, 9)]).ravel().astype(np.int64)
    pixels = np.tile([3, 1], n).astype(np.int64)
    sets = PointSets(offsets, ids, pixels)
    pts = cell_field_points(lat, EAST.polygon)
    got_ids, got_px = sets.union(pts)
    want = {int(j): 0 for j in np.unique(pts % 5)}
    for k in pts.tolist():
        want[k % 5] += 3
    want[9] = len(pts)
    assert dict(zip(got_ids.tolist(), got_px.tolist(), strict=True)) == want
    (cid, pvs, ach), = field_cell_pvs(lat, sets, [EAST])
    assert cid == 1 and set(pvs.tolist()) == set(want)
    assert ach[pvs.tolist().index(9)] == pytest.approx(len(pts) / sum(want.values()))


# --------------------------------------------------------------------- the bake

FAST = BakeSettings(resolution=32, sampling="field", field_spacing=8.0)


@pytest.fixture(scope="module")
def city(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("fieldsampling") / "city.geojson"
    write_city(path, 150, 2)
    return path


#: the ``(step, unit)`` of every step the ``baked`` bake started, in order
STAGES: list[tuple[str, str]] = []


@pytest.fixture(scope="module")
def baked(city: Path, gl_ctx: object) -> tuple[Path, dict]:
    out = city.parent / "field.db"
    return out, bake(city, out, settings=FAST, stage=lambda step, unit: STAGES.append((step, unit)))


@pytest.mark.gl
def test_the_progress_bar_counts_field_points_as_points(baked: tuple[Path, dict]) -> None:
    """The field step is labelled as such (it once counted field points as "cell")."""
    assert STAGES and STAGES[0] == ("visibility field", "point")
    assert all(unit != "cell" for step, unit in STAGES if step == "visibility field")


def test_the_bar_takes_each_steps_label_and_unit(capsys: pytest.CaptureFixture[str]) -> None:
    from walkstream.terminal import count_bar, stage_setter

    bar, progress = count_bar("baking cells", "cell")
    stage = stage_setter(bar)
    stage("visibility field", "point")
    progress(3, 10)
    assert bar.desc.startswith("visibility field") and bar.unit == "point" and bar.n == 3
    stage("impostor images", "image")
    assert bar.desc.startswith("impostor images") and bar.unit == "image" and bar.n == 0
    progress(1, 4)
    bar.close()
    assert "visibility field" in capsys.readouterr().err


@pytest.mark.gl
def test_street_cells_get_the_union_of_their_field_points(city: Path, baked: tuple[Path, dict]) -> None:
    db, summary = baked
    assert summary["field_points"] > 0 and summary["field_spacing"] == 8.0
    with SceneReader.open(db) as r:
        cells = list(r.cells())
        assert {c.kind for c in cells} <= {"street", "crossroad", "square"}
        assert r.meta.settings["sampling"] == "field" and r.meta.settings["field_spacing"] == 8.0
        assert "redundancy" not in r.meta.settings
        folder = next(Path(str(db) + ".field").iterdir())
        blocks = sorted(folder.glob("*.npz"))
        offs, ids = [np.load(b)["offsets"] for b in blocks], [np.load(b)["ids"] for b in blocks]
        sets = [set(i[o[k] : o[k + 1]].tolist()) for i, o in zip(ids, offs, strict=True) for k in range(len(o) - 1)]
        views = [ViewCell(c.id, c.kind, np.asarray(c.boundary), c.zmin, c.zmax, tuple(c.neighbours)) for c in cells]
    scene = read_source(city)
    lat = sampling_lattice(views, [shapely.Polygon(b.rings[0], b.rings[1:]) for b in scene.buildings], 8.0)
    assert len(lat) == len(sets) == summary["field_points"] and lat.origin[0] % 8.0 == 0.0
    foot = shapely.union_all([shapely.Polygon(b.rings[0], b.rings[1:]) for b in scene.buildings])
    assert not shapely.contains_xy(foot, lat.eyes[:, 0], lat.eyes[:, 1]).any()
    for c in cells:
        pts = cell_field_points(lat, c.boundary)
        assert len(pts) > 0
        assert set(c.pvs.tolist()) == set().union(*(sets[k] for k in pts.tolist()))
        assert c.ach.sum() == pytest.approx(1.0)
    # neighbours share the field points on their common outline
    shared = [len(np.intersect1d(cell_field_points(lat, c.boundary), cell_field_points(lat, cells[n].boundary)))
              for c in cells for n in c.neighbours]
    assert sum(1 for k in shared if k > 0) > len(shared) // 2


@pytest.mark.gl
def test_a_field_sampled_bake_resumes_after_a_kill(city: Path, baked: tuple[Path, dict], tmp_path: Path) -> None:
    db, summary = baked
    out = tmp_path / "again.db"
    assert bake(city, out, settings=FAST, max_cells=64, name="field") == {}
    folder = next(Path(str(out) + ".field").iterdir())
    n_blocks = len(list(next(Path(str(db) + ".field").iterdir()).glob("*.npz")))
    assert 0 < len(list(folder.glob("*.npz"))) < n_blocks
    # a block being written when the bake was killed leaves only its temporary file
    (folder / "000999.tmp.npz").write_bytes(b"half")
    again = bake(city, out, settings=FAST, name="field")
    assert again["version"] == summary["version"]  # the same scene, baked whole or resumed
    with SceneReader.open(db) as a, SceneReader.open(out) as b:
        for ca, cb in zip(a.cells(), b.cells(), strict=True):
            np.testing.assert_array_equal(ca.pvs, cb.pvs)


@pytest.mark.gl
def test_the_field_spread_over_local_processes_bakes_the_same_scene(
    city: Path, baked: tuple[Path, dict], tmp_path: Path
) -> None:
    db, summary = baked
    out = tmp_path / "pool.db"
    again = bake(city, out, settings=FAST, workers=2, name="field")
    assert again["version"] == summary["version"]
    with SceneReader.open(db) as a, SceneReader.open(out) as b:
        for ca, cb in zip(a.cells(), b.cells(), strict=True):
            np.testing.assert_array_equal(ca.pvs, cb.pvs)


@pytest.mark.gl
def test_grid_cells_past_the_citys_edge(city: Path, tmp_path: Path) -> None:
    # a bbox reaching 60 m past the buildings: grid cells over empty ground
    out = tmp_path / "edge.db"
    st = BakeSettings(resolution=32, sampling="field", field_spacing=10.0, cells="grid", bbox=(-60.0, -60.0, 90.0, 90.0))
    summary = bake(city, out, settings=st)
    with SceneReader.open(out) as r:
        cells = list(r.cells())
    assert summary["cells"] == len(cells) > 1 and all(c.kind == "grid" for c in cells)
    assert all(len(c.pvs) == 0 or c.ach.sum() == pytest.approx(1.0) for c in cells)


@pytest.mark.parametrize(("args", "says"), [(["--sampling", "field", "--field-spacing", "0"], "--field-spacing"),
                                             (["--sampling", "field", "--field-spacing", "nan"], "--field-spacing")])
def test_bad_field_flags_get_one_line(city: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                      args: list[str], says: str) -> None:
    assert main(["bake", str(city), "-o", str(tmp_path / "x.db"), *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and says in err[0]
    assert not (tmp_path / "x.db").exists()


def test_the_field_spacing_is_stored_only_when_it_is_used() -> None:
    assert "field_spacing" not in BakeSettings().record()
    assert BakeSettings(sampling="field").record()["field_spacing"] == 4.0
    assert "redundancy" not in BakeSettings(sampling="field").record()


def test_bench_city_refuses_an_unknown_cell_kind(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    assert main(["bench", "city", "--kinds", "street,rooms", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--kinds" in err[0] and "rooms" in err[0]
