"""The client caches (walkstream.client.stream.cache, .diskcache): the byte-budget LRU and the on-disk cache."""

from __future__ import annotations

import multiprocessing
import os
import sqlite3
import time
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from walkstream.client.stream.cache import Cache
from walkstream.client.stream.diskcache import KEEP_VERSIONS, DiskCache, safe_name
from walkstream.shared.errors import InputError

# ---------------------------------------------------------------------------
# Cache (memory)
# ---------------------------------------------------------------------------


def evict_log(cache_budget: int) -> tuple[Cache, list[tuple[str, int]]]:
    log: list[tuple[str, int]] = []
    return Cache(cache_budget, on_evict=lambda k, i: log.append((k, i))), log


def test_get_put_and_counters() -> None:
    c = Cache(100)
    assert c.get("params", 1) is None
    c.put("params", 1, "p1", 10)
    assert c.get("params", 1) == "p1" and c.peek("params", 1) == "p1"
    assert c.has("params", 1) and ("params", 1) in c and ("geom", 1) not in c
    assert c.hits["params"] == 1 and c.misses["params"] == 1
    # peek and has are not counted
    assert c.hits == {"index": 0, "cell": 0, "params": 1, "mesh": 0, "cellmesh": 0, "impostor": 0, "walltex": 0, "geom": 0}
    c.put("params", 1, "p1b", 30)  # replaced: bytes follow the new size
    assert c.bytes_used == 30 and c.peek("params", 1) == "p1b" and len(c) == 1
    assert c.size_of("params", 1) == 30 and c.size_of("geom", 1) is None
    s = c.stats()
    assert s["bytes_used"] == 30
    assert s["entries"] == {"index": 0, "cell": 0, "params": 1, "mesh": 0, "cellmesh": 0, "impostor": 0, "walltex": 0, "geom": 0}


def test_lru_order_within_a_kind() -> None:
    c, log = evict_log(30)
    for i in (1, 2, 3):
        c.put("geom", i, i, 10)
    assert c.get("geom", 1) == 1  # 1 is now the most recently used
    c.peek("geom", 2)  # a peek does not touch the order
    c.put("geom", 4, 4, 10)
    assert log == [("geom", 2)]
    c.put("geom", 5, 5, 10)
    assert log == [("geom", 2), ("geom", 3)]
    assert sorted(c.ids("geom")) == [1, 4, 5]


def test_geometry_goes_before_parameters_before_cells_before_index_tiles() -> None:
    c, log = evict_log(70)
    # oldest first: a tile, a cell, then params, then geometry; kind order beats age
    c.put("index", 1, "i", 10)
    c.put("cell", 1, "c", 10)
    c.put("params", 1, "p", 10)
    c.put("params", 2, "p", 10)
    c.put("geom", 1, "g", 10)
    c.put("geom", 2, "g", 10)
    c.put("cell", 2, "c", 10)
    assert log == []
    c.put("params", 3, "p", 25)
    assert log == [("geom", 1), ("geom", 2), ("params", 1)]
    c.put("cell", 3, "c", 20)
    assert log[3:] == [("params", 2), ("params", 3)]
    c.put("cell", 4, "c", 21)
    assert log[5:] == [("cell", 1)]
    c.put("index", 2, "i", 40)
    assert log[6:] == [("cell", 2), ("cell", 3), ("cell", 4)]
    c.put("index", 3, "i", 30)
    assert log[9:] == [("index", 1)]
    assert c.evictions == {"index": 1, "geom": 2, "params": 3, "mesh": 0, "cellmesh": 0, "impostor": 0, "walltex": 0, "cell": 4}
    assert c.bytes_used <= 70


def test_pinned_entries_are_never_evicted() -> None:
    c, log = evict_log(50)
    c.set_pinned(params_ids=[1], cell_ids=[7])
    c.put("cell", 7, "c7", 20)
    c.put("params", 1, "p1", 20)
    c.put("geom", 1, "g1", 20)  # pinned too (geometry of a pinned object)
    assert c.over_budget and c.over_budget_events == 1 and log == []
    c.put("geom", 2, "g2", 5)  # unpinned: goes at once, the pinned stay
    assert log == [("geom", 2)] and c.bytes_used == 60 and c.over_budget_events == 2
    assert c.pinned_bytes() == 60 and c.peak_bytes == 60
    # moving on: the old entries become evictable and the cache shrinks at once
    c.set_pinned(params_ids=[2], cell_ids=[8])
    assert not c.over_budget and c.bytes_used <= 50
    assert log[1:] == [("geom", 1)]
    assert c.pinned == {("params", 2), ("geom", 2), ("cell", 8)}


def test_index_tiles_and_cells_keep_a_reserve_when_the_pins_fill_the_budget() -> None:
    """Pinned entries alone over the budget: the small index tiles and cell records are
    kept up to the reserve (evicting them would not help, only cost round trips)."""
    c, log = evict_log(80)  # reserve 10 bytes
    c.set_pinned(params_ids=[1], cell_ids=[])
    c.put("params", 1, "p1", 100)
    c.put("index", 1, "i", 4)
    c.put("cell", 1, "c", 4)
    c.put("geom", 9, "g", 4)  # geometry still goes at once
    assert log == [("geom", 9)] and c.has("index", 1) and c.has("cell", 1)
    c.put("index", 2, "i", 4)  # 12 bytes of metadata: over the reserve
    assert log[1:] == [("cell", 1)] and c.has("index", 1) and c.has("index", 2)
    c.put("index", 3, "i", 4)
    assert log[2:] == [("index", 1)]
    c.set_pinned(params_ids=[], cell_ids=[])  # the pins go: back within the budget
    assert log[3:] == [("params", 1)] and c.bytes_used == 8
    with pytest.raises(InputError, match="metadata share"):
        Cache(10, metadata_share=1.5)


def test_pin_unpin_and_pin_before_arrival() -> None:
    c, log = evict_log(10)
    c.pin([("params", 5)])
    c.put("params", 5, "p5", 8)
    c.put("params", 6, "p6", 8)  # unpinned and over budget: evicted
    assert log == [("params", 6)] and c.has("params", 5)
    c.unpin([("params", 5)])
    assert c.has("params", 5)  # within budget, nothing to evict
    c.put("geom", 5, "g5", 8)
    assert log[1:] == [("geom", 5)]  # geometry before params, even the newest
    with pytest.raises(InputError, match="kind"):
        c.pin([("texture", 1)])


def test_on_evict_sees_the_updated_cache_and_remove() -> None:
    seen: list[bool] = []
    c = Cache(10)
    c.on_evict = lambda k, i: seen.append(c.has(k, i))
    c.put("geom", 1, "g", 10)
    c.put("geom", 2, "g", 10)
    assert seen == [False]
    assert c.remove("geom", 2) and not c.remove("geom", 2)
    assert seen == [False, False] and c.bytes_used == 0
    assert c.evictions["geom"] == 1  # a removal is not an eviction


def test_redownloads_and_rebuilds_are_counted() -> None:
    c = Cache(10)
    assert not c.note_download(1) and not c.note_build(1)
    c.put("params", 1, "p", 8)
    c.put("params", 2, "p", 8)  # evicts params 1
    assert not c.has("params", 1) and c.ever_had("params", 1)
    assert c.note_download(1) and c.redownloads == 1
    assert c.note_build(1) and c.note_build(1) and c.rebuilds == 2
    assert not c.note_download(2) and c.redownloads == 1
    assert not c.ever_had("geom", 1)


def test_bad_arguments() -> None:
    with pytest.raises(InputError, match="budget"):
        Cache(-1)
    c = Cache(10)
    with pytest.raises(InputError, match="kind"):
        c.put("texture", 1, "x", 1)
    with pytest.raises(InputError, match="size"):
        c.put("geom", 1, "x", -1)


_ops = st.lists(
    st.tuples(
        st.sampled_from(["put", "put", "put", "get", "pin", "unpin", "set_pinned", "remove"]),
        st.sampled_from(["cell", "params", "geom"]),
        st.integers(0, 6),
        st.integers(0, 40),
    ),
    max_size=60,
)


@settings(max_examples=150, deadline=None, derandomize=True, database=None)
@given(budget=st.integers(0, 100), ops=_ops)
def test_cache_invariants_under_random_operations(
    budget: int, ops: list[tuple[str, str, int, int]]
) -> None:
    model: dict[tuple[str, int], int] = {}
    bad: list[tuple[str, int]] = []
    c = Cache(budget)

    def gone(kind: str, oid: int) -> None:
        if (kind, oid) in c.pinned and not removing:
            bad.append((kind, oid))
        model.pop((kind, oid), None)

    c.on_evict = gone
    removing = False
    for op, kind, oid, n in ops:
        if op == "put":
            model[(kind, oid)] = n
            c.put(kind, oid, (kind, oid), n)
        elif op == "get":
            got = c.get(kind, oid)
            assert got == ((kind, oid) if (kind, oid) in model else None)
        elif op == "pin":
            c.pin([(kind, oid)])
        elif op == "unpin":
            c.unpin([(kind, oid)])
        elif op == "set_pinned":
            c.set_pinned(params_ids=range(oid, oid + n % 4), cell_ids=[oid])
        else:
            removing = True
            c.remove(kind, oid)
            removing = False
        # bytes_used is the sum of what is held, and what is held is what the model says
        held = {(k, i): c.size_of(k, i) for k in ("cell", "params", "geom") for i in c.ids(k)}
        assert held == model
        assert c.bytes_used == sum(model.values())
        assert not bad, f"pinned entries evicted: {bad}"
        # every pinned key that was put is still there
        assert all(c.has(k, i) for k, i in c.pinned if (k, i) in model)
        # over the budget only when nothing unpinned is left to evict but cell records
        # within the reserve
        unpinned_cells = sum(n for (k, i), n in model.items() if k == "cell" and (k, i) not in c.pinned)
        cells = sum(n for (k, _i), n in model.items() if k == "cell")
        assert (
            c.bytes_used <= budget
            or c.bytes_used == c.pinned_bytes()
            or (c.bytes_used == c.pinned_bytes() + unpinned_cells and cells <= budget / 8)
        )
        assert c.peak_bytes >= c.bytes_used


# ---------------------------------------------------------------------------
# DiskCache
# ---------------------------------------------------------------------------


def test_disk_cache_persists_across_open_and_close(tmp_path: Path) -> None:
    with DiskCache.open(tmp_path, "tiny", "v1") as d:
        assert d.available and d.get_cell(3) is None and d.get_objects([1, 2]) == {}
        assert d.put_cell(3, b"cell three") and d.put_index(-1, b"the whole index")
        assert d.put_objects({1: b"one", 2: b"two"}, "params")
        assert d.put_objects([(1, b"mesh one")], "lod2")
        assert d.path == tmp_path / "tiny" / "v1.sqlite"
    with DiskCache.open(tmp_path, "tiny", "v1") as d:
        assert d.get_cell(3) == b"cell three" and d.get_index(-1) == b"the whole index"
        assert d.get_index(7) is None
        assert d.get_objects([2, 1, 9, 1]) == {1: b"one", 2: b"two"}
        assert d.get_objects([1, 2], "lod2") == {1: b"mesh one"}
        # replacing keeps the byte count exact
        assert d.put_cell(3, b"x") and d.put_index(-1, b"idx")
        assert d.bytes_stored() == len(b"x") + 3 + 3 + 3 + len(b"mesh one")
        assert d.recovered == 0 and d.errors == 0


def test_disk_cache_versions_are_separate(tmp_path: Path) -> None:
    with DiskCache.open(tmp_path, "tiny", "v1") as d:
        d.put_objects({1: b"old"})
    with DiskCache.open(tmp_path, "tiny", "v2") as d:
        assert d.get_objects([1]) == {}
        d.put_objects({1: b"new"})
    with DiskCache.open(tmp_path, "tiny", "v1") as d:
        assert d.get_objects([1]) == {1: b"old"}
    with DiskCache.open(tmp_path, "other", "v1") as d:
        assert d.get_objects([1]) == {}


def test_manifest_is_per_scene(tmp_path: Path) -> None:
    d = DiskCache(tmp_path)
    assert d.manifest_etag("tiny") is None and not d.available
    assert d.put_manifest("tiny", '"v1-manifest-msgpack"', b"m1")
    d.use("tiny", "v1")
    d.use("tiny", "v2")  # switching versions keeps the manifest
    assert d.manifest_etag("tiny") == '"v1-manifest-msgpack"'
    assert d.put_manifest("tiny", '"v2-manifest-msgpack"', b"m2")
    assert DiskCache(tmp_path).get_manifest("tiny") == ('"v2-manifest-msgpack"', b"m2")
    assert d.manifest_etag("elsewhere") is None
    d.close()
    # a damaged manifest file reads as absent, never raises
    (tmp_path / "tiny" / "manifest.msgpack").write_bytes(b"\xc1garbage")
    assert d.get_manifest("tiny") is None and d.errors == 1


@pytest.mark.parametrize("damage", ["garbage", "foreign", "other version", "torn pages"])
def test_damaged_file_is_moved_aside_and_replaced(tmp_path: Path, damage: str) -> None:
    with DiskCache.open(tmp_path, "tiny", "v0") as d:
        d.put_objects({1: b"keep me"})
    path = tmp_path / "tiny" / "v1.sqlite"
    if damage == "garbage":
        path.write_bytes(b"this is not a database" * 100)
    elif damage == "foreign":
        conn = sqlite3.connect(path)
        conn.execute("CREATE TABLE objects (id INTEGER, params BLOB)")
        conn.commit()
        conn.close()
    elif damage == "other version":
        with DiskCache.open(tmp_path, "tiny", "v9") as d:
            d.put_objects({1: b"v9"})
        os.replace(tmp_path / "tiny" / "v9.sqlite", path)
    else:
        with DiskCache.open(tmp_path, "tiny", "v1") as d:
            d.put_objects({i: os.urandom(3000) for i in range(100)})
        raw = bytearray(path.read_bytes())
        assert len(raw) > 40_000
        raw[8192:40_000] = os.urandom(40_000 - 8192)  # keep the header, tear the pages
        path.write_bytes(bytes(raw))
    d = DiskCache.open(tmp_path, "tiny", "v1")
    assert d.available and d.recovered == 1
    assert (tmp_path / "tiny" / "v1.sqlite.corrupt-1").exists()
    assert d.get_objects([1]) == {} and d.put_objects({1: b"fresh"})
    assert d.get_objects([1]) == {1: b"fresh"}
    d.close()
    with DiskCache.open(tmp_path, "tiny", "v0") as d0:  # the other version is untouched
        assert d0.get_objects([1]) == {1: b"keep me"} and d0.recovered == 0


def test_damage_found_while_in_use_is_recovered(tmp_path: Path) -> None:
    d = DiskCache.open(tmp_path, "tiny", "v1")
    d.put_objects({1: b"one"})
    d._failed(sqlite3.DatabaseError("database disk image is malformed"))
    assert d.errors == 1 and d.available  # the file checked fine again: kept
    (tmp_path / "tiny" / "v1.sqlite").write_bytes(b"x" * 4096)
    d._failed(sqlite3.DatabaseError("file is not a database"))
    assert d.available and d.recovered == 1 and d.get_objects([1]) == {}
    d._failed(sqlite3.OperationalError("database is locked"))  # transient: nothing moved
    assert d.recovered == 1 and d.errors == 3
    d.close()


def test_unusable_directory_never_raises(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_bytes(b"")
    d = DiskCache.open(blocker, "tiny", "v1")
    assert not d.available and d.last_error and "cannot open" in d.last_error
    assert d.get_cell(1) is None and d.get_objects([1]) == {}
    assert not d.put_cell(1, b"x") and not d.put_objects({1: b"x"})
    assert d.get_index(1) is None and not d.put_index(1, b"x")
    assert not d.put_manifest("tiny", "e", b"m") and d.get_manifest("tiny") is None


def test_disk_cache_is_bounded(tmp_path: Path) -> None:
    with DiskCache.open(tmp_path, "tiny", "v1", max_bytes=1000) as d:
        assert d.put_objects({i: b"x" * 100 for i in range(9)})
        assert not d.full
        assert not d.put_objects({i: b"y" * 100 for i in range(9, 11)})
        assert d.full and d.bytes_stored() == 900
        assert d.get_objects([9, 10]) == {}  # all or nothing per call
        assert d.put_objects({0: b"z" * 50})  # a replacement that shrinks still fits
        assert d.bytes_stored() == 850
        assert d.put_objects([(1, b"a" * 10), (1, b"b" * 20)])  # repeats: the last wins
        assert d.bytes_stored() == 770 and d.get_objects([1]) == {1: b"b" * 20}


def test_old_versions_are_pruned(tmp_path: Path) -> None:
    t0 = time.time() - 1000
    d = DiskCache(tmp_path)
    for k in range(6):
        d.use("tiny", f"v{k}")
        d.put_objects({1: b"x"})
        os.utime(tmp_path / "tiny" / f"v{k}.sqlite", (t0 + k, t0 + k))
    # the next use prunes: the version in use counts as the newest
    d.use("tiny", "v1")
    left = sorted(p.name for p in (tmp_path / "tiny").glob("*.sqlite"))
    assert len(left) == KEEP_VERSIONS
    assert left == ["v1.sqlite", "v4.sqlite", "v5.sqlite"]
    assert not list((tmp_path / "tiny").glob("v0.sqlite*"))
    d.close()


def test_safe_names() -> None:
    assert safe_name("tiny") == "tiny"
    names = ["../etc", "a/b", "a_b", ".", "..", "", "Wien Innere Stadt", "a:b"]
    safe = [safe_name(n) for n in names]
    assert len(set(safe)) == len(safe)
    assert all("/" not in s and "." not in s and s for s in safe)


def _writer(root: str, worker: int, n: int) -> None:
    d = DiskCache.open(root, "tiny", "v1")
    assert d.available, d.last_error
    for i in range(n):
        # own ids and shared ones, one transaction each so the writers interleave
        assert d.put_objects({worker * 1000 + i: os.urandom(200), i: b"shared" * (worker + 1)})
        assert d.put_cell(i % 7, b"cell")
    d.close()


def test_two_processes_write_without_corruption(tmp_path: Path) -> None:
    ctx = multiprocessing.get_context("spawn")
    procs = [ctx.Process(target=_writer, args=(str(tmp_path), w, 300)) for w in (1, 2)]
    for p in procs:
        p.start()
    for p in procs:
        p.join(60)
    assert [p.exitcode for p in procs] == [0, 0]
    with DiskCache.open(tmp_path, "tiny", "v1") as d:
        assert d.recovered == 0
        got = d.get_objects([*range(1000, 1300), *range(2000, 2300), *range(300)])
        assert len(got) == 900
        assert d.get_cell(3) is not None
        conn = sqlite3.connect(d.path)  # type: ignore[arg-type]
        assert conn.execute("PRAGMA integrity_check").fetchone() == ("ok",)
        total = conn.execute(
            "SELECT (SELECT SUM(length(body)) FROM objects) + (SELECT SUM(length(body)) FROM cells)"
        ).fetchone()[0]
        conn.close()
        assert d.bytes_stored() == total
