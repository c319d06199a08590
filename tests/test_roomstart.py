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

from walkstream.client.net.link import LinkProfile
from walkstream.client.replay import ReplayConfig, run_replay
from walkstream.client.stream.rooms import cell_of, stack_planes
from walkstream.server.bake import bake
from walkstream.server.service.main import create_app
from walkstream.server.sources.interiorgen import InteriorPlan, write_interior
from walkstream.server.store import SceneReader
from walkstream.shared.errors import CodecError
from walkstream.shared.pathcodec import (
    PATH_Q_MAGIC,
    PATH_Q_MEDIA,
    decode_path_any,
    decode_path_q,
    encode_path_q,
    path_error_bound,
)
from walkstream.shared.paths import RecordedPath
from walkstream.shared.roomcompact import (
    TOPOLOGY_COMPACT_MAGIC,
    TOPOLOGY_COMPACT_MEDIA,
    decode_topology_compact,
    encode_topology_compact,
)
from walkstream.shared.roomwire import Topology, decode_topology, decode_topology_packed
from walkstream.shared.wire import decode_start_part

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
    assert bound.tolist() == [5e-4] * 6
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
        assert (a.id, a.kind, a.name, a.storey, a.neighbours) == (b.id, b.kind, b.name, b.storey, b.neighbours)
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
    obj = msgpack.unpackb(zlib.decompress(body[5:]), strict_map_key=False)
    cells = obj["cells"]
    bad_n = {**obj, "cells": {**cells, "n": [n + 1 for n in cells["n"]]}}
    bad_names = {**obj, "cells": {**cells, "name": cells["name"][:-1]}}
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


def _replay(office: Path, no_bundle: bool = False, **kw: Any) -> dict[str, Any]:
    cfg = ReplayConfig(**{"link": MODEM, "device": "desktop2003", "path": "tour", "kind": "interior",
                          "duration_s": 3.0, **kw})
    app = create_app([office])
    try:
        inner: httpx.AsyncBaseTransport = httpx.ASGITransport(app=app)
        r = run_replay(_NoBundle(inner) if no_bundle else inner, "http://walkstream.test", cfg)
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
    assert bundle["requests"] < plain["requests"] and bundle["first_bytes"] < plain["first_bytes"]
    # refused: the old sequence, one wasted round trip later
    assert refused["setup_s"] >= plain["setup_s"]
    assert refused["perfect_frame_ratio"] == pytest.approx(plain["perfect_frame_ratio"], abs=0.05)
