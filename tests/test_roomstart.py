"""The interior walk's start: the compact path, the compact topology, the interior start bundle.

One small generated office (two storeys), baked once per module.
"""

from __future__ import annotations

import asyncio
import zlib
from pathlib import Path
from typing import Any

import httpx
import msgpack
import numpy as np
import pytest

from walkstream.client.config import ReplayConfig
from walkstream.client.net.link import LinkProfile
from walkstream.client.replay import run_replay
from walkstream.server.bake import bake
from walkstream.server.service.main import create_app
from walkstream.server.sources.interiorgen import InteriorPlan, write_interior
from walkstream.server.store import SceneReader
from walkstream.shared.codec.cellbatch import check_contents_part
from walkstream.shared.codec.cellmesh import decode_cell_mesh
from walkstream.shared.codec.contentspack import is_pack, unpack_parts
from walkstream.shared.codec.rawlzma import compress_raw, decompress_raw
from walkstream.shared.errors import CodecError
from walkstream.shared.pathcodec import (
    PATH_Q_MAGIC,
    PATH_Q_MEDIA,
    decode_path_any,
    decode_path_q,
    encode_path_q,
    head_path_q,
    path_error_bound,
)
from walkstream.shared.paths import RecordedPath, wrap_angle
from walkstream.shared.portalgraph import PortalGraph
from walkstream.shared.roomcompact import (
    TOPOLOGY_COMPACT_MAGIC,
    TOPOLOGY_COMPACT_MEDIA,
    decode_topology_compact,
    encode_topology_compact,
)
from walkstream.shared.roomview import RoomLocator, RoomView, cell_of, cells_seen, stack_planes
from walkstream.shared.roomwire import Topology, decode_topology, decode_topology_packed
from walkstream.shared.startwire import decode_start_part

MODEM = LinkProfile(56_000.0, 56_000.0, 0.2)


@pytest.fixture(scope="module")
def office(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("roomstart")
    write_interior(d / "office.json", InteriorPlan(storeys=2, length=16, width=14, seed=5))
    bake(d / "office.json", d / "office.db")
    return d / "office.db"


@pytest.fixture(scope="module")
def tour(office: Path) -> RecordedPath:
    with SceneReader.open(office) as db:
        return RecordedPath.from_msgpack(db.path_blob("tour"), "tour")


def _get(app: Any, url: str, **headers: str) -> httpx.Response:
    async def go() -> httpx.Response:
        async with httpx.AsyncClient(transport=httpx.ASGITransport(app=app), base_url="http://t") as c:
            return await c.get(url, headers=headers)

    return asyncio.run(go())


def _one_line(exc: pytest.ExceptionInfo[CodecError], *words: str) -> None:
    msg = str(exc.value)
    assert "\n" not in msg and all(w in msg for w in words), msg


# -- the compact path ----------------------------------------------------------


def test_compact_path_round_trips_within_its_bound(tour: RecordedPath) -> None:
    blob = encode_path_q(tour)
    assert blob[:4] == PATH_Q_MAGIC and len(blob) < len(tour.to_msgpack()) / 4
    back = decode_path_q(blob, "tour")
    bound = np.asarray(path_error_bound(blob))
    assert bound.tolist() == [5e-4] * 4 + [1.5e-3, 5e-4]
    err = np.abs(back.table() - tour.table()).max(axis=0)
    assert (err <= bound + 1e-12).all(), err
    assert back.name == tour.name and back.speed_kmh == tour.speed_kmh
    assert decode_path_any(tour.to_msgpack(), "tour") == tour  # the old encoding still reads
    # key points closer than the time step: the step halves, times keep increasing
    rng = np.random.default_rng(3)
    t = np.cumsum(np.r_[0.0, rng.uniform(1e-4, 3e-4, 40)])
    dense = RecordedPath("dense", t, rng.normal(0, 50, (41, 3)), rng.uniform(-3, 3, 41), rng.uniform(-0.2, 0.2, 41))
    blob = encode_path_q(dense)
    back = decode_path_q(blob)
    assert path_error_bound(blob)[0] < 1e-4 and (np.diff(back.t) > 0).all()
    err = np.abs(back.table() - dense.table()).max(axis=0)
    assert (err <= np.asarray(path_error_bound(blob)) + 1e-12).all()


def test_compact_path_keeps_the_direction_of_every_turn() -> None:
    # U-turns of exactly half a circle, on the spot and walking, from yaws whose
    # rounding would tip half of them the other way round
    rng = np.random.default_rng(5)
    y0 = rng.uniform(-np.pi, np.pi, 200)
    yaw = np.column_stack([y0, y0 + np.pi, y0 + np.pi, y0, y0 + 0.5 * np.pi]).reshape(-1)
    n = len(yaw)
    xyz = np.column_stack([np.repeat(np.arange(n // 5), 5) % 2, np.zeros(n), np.full(n, 1.6)])
    path = RecordedPath("u", np.arange(n, dtype=float), xyz, wrap_angle(yaw), np.zeros(n))
    blob = encode_path_q(path)
    back = decode_path_q(blob)
    turns, got = wrap_angle(np.diff(path.yaw)), wrap_angle(np.diff(back.yaw))
    assert np.array_equal(np.sign(turns), np.sign(got))
    assert np.abs(wrap_angle(back.yaw - path.yaw)).max() <= path_error_bound(blob)[4] + 1e-12
    # the same through the interpolation the walk samples: halfway through each half turn
    mid = np.arange(n - 1) + 0.5
    assert np.abs(wrap_angle(path.sample(mid)[1] - back.sample(mid)[1])).max() < 2e-3


def test_a_paths_head_decodes_exactly_as_the_whole_paths_first_samples(tour: RecordedPath) -> None:
    # odd steps and a halved time step too: the head re-rounds nothing
    for steps in ((1e-3,) * 6, (0.007, 0.003, 0.003, 0.01, 0.002, 0.05)):
        blob = encode_path_q(tour, steps)
        whole = decode_path_q(blob)
        for s in (0.0, 1.0, 2.5, whole.duration / 2):
            head = decode_path_q(head_path_q(blob, s) or b"")
            k = len(head)
            assert k >= 2 and head.t[-1] >= min(s, whole.duration) and (k == 2 or head.t[-2] < s)
            assert head == RecordedPath(whole.name, whole.t[:k], whole.xyz[:k], whole.yaw[:k], whole.pitch[:k],
                                        whole.speed_kmh)
            assert len(head_path_q(blob, s) or b"") < len(blob)
        assert head_path_q(blob, whole.duration) is None  # the head would be the whole path
    with pytest.raises(CodecError) as exc:
        head_path_q(b"WSPQ\x01junk", 1.0, "path 'x'")
    _one_line(exc, "path 'x'")


def test_bad_compact_paths_are_one_line_codec_errors(tour: RecordedPath) -> None:
    blob = encode_path_q(tour)
    with pytest.raises(CodecError) as e:
        decode_path_q(blob[:-7], "p")
    _one_line(e, "p:", "truncated")
    with pytest.raises(CodecError) as e:  # a zlib bomb: 200 MB of zeros in 200 kB
        decode_path_q(PATH_Q_MAGIC + b"\x01" + zlib.compress(b"\0" * (200 << 20), 9), "p")
    _one_line(e, "inflates to more than")
    body = msgpack.unpackb(zlib.decompress(blob[5:]))
    for change, words in (({"n": body["n"] + 1}, ("holds", "expected")), ({"n": 1}, ("n:",)),
                          ({"steps": [1e-3] * 5}, ("steps",)), ({"d": body["d"][:-1]}, ("d",))):
        bad = PATH_Q_MAGIC + b"\x01" + zlib.compress(msgpack.packb({**body, **change}))
        with pytest.raises(CodecError) as e:
            decode_path_q(bad, "p")
        _one_line(e, *words)
    with pytest.raises(CodecError) as e:
        decode_path_q(blob[:4] + b"\x07" + blob[5:], "p")
    _one_line(e, "version 7")
    with pytest.raises(CodecError) as e:
        decode_path_q(b"nope", "p")
    _one_line(e, "not a compact path")


# -- the compact topology ------------------------------------------------------


def _topologies(office: Path) -> tuple[Topology, Topology, bytes, bytes]:
    app = create_app([office])
    try:
        full = decode_topology(_get(app, "/v1/scenes/office/topology").content, "t")
        packed = _get(app, "/v1/scenes/office/topology/packed").content
        r = _get(app, "/v1/scenes/office/topology/compact")
        assert r.headers["content-type"] == TOPOLOGY_COMPACT_MEDIA and "immutable" in r.headers["cache-control"]
        assert _get(app, "/v1/scenes/office/topology/compact", **{"if-none-match": r.headers["etag"]}).status_code == 304
        assert r.headers["etag"] != _get(app, "/v1/scenes/office/topology/packed").headers["etag"]
        old = decode_topology_packed(packed, "t")  # the old routes keep working
        assert [c.id for c in old.cells] == [c.id for c in full.cells]
        assert all(np.array_equal(a.planes, b.planes) for a, b in zip(old.cells, full.cells, strict=True))
        return full, decode_topology_compact(r.content, "t"), r.content, packed
    finally:
        app.state.scenes.close()


def test_compact_topology_is_exact_enough(office: Path, tour: RecordedPath) -> None:
    full, compact, body, packed = _topologies(office)
    assert body[:4] == TOPOLOGY_COMPACT_MAGIC and len(body) < 0.6 * len(packed)
    assert compact.nbytes == len(body) and compact.storeys == full.storeys
    for a, b in zip(full.cells, compact.cells, strict=True):
        assert (a.id, a.kind, a.storey, a.neighbours) == (b.id, b.kind, b.storey, b.neighbours)
        assert b.name == ""  # version 4 leaves the names out (GET .../topology has them)
        assert np.abs(a.outline - b.outline).max() <= 5e-4 and abs(a.zmin - b.zmin) <= 5e-4
        assert a.planes.shape == b.planes.shape and np.allclose(a.planes, b.planes, rtol=0, atol=1e-6)
        assert a.contents.triangles == b.contents.triangles and a.contents.nbytes == b.contents.nbytes
    # portal polygons never shrink: each coordinate moves away from the centroid (or
    # stays, on the wall's plane), by a millimetre at most
    for (pid, kind, a, b, poly), (qid, qkind, qa, qb, q) in zip(full.portals, compact.portals, strict=True):
        assert (pid, kind, a, b) == (qid, qkind, qa, qb)
        c = poly.mean(axis=0)
        moved = (q - poly) * np.sign(poly - c)
        assert (moved >= -1e-6).all() and np.abs(q - poly).max() <= 1e-3 + 1e-9
    for s, t in zip(full.stairs, compact.stairs, strict=True):
        assert s[:3] == t[:3] and np.abs(s[3] - t[3]).max() <= 5e-4
    # cell location unchanged: along the tour and at random points in the building
    rng = np.random.default_rng(1)
    eyes = np.concatenate([
        tour.sample(np.arange(0.0, tour.duration, 0.05))[0],
        rng.uniform([-12, -12, 0], [12, 12, 8], (4000, 3)),
    ])

    def locate(t: Topology) -> list[tuple[int, ...]]:
        ids, planes = stack_planes([c for c in t.cells if c.kind != "outside"])
        return [tuple(ids[cell_of(planes, e)].tolist()) for e in eyes]

    assert locate(full) == locate(compact)


def test_bad_compact_topologies_are_one_line_codec_errors(office: Path) -> None:
    full, _, body, _ = _topologies(office)
    assert encode_topology_compact(full) == body
    with pytest.raises(CodecError) as e:
        decode_topology_compact(body[:-9], "t")
    _one_line(e, "t:", "truncated")
    with pytest.raises(CodecError) as e:
        decode_topology_compact(TOPOLOGY_COMPACT_MAGIC + b"\x02" + zlib.compress(b"\0" * (80 << 20), 9), "t")
    _one_line(e, "inflates to more than")
    with pytest.raises(CodecError) as e:  # version 3, LZMA
        decode_topology_compact(body[:5] + compress_raw(b"\0" * (80 << 20)), "t")
    _one_line(e, "more than")
    obj = msgpack.unpackb(decompress_raw(body[5:], "t", 1 << 24), strict_map_key=False)
    cells = obj["cells"]
    bad_n = {**obj, "cells": {**cells, "n": [n + 1 for n in cells["n"]]}}
    bad_names = {**obj, "cells": {**cells, "name": [c.name for c in full.cells][:-1]}}
    bad_outline = {**obj, "cells": {**cells, "outline": [o[:-1] for o in cells["outline"]]}}
    for o, words in ((bad_n, ("vertices", "n says")), (bad_names, ("cells.name", "expected")),
                     (bad_outline, ("outline",)), ({**obj, "kinds": None}, ("t:",))):
        with pytest.raises(CodecError) as e:
            decode_topology_compact(TOPOLOGY_COMPACT_MAGIC + b"\x02" + zlib.compress(msgpack.packb(o)), "t")
        _one_line(e, *words)
    with pytest.raises(CodecError) as e:
        decode_topology_compact(b"WSTC\x01" + body[5:], "t")
    _one_line(e, "version 1")


# -- the interior start bundle -------------------------------------------------


def _parts(r: httpx.Response) -> list[tuple[str, str | None, bytes]]:
    assert r.status_code == 200, r.text
    out = []
    for obj in _unpack(r.content):
        part, etag, body = decode_start_part(obj, "bundle")
        assert isinstance(body, bytes)
        out.append((part, etag, body))
    return out


def _unpack(content: bytes) -> list[Any]:
    u = msgpack.Unpacker(raw=False)
    u.feed(content)
    return list(u)


def test_the_interior_start_bundle_brings_path_topology_and_manifest(office: Path) -> None:
    app = create_app([office])
    try:
        parts = _parts(_get(app, "/v1/scenes/office/start?path=tour"))
        assert [p for p, _, _ in parts] == ["path", "topology", "manifest"]
        # each body (and ETag) as its own endpoint sends it
        own = {
            "path": _get(app, "/v1/scenes/office/paths/tour", accept=PATH_Q_MEDIA),
            "topology": _get(app, "/v1/scenes/office/topology/compact"),
            "manifest": _get(app, "/v1/scenes/office"),
        }
        for part, etag, body in parts:
            assert body == own[part].content and etag == own[part].headers["etag"], part
        assert own["path"].headers["content-type"] == PATH_Q_MEDIA
        # /v1/start picks the (only) scene; JSON for people
        assert _parts(_get(app, "/v1/start?path=tour")) == parts
        js = _get(app, "/v1/start?path=tour", accept="application/json").json()
        assert [p["part"] for p in js] == ["path", "topology", "manifest"] and js[1]["body"]["cells"]
        # an unknown path: a 404 that names it, not a 500
        r = _get(app, "/v1/scenes/office/start?path=nope")
        assert r.status_code == 404 and "'nope'" in r.json()["error"]
    finally:
        app.state.scenes.close()


class _NoBundle(httpx.AsyncBaseTransport):
    """The app behind a server that has no start bundle (404 on ``.../start``)."""

    def __init__(self, inner: httpx.AsyncBaseTransport) -> None:
        self.inner = inner

    async def handle_async_request(self, request: httpx.Request) -> httpx.Response:
        if request.url.path.endswith("/start"):
            return httpx.Response(404, json={"error": "no start bundle here"})
        return await self.inner.handle_async_request(request)


class _Seen(httpx.AsyncBaseTransport):
    """The app, noting each request's path."""

    def __init__(self, inner: httpx.AsyncBaseTransport, seen: list[str]) -> None:
        self.inner, self.seen = inner, seen

    async def handle_async_request(self, request: httpx.Request) -> httpx.Response:
        self.seen.append(request.url.path)
        return await self.inner.handle_async_request(request)


def _replay(office: Path, no_bundle: bool = False, cut: int = 0, seen: list[str] | None = None,
            **kw: Any) -> dict[str, Any]:
    cfg = ReplayConfig(**{"link": MODEM, "device": "desktop2003", "path": "tour", "kind": "interior",
                          "duration_s": 3.0, **kw})
    app = create_app([office])
    try:
        inner: httpx.AsyncBaseTransport = httpx.ASGITransport(app=app)
        if no_bundle:
            inner = _NoBundle(inner)
        elif cut:
            inner = _CutBundle(inner, cut)
        if seen is not None:
            inner = _Seen(inner, seen)
        r = run_replay(inner, "http://walkstream.test", cfg)
        s: dict[str, Any] = r.summary
        s["first_bytes"] = int(r.log.bytes_down[0])  # what came down before the first frame
        assert r.log.t[0] == pytest.approx(s["setup_s"], abs=0.05)
        return s
    finally:
        app.state.scenes.close()


def test_the_interior_replay_starts_with_the_bundle_and_falls_back(office: Path) -> None:
    bundle = _replay(office)
    plain = _replay(office, start_bundle=False)
    refused = _replay(office, no_bundle=True)
    for s in (bundle, plain, refused):
        assert "error" not in s and s["frames"] > 0 and s["kind"] == "interior" and s["scene_version"]
        assert s["topology_bytes"] < 4000  # the compact topology, either way
    # one round trip instead of three in a row: the walk starts sooner
    assert bundle["setup_s"] + 0.3 < plain["setup_s"]
    assert bundle["requests"] < plain["requests"]
    # the bundle brings the first view's contents before the first frame (as deep as
    # the fog reaches), the plain start only what the walk starts with; the first
    # perfect frame comes sooner all the same
    assert bundle["start_contents_cells"] > 0
    assert bundle["time_to_first_perfect_frame_s"] < plain["time_to_first_perfect_frame_s"]
    # refused: the old sequence, one wasted round trip later
    assert refused["setup_s"] >= plain["setup_s"]
    assert refused["perfect_frame_ratio"] == pytest.approx(plain["perfect_frame_ratio"], abs=0.05)


# -- the first view's contents in the start bundle -------------------------------


def _items(r: httpx.Response) -> list[tuple[str, Any]]:
    """The bundle's parts, each contents part as ``("room", (cell, etag, body))``."""
    assert r.status_code == 200, r.text
    out: list[tuple[str, Any]] = []
    rooms: list[int] = []
    for obj in _unpack(r.content):
        if rooms:
            cid, etag, body = check_contents_part(obj, "bundle")
            assert cid == rooms.pop(0)
            out.append(("room", (cid, etag, body)))
            continue
        part, _etag, body = decode_start_part(obj, "bundle")
        if part == "contents":
            assert isinstance(body, list)
            rooms.extend(body)
        out.append((part, body))
    assert not rooms
    return out


def test_the_start_bundle_brings_what_the_first_view_sees(office: Path) -> None:
    app = create_app([office])
    try:
        for enc in ("gzip", "identity"):
            items = _items(_get(app, "/v1/scenes/office/start?path=tour&view=320x240&fov=60&fog=40",
                                **{"accept-encoding": enc}))
            names = [p for p, _ in items]
            assert names[:3] == ["path", "topology", "contents"] and names[-1] == "manifest"
            cells = items[2][1]
            assert cells and names[3:-1] == ["room"] * len(cells)
            # the cells the client's own culling keeps from the path's first pose come
            # first, in its order (the server culls the compact topology and path as sent)
            topo = decode_topology_compact(items[1][1], "topology")
            path = decode_path_q(items[0][1], "path")
            xyz, yaw, pitch = path.at(0.0)
            seen = cells_seen(PortalGraph.from_topology(topo), RoomLocator(topo.cells), [(xyz, yaw, pitch)],
                              RoomView((320, 240), 60.0, 40.0))[0]
            seen = [c for c in seen if topo.cells[[x.id for x in topo.cells].index(c)].contents.nbytes]
            assert cells[: len(seen)] == seen
            # each cell's contents as its own endpoint sends them (inflated when gzip is on)
            for _, (cid, etag, body) in items[3:-1]:
                own = _get(app, f"/v1/scenes/office/rooms/{cid}/contents", **{"accept-encoding": "identity"})
                assert etag == own.headers["etag"]
                a, b = decode_cell_mesh(body, "bundle"), decode_cell_mesh(own.content, "own")
                assert a.triangles == b.triangles and np.array_equal(a.parts[0].positions, b.parts[0].positions)
        # a narrower field of view and a nearer fog see no more
        narrow = _items(_get(app, "/v1/scenes/office/start?path=tour&view=320x240&fov=20&fog=5"))[2][1]
        assert set(narrow) <= set(cells) and len(narrow) < len(cells)
        # JSON for people: the contents part is the array of its cells' parts
        js = _get(app, "/v1/start?path=tour&view=320x240", accept="application/json").json()
        assert [p["part"] for p in js] == ["path", "topology", "contents", "manifest"]
        assert [c["cell"] for c in js[2]["body"]] == cells
        # without view= the bundle is as before (no contents)
        assert "contents" not in [p for p, _ in _items(_get(app, "/v1/start?path=tour"))]
        # head=: the path's head in place of the path; the rest unchanged
        split = _items(_get(app, "/v1/scenes/office/start?path=tour&view=320x240&fov=60&fog=40&head=1.5"))
        assert [p for p, _ in split] == ["pathhead", *names[1:]] and split[2][1] == cells
        head, whole = decode_path_q(split[0][1], "head"), decode_path_q(items[0][1], "path")
        assert 1.5 <= head.duration < whole.duration and np.array_equal(head.xyz, whole.xyz[: len(head)])
        assert len(split[0][1]) < len(items[0][1]) / 2
        # a head as long as the path, JSON, or no view: one whole path first, as before
        for url in ("/v1/start?path=tour&view=320x240&head=1e4", "/v1/start?path=tour&head=1.5"):
            assert _items(_get(app, url))[0][0] == "path"
        js = _get(app, "/v1/start?path=tour&view=320x240&head=1.5", accept="application/json").json()
        assert [p["part"] for p in js] == ["path", "topology", "contents", "manifest"]
    finally:
        app.state.scenes.close()


@pytest.mark.parametrize(
    "query, word",
    [("view=10x10", "view"), ("view=640", "view"), ("view=640x480&fov=500", "fov"),
     ("view=640x480&fog=-1", "fog"), ("view=640x480&depth=9999", "depth"), ("view=9999x480", "view"),
     ("view=640x480&head=-1", "head"), ("view=640x480&head=nan", "head")],
)
def test_a_bad_view_is_a_422_that_names_it(office: Path, query: str, word: str) -> None:
    app = create_app([office])
    try:
        r = _get(app, f"/v1/scenes/office/start?path=tour&{query}")
        assert r.status_code == 422 and word in r.text, r.text
    finally:
        app.state.scenes.close()


class _CutBundle(httpx.AsyncBaseTransport):
    """The app, but the start bundle's body stops after ``keep`` bytes (plain, not gzip)."""

    def __init__(self, inner: httpx.AsyncBaseTransport, keep: int) -> None:
        self.inner, self.keep = inner, keep

    async def handle_async_request(self, request: httpx.Request) -> httpx.Response:
        if not request.url.path.endswith("/start"):
            return await self.inner.handle_async_request(request)
        headers = [(k, v) for k, v in request.headers.raw if k.lower() != b"accept-encoding"]
        r = await self.inner.handle_async_request(httpx.Request(request.method, request.url, headers=headers))
        body = b"".join([c async for c in r.stream])  # type: ignore[union-attr]
        return httpx.Response(r.status_code, headers=r.headers, content=body[: self.keep])


def test_the_walk_starts_with_the_first_views_contents(office: Path, tour: RecordedPath) -> None:
    # every cell whole (heads, which send a cell twice, are tests/test_firstheads.py's)
    with_contents = _replay(office, start_heads=False)
    without = _replay(office, start_contents=False)
    headed = _replay(office)
    assert "error" not in headed and headed["redownloads"] == 0 and headed["perfect_frame_ratio"] > 0
    assert headed["time_to_first_perfect_frame_s"] < without["time_to_first_perfect_frame_s"]
    for s in (with_contents, without):
        assert "error" not in s and s["redownloads"] == 0 and s["perfect_frame_ratio"] > 0
    assert with_contents["start_contents_cells"] > 0 and without["start_contents_cells"] == 0
    # no round trip between the bundle and the first view's contents
    assert with_contents["time_to_first_perfect_frame_s"] < without["time_to_first_perfect_frame_s"]
    assert with_contents["contents_requests"] <= without["contents_requests"]
    # a bundle cut among the contents: the cells it did not bring are asked for, once
    app = create_app([office])
    try:
        # a head the walk outruns at once: the whole path is due
        url = "/v1/scenes/office/start?path=tour&view=640x480&head=0.2"
        whole = _items(_get(app, url, **{"accept-encoding": "identity"}))
        head = sum(len(msgpack.packb(o)) for o in _unpack(
            _get(app, url, **{"accept-encoding": "identity"}).content)[:5])
    finally:
        app.state.scenes.close()
    assert whole[0][0] == "pathhead" and len(whole[2][1]) > 2  # the cut falls among the contents
    cut = _replay(office, cut=head + 7, path_head_s=0.2, start_heads=False)
    assert "error" not in cut and cut["start_contents_cells"] == 2 and cut["redownloads"] == 0
    assert cut["perfect_frame_ratio"] > 0 and cut["scene_version"]  # the manifest came on its own
    # ... and the whole path by a request of its own: the walk's path is the tour
    assert cut["path_duration_s"] == pytest.approx(tour.duration, abs=1e-3)
    # a bundle cut just after a cell's head: the cell is asked for whole, once
    app = create_app([office])
    try:
        objs = _unpack(_get(app, url + "&heads=true", **{"accept-encoding": "identity"}).content)
    finally:
        app.state.scenes.close()
    # (or just after the first view's pack, which holds the heads: shared/codec/contentspack.py)
    k = next(i for i, o in enumerate(objs) if isinstance(o, dict) and ("missing" in o or is_pack(o)))
    inner = [o for o, _ in unpack_parts(objs[k])] if is_pack(objs[k]) else objs[3 : k + 1]
    cut = _replay(office, cut=sum(len(msgpack.packb(o)) for o in objs[: k + 1]) + 7, path_head_s=0.2,
                  start_pose=False)  # the stream as asked above (the posed start: tests/test_firstpose.py)
    assert "error" not in cut and cut["redownloads"] == 0
    assert cut["start_head_cells"] == sum("missing" in o for o in inner) >= 1
    # the heads' cells are counted when whole, so not here: they are asked for again
    assert cut["start_contents_cells"] == sum("missing" not in o for o in inner) and cut["perfect_frame_ratio"] > 0


def test_the_walk_starts_on_the_paths_head(office: Path, tour: RecordedPath) -> None:
    # the walker walks at once (no start hold): the head's end comes while the link is busy
    headed = _replay(office, start_hold_s=0.0)
    asked: dict[str, list[str]] = {"whole": [], "short": []}
    whole_first = _replay(office, path_head_s=None, seen=asked["whole"], start_hold_s=0.0)
    short = _replay(office, path_head_s=0.2, seen=asked["short"], start_hold_s=0.0)  # a head shorter than the contents take to come
    # the whole path in the bundle is taken as such; a head's whole path is asked for once
    assert [p for p in asked["whole"] if "/paths/" in p] == []
    assert [p for p in asked["short"] if "/paths/" in p] == ["/v1/scenes/office/paths/tour"]
    for s in (headed, whole_first, short):
        assert "error" not in s and s["redownloads"] == 0 and s["perfect_frame_ratio"] > 0
    # the path walked: the whole tour, or (a walk of 3 s ending first) its 10 s head
    assert whole_first["path_duration_s"] == short["path_duration_s"] == pytest.approx(tour.duration, abs=1e-3)
    assert headed["path_duration_s"] >= 10.0
    # less comes before the first frame, the same cells, no later first perfect frame
    assert headed["first_bytes"] < whole_first["first_bytes"]
    assert headed["start_contents_cells"] == whole_first["start_contents_cells"]
    assert headed["time_to_first_perfect_frame_s"] <= whole_first["time_to_first_perfect_frame_s"]
    assert headed["path_wait_s"] == whole_first["path_wait_s"] == 0.0
    # the walker waits at the head's end for the whole path, then walks on (no jump)
    assert short["path_wait_s"] > 0.0 and short["frames"] > headed["frames"]


def test_the_walk_bar_follows_a_path_that_grows() -> None:
    from walkstream.terminal import WalkBar

    bar = WalkBar("replay tour")
    bar(1.0, 10.5)  # walking the head
    bar(11.0, 47.8)  # the whole path is in: a longer walk
    bar(47.8, 47.8)
    assert bar.bar.total == 47.8 and bar.bar.n == 47.8
    bar.close()


def test_the_walker_stands_at_the_start_until_its_first_view_is_in(office: Path) -> None:
    walking = _replay(office, start_hold_s=0.0)
    held = _replay(office)  # the default: at most 3 s
    short = _replay(office, start_hold_s=0.1)  # a bound shorter than the first view takes
    for s in (walking, held, short):
        assert "error" not in s and s["redownloads"] == 0 and s["perfect_frame_ratio"] > 0
    assert walking["start_hold_s"] == 0.0 and 0.0 < short["start_hold_s"] <= 0.1 + 0.05
    # the walker stood until the first view was in (and no contents were on the link, or
    # 3 s), the same 3 s of path walked after it (more frames), none walked half-seen
    assert 0.0 < held["start_hold_s"] <= 3.0 + 0.05
    assert held["time_to_first_perfect_frame_s"] <= held["setup_s"] + held["start_hold_s"] + 1e-9
    assert held["frames"] > walking["frames"]
    # the held walk starts posed (the first pose alone, the head after the first view):
    # its head came and replaced the pose, and it never waited for its path
    assert held["path_wait_s"] == 0.0 and held["path_duration_s"] >= 10.0
    assert held["time_to_first_perfect_frame_s"] <= walking["time_to_first_perfect_frame_s"] + 0.5
    # the report says which cells a frame missed, and why
    late = walking["late_cells"]
    assert late["cells"] == len(late["worst"]) or len(late["worst"]) == 20
    assert sum(late["cell_frames_by_cause"].values()) >= sum(w["frames"] for w in late["worst"])
    assert all(w["wanted_s"] <= w["missing_s"] for w in late["worst"])


# -- the posed start: the first pose alone, the head after the first view ----------


def test_the_posed_start_brings_the_first_pose_then_the_head_after_the_first_view(office: Path) -> None:
    app = create_app([office])
    try:
        url = "/v1/scenes/office/start?path=tour&view=160x120&head=10&heads=true"
        plain = _unpack(_get(app, url, **{"accept-encoding": "identity"}).content)
        posed = _unpack(_get(app, url + "&pose=true", **{"accept-encoding": "identity"}).content)
        # first the head's first pose alone (its first two samples, no ETag), then the topology
        assert posed[0]["part"] == plain[0]["part"] == "pathhead" and "etag" not in posed[0]
        pose, head = decode_path_q(posed[0]["body"], "pose"), decode_path_q(plain[0]["body"], "head")
        assert len(pose) == 2 and np.array_equal(pose.xyz, head.xyz[:2]) and np.array_equal(pose.yaw, head.yaw[:2])
        assert len(posed[0]["body"]) < len(plain[0]["body"]) and posed[1] == plain[1]
        assert posed[2] == plain[2] and posed[2]["part"] == "contents"
        # the head, as the plain bundle sends it, right after the frames of the first pose's view
        k = next(i for i, o in enumerate(posed) if i > 0 and o.get("part") == "pathhead")
        assert posed[k] == plain[0] and (is_pack(posed[k - 1]) or "cell" in posed[k - 1])
        assert posed[3:k] + posed[k + 1 :] == plain[3:]
        # the client's decoder takes it among the contents' frames
        from walkstream.client.net.startitems import StartDecoder

        dec = StartDecoder("params", heads=True)
        kinds = [dec(o, len(msgpack.packb(o)))[0] for o in posed]
        assert kinds.count("pathhead") == 2 and kinds[k] == "pathhead" and not dec.rooms
        # without heads (or a head), pose changes nothing
        for other in ("/v1/scenes/office/start?path=tour&view=160x120&head=10",
                      "/v1/scenes/office/start?path=tour&view=160x120&heads=true"):
            assert _get(app, other + "&pose=true").content == _get(app, other).content
        # a part without an ETag goes without the field, one with it keeps it
        assert "etag" not in posed[2] and posed[1]["etag"].endswith('-topology-c4"')
        r = _get(app, url + "&pose=maybe")
        assert r.status_code == 422 and "pose" in r.text
        # the compact topology's version 4 has an ETag of its own: a client holding the
        # version 3 body under its ETag gets the new one, not a 304
        r = _get(app, "/v1/scenes/office/topology/compact")
        assert r.headers["etag"].endswith('-topology-c4"') and r.content[:5] == b"WSTC\x04"
        old = r.headers["etag"].replace("-c4", "-c3")
        again = _get(app, "/v1/scenes/office/topology/compact", **{"if-none-match": old})
        assert again.status_code == 200 and again.content == r.content
    finally:
        app.state.scenes.close()


def test_the_first_views_cells_and_the_first_poses_come_from_one_culling(office: Path) -> None:
    from walkstream.server.service.scenes import Scene
    from walkstream.server.service.startbundle import START_ROOM_BYTES, room_lead

    scene = Scene.load(office)
    try:
        interior = scene.interior
        assert interior is not None
        lead, view = room_lead(scene, "tour"), RoomView((160, 120), 60.0, 40.0)
        cells, first = interior.first_view(lead, view, START_ROOM_BYTES)
        assert first == interior.first_view(lead[:1], view, START_ROOM_BYTES)[0]
        assert first and cells[: len(first)] == first
        # the byte bound cuts the first pose's cells alike
        small = interior.records[cells[0]].contents.nbytes
        assert interior.first_view(lead, view, small) == ([cells[0]], [cells[0]])
    finally:
        scene.close()


def test_a_posed_start_cut_before_its_head_walks_on_the_whole_path(office: Path, tour: RecordedPath) -> None:
    # (the posed start walked whole: the default replays of the tests above)
    # a bundle cut after the first view, before the head: the whole path comes on its own
    app = create_app([office])
    try:
        url = "/v1/scenes/office/start?path=tour&view=640x480&fov=60.0&fog=40.0&head=10.0&heads=true&pose=true"
        objs = _unpack(_get(app, url, **{"accept-encoding": "identity"}).content)
    finally:
        app.state.scenes.close()
    k = next(i for i, o in enumerate(objs) if i > 0 and o.get("part") == "pathhead")
    cut = _replay(office, cut=sum(len(msgpack.packb(o)) for o in objs[:k]) + 7)
    assert "error" not in cut and cut["perfect_frame_ratio"] > 0
    assert cut["path_duration_s"] == pytest.approx(tour.duration, abs=1e-3)


def test_the_posed_start_flushes_its_gzip_stream_once_before_the_first_view_ends(office: Path) -> None:
    from walkstream.server.service.routers.start import _join_first_view, _msgpack_parts
    from walkstream.server.service.scenes import Scene
    from walkstream.server.service.startbundle import start_parts, start_position

    scene = Scene.load(office)
    xy, h, v = start_position(scene, path="tour")
    view = RoomView((160, 120), 60.0, 40.0)

    def pieces(pose: bool) -> tuple[list[Any], list[bytes]]:
        parts = start_parts(scene, xy, "msgpack", "tour", h, v, view=view, inflate=True, path_head_s=10.0,
                            heads=True, pose=pose)
        return parts, list(_msgpack_parts(parts))

    def first_view_end(ps: list[bytes], k: int) -> int:  # the gzip stream's bytes, flushed after each piece
        co = zlib.compressobj(9, zlib.DEFLATED, 31)
        return sum(len(co.compress(p) + co.flush(zlib.Z_SYNC_FLUSH)) for p in ps[:k])

    try:
        parts, each = pieces(True)
        joined = _join_first_view(each, parts)
        # one piece: the first pose, the topology, the contents' list and the first view's
        # frames, in order; then the head, then the rest as before
        first = _unpack(joined[0])
        assert [o.get("part") for o in first[:3]] == ["pathhead", "topology", "contents"]
        assert b"".join(joined) == b"".join(each) and len(joined) == len(each) - len(first) + 1
        assert _unpack(joined[1])[0]["part"] == "pathhead" and joined[1:] == each[len(first):]
        # the first view ends sooner on the stream: fewer flushes before it
        assert first_view_end(joined, 1) < first_view_end(each, len(first))
        # without pose nothing is joined (the walk may start once the topology is in)
        plain_parts, plain = pieces(False)
        assert _join_first_view(plain, plain_parts) == plain
    finally:
        scene.close()
