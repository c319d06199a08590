"""Tests of walkstream.benchmarks.lod (``walkstream bench lod``) on a tiny scene database."""

from __future__ import annotations

import math
from pathlib import Path

import moderngl
import numpy as np
import pytest
from scenes import PATH_NAME, build_city_db

from walkstream.benchmarks.lod import (
    PIXEL_TOLERANCE,
    format_table,
    image_error,
    load_views,
    plot_lod_bench,
    run_lod_bench,
    summary_line,
)
from walkstream.cli import build_parser
from walkstream.server.store import SceneReader, write_path
from walkstream.shared.errors import InputError, WalkstreamError

SIZE = (64, 48)
SHARES = (0.1, 0.5)


@pytest.fixture(scope="module")
def city_db(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("lodbench") / "city.db"
    build_city_db(path, size=200.0, k=12)
    return path


def test_image_error() -> None:
    a = np.zeros((4, 5, 3), np.uint8)
    b = a.copy()
    assert image_error(a, b) == (0.0, 0.0)
    b[0, 0] = (PIXEL_TOLERANCE, 0, 0)  # within tolerance: not differing, still an error
    frac, err = image_error(b, a)
    assert frac == 0.0 and err == pytest.approx(PIXEL_TOLERANCE / 60)
    b[1, 1] = (0, 0, PIXEL_TOLERANCE + 1)
    frac, _ = image_error(b, a)
    assert frac == pytest.approx(1 / 20)
    full = np.full_like(a, 255)
    assert image_error(full, a) == (1.0, 255.0)
    with pytest.raises(InputError):
        image_error(a, a[:2])


def test_views_fall_back_to_street_cells(city_db: Path) -> None:
    with SceneReader.open(city_db) as r:
        views, source = load_views(r, 3)  # no path "SE"
        assert len(views) == 3
        assert "street-cell" in source and "SE" in source
        for v in views:
            cell = r.cell(v.cell)
            assert cell.kind == "street" and len(cell.pvs) > 0
            assert math.isfinite(v.yaw) and v.eye[2] == pytest.approx(1.7)
        # the test db's path is a tiny made-up one outside the cells: cells again
        views2, source2 = load_views(r, 2, path_name=PATH_NAME)
        assert "street-cell" in source2 and "outside every cell" in source2
        assert len(views2) == 2
        with pytest.raises(InputError):
            load_views(r, 0)


def test_views_along_a_recorded_path(tmp_path: Path, city_db: Path) -> None:
    from walkstream.shared.paths import RecordedPath

    db = tmp_path / "city.db"
    db.write_bytes(city_db.read_bytes())
    with SceneReader.open(db) as r:
        cells = [c for c in r.cells() if c.kind == "street"][:2]
        xy = [c.boundary.mean(axis=0) for c in cells]
    path = RecordedPath(
        "SE",
        np.array([0.0, 10.0]),
        np.array([[*xy[0], 1.7], [*xy[1], 1.7]]),
        np.zeros(2),
        np.zeros(2),
    )
    write_path(db, "SE", path.to_msgpack())
    with SceneReader.open(db) as r:
        views, source = load_views(r, 4)
    assert "'SE'" in source
    assert len(views) >= 1
    assert all(v.name.startswith("SE@") for v in views)


@pytest.mark.gl
def test_run_lod_bench_on_a_tiny_db(gl: moderngl.Context, city_db: Path, tmp_path: Path) -> None:
    sides = tmp_path / "side.png"
    rows = run_lod_bench(
        city_db,
        views=2,
        shares=SHARES,
        size=SIZE,
        repeats=2,
        images=sides,
        ctx=gl,
        progress=False,
    )
    modes = [(r["mode"], r["share"]) for r in rows]
    assert modes == [
        ("lod2", 1.0),
        ("ach", 0.1),
        ("distance", 0.1),
        ("ach", 0.5),
        ("distance", 0.5),
    ]
    ref = rows[0]
    assert ref["differing_pct"] == 0.0 and ref["mean_color_error"] == 0.0
    assert ref["triangles"] > 0
    for r in rows:
        assert r["views"] == 2 and len(r["per_view"]) == 2
        assert 0.0 <= r["differing_pct"] <= 100.0
        assert 0.0 <= r["mean_color_error"] <= 255.0
        assert math.isfinite(r["frame_ms"]) and r["frame_ms"] > 0
        assert r["size"] == list(SIZE)
        if r["mode"] == "ach" and not r["floor_limited"]:
            # within the budget up to the lowest LODs of objects served late
            assert r["triangles"] <= ref["triangles"]
        if r["mode"] == "distance":
            assert all(0 <= it["d1"] <= it["d2"] for it in r["per_view"])
    ach = {r["share"]: r for r in rows if r["mode"] == "ach"}
    dist = {r["share"]: r for r in rows if r["mode"] == "distance"}
    for s in SHARES:
        # equal triangles stand in for equal time: distance never uses more than ACH
        # did unless even its cheapest selection does
        for a, d in zip(ach[s]["per_view"], dist[s]["per_view"], strict=True):
            assert d["triangles"] <= a["triangles"] or d["floor_limited"]
    # a bigger budget buys at least as many triangles (same viewpoints)
    assert ach[0.5]["triangles"] >= ach[0.1]["triangles"]

    table = format_table(rows)
    for word in ("lod2", "ach", "distance", "differing %", "colour err", "ACH vs distance"):
        assert word in table
    assert "8/255" in table
    assert summary_line(rows) in table
    assert sides.read_bytes()[:4] == b"\x89PNG"
    plot = tmp_path / "plot.png"
    plot_lod_bench(rows, plot)
    assert plot.read_bytes()[:4] == b"\x89PNG"


def test_summary_line_verdicts() -> None:
    def rows(a_err: float, d_err: float, a_px: float, d_px: float) -> list[dict[str, object]]:
        base = {"share": 0.1, "views": 3, "frame_ms": 2.0}
        return [
            {**base, "mode": "ach", "mean_color_error": a_err, "differing_pct": a_px},
            {**base, "mode": "distance", "mean_color_error": d_err, "differing_pct": d_px},
        ]

    assert "yes" in summary_line(rows(1.0, 2.0, 1.0, 2.0))
    assert "no, distance" in summary_line(rows(2.0, 1.0, 2.0, 1.0))
    assert "no clear winner" in summary_line(rows(1.0, 1.01, 1.0, 1.01))
    assert "mixed" in summary_line(rows(1.0, 2.0, 2.0, 1.0))
    assert "no ACH/distance" in summary_line([])


def test_missing_db_names_make_demo(tmp_path: Path) -> None:
    with pytest.raises(WalkstreamError, match="make demo"):
        run_lod_bench(tmp_path / "nope.db", progress=False)


def test_bad_shares_rejected(city_db: Path) -> None:
    with pytest.raises(InputError):
        run_lod_bench(city_db, shares=(0.0,), progress=False)
    with pytest.raises(InputError):
        run_lod_bench(city_db, shares=(1.5,), progress=False)


def test_parser() -> None:
    p = build_parser()
    a = p.parse_args(["bench", "lod", "x.db", "--budgets", "5,10%", "--size", "320x240", "--views", "3"])
    assert a.db == "x.db" and a.budgets == (0.05, 0.10) and a.size == (320, 240)
    assert a.views == 3 and a.distance_ratio is None and callable(a.func)
    a = p.parse_args(["bench", "lod", "--distance-ratio", "2"])
    assert a.distance_ratio == 2.0 and a.db.endswith("city.db")
    for bad in (
        ["bench", "lod", "--size", "10"],
        ["bench", "lod", "--budgets", "0"],
        ["bench", "lod", "--distance-ratio", "0.5"],
    ):
        with pytest.raises(SystemExit):
            p.parse_args(bad)
