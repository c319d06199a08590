"""The bake end to end: database contents, atomic replace, resume, workers, Dask."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from daskcluster import local_cluster

from walkstream.cli import main
from walkstream.server.bake import BakeSettings, bake
from walkstream.server.sources.citygen import write_city
from walkstream.server.store import SceneReader
from walkstream.shared.errors import InputError, StoreError

pytestmark = pytest.mark.gl

FAST = BakeSettings(resolution=32)


@pytest.fixture(scope="module")
def city(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("bake") / "city.geojson"
    write_city(path, 150, 2)
    return path


@pytest.fixture(scope="module")
def baked(city: Path, gl_ctx: object) -> tuple[Path, dict]:
    out = city.parent / "city.db"
    return out, bake(city, out, settings=FAST)


def test_bake_writes_a_complete_database(baked: tuple[Path, dict]) -> None:
    db, summary = baked
    assert summary["name"] == "city"
    assert summary["cells"] > 5 and summary["objects"] > 10
    assert 0 < summary["pvs_mean"] <= summary["pvs_max"] <= summary["objects"]
    reader = SceneReader.open(db)
    try:
        meta = reader.meta
        assert "building" in meta.grammar_text and meta.crs == "EPSG:32633"
        assert {"buildings", "streets", "street_cells"} == set(meta.features)
        assert reader.viewpoints()
        for cell in reader.cells():
            if len(cell.pvs):
                assert cell.ach.sum() == pytest.approx(1.0)
                assert (cell.ach > 0).all()
            assert set(cell.neighbours) and cell.id not in set(cell.neighbours)
        info = reader.object_info([0])[0]
        assert info.tris[0] < info.tris[1] < info.tris[2]
    finally:
        reader.close()


def test_interrupted_bake_keeps_old_database_and_resumes(city: Path, baked: tuple[Path, dict], tmp_path: Path) -> None:
    db, summary = baked
    target = tmp_path / "scene.db"
    target.write_bytes(db.read_bytes())
    before = target.read_bytes()
    # a different setting makes a different scene; stop it after a few cells
    other = BakeSettings(resolution=32, threshold=1, sampling="region", edge_pass=True, split=0.5)
    assert bake(city, target, settings=other, max_cells=3) == {}
    assert target.read_bytes() == before  # the good database is untouched
    resumed = bake(city, target, settings=other)
    assert resumed["resumed_cells"] == 3
    assert resumed["cells"] == summary["cells"]
    assert resumed["version"] != summary["version"]
    assert target.read_bytes() != before


def test_local_workers_give_the_same_pvs(city: Path, baked: tuple[Path, dict], tmp_path: Path) -> None:
    db, _ = baked
    out = tmp_path / "w2.db"
    bake(city, out, settings=FAST, workers=2)
    a, b = SceneReader.open(db), SceneReader.open(out)
    try:
        for ca, cb in zip(a.cells(), b.cells(), strict=True):
            assert np.array_equal(ca.pvs, cb.pvs)
    finally:
        a.close()
        b.close()


def test_dask_local_cluster(city: Path, baked: tuple[Path, dict], tmp_path: Path) -> None:
    db, _ = baked
    out = tmp_path / "dask.db"
    with local_cluster() as cluster:
        summary = bake(city, out, settings=FAST, scheduler=cluster.scheduler_address)
    ref = SceneReader.open(db)
    try:
        assert summary["pvs_mean"] == ref.summary()["pvs_mean"]
    finally:
        ref.close()


def test_bad_settings_and_sources(city: Path, tmp_path: Path) -> None:
    with pytest.raises(InputError, match="resolution"):
        bake(city, tmp_path / "x.db", settings=BakeSettings(resolution=2))
    with pytest.raises(InputError, match="bbox"):
        bake(city, tmp_path / "x.db", settings=BakeSettings(bbox=(1e6, 1e6, 1e6 + 10, 1e6 + 10)))
    assert not (tmp_path / "x.db").exists()
    with pytest.raises(InputError, match="--thin-pass"):
        BakeSettings(thin_pass=-1.0).check()
    with pytest.raises(InputError, match="--thin-pass"):
        BakeSettings(thin_pass=float("nan")).check()
    for budget in (-1e-5, 0.01, float("nan")):
        with pytest.raises(InputError, match="--pvs-budget"):
            BakeSettings(pvs_budget=budget).check()


def test_the_thin_pass_is_part_of_a_bakes_identity_only_when_on() -> None:
    # a bake without it keeps the header (and scene version) it had before it existed
    assert "thin_pass" not in BakeSettings(thin_pass=0.0).record()
    assert BakeSettings(thin_pass=2.0).record()["thin_pass"] == 2.0
    assert "pvs_budget" not in BakeSettings().record()
    assert BakeSettings(pvs_budget=3e-5).record()["pvs_budget"] == 3e-5


def test_inspect_cli_json_map_and_bad_files(baked: tuple[Path, dict], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    db, _ = baked
    png = tmp_path / "map.png"
    assert main(["inspect", str(db), "--json", "--map", str(png)]) == 0
    got = json.loads(capsys.readouterr().out)
    for key in ("name", "version", "cells", "objects", "pvs_mean", "pvs_max", "culled_ratio",
                "bake_seconds", "db_bytes", "schema_version", "features"):
        assert key in got
    assert png.read_bytes()[:4] == b"\x89PNG"
    junk = tmp_path / "junk.db"
    junk.write_bytes(b"not a database" * 100)
    assert main(["inspect", str(junk)]) == 2
    err = capsys.readouterr().err
    assert "junk.db" in err and "Traceback" not in err
    with pytest.raises(StoreError):
        SceneReader.open(junk)


def test_a_killed_bake_process_leaves_the_database_and_resumes(tmp_path: Path, gl_ctx: object) -> None:
    """SIGKILL a real `walkstream bake` mid-way; the old file survives and the rerun resumes."""
    import os
    import signal
    import sqlite3
    import subprocess
    import sys
    import time

    src = tmp_path / "city.geojson"
    write_city(src, 350, 4)
    db = tmp_path / "scene.db"
    db.write_bytes(b"previous good database stands in here")
    before = db.read_bytes()
    argv = [sys.executable, "-m", "walkstream", "bake", str(src), "-o", str(db), "--resolution", "64"]
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    partial = Path(str(db) + ".partial")
    done = 0
    deadline = time.monotonic() + 120
    try:
        while time.monotonic() < deadline and proc.poll() is None:
            if partial.exists():
                try:
                    with sqlite3.connect(f"file:{partial}?mode=ro", uri=True, timeout=1) as c:
                        done = c.execute("SELECT count(*) FROM cells WHERE done = 1").fetchone()[0]
                except sqlite3.Error:
                    done = 0
                if done >= 5:
                    break
            time.sleep(0.05)
    finally:
        if proc.poll() is None:
            os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    if proc.returncode == 0:
        pytest.skip("the bake finished before it could be killed")
    assert done >= 5
    assert db.read_bytes() == before
    summary = bake(src, db, settings=BakeSettings(resolution=64))
    assert summary["resumed_cells"] >= 5
    assert summary["cells"] > summary["resumed_cells"]


def test_bench_visibility_cli(baked: tuple[Path, dict], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    db, _ = baked
    png, js = tmp_path / "vis.png", tmp_path / "vis.json"
    args = ["bench", "visibility", str(db), "--sample", "1", "--ref-points", "4", "--ref-resolution", "32",
            "--views", "1", "--settings", "corners-16,boundary20-16-t2", "--plot", str(png), "--json", str(js)]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "corners-64" in out and "boundary20-16-t2" in out and "baked" in out and "targets:" in out
    assert png.read_bytes()[:4] == b"\x89PNG"
    assert {r["name"] for r in json.loads(js.read_text())["rows"]} >= {"corners-64", "corners-16", "baked"}
    assert main(["bench", "visibility", str(db), "--settings", "nonsense"]) == 2


def test_demo_bakes_again_when_the_bake_defaults_changed(city: Path, baked: tuple[Path, dict], tmp_path: Path) -> None:
    """`make demo` keeps its database only while it matches today's bake defaults."""
    from walkstream.cmd_demo import stale_reason

    db, _ = baked
    assert stale_reason(db, ()) == "was baked with other settings than today's defaults (resolution)"
    fresh = tmp_path / "default.db"
    bake(city, fresh)
    assert stale_reason(fresh, ()) is None
    assert stale_reason(fresh, ("no-such-path",)) == "has no recorded path no-such-path"
    junk = tmp_path / "junk.db"
    junk.write_bytes(b"not a database")
    assert stale_reason(junk, ()) == "is not a readable scene database"
