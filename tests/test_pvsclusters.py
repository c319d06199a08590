"""Visibility-list clusters (m-LOMA): the codec, the growth, the bench on a baked city."""

from __future__ import annotations

from pathlib import Path

import msgpack
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from walkstream.server.bake.pvsclusters import ClusterSettings, cluster_lists
from walkstream.shared.codec.ints import pack_ints
from walkstream.shared.codec.pvs import ACH_UNITS, quantise_ach
from walkstream.shared.codec.pvsclusters import (
    clustered_cell_to_wire,
    decode_cluster,
    decode_clustered_cell,
    encode_cluster,
    expand_list,
)
from walkstream.shared.errors import CodecError
from walkstream.shared.wire import CellRecord, decode_cell

ID_SETS = st.sets(st.integers(0, 2**40), min_size=1, max_size=200)


def _grid(nx: int, ny: int) -> dict[int, list[int]]:
    """4-adjacency of an nx x ny grid of cells numbered row by row."""
    adj: dict[int, list[int]] = {}
    for j in range(ny):
        for i in range(nx):
            c = j * nx + i
            adj[c] = [
                j2 * nx + i2
                for i2, j2 in ((i - 1, j), (i + 1, j), (i, j - 1), (i, j + 1))
                if 0 <= i2 < nx and 0 <= j2 < ny
            ]
    return adj


@given(ID_SETS, st.integers(0, 2**31))
def test_cluster_record_round_trips(ids: set[int], cid: int) -> None:
    a = np.array(sorted(ids), np.int64)
    got_id, got = decode_cluster(encode_cluster(cid, a))
    assert got_id == cid and np.array_equal(got, a)
    assert not got.flags.writeable


@settings(max_examples=40, deadline=None)
@given(
    st.integers(2, 5),
    st.integers(1, 4),
    st.lists(st.sets(st.integers(0, 60), max_size=40), min_size=20, max_size=20),
    st.integers(1, 6),
)
def test_expanded_lists_are_the_cells_lists(nx: int, ny: int, sets: list[set[int]], min_objects: int) -> None:
    """Whatever the lists, each cell's clusters and rest are disjoint and give exactly its
    list, and its clustered record decodes to the delta-coded record's ids and ACH."""
    adj = _grid(nx, ny)
    pvs = {c: np.array(sorted(sets[c]), np.int64) for c in adj}
    lc = cluster_lists(pvs, adj, ClusterSettings(min_objects=min_objects, id_bytes=2.0, cluster_bytes=1.0))
    clusters = {k: decode_cluster(encode_cluster(k, v))[1] for k, v in lc.clusters.items()}
    rng = np.random.default_rng(len(sets[0]))
    for c, ids in pvs.items():
        assert np.array_equal(lc.expanded(c), ids)
        parts = [lc.rest[c], *(lc.clusters[int(k)] for k in lc.cell_clusters[c])]
        assert sum(map(len, parts)) == len(ids)
        ach = rng.uniform(0.01, 1.0, len(ids))
        rec = CellRecord(id=c, kind="street", pvs=ids, ach=ach)
        wire = rec.to_wire()
        body = msgpack.packb(clustered_cell_to_wire(wire, lc.cell_clusters[c], lc.rest[c]), use_bin_type=True)
        cid, got, units = decode_clustered_cell(body, clusters)
        assert cid == c and np.array_equal(got, ids)
        assert np.array_equal(units, quantise_ach(ach) if len(ids) else np.zeros(0, np.int64))


def test_shared_runs_become_one_cluster_and_records_shrink() -> None:
    """A row of cells that all see the same 40 objects (and a few of their own) shares them
    as one cluster named by every cell; the records with the cluster once are smaller, but
    each still carries its ACH of every object (the part no cluster can share)."""
    adj = _grid(8, 1)
    common = np.arange(100, 140)
    pvs = {c: np.union1d(common, [1000 + 3 * c, 1001 + 3 * c]) for c in adj}
    lc = cluster_lists(pvs, adj)
    assert len(lc.clusters) == 1 and np.array_equal(lc.clusters[0], common)
    assert all(lc.cell_clusters[c].tolist() == [0] for c in adj)
    clustered, delta = len(encode_cluster(0, lc.clusters[0])), 0
    for c, ids in pvs.items():
        wire = CellRecord(id=c, kind="street", pvs=ids, ach=np.linspace(1.0, 9.0, len(ids))).to_wire()
        delta += len(msgpack.packb(wire))
        cw = clustered_cell_to_wire(wire, lc.cell_clusters[c], lc.rest[c])
        assert cw["ach"] == wire["ach"]
        clustered += len(msgpack.packb(cw))
    assert clustered < 0.9 * delta


def test_no_shared_set_leaves_records_as_they_are() -> None:
    """Cells sharing fewer objects than the minimum get no cluster: their records are the
    delta-coded ones, byte for byte (no ``cl`` field)."""
    adj = _grid(3, 1)
    pvs = {0: np.array([1, 2, 3]), 1: np.array([3, 4]), 2: np.array([5])}
    lc = cluster_lists(pvs, adj)
    assert lc.clusters == {}
    for c, ids in pvs.items():
        wire = CellRecord(id=c, kind="grid", pvs=ids, ach=np.ones(len(ids))).to_wire()
        assert clustered_cell_to_wire(wire, lc.cell_clusters[c], lc.rest[c]) == wire
        assert np.array_equal(decode_cell(msgpack.packb(wire), "cell").pvs, ids)


def _record(cid: int, rest: list[int], cl: list[int] | None, units: list[int]) -> bytes:
    obj: dict[str, object] = {
        "id": cid, "kind": "street", "pvs": pack_ints(np.diff(rest, prepend=0).tolist()) if rest else [0, []],
        "ach": pack_ints(units),
    }
    if cl is not None:
        obj["cl"] = pack_ints(np.diff(cl, prepend=0).tolist())
    return msgpack.packb(obj, use_bin_type=True)


CLUSTERS = {0: np.array([10, 11, 12]), 1: np.array([12, 13]), 2: np.array([20])}


@pytest.mark.parametrize(
    ("body", "message"),
    [
        (_record(1, [1, 2], [5], [ACH_UNITS - 4, 1, 1, 1, 1]), "names cluster 5"),
        (_record(1, [1], [0, 1], [ACH_UNITS - 5, 1, 1, 1, 1, 1]), "in two of its clusters"),
        (_record(1, [10], [0], [ACH_UNITS - 2, 1, 1]), "in two of its clusters"),
        (_record(1, [1], [0], [ACH_UNITS]), "but 1 ach values"),
        (_record(1, [1], [0], [1, 1, 1, 1]), "sum to"),
        (_record(1, [1], [2, 2], [ACH_UNITS - 2, 1, 1]), "strictly ascending"),
        (msgpack.packb({"id": -1, "pvs": [0, []], "ach": [0, []]}), "non-negative"),
        (msgpack.packb({"id": 1, "ach": [0, []]}), "missing field 'pvs'"),
        (msgpack.packb([1, 2, 3]), "expected a map"),
        (b"\xc1", "cell"),
        (b"\xdd\xff\xff\xff\xff", "cell"),
    ],
)
def test_hostile_clustered_records_are_codec_errors(body: bytes, message: str) -> None:
    with pytest.raises(CodecError, match=message):
        decode_clustered_cell(body, CLUSTERS, "cell")


def test_expansion_is_bounded() -> None:
    with pytest.raises(CodecError, match="more than 4 objects"):
        expand_list([0, 1], np.array([1]), {0: np.arange(2), 1: np.arange(5, 8)}, "cell", max_objects=4)


@pytest.mark.parametrize(
    "body",
    [
        msgpack.packb({"id": 1, "pvs": [0, []]}),
        msgpack.packb({"id": 1, "pvs": [0, [5, 0]]}),
        msgpack.packb({"id": 1, "pvs": [9, b""]}),
        msgpack.packb({"id": "a", "pvs": [0, [1]]}),
        msgpack.packb({"id": 1, "pvs": [3, b"\xff\xff"]}),
        b"",
    ],
)
def test_hostile_cluster_records_are_codec_errors(body: bytes) -> None:
    with pytest.raises(CodecError):
        decode_cluster(body)


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=64))
def test_random_bytes_never_crash_the_decoders(data: bytes) -> None:
    for decode in (lambda b: decode_cluster(b), lambda b: decode_clustered_cell(b, CLUSTERS)):
        try:
            decode(data)
        except CodecError:
            pass


@pytest.mark.gl
def test_bench_on_a_baked_city(tmp_path: Path, gl_ctx: object) -> None:
    """The bench on a real bake: every clustered record decodes to its cell's PVS and ACH
    (checked inside), the figures add up, and an old database is left as it was."""
    from walkstream.benchmarks.clusters import format_clusters_table, run_clusters_bench
    from walkstream.server.bake import BakeSettings, bake
    from walkstream.server.sources.citygen import write_city

    src = tmp_path / "city.geojson"
    write_city(src, 150, 2)
    db = tmp_path / "city.db"
    bake(src, db, settings=BakeSettings(resolution=32))
    before = db.read_bytes()
    (row,) = run_clusters_bench([db])
    assert db.read_bytes() == before
    assert row["cells"] > 5 and row["delta_bytes"] > 0
    assert row["delta_ids"] + row["delta_ach"] < row["delta_bytes"]
    assert row["walks"] and all(w["cells"] >= 1 for w in row["walks"])
    for w in row["walks"]:
        assert min(w["delta"], w["delta_gz"], w["delta_gz4"], w["clustered"], w["ids_gz"], w["ach_gz"]) > 0
    table = format_clusters_table([row])
    assert "| city | " in table and "one stream" in table and "batches of 4" in table

    from walkstream.cli import main

    png = tmp_path / "clusters.png"
    assert main(["bench", "clusters", str(db), "--plot", str(png)]) == 0
    assert png.stat().st_size > 1000
    assert main(["bench", "clusters", str(db), "--min-objects", "0"]) == 2
    assert main(["bench", "clusters", str(tmp_path / "missing.db")]) == 2
    assert main(["bench", "clusters", str(src)]) == 2  # not a database: one line, no traceback
    assert db.read_bytes() == before


def test_bench_refuses_a_scene_without_pvs_cells(office_db: Path) -> None:
    """An interior (room cells, portals) has no visibility list to cluster: a clear error."""
    from walkstream.benchmarks.clusters import run_clusters_bench
    from walkstream.shared.errors import InputError

    with pytest.raises(InputError, match="no cell with a PVS"):
        run_clusters_bench([office_db])
