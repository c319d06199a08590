"""A city start bundle's first view (``server/service/streetheads.py``,
``shared/codec/objectboxes.py``): the objects the first pose draws first, boxes standing
in for the first cell's others; the client waits only for what its frustum keeps."""

from __future__ import annotations

import asyncio
import csv
import json
from pathlib import Path
from typing import Any

import httpx
import msgpack
import numpy as np
import pytest

from walkstream.cli import main
from walkstream.client.clock import SimClock
from walkstream.client.net.api import SceneClient
from walkstream.client.rewrite.geometry import rebuild
from walkstream.client.stream.cache import Cache
from walkstream.client.stream.streamer import Streamer, StreamerConfig
from walkstream.client.walk.measure import unseen_stand_ins
from walkstream.server.service.main import create_app
from walkstream.server.service.streetheads import object_boxes_body
from walkstream.server.store.reader import SceneReader
from walkstream.shared.buildings import default_grammar
from walkstream.shared.camera import camera, perspective
from walkstream.shared.codec.objectboxes import decode_object_boxes, encode_object_boxes
from walkstream.shared.errors import CodecError
from walkstream.shared.frustum import frustum_cull
from walkstream.shared.paths import RecordedPath
from walkstream.shared.startwire import decode_start_part
from walkstream.shared.wire import decode_cell


def test_boxes_round_trip_widened_outward() -> None:
    rng = np.random.default_rng(3)
    ids = np.array([907, 3, 40, 41])
    lo = rng.uniform(-500, 500, (4, 3))
    hi = lo + rng.uniform(0.0, 30.0, (4, 3))
    hi[1] = lo[1]  # a flat box
    got = decode_object_boxes(encode_object_boxes(ids, lo, hi))
    order = np.argsort(ids)
    assert got.ids.tolist() == [3, 40, 41, 907]
    assert np.all(got.lo <= lo[order]) and np.all(got.hi >= hi[order])
    assert np.all(lo[order] - got.lo < 1.0) and np.all(got.hi - hi[order] < 1.0)
    empty = decode_object_boxes(encode_object_boxes([], np.zeros((0, 3)), np.zeros((0, 3))))
    assert len(empty.ids) == 0


@pytest.mark.parametrize("ids, lo, hi", [
    ([1, 1], np.zeros((2, 3)), np.ones((2, 3))),  # an id twice
    ([-1], np.zeros((1, 3)), np.ones((1, 3))),  # a negative id
    ([1], np.ones((1, 3)), np.zeros((1, 3))),  # inside out
    ([1], np.full((1, 3), np.nan), np.ones((1, 3))),  # not finite
    ([1, 2], np.zeros((1, 3)), np.ones((1, 3))),  # shapes differ
])
def test_bad_boxes_are_refused(ids: list[int], lo: Any, hi: Any) -> None:
    with pytest.raises(CodecError):
        encode_object_boxes(ids, lo, hi)


@pytest.mark.parametrize("body", [b"", b"\x05\x01", b"\x02" + b"\x01" * 7 + b"\x00" + b"\x01" * 6, b"\xff"])
def test_damaged_boxes_say_so(body: bytes) -> None:
    with pytest.raises(CodecError):
        decode_object_boxes(body, "boxes")


def test_a_missing_object_out_of_view_is_not_waited_for() -> None:
    vp = perspective(60.0, 4 / 3, 0.5, 2000.0).astype(np.float64) @ camera(np.zeros(3), 0.0).astype(np.float64)
    boxes = {1: (np.array([10.0, -1, 0]), np.array([12.0, 1, 5])),  # ahead (+x)
             2: (np.array([-12.0, -1, 0]), np.array([-10.0, 1, 5])),  # behind
             3: (np.array([-1.0, 10, 0]), np.array([1.0, 12, 5]))}  # to the left, out of the frustum
    cache = Cache(1 << 20)
    assert unseen_stand_ins([1, 2, 3, 4], boxes, cache, vp) == {2, 3}
    assert unseen_stand_ins([1, 2, 3], {}, cache, vp) == set()


def _bundle(app: Any, url: str) -> list[tuple[str, Any]]:
    async def go() -> bytes:
        async with httpx.AsyncClient(transport=httpx.ASGITransport(app=app), base_url="http://t") as c:
            r = await c.get(url)
            assert r.status_code == 200
            return r.content

    out: list[tuple[str, Any]] = []
    left = 0
    u = msgpack.Unpacker(raw=False)
    u.feed(asyncio.run(go()))
    for o in u:
        if left:
            out.append(("object", o["id"]))
            left -= 1
            continue
        part, _etag, body = decode_start_part(o, "bundle")
        if part == "objects":
            assert isinstance(body, int)
            left = body
        out.append((part, body))
    return out


def test_the_first_view_comes_first_and_boxes_stand_in_for_the_rest(small_city_db: Path) -> None:
    app = create_app([small_city_db])
    try:
        plain = _bundle(app, "/v1/start?path=SE")
        first = _bundle(app, "/v1/start?path=SE&view=640x480&heads=true")
    finally:
        app.state.scenes.close()
    names = [n for n, _ in first]
    assert "boxes" not in [n for n, _ in plain]
    # the same records and objects, in another order: the path, the first cell's record
    # and tile, the manifest, the objects drawn, the boxes, then the rest
    same = [sorted(str(p) for p in b if p[0] not in ("boxes", "objects")) for b in (plain, first)]
    assert same[0] == same[1]
    assert names[:4] == ["path", "cell", "index", "manifest"] and names[4] == "objects"
    k = names.index("boxes")
    drawn = [b for n, b in first[:k] if n == "object"]
    boxes = decode_object_boxes(first[k][1])
    cell = decode_cell(first[1][1], "cell")
    assert sorted(drawn + boxes.ids.tolist()) == sorted(cell.pvs.tolist()) and drawn and len(boxes.ids)
    with SceneReader.open(small_city_db) as r:
        p = RecordedPath.from_msgpack(r.path_blob("SE"), "SE")
        info = r.object_info(cell.pvs.tolist())
    xyz, yaw, pitch = p.at(0.0)
    vp = perspective(60.0, 640 / 480, 0.5, 2000.0).astype(np.float64) @ camera(np.asarray(xyz), yaw, pitch).astype(
        np.float64)
    stored = np.array([info[i].bbox for i in boxes.ids.tolist()])
    # each box holds the stored one; the client's frustum drops every box as it decodes
    # them (the server kept what the client keeps)
    assert np.all(boxes.lo <= stored[:, :3]) and np.all(boxes.hi >= stored[:, 3:])
    assert not frustum_cull(boxes.lo, boxes.hi, vp).any()


@pytest.mark.gl  # the truth draws
def test_a_city_walk_waits_for_what_its_first_view_draws_and_hides_nothing(
    crossing_scene: tuple[Path, dict[str, Any], Path], tmp_path: Path, gl_ctx: object
) -> None:
    db, out = crossing_scene[2] / "city.db", tmp_path / "first"  # the 250 m city alone
    # 2 kB/s: the generated city's objects (about 50 bytes each) take seconds, as Kouvola's do at 5 kB/s
    main(["replay", str(db), "--path", "SE", "--bandwidth", "2kB/s", "--rtt", "500ms", "--clock", "sim",
          "--size", "160x120", "--device", "desktop2003", "--duration", "5s", "--truth-every", "5",
          "--report", str(out), "--no-plots"])
    first = json.loads((out / "report.json").read_text())
    # the walker stood at its start for its first view, with boxes for the objects it does not draw
    assert first["start_hold_s"] > 0 and first["start_boxes"] > 0
    # every compared frame the client called perfect shows every object the truth shows
    with (out / "frames.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    perfect = [int(r["cell"]) >= 0 and min(float(r["download_quality"]), float(r["rewrite_quality"])) >= 1 - 1e-9
               for r in rows]
    with (out / "truth.csv").open() as fh:
        truth = list(csv.DictReader(fh))
    compared = [r for r in truth if perfect[int(r["frame"])]]
    assert compared and all(float(r["not_received"]) + float(r["not_built"]) == 0.0 for r in compared)


def test_a_box_sent_holds_what_the_client_rebuilds(small_city_db: Path) -> None:
    app = create_app([small_city_db])
    try:
        scene = app.state.scenes.get("city")
        with SceneReader.open(small_city_db) as r:
            ids = r.object_ids().tolist()
            info = r.object_info(ids)
            params = {i: r.building(i) if info[i].kind == "building" else
                      r.area(i) if info[i].kind == "area" else r.street(i) for i in ids}
        boxes = decode_object_boxes(object_boxes_body(scene, ids))
    finally:
        app.state.scenes.close()
    grammar = default_grammar()
    assert {info[i].kind for i in ids} >= {"building", "street"}
    for k, oid in enumerate(boxes.ids.tolist()):
        g = rebuild(oid, params[oid], grammar)
        assert np.all(boxes.lo[k] <= g.bbox_min) and np.all(boxes.hi[k] >= g.bbox_max), (oid, info[oid].kind)


@pytest.mark.parametrize("query", ["path=drive", "path=drive&view=640x480&heads=true"])
def test_a_record_whose_objects_the_bundle_does_not_bring_says_so(small_city_db: Path, query: str) -> None:
    """The bundle's records reach further than its objects (the cells of the next seconds
    after the first three): those records come as ``record`` parts, so that the client
    asks for their objects itself instead of waiting for a bundle that never brings them."""
    app = create_app([small_city_db])
    try:
        parts = _bundle(app, f"/v1/start?{query}")
    finally:
        app.state.scenes.close()
    brought = {b for n, b in parts if n == "object"}
    recs = {n: [decode_cell(b, n) for p, b in parts if p == n] for n in ("cell", "record")}
    assert recs["cell"] and recs["record"]  # at 50 km/h the records reach past the objects
    for rec in recs["cell"]:
        assert set(rec.pvs.tolist()) <= brought  # a cell part: all its objects come
    for rec in recs["record"]:
        assert not set(rec.pvs.tolist()) <= brought  # a record part: some never come


def test_the_client_holds_as_coming_only_what_the_bundle_brings(small_city_db: Path) -> None:
    """While the bundle runs, the objects it is expected to bring count as in flight (the
    streamer does not ask for them); those of a ``record`` part's cell are not among them,
    so the streamer asks for them by their need time instead of waiting for the bundle's end."""
    app = create_app([small_city_db])
    brought = {b for n, b in _bundle(app, "/v1/start?path=drive") if n == "object"}

    async def go() -> set[int]:
        clock = SimClock()
        async with httpx.AsyncClient(transport=httpx.ASGITransport(app=app), base_url="http://t") as http:
            st = Streamer(SceneClient(http, clock, "city"), clock, Cache(64 << 20), StreamerConfig())
            coming: list[set[int]] = []

            def at_manifest(_m: object) -> None:  # every record is in, no object yet (the plain order)
                assert st.start_feed.bundle is not None
                coming.append(set(st.start_feed.bundle.ids))

            task = st.start_feed.start_bundle("drive", lambda _p, _n: None, at_manifest, lambda _e: None)
            await task
            await st.close()
            return coming[0]

    try:
        coming = asyncio.run(go())
    finally:
        app.state.scenes.close()
    assert coming == brought  # all of it comes, and nothing else is waited for
