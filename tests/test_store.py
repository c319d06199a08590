"""The scene database (walkstream.server.store): round trip, atomicity, resume, validation."""

from __future__ import annotations

import os
import sqlite3
import subprocess
import sys
import textwrap
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from contextlib import closing
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from walkstream.server.store import (
    SCHEMA_VERSION,
    CellRow,
    ObjectRow,
    SceneReader,
    SceneWriter,
    write_path,
)
from walkstream.shared.codec import encode_building, encode_street
from walkstream.shared.errors import InputError, NotFoundError, StoreError
from walkstream.shared.records import BuildingParams, StreetParams

ROOT = Path(__file__).resolve().parents[1]


# ---------------------------------------------------------------------------
# a small made-up scene
# ---------------------------------------------------------------------------


def _square(x: float, y: float, w: float) -> np.ndarray:
    return np.array([[x, y], [x + w, y], [x + w, y + w], [x, y + w]], dtype=np.float64)


@dataclass
class Scene:
    buildings: list[BuildingParams]
    streets: list[StreetParams]
    cells: list[CellRow]
    pvs: dict[int, tuple[list[int], list[float]]]

    @property
    def rows(self) -> list[ObjectRow]:
        return [ObjectRow.of(b, tris=(12, 40, 300)) for b in self.buildings] + [
            ObjectRow.of(s, tris=(2, 2, 2)) for s in self.streets
        ]


@pytest.fixture
def scene() -> Scene:
    """Three buildings, two street pieces, four cells (one sees nothing)."""
    buildings = [
        BuildingParams(
            i,
            (_square(20.0 * i, 0.0, 12.0),),
            (np.array([0.0, 9.0 if i else 0.0, 0.0, 0.0]),),
            floors=3 + i,
            floor_height=3.0,
            style=i,
            source_id=f"b{i}",
        )
        for i in range(3)
    ]
    streets = [
        StreetParams(3, "street", _square(0.0, -10.0, 8.0), 8.0),
        StreetParams(4, "crossroad", _square(10.0, -10.0, 8.0), 10.0),
    ]
    cells = [
        CellRow(c, "street", _square(10.0 * c, -10.0, 10.0), 1.5, 1.8, np.array(nb))
        for c, nb in enumerate([[1], [0, 2], [1, 3], [2]])
    ]
    pvs = {
        0: ([0, 3, 4], [500.0, 300.0, 200.0]),
        1: ([4, 1, 0, 3], [1.0, 1.0, 1.0, 1.0]),
        2: ([2], [77.0]),
        3: ([], []),
    }
    return Scene(buildings, streets, cells, pvs)


SETTINGS: dict[str, Any] = {"resolution": 64, "views": 48, "source": "made-up"}


def create(path: Path, **overrides: Any) -> SceneWriter:
    kwargs: dict[str, Any] = {
        "name": "tiny",
        "crs": "EPSG:32633",
        "origin": (600_000.0, 5_340_000.0),
        "grammar_text": "building(h) -> massing(h)\n",
        "grammar_version": "1",
        "features": ["street_cells"],
        "settings": SETTINGS,
    }
    kwargs.update(overrides)
    return SceneWriter.create(path, **kwargs)


@pytest.fixture
def bake(scene: Scene) -> Callable[..., str]:
    """Bake ``scene`` into a path; returns the version."""

    def run(path: Path, bake_seconds: float = 1.25, **overrides: Any) -> str:
        with create(path, **overrides) as w:
            w.add_objects(scene.rows)
            w.add_cells(scene.cells)
            for cid, (ids, ach) in scene.pvs.items():
                w.set_pvs(cid, ids, ach)
            w.add_viewpoint("start", 5.0, -5.0, 1.7, 0.5, cell=0)
            w.add_viewpoint("above", 5.0, 5.0, 80.0)
            return w.finish(bake_seconds)

    return run


@pytest.fixture
def db(tmp_path: Path, bake: Callable[..., str]) -> Path:
    """A finished scene database."""
    path = tmp_path / "scene.db"
    bake(path)
    return path


@pytest.fixture
def reader(db: Path) -> Iterator[SceneReader]:
    with SceneReader.open(db) as r:
        yield r


# ---------------------------------------------------------------------------
# round trip
# ---------------------------------------------------------------------------


def test_round_trip(reader: SceneReader, scene: Scene, db: Path) -> None:
    m = reader.meta
    assert (m.name, m.crs, m.origin, m.schema_version) == (
        "tiny",
        "EPSG:32633",
        (600_000.0, 5_340_000.0),
        SCHEMA_VERSION,
    )
    assert m.grammar_text.startswith("building") and m.grammar_version == "1"
    assert m.features == ("street_cells",) and m.settings == SETTINGS
    assert len(m.version) == 16 and int(m.version, 16) >= 0
    assert m.bake_seconds == 1.25 and m.created

    params = reader.object_params([4, 0, 99, 3])
    assert list(params) == [0, 3, 4]  # unknown 99 left out, ordered by id
    assert params[0] == encode_building(scene.buildings[0])
    assert params[4] == encode_street(scene.streets[1])
    b = reader.building(2)
    np.testing.assert_allclose(b.rings[0], scene.buildings[2].rings[0], atol=0.005)
    assert (b.floors, b.style, b.source_id) == (5, 2, "b2")
    assert reader.street(4).kind == "crossroad"
    info = reader.object_info([1])[1]
    assert info.kind == "building" and info.tris == (12, 40, 300)
    assert info.bbox == (20.0, 0.0, 0.0, 32.0, 12.0, 12.0)
    np.testing.assert_array_equal(reader.object_ids(), [0, 1, 2, 3, 4])
    assert reader.bounds() == (0.0, -10.0, 0.0, 52.0, 12.0, 15.0)

    c = reader.cell(1)
    assert c.kind == "street" and (c.zmin, c.zmax) == (1.5, 1.8)
    np.testing.assert_array_equal(c.boundary, scene.cells[1].boundary)
    np.testing.assert_array_equal(c.neighbours, [0, 2])
    np.testing.assert_array_equal(c.pvs, [0, 1, 3, 4])
    np.testing.assert_allclose(c.ach, 0.25, atol=1 / 65535)
    assert abs(c.ach.sum() - 1) < 1e-12
    c0 = reader.cell(0)
    np.testing.assert_allclose(c0.ach, [0.5, 0.3, 0.2], atol=1 / 65535)

    cells = list(reader.cells())
    assert [c.id for c in cells] == [0, 1, 2, 3]
    assert reader.cell_pvs_blob(3) == b"\x01\x00"

    vps = reader.viewpoints()
    assert [v.name for v in vps] == ["above", "start"]
    assert vps[1].cell == 0 and vps[0].cell is None and vps[1].yaw == 0.5
    assert reader.path_names() == []


def test_empty_pvs_cell(reader: SceneReader) -> None:
    c = reader.cell(3)
    assert c.pvs.shape == (0,) and c.ach.shape == (0,)
    assert not c.pvs.flags.writeable


def test_summary(reader: SceneReader, db: Path) -> None:
    s = reader.summary()
    sizes = np.array([3, 4, 1, 0])
    assert s["name"] == "tiny" and s["version"] == reader.version
    assert (s["cells"], s["objects"]) == (4, 5)
    assert s["pvs_mean"] == pytest.approx(sizes.mean())
    assert s["pvs_max"] == 4
    assert s["culled_ratio"] == pytest.approx(np.mean(1 - sizes / 5))
    assert s["bake_seconds"] == 1.25
    assert s["db_bytes"] == db.stat().st_size
    assert s["schema_version"] == SCHEMA_VERSION and s["features"] == ["street_cells"]


def test_finished_file_is_self_contained(db: Path) -> None:
    names = sorted(p.name for p in db.parent.iterdir())
    assert names == ["scene.db", "scene.db.lock"]  # no .partial, -wal, -shm or temp file left
    head = db.read_bytes()[:100]
    assert head[18:20] == b"\x01\x01"  # rollback journal, not WAL: one file is the database


def test_optional_tables_only_when_used(tmp_path: Path, db: Path, bake: Callable[..., str]) -> None:
    def tables(p: Path) -> set[str]:
        with closing(sqlite3.connect(p)) as c:
            return {r[0] for r in c.execute("SELECT name FROM sqlite_master WHERE type='table'")}

    assert "portals" not in tables(db)
    rooms = tmp_path / "rooms.db"
    bake(rooms, features=["rooms", "portals"])
    assert "portals" in tables(rooms)


def test_concurrent_readers(reader: SceneReader) -> None:
    expected = {c.id: c.pvs.tolist() for c in reader.cells()}

    def work(k: int) -> bool:
        for _ in range(50):
            cid = k % 4
            if reader.cell(cid).pvs.tolist() != expected[cid]:
                return False
            if len(reader.object_params(range(5))) != 5:
                return False
        return True

    with ThreadPoolExecutor(8) as pool:
        assert all(pool.map(work, range(32)))


# ---------------------------------------------------------------------------
# atomicity and resume
# ---------------------------------------------------------------------------


def test_interrupted_bake_keeps_old_db_and_resumes(
    db: Path, scene: Scene, bake: Callable[..., str]
) -> None:
    before = db.read_bytes()
    new = {**SETTINGS, "resolution": 128}
    with pytest.raises(RuntimeError, match="killed"), create(db, settings=new) as w:
        assert not w.resumed
        w.add_objects(scene.rows)
        w.add_cells(scene.cells)
        w.set_pvs(0, *scene.pvs[0])
        w.set_pvs(2, *scene.pvs[2])
        raise RuntimeError("killed")
    assert db.read_bytes() == before
    assert Path(str(db) + ".partial").exists()
    with SceneReader.open(db) as r:  # the old scene still opens
        assert r.summary()["cells"] == 4

    with create(db, settings=new) as w:
        assert w.resumed and w.done_cells() == {0, 2}
        # re-adding the same objects and cells keeps what was done
        w.add_objects(scene.rows)
        w.add_cells(scene.cells)
        assert w.done_cells() == {0, 2}
        with pytest.raises(StoreError, match="2 cells have no PVS"):
            w.finish(1.0)
        assert db.read_bytes() == before
        for cid in (1, 3):
            w.set_pvs(cid, *scene.pvs[cid])
        version = w.finish(3.0)
    assert not Path(str(db) + ".partial").exists()
    with SceneReader.open(db) as r:
        assert r.version == version and r.meta.settings["resolution"] == 128


def test_changed_cell_loses_its_pvs_on_resume(tmp_path: Path, scene: Scene) -> None:
    path = tmp_path / "s.db"
    with create(path) as w:
        w.add_cells(scene.cells)
        w.set_pvs(0, *scene.pvs[0])
        w.set_pvs(1, *scene.pvs[1])
    moved = CellRow(1, "street", _square(11.0, -10.0, 10.0), 1.5, 1.8, np.array([0, 2]))
    with create(path) as w:
        w.add_cells([scene.cells[0], moved])
        assert w.done_cells() == {0}


def test_other_settings_or_no_resume_start_over(tmp_path: Path, scene: Scene) -> None:
    path = tmp_path / "s.db"
    with create(path) as w:
        w.add_cells(scene.cells)
        w.set_pvs(0, *scene.pvs[0])
    with create(path, settings={**SETTINGS, "views": 6}) as w:
        assert not w.resumed and w.done_cells() == set()
        w.add_cells(scene.cells)
        w.set_pvs(1, *scene.pvs[1])
    with create(path, settings={**SETTINGS, "views": 6}, resume=False) as w:
        assert not w.resumed and w.done_cells() == set()


def test_killed_process_loses_at_most_the_current_cell(tmp_path: Path) -> None:
    path = tmp_path / "k.db"
    code = textwrap.dedent(
        f"""
        import os, signal
        import numpy as np
        from walkstream.server.store import CellRow, SceneWriter
        w = SceneWriter.create({str(path)!r}, name="k", crs="", origin=(0.0, 0.0),
            grammar_text="", grammar_version="1", features=[], settings={{}})
        sq = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=float)
        w.add_cells([CellRow(i, "grid", sq + i, 0.0, 2.0, np.array([], np.int64)) for i in range(10)])
        for i in range(6):
            w.set_pvs(i, [i], [1.0])
        os.kill(os.getpid(), signal.SIGKILL)
        """
    )
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, timeout=60)
    assert proc.returncode == -9, proc.stderr.decode()
    assert not path.exists()
    with SceneWriter.create(
        path, name="k", crs="", origin=(0.0, 0.0), grammar_text="", grammar_version="1",
        features=[], settings={},
    ) as w:  # fmt: skip
        assert w.resumed and w.done_cells() == set(range(6))


def test_second_bake_of_same_path_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "s.db"
    with create(path), pytest.raises(StoreError, match="another bake"):
        create(path)


# ---------------------------------------------------------------------------
# validation
# ---------------------------------------------------------------------------


def _reject(path: Path, match: str) -> None:
    with pytest.raises(StoreError, match=match) as info:
        SceneReader.open(path)
    assert path.name in str(info.value)
    assert isinstance(info.value, InputError)


def test_missing_and_non_files(tmp_path: Path) -> None:
    _reject(tmp_path / "nope.db", "no such file")
    (tmp_path / "dir.db").mkdir()
    _reject(tmp_path / "dir.db", "not a file")


def test_random_bytes_and_empty_file(tmp_path: Path) -> None:
    p = tmp_path / "noise.db"
    p.write_bytes(np.random.default_rng(3).bytes(5000))
    _reject(p, "not an SQLite database")
    e = tmp_path / "empty.db"
    e.write_bytes(b"")
    _reject(e, "not an SQLite database")


def test_foreign_sqlite_db(tmp_path: Path) -> None:
    p = tmp_path / "foreign.db"
    with closing(sqlite3.connect(p)) as c:
        c.execute("CREATE TABLE meta(key, value)")
        c.commit()
    _reject(p, "not a walkstream scene database")


def test_wrong_schema_version(db: Path) -> None:
    with closing(sqlite3.connect(db)) as c:
        c.execute("PRAGMA user_version=7")
    _reject(db, r"scene\.db: schema version 7, this walkstream reads versions 1, 2")


def test_unfinished_bake_is_refused(tmp_path: Path, scene: Scene) -> None:
    path = tmp_path / "s.db"
    with create(path) as w:
        w.add_cells(scene.cells)
    _reject(Path(str(path) + ".partial"), "unfinished bake")


def test_truncated_db(db: Path, tmp_path: Path) -> None:
    data = db.read_bytes()
    p = tmp_path / "cut.db"
    p.write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError, match="cut.db"):
        with SceneReader.open(p) as r:
            list(r.cells())
            r.object_params(range(5))
            r.summary()


def test_corrupted_pages(db: Path, tmp_path: Path) -> None:
    data = bytearray(db.read_bytes())
    page = int.from_bytes(data[16:18], "big")
    rng = np.random.default_rng(0)
    for k in range(1, len(data) // page):
        for fill in (rng.bytes(page), bytes(page)):
            p = tmp_path / f"bad{k}.db"
            bad = bytearray(data)
            bad[k * page : (k + 1) * page] = fill
            p.write_bytes(bytes(bad))
            # without check=True, damage shows when the damaged part is read: as
            # StoreError, or CodecError for a damaged blob; both InputError naming the file
            with pytest.raises(InputError, match=f"bad{k}.db"):
                with SceneReader.open(p) as r:
                    list(r.cells())
                    for i in range(5):
                        r.building(i) if i < 3 else r.street(i)
                    r.viewpoints()
                    r.summary()
                    SceneReader.open(p, check=True).close()


def test_lookups_that_fail(reader: SceneReader) -> None:
    with pytest.raises(NotFoundError, match="no object 99"):
        reader.building(99)
    with pytest.raises(StoreError, match="is a street, not a building"):
        reader.building(3)
    with pytest.raises(StoreError, match="not a street piece"):
        reader.street(0)
    with pytest.raises(NotFoundError, match="no cell 9"):
        reader.cell(9)
    with pytest.raises(NotFoundError, match="no recorded path"):
        reader.path_blob("walk")


def test_writer_validation(tmp_path: Path, scene: Scene) -> None:
    with create(tmp_path / "v.db") as w:
        with pytest.raises(StoreError, match="kind"):
            w.add_cells([CellRow(0, "tunnel", _square(0, 0, 1), 0.0, 1.0, np.array([]))])
        with pytest.raises(StoreError, match="polygon"):
            w.add_cells([CellRow(0, "grid", np.zeros((2, 2)), 0.0, 1.0, np.array([]))])
        with pytest.raises(NotFoundError, match="no cell 5"):
            w.set_pvs(5, [1], [1.0])
        w.add_cells(scene.cells[:1])
        with pytest.raises(StoreError, match="repeat"):
            w.set_pvs(0, [1, 1], [1.0, 2.0])
        assert w.done_cells() == set()
    with pytest.raises(StoreError, match="settings"):
        create(tmp_path / "w.db", settings={"x": object()})
    with pytest.raises(StoreError, match="folder does not exist"):
        create(tmp_path / "missing" / "x.db")


# ---------------------------------------------------------------------------
# content hash and recorded paths
# ---------------------------------------------------------------------------


def test_content_hash_is_deterministic(tmp_path: Path, bake: Callable[..., str], db: Path) -> None:
    with SceneReader.open(db) as r:
        v1 = r.version
    # the same scene baked again, slower, elsewhere: same version
    assert bake(tmp_path / "again.db", bake_seconds=99.0) == v1
    # different content: different version
    assert bake(tmp_path / "other.db", name="other") != v1


def test_write_path(db: Path) -> None:
    old = SceneReader.open(db)
    v0 = old.version
    v1 = write_path(db, "walk", b"\x93\x01\x02\x03")
    assert v1 != v0 and len(v1) == 16
    with SceneReader.open(db) as r:
        assert r.version == v1
        assert r.path_names() == ["walk"] and r.path_blob("walk") == b"\x93\x01\x02\x03"
        assert r.summary()["paths"] == 1
    # a reader opened before keeps its consistent view of the old version
    assert old.version == v0 and old.path_names() == [] and len(list(old.cells())) == 4
    old.close()
    v2 = write_path(db, "drive", b"\x90")
    assert v2 not in (v0, v1)
    # replacing a path by the same bytes changes nothing
    assert write_path(db, "drive", b"\x90") == v2
    leftovers = [p.name for p in db.parent.iterdir() if ".tmp-" in p.name]
    assert leftovers == []


def test_concurrent_write_paths_all_land(db: Path) -> None:
    names = [f"walk{i}" for i in range(8)]
    with ThreadPoolExecutor(8) as pool:
        list(pool.map(lambda n: write_path(db, n, n.encode()), names))
    with SceneReader.open(db) as r:
        assert r.path_names() == names
        assert all(r.path_blob(n) == n.encode() for n in names)


def test_write_path_is_deterministic(tmp_path: Path, bake: Callable[..., str]) -> None:
    a, b = tmp_path / "a.db", tmp_path / "b.db"
    bake(a)
    bake(b, bake_seconds=7.0)
    assert write_path(a, "walk", b"xyz") == write_path(b, "walk", b"xyz")


def test_write_path_validation(db: Path, tmp_path: Path) -> None:
    before = db.read_bytes()
    for bad in ("", "a\nb", "x" * 201):
        with pytest.raises(StoreError, match="path name"):
            write_path(db, bad, b"")
    with pytest.raises(StoreError, match="expected bytes"):
        write_path(db, "walk", "not bytes")  # type: ignore[arg-type]
    noise = tmp_path / "noise.db"
    noise.write_bytes(os.urandom(300))
    with pytest.raises(StoreError, match="noise.db: not an SQLite"):
        write_path(noise, "walk", b"")
    assert db.read_bytes() == before
