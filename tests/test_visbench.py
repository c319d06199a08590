"""The visibility benchmark (walkstream.benchmarks.visibility) on a tiny generated city."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pytest
from teamdata import team_data

from walkstream.benchmarks.visibility import least_pvs, view_need, visibility_benchmark
from walkstream.benchmarks.visinput import BenchInput, load_bench_input, pick_cells
from walkstream.benchmarks.visreport import format_table, plot_visibility_benchmark
from walkstream.benchmarks.vissettings import TODAY, bake_default, parse_setting
from walkstream.server.bake.cells import make_cells
from walkstream.server.sources.citygen import generate_city
from walkstream.server.sources.geojson import load_geojson_dict
from walkstream.shared.errors import InputError

if TYPE_CHECKING:
    import moderngl

SETTINGS = ["boundary20-32", "boundary20-32-t4", "corners-32", "boundary10-64", "field8-32"]


@pytest.fixture(scope="module")
def city() -> BenchInput:
    scene = load_geojson_dict(generate_city(150, 2))
    return BenchInput(scene, make_cells(scene), 800.0, "citygen 150 2")


@pytest.fixture(scope="module")
def result(city: BenchInput, gl_ctx: moderngl.Context) -> dict[str, Any]:
    # a bake or replay run in-process by an earlier module makes its own context current
    # and releases it: the session's is made current again (as the ``gl`` fixture does)
    gl_ctx.__enter__()
    calls: list[tuple[int, int]] = []
    out = visibility_benchmark(
        city,
        settings=SETTINGS,
        sample=2,
        ref_points=6,
        ref_resolution=64,
        views=1,
        view_size=(96, 72),
        ctx=gl_ctx,
        progress=lambda d, n: calls.append((d, n)),
    )
    out["_progress"] = calls
    return out


def test_rows_and_ranges(result: dict[str, Any]) -> None:
    rows = {r["name"]: r for r in result["rows"]}
    least = rows.pop("least PVS")
    # the first default and the bake's default are the yardsticks of the ratios: added when not asked for
    dflt = bake_default().name
    assert list(rows) == [TODAY.name, dflt, *SETTINGS]
    # the floor meets both miss targets against the reference, and no setting that meets them holds less
    assert least["meets"]["miss_px"] and least["meets"]["miss_max"] and least["sec_per_cell"] is None
    assert least["pvs_mean"] <= result["reference"]["pvs_mean"]
    for r in rows.values():
        if r["meets"]["miss_px"] and r["meets"]["miss_max"]:
            assert r["pvs_mean"] >= least["pvs_mean"]
    assert rows[TODAY.name]["time_ratio"] == 1.0 and rows[TODAY.name]["pvs_ratio"] == 1.0
    assert rows[dflt]["time_ratio_default"] == 1.0 and result["default"] == dflt
    for r in rows.values():
        for key in ("miss_count", "miss_px", "miss_max", "view_miss_px", "view_miss_count", "culled"):
            assert 0.0 <= r[key] <= 1.0, key
        assert r["sec_per_cell"] > 0 and r["pvs_mean"] >= 0 and r["points_per_cell"] >= 1
        assert set(r["meets"]) == {"miss_max", "miss_px", "time_ratio_default", "pvs_ratio"}
        assert r["missed"] == len(r["missed_ref_shares"])
    # the field row: a cell's field points, and what the bake would render per cell
    f = rows["field8-32"]
    assert f["sampling"] == "field" and f["field_points"] > 0
    assert f["bake_sec_per_cell"] == pytest.approx(f["sec_per_cell"] * f["field_points_per_cell"] / f["points_per_cell"])
    # a hardly-visible threshold only ever drops objects
    plain, thr = rows["boundary20-32"], rows["boundary20-32-t4"]
    assert thr["pvs_mean"] <= plain["pvs_mean"] and thr["miss_count"] >= plain["miss_count"]
    assert rows["boundary10-64"]["points_per_cell"] > rows["boundary20-32"]["points_per_cell"]
    ref = result["reference"]
    assert ref["resolution"] == 64 and ref["lod"] == 2 and ref["frustum_culling"] is False
    assert ref["points_per_cell"] <= 6 and ref["cells_scored"] >= 1
    assert result["views"] == 2
    for r in rows.values():
        assert 0.0 <= r["view_over_hundredth"] <= 1.0 and r["view_over_hundredth"] >= r["view_over_half"]
    need = result["view_need"]
    assert need["pvs_ratio"] == pytest.approx(need["pvs_mean"] / rows[TODAY.name]["pvs_mean"])
    assert need["must_mean"] <= need["pvs_mean"]
    assert result["_progress"][-1] == (2 * 3, 2 * 3)


def test_table_and_plot(result: dict[str, Any], tmp_path: Path) -> None:
    table = format_table(result)
    for name in SETTINGS:
        assert name in table
    assert "targets:" in table and "missed objects' sizes" in table and "x dflt" in table
    assert "field8-32: the bench renders a cell's" in table
    out = tmp_path / "vis.png"
    plot_visibility_benchmark(result, out)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    json.dumps(result)  # the CLI writes it as JSON


def test_least_pvs_leaves_out_the_least_seen_objects_within_both_targets() -> None:
    ref = [{1: 9_000, 2: 600, 3: 300, 4: 100}, {5: 9_990, 6: 10}, {}]
    # 20,000 pixels: the budget 1 % is 200 (4 and 6 fit, 3 would not); the cap 4 % of a cell
    got = least_pvs(ref, 0.01, 0.04)
    assert got == [{1, 2, 3}, {5}, set()]
    # the cap keeps what is large in its own cell even when the budget would allow it
    assert least_pvs(ref, 0.5, 0.005) == [{1, 2, 3, 4}, {5}, set()]
    # a PVS that left out anything more would miss the budget: nothing to leave out at 0
    assert least_pvs(ref, 0.0, 1.0) == [set(r) for r in ref]


def test_view_need_leaves_out_what_each_view_can_spare() -> None:
    frame = np.zeros((100, 100), np.uint32)  # 10,000 pixels: 0.01 % is one pixel
    frame[:50] = 4  # object 3 (ids are object + 1)
    frame[50:, :40] = 8
    frame[99, 99] = 10  # object 9: one pixel, spared
    other = np.zeros((100, 100), np.uint32)
    other[0, 0], other[0, 1] = 6, 7  # one pixel each: 5 is spared, 6 then makes two
    views = [(0, frame, frame), (1, other, other), (1, frame, frame)]
    need, must = view_need(views, 3)
    assert need == [{3, 7}, {6, 3, 7}, set()]
    # alone over one pixel: 3 and 7, not the one-pixel objects
    assert must == [{3, 7}, {3, 7}, set()]


def test_parse_setting() -> None:
    s = parse_setting("boundary15-96-t2-L1-h0.5+c").bake
    assert (s.sampling, s.spacing, s.resolution, s.threshold, s.occluder_lod, s.height_step, s.centre) == (
        "boundary", 15.0, 96, 2, 1, 0.5, True
    )
    assert parse_setting("corners-64").bake.sampling == "corners"
    assert parse_setting("region20-256-p0.003").bake.pvs_budget == pytest.approx(3e-5)
    r = parse_setting("region10-128+e+c").bake
    assert (r.sampling, r.spacing, r.edge_pass, r.centre) == ("region", 10.0, True, True)
    for bad in ("random-64", "corners", "boundary20-128-x3", "corners-4"):
        with pytest.raises(InputError):
            parse_setting(bad)


def test_pick_cells_is_deterministic_and_prefers_streets(city: BenchInput) -> None:
    a = pick_cells(city.cells, 3, seed=5)
    assert [c.id for c in a] == [c.id for c in pick_cells(city.cells, 3, seed=5)]
    assert len({c.id for c in a}) == 3
    if any(c.kind == "street" for c in city.cells):
        assert all(c.kind == "street" for c in a)
    with pytest.raises(InputError):
        pick_cells(city.cells, 0)


def test_a_database_is_read_alone_and_its_pvs_scored(tmp_path: Path, gl_ctx: moderngl.Context) -> None:
    from walkstream.server.bake import BakeSettings, bake

    src = tmp_path / "city.geojson"
    src.write_text(json.dumps(generate_city(150, 2)))
    direct = load_bench_input(src)
    assert direct.view_distance == 800.0 and direct.cells and direct.baked is None
    db = tmp_path / "city.db"
    bake(src, db, settings=BakeSettings(view_distance=500.0, resolution=32, sampling="corners"))
    gl_ctx.__enter__()  # the bake made its own context current and released it
    src.unlink()  # the database alone is enough (a source of any kind)
    baked = load_bench_input(db)
    assert baked.view_distance == 500.0 and baked.baked is not None
    assert [c.id for c in baked.cells] == [c.id for c in direct.cells]
    assert len(baked.scene.buildings) == len(direct.scene.buildings)
    assert len(baked.scene.streets) == len(direct.scene.streets)
    np.testing.assert_allclose(baked.scene.buildings[3].rings[0], direct.scene.buildings[3].rings[0], atol=0.01)
    res = visibility_benchmark(
        baked, settings=["corners-32"], sample=2, ref_points=4, ref_resolution=32, views=0, ctx=gl_ctx
    )
    rows = {r["name"]: r for r in res["rows"]}
    # the benchmark computes a PVS exactly as the bake does
    for key in ("pvs_mean", "miss_count", "miss_px", "miss_max"):
        assert rows["baked"][key] == pytest.approx(rows["corners-32"][key]), key
    with pytest.raises(InputError, match="no such file"):
        load_bench_input(tmp_path / "missing.db")
    (tmp_path / "junk.db").write_bytes(b"not a database at all")
    with pytest.raises(InputError, match="neither"):
        load_bench_input(tmp_path / "junk.db")


def test_an_openstreetmap_extract_is_read_as_a_source(gl_ctx: moderngl.Context) -> None:
    osm = team_data("osm", "village-10.068_48.135.osm")
    got = load_bench_input(osm)
    # street cells of the real network, not quads only, and an 800 m view distance
    assert got.cells and got.baked is None and got.view_distance == 800.0
    assert {c.kind for c in got.cells} & {"street", "crossroad"}
    res = visibility_benchmark(
        got, settings=["corners-32"], sample=2, ref_points=4, ref_resolution=32, views=0, ctx=gl_ctx
    )
    rows = {r["name"]: r for r in res["rows"]}
    assert "corners-32" in rows and 0.0 <= rows["corners-32"]["miss_count"] <= 1.0


def test_the_reference_is_cached_on_disk(city: BenchInput, gl_ctx: moderngl.Context, tmp_path: Path) -> None:
    kw: dict[str, Any] = {"settings": ["corners-16"], "sample": 2, "ref_points": 4, "ref_resolution": 32, "views": 0, "repeat": 1, "ctx": gl_ctx}
    first = visibility_benchmark(city, cache=tmp_path, **kw)
    assert first["reference"]["cached"] == 0 and len(list(tmp_path.glob("*.npz"))) == 2
    again = visibility_benchmark(city, cache=tmp_path, **kw)
    assert again["reference"]["cached"] == 2
    for a, b in zip(first["rows"], again["rows"], strict=True):
        assert (a["miss_count"], a["miss_px"], a["miss_max"]) == (b["miss_count"], b["miss_px"], b["miss_max"])
    # another resolution is another entry
    visibility_benchmark(city, cache=tmp_path, **(kw | {"ref_resolution": 48}))
    assert len(list(tmp_path.glob("*.npz"))) == 4
