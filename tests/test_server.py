"""The HTTP service (walkstream.server.service).

Most tests talk to the ASGI app in-process through httpx; one test runs a real
uvicorn server on a free loopback port for what only a socket shows (a streamed
body arriving in pieces, a client that vanishes mid-stream).  A schemathesis run
over the OpenAPI schema (:mod:`walkstream.benchmarks.apifuzz`) checks that every answer
is one the schema promises.
"""

from __future__ import annotations

import asyncio
import base64
import io
import json
import os
import shutil
import socket
import time
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import msgpack
import numpy as np
import pytest
from fastapi import FastAPI
from liveserver import serve_in_thread
from scenes import PATH, PATH_DATA, PATH_NAME, CityDb, build_city_db

import walkstream.server.service.run as serve_mod
from walkstream.server.service.http import accepts_gzip, etag_matches, negotiate
from walkstream.server.service.lru import LRU
from walkstream.server.service.main import create_app
from walkstream.server.service.scenes import MAX_IDS
from walkstream.shared.cells import inside_convex
from walkstream.shared.codec import decode_object
from walkstream.shared.errors import StoreError
from walkstream.shared.pathcodec import PATH_Q_MEDIA, decode_path_q
from walkstream.shared.records import StreetParams
from walkstream.shared.startwire import decode_start_part
from walkstream.shared.wire import (
    cell_from_wire,
    decode_cell,
    decode_cell_index,
    decode_manifest,
)

JSON_ACCEPT = {"accept": "application/json"}


# ---------------------------------------------------------------------------
# fixtures
# ---------------------------------------------------------------------------


class Client:
    """A synchronous face on ``httpx.AsyncClient`` over the ASGI app (one event loop)."""

    def __init__(self, app: FastAPI) -> None:
        self.loop = asyncio.new_event_loop()
        self.http = httpx.AsyncClient(
            transport=httpx.ASGITransport(app=app), base_url="http://testserver"
        )

    def request(self, method: str, url: str, **kwargs: Any) -> httpx.Response:
        return self.loop.run_until_complete(self.http.request(method, url, **kwargs))

    def get(self, url: str, **kwargs: Any) -> httpx.Response:
        return self.request("GET", url, **kwargs)

    def post(self, url: str, **kwargs: Any) -> httpx.Response:
        return self.request("POST", url, **kwargs)

    def close(self) -> None:
        self.loop.run_until_complete(self.http.aclose())
        self.loop.close()


@pytest.fixture(scope="module")
def city(tmp_path_factory: pytest.TempPathFactory) -> CityDb:
    return build_city_db(tmp_path_factory.mktemp("server") / "tiny.db")


@pytest.fixture(scope="module")
def app(city: CityDb) -> Iterator[FastAPI]:
    app = create_app([city.path])
    yield app
    app.state.scenes.close()


@pytest.fixture(scope="module")
def client(app: FastAPI) -> Iterator[Client]:
    c = Client(app)
    yield c
    c.close()


def scene_url(city: CityDb, rest: str = "") -> str:
    return f"/v1/scenes/{city.name}{rest}"


def unpack(r: httpx.Response) -> Any:
    assert r.headers["content-type"] == "application/msgpack", r.text
    return msgpack.unpackb(r.content)


def both(client: Client, url: str) -> tuple[Any, Any, httpx.Response, httpx.Response]:
    """The msgpack (default) and JSON answers for ``url``, both 200."""
    rm = client.get(url)
    rj = client.get(url, headers=JSON_ACCEPT)
    assert rm.status_code == 200, rm.text
    assert rj.status_code == 200, rj.text
    assert rj.headers["content-type"] == "application/json"
    return unpack(rm), rj.json(), rm, rj


def assert_error(r: httpx.Response, status: int, *needles: str) -> dict[str, Any]:
    """``r`` is a JSON error with this status whose message contains every needle."""
    assert r.status_code == status, (r.status_code, r.text)
    assert r.headers["content-type"] == "application/json"
    body = r.json()
    assert set(body) == {"error", "detail"}
    for n in needles:
        assert n in body["error"], (n, body)
    return body


def post_ids(client: Client, city: CityDb, ids: Any, **kwargs: Any) -> httpx.Response:
    return client.post(scene_url(city, "/objects"), json={"ids": ids}, **kwargs)


# ---------------------------------------------------------------------------
# small units
# ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("accept", "rep"),
    [
        (None, "msgpack"),
        ("", "msgpack"),
        ("*/*", "msgpack"),
        ("application/json", "json"),
        ("text/html,application/json;q=0.9,*/*;q=0.8", "json"),
        ("application/msgpack, application/json", "msgpack"),
        ("application/msgpack;q=0.5, application/json", "json"),
        ("application/json;q=0", "msgpack"),
        ("application/json;q=nan", "msgpack"),
        ("application/json;q=abc", "msgpack"),
        ("application/json, " + ", ".join(f"x/y{i};q=0.1" for i in range(100)), "json"),
    ],
)
def test_negotiate(accept: str | None, rep: str) -> None:
    assert negotiate(accept) == rep


def test_etag_matching() -> None:
    tag = '"abc-cell:1-json"'
    assert etag_matches(tag, tag)
    assert etag_matches(f'"x", W/{tag}', tag)
    assert etag_matches("*", tag)
    assert not etag_matches('"abc-cell:1-msgpack"', tag)
    assert not etag_matches(None, tag)


def test_lru_is_bounded_by_bytes() -> None:
    lru = LRU(100)
    for i in range(10):
        lru.put(i, b"x" * 30, 30)
    assert len(lru) == 3 and lru.get(9) is not None and lru.get(0) is None
    lru.get(7)  # 7 becomes the most recent; 8 is evicted next
    lru.put(10, b"y" * 30, 30)
    assert lru.get(8) is None and lru.get(7) is not None
    lru.put(11, b"z" * 1000, 1000)  # larger than the budget: not cached, nothing evicted
    assert lru.get(11) is None and len(lru) == 3
    found, missing = lru.get_many([7, 7, 99, 10, 99])
    assert set(found) == {7, 10} and missing == [99]


# ---------------------------------------------------------------------------
# endpoints, both representations
# ---------------------------------------------------------------------------


def test_health_and_scene_list(client: Client, city: CityDb) -> None:
    m, j, _, _ = both(client, "/v1/health")
    assert m == j == {"status": "ok", "scenes": 1}
    m, j, rm, rj = both(client, "/v1/scenes")
    assert m == j == [{"name": city.name, "version": city.version}]
    assert rm.headers["etag"] != rj.headers["etag"]
    assert rm.headers["cache-control"] == "no-cache"


def test_manifest(client: Client, city: CityDb) -> None:
    m, j, rm, rj = both(client, scene_url(city))
    assert m == j
    assert m["name"] == city.name and m["version"] == city.version
    assert m["crs"] == "EPSG:32633" and len(m["origin"]) == 2
    assert len(m["bounds"]) == 6 and m["bounds"][0] < m["bounds"][3]
    assert m["features"] == ["street_cells"]
    assert m["grammar"]["id"] and "->" in m["grammar"]["text"]
    assert [v["name"] for v in m["viewpoints"]] == ["start"]
    assert m["viewpoints"][0]["cell"] in city.pvs
    assert m["paths"] == [PATH_NAME]
    assert m["objects"] == len(city.object_ids) and m["cells"] == len(city.pvs)
    assert m["limits"] == {"objects_per_request": MAX_IDS}
    for r, rep in ((rm, "msgpack"), (rj, "json")):
        assert r.headers["cache-control"] == "public, max-age=31536000, immutable"
        assert r.headers["vary"] == "Accept"
        etag = r.headers["etag"]
        assert city.version in etag and "manifest" in etag and rep in etag


def test_cell_record(client: Client, city: CityDb) -> None:
    """A cell record carries what is the cell's own: its PVS and ACH, compact."""
    for cid, pvs in city.pvs.items():
        m, j, rm, _ = both(client, scene_url(city, f"/cells/{cid}"))
        assert list(m) == list(j) == ["id", "kind", "pvs", "ach"]
        fast, plain = decode_cell(rm.content, "cell"), cell_from_wire(j, "cell")
        assert fast.id == plain.id == cid and fast.kind in ("street", "crossroad")
        assert tuple(fast.pvs) == tuple(plain.pvs) == pvs
        assert np.array_equal(fast.ach, plain.ach) and abs(fast.ach.sum() - 1) < 1e-9
        assert j["pvs"][0] == 0 and j["pvs"][1][0] == pvs[0]  # JSON: a plain delta list
        assert len(rm.content) < 40 + 3 * len(pvs)  # a few bytes per PVS object, all told


def test_cell_index_tiles_cover_every_cell_once(client: Client, city: CityDb) -> None:
    """The tiles of the index hold every cell once, with its outline, heights and neighbours."""
    m = unpack(client.get(scene_url(city)))
    grid = m["index"]
    assert set(grid) == {"origin", "tile", "shape", "reach"} and "cell-index" in m["offers"]
    nx, ny = grid["shape"]
    seen: dict[int, Any] = {}
    for i in range(nx):
        for j in range(ny):
            rm = client.get(scene_url(city, f"/index/{i}/{j}"))
            rj = client.get(scene_url(city, f"/index/{i}/{j}"), headers=JSON_ACCEPT)
            idx = decode_cell_index(rm.content, "tile")
            assert idx.tile == (i, j) and rj.json()["tile"] == [i, j]
            for k, cid in enumerate(idx.ids.tolist()):
                assert cid not in seen
                seen[cid] = (idx.outlines[k], set(idx.neighbours[k].tolist()))
                assert idx.zmin[k] <= idx.zmax[k] and len(idx.outlines[k]) >= 3
    assert set(seen) == set(city.pvs)
    for cid, (outline, nbs) in seen.items():
        assert all(cid in seen[n][1] for n in nbs)  # adjacency is symmetric
        # the point where the cell was made lies in it (centimetre outlines)
        assert inside_convex(outline, [city.centroids[cid]])[0]
    whole = decode_cell_index(client.get(scene_url(city, "/index")).content, "whole")
    assert whole.tile is None and set(whole.ids.tolist()) == set(city.pvs)
    assert_error(client.get(scene_url(city, f"/index/{nx}/0")), 404, f"({nx}, 0)", "grid")
    assert_error(client.get(scene_url(city, "/index/-1/0")), 404, "(-1, 0)")
    assert_error(client.get(scene_url(city, "/index/a/0")), 422, "i")


def test_cells_batch_streams_records_in_the_order_asked(client: Client, city: CityDb) -> None:
    ids = sorted(city.pvs)[::-1][:7] + [sorted(city.pvs)[0]]
    r = client.post(scene_url(city, "/cells"), json={"ids": ids})
    assert r.status_code == 200 and r.headers["x-cell-count"] == str(len(ids))
    got = [cell_from_wire(o, "batch") for o in frames(r.content)]
    assert [c.id for c in got] == ids and all(tuple(c.pvs) == city.pvs[c.id] for c in got)
    js = client.post(scene_url(city, "/cells"), json={"ids": ids}, headers=JSON_ACCEPT).json()
    assert [c["id"] for c in js] == ids and js[0]["pvs"][0] == 0
    assert_error(client.post(scene_url(city, "/cells"), json={"ids": [10**9]}), 404, str(10**9))
    assert_error(client.post(scene_url(city, "/cells"), json={"ids": "x"}), 422, "ids")
    too_many = client.post(scene_url(city, "/cells"), json={"ids": [0] * (MAX_IDS + 1)})
    assert_error(too_many, 422, str(MAX_IDS))


def _bundle(r: httpx.Response) -> list[tuple[str, Any]]:
    """The parts of a start bundle, decoded (objects as frames)."""
    out: list[tuple[str, Any]] = []
    left = 0
    for o in frames(r.content):
        if left:
            out.append(("object", o))
            left -= 1
            continue
        part, etag, body = decode_start_part(o, "bundle")
        if part == "objects":
            assert isinstance(body, int)
            left = body
        out.append((part, body))
    assert left == 0
    return out


def test_start_bundle_brings_everything_for_the_first_frame(client: Client, city: CityDb) -> None:
    r = client.get("/v1/start?viewpoint=start")
    assert r.status_code == 200 and r.headers["x-scene"] == city.name
    parts = _bundle(r)
    names = [p for p, _ in parts]
    # cells, index tiles, manifest, then the objects
    order = [n for k, n in enumerate(names) if k == 0 or n != names[k - 1]]
    assert order == ["cell", "index", "manifest", "objects", "object"]
    cells = [decode_cell(b, "cell") for p, b in parts if p == "cell"]
    x, y = city.centroids[cells[0].id]
    here = unpack(client.get(scene_url(city, f"/locate?x={x!r}&y={y!r}")))["cell"]
    assert cells[0].id == here  # the cell at the viewpoint comes first
    # the objects: the first cell's PVS by ACH, then each next cell's new ones, once
    want: list[int] = []
    for c in cells:
        want += [int(i) for i in c.pvs[np.argsort(-c.ach, kind="stable")] if i not in want]
    assert [o["id"] for p, o in parts if p == "object"] == want
    m = decode_manifest([b for p, b in parts if p == "manifest"][0], "manifest")
    assert m.name == city.name and m.index is not None
    tiles = [decode_cell_index(b, "tile") for p, b in parts if p == "index"]
    assert any(here in t.ids.tolist() for t in tiles)
    # moving fast along the street: the cells ahead come too, in the order entered
    ahead = _bundle(client.get(f"/v1/start?x={x!r}&y={y!r}&heading=0&speed=15"))
    ahead_cells = [decode_cell(b, "cell").id for p, b in ahead if p in ("cell", "record")]
    assert ahead_cells[0] == here and len(ahead_cells) > 1
    # the records reach further than the objects (START_RECORD_LEAD_S), each cell's
    # index tile comes with it and no other, all before the manifest and the objects
    recs = {c.id: c for c in (decode_cell(b, "cell") for p, b in ahead if p in ("cell", "record"))}
    got = [o["id"] for p, o in ahead if p == "object"]
    # the objects are those of a prefix of the cells (the last ones' may not come)
    assert any(set(got) == {int(i) for c in ahead_cells[:k] for i in recs[c].pvs}
               for k in range(1, len(ahead_cells) + 1))
    # a record whose objects do not all come is a ``record`` part, so that the client
    # does not wait for them; one whose objects all come a ``cell`` part
    kinds = {decode_cell(b, "cell").id: p for p, b in ahead if p in ("cell", "record")}
    for cid, p in kinds.items():
        assert ({int(i) for i in recs[cid].pvs} <= set(got)) == (p == "cell"), (cid, p)
    tiles_ahead = [decode_cell_index(b, "tile") for p, b in ahead if p == "index"]
    held = {i for t in tiles_ahead for i in t.ids.tolist()}
    assert set(ahead_cells) <= held
    assert all(set(t.ids.tolist()) & set(ahead_cells) for t in tiles_ahead)
    names_ahead = [p for p, _ in ahead]
    assert names_ahead.index("manifest") > max(i for i, p in enumerate(names_ahead) if p in ("cell", "record", "index"))
    # a path: the path first (the walk can start), from its own start (here outside
    # every cell: no cell, no objects)
    by_path = _bundle(client.get(f"/v1/start?path={PATH_NAME}"))
    # (in the compact encoding: within half a millimetre, millisecond, milliradian)
    assert by_path[0][0] == "path"
    assert np.allclose(decode_path_q(by_path[0][1], "p").table(), PATH.table(), rtol=0, atol=5e-4)
    x0, y0 = (float(v) for v in PATH.xyz[0, :2])
    if unpack(client.get(scene_url(city, f"/locate?x={x0!r}&y={y0!r}")))["cell"] is None:
        assert "cell" not in [p for p, _ in by_path]
    # the same for a named scene; JSON for people
    assert _bundle(client.get(scene_url(city, "/start?viewpoint=start"))) == parts
    outside = _bundle(client.get("/v1/start?x=1e6&y=1e6"))
    assert [p for p, _ in outside] == ["manifest"]  # no cell, no tile, no objects
    js = client.get("/v1/start?viewpoint=start", headers=JSON_ACCEPT).json()
    assert [p["part"] for p in js][:1] == ["cell"]
    assert js[-1]["part"] == "objects" and len(js[-1]["body"]) == len(want)


def test_start_bundle_takes_every_combination_of_where(client: Client, city: CityDb) -> None:
    # nothing: the scene's default start, its first viewpoint
    assert _bundle(client.get("/v1/start")) == _bundle(client.get("/v1/start?viewpoint=start"))
    # each of path, viewpoint, x and y overrides the one before
    x, y = next(iter(city.centroids.values()))  # a cell centroid
    at_xy = _bundle(client.get(f"/v1/start?x={x!r}&y={y!r}"))
    with_path = _bundle(client.get(f"/v1/start?path={PATH_NAME}&x={x!r}&y={y!r}"))
    assert with_path[0][0] == "path" and with_path[1:] == at_xy  # the path, then the start at x, y
    assert _bundle(client.get(f"/v1/start?path={PATH_NAME}&viewpoint=start"))[1:] == _bundle(
        client.get("/v1/start?viewpoint=start")
    )
    # one coordinate: the other is the default start's
    start = _bundle(client.get("/v1/start?viewpoint=start"))
    vx = decode_manifest([b for p, b in start if p == "manifest"][0], "m").viewpoints[0]
    assert _bundle(client.get(f"/v1/start?x={vx.x!r}")) == _bundle(
        client.get(f"/v1/start?x={vx.x!r}&y={vx.y!r}")
    )


def test_start_bundle_refuses_what_it_cannot_answer(client: Client, city: CityDb) -> None:
    assert_error(client.get("/v1/start?path=nope"), 404, "'nope'")
    assert_error(client.get("/v1/start?viewpoint=nope"), 404, "'nope'")
    assert_error(client.get("/v1/start?viewpoint=start&path=nope"), 404, "'nope'")
    assert_error(client.get("/v1/start?scene=atlantis&x=0&y=0"), 404, "atlantis")
    assert_error(client.get("/v1/start?x=nan&y=0"), 422, "x")
    assert_error(client.get("/v1/start?x=0&y=0&speed=-1"), 422, "speed")
    assert_error(client.get("/v1/start?form=mesh"), 422, "form")


def test_streams_are_gzipped_when_the_client_accepts_it(client: Client, city: CityDb) -> None:
    ids = list(city.object_ids[:200])
    plain = post_ids(client, city, ids, headers={"accept-encoding": "identity"})
    assert "content-encoding" not in plain.headers
    zipped = post_ids(client, city, ids, headers={"accept-encoding": "gzip"})
    assert zipped.headers["content-encoding"] == "gzip"
    assert zipped.content == plain.content  # httpx inflates it
    assert "Accept-Encoding" in zipped.headers["vary"]
    raw = client.loop.run_until_complete(
        client.http.post(
            scene_url(city, "/objects"),
            json={"ids": ids},
            headers={"accept-encoding": "gzip"},
            extensions={},
        )
    )
    assert raw.status_code == 200
    assert accepts_gzip("gzip;q=0.5, identity") and not accepts_gzip("gzip;q=0, br")


def test_locate(client: Client, city: CityDb) -> None:
    for cid, (x, y) in list(city.centroids.items())[:10]:
        m, j, _, _ = both(client, scene_url(city, f"/locate?x={x!r}&y={y!r}"))
        assert m == j == {"cell": cid}
    m, j, _, _ = both(client, scene_url(city, "/locate?x=1e6&y=-1e6"))
    assert m == j == {"cell": None, "reason": "outside every cell"}


@pytest.mark.parametrize(
    "query",
    ["x=nan&y=0", "x=0&y=inf", "x=-Infinity&y=0", "x=1e999&y=0", "x=abc&y=0", "y=0", "x=0", ""],
)
def test_locate_refuses_bad_coordinates(client: Client, city: CityDb, query: str) -> None:
    r = client.get(scene_url(city, f"/locate?{query}"))
    body = assert_error(r, 422)
    named = {e["loc"][-1] for e in body["detail"]}
    assert named and named <= {"x", "y"}
    assert any(f"query.{n}" in body["error"] for n in named)


def test_recorded_path(client: Client, city: CityDb) -> None:
    url = scene_url(city, f"/paths/{PATH_NAME}")
    rm = client.get(url)
    assert rm.status_code == 200 and rm.headers["content-type"] == "application/msgpack"
    assert msgpack.unpackb(rm.content) == PATH_DATA
    rj = client.get(url, headers=JSON_ACCEPT)
    assert rj.json() == {"name": PATH_NAME, "data": PATH_DATA}
    assert rm.headers["etag"] != rj.headers["etag"]
    # the compact encoding when Accept names it: its own media type and ETag
    rq = client.get(url, headers={"accept": f"{PATH_Q_MEDIA}, application/msgpack;q=0.5"})
    assert rq.headers["content-type"] == PATH_Q_MEDIA and rq.headers["etag"] not in (rm.headers["etag"], rj.headers["etag"])
    assert np.allclose(decode_path_q(rq.content, "p").table(), PATH.table(), rtol=0, atol=5e-4)
    again = client.get(url, headers={"accept": PATH_Q_MEDIA, "if-none-match": rq.headers["etag"]})
    assert again.status_code == 304
    assert_error(client.get(scene_url(city, "/paths/nope")), 404, "'nope'")


def test_etag_and_304(client: Client, city: CityDb) -> None:
    urls = [
        "/v1/scenes",
        scene_url(city),
        scene_url(city, "/cells/0"),
        scene_url(city, "/locate?x=0&y=0"),
        scene_url(city, f"/paths/{PATH_NAME}"),
    ]
    for url in urls:
        for headers in ({}, JSON_ACCEPT):
            r = client.get(url, headers=headers)
            etag = r.headers["etag"]
            assert etag.startswith('"') and etag.endswith('"')
            again = client.get(url, headers={**headers, "if-none-match": etag})
            assert again.status_code == 304 and again.content == b""
            assert again.headers["etag"] == etag and again.headers["vary"] == "Accept"
            assert again.headers["cache-control"] == r.headers["cache-control"]
            weak = client.get(url, headers={**headers, "if-none-match": f'"other", W/{etag}'})
            assert weak.status_code == 304
            stale = client.get(url, headers={**headers, "if-none-match": '"old"'})
            assert stale.status_code == 200 and stale.content == r.content
    # the representations never share an ETag: msgpack's does not validate JSON
    url = scene_url(city, "/cells/0")
    tag = client.get(url).headers["etag"]
    assert client.get(url, headers={"if-none-match": tag, **JSON_ACCEPT}).status_code == 200


def test_vary_on_every_response(client: Client, city: CityDb) -> None:
    for r in (
        client.get("/v1/health"),
        client.get("/metrics"),
        client.get("/v1/scenes/nope"),
        client.get("/nope"),
        post_ids(client, city, [0]),
        post_ids(client, city, ["x"]),
    ):
        assert "Accept" in [v.strip() for v in r.headers["vary"].split(",")], r.url


# ---------------------------------------------------------------------------
# objects
# ---------------------------------------------------------------------------


def frames(content: bytes) -> list[dict[str, Any]]:
    return list(msgpack.Unpacker(io.BytesIO(content), raw=False))


def test_objects_stream_in_the_order_asked(client: Client, city: CityDb) -> None:
    rng = np.random.default_rng(3)
    ids = [int(i) for i in rng.permutation(city.object_ids)] + [city.object_ids[0]] * 2
    r = post_ids(client, city, ids)
    assert r.status_code == 200 and r.headers["content-type"] == "application/msgpack"
    assert r.headers["x-scene-version"] == city.version
    assert r.headers["x-object-count"] == str(len(ids))
    got = frames(r.content)
    assert [f["id"] for f in got] == ids
    for f in got:
        p = decode_object(f["params"])
        assert p.id == f["id"]
        assert f["kind"] == (p.kind if isinstance(p, StreetParams) else "building")
    # a msgpack body gives the same bytes; so does a second (cached) request
    rb = client.post(
        scene_url(city, "/objects"),
        content=msgpack.packb({"ids": ids}),
        headers={"content-type": "application/msgpack"},
    )
    assert rb.status_code == 200 and rb.content == r.content
    assert post_ids(client, city, ids).content == r.content


def test_objects_json(client: Client, city: CityDb) -> None:
    ids = list(city.object_ids[:5])[::-1]
    rm = post_ids(client, city, ids)
    rj = post_ids(client, city, ids, headers=JSON_ACCEPT)
    assert rj.status_code == 200 and rj.headers["content-type"] == "application/json"
    items = rj.json()
    assert [o["id"] for o in items] == ids
    assert [base64.b64decode(o["params"]) for o in items] == [
        f["params"] for f in frames(rm.content)
    ]


def test_objects_empty_request(client: Client, city: CityDb) -> None:
    r = post_ids(client, city, [])
    assert r.status_code == 200 and r.content == b""
    assert post_ids(client, city, [], headers=JSON_ACCEPT).json() == []


def test_objects_unknown_ids_are_named(client: Client, city: CityDb) -> None:
    top = max(city.object_ids)
    r = post_ids(client, city, [city.object_ids[0], top + 7, top + 1, top + 7])
    body = assert_error(r, 404, str(top + 7), str(top + 1))
    assert body["detail"] == {"ids": [top + 7, top + 1]}


def test_objects_limit(client: Client, city: CityDb) -> None:
    ok = [city.object_ids[i % len(city.object_ids)] for i in range(MAX_IDS)]
    r = post_ids(client, city, ok)
    assert r.status_code == 200 and len(frames(r.content)) == MAX_IDS
    assert_error(post_ids(client, city, ok + ok[:1]), 422, str(MAX_IDS + 1), str(MAX_IDS))
    big = b'{"ids": [' + b" " * 70_000 + b"]}"
    r = client.post(
        scene_url(city, "/objects"), content=big, headers={"content-type": "application/json"}
    )
    assert_error(r, 413, "limit")


@pytest.mark.parametrize(
    "ids",
    [
        ["1"],
        [1.5],
        [True],
        [-1],
        [2**63],
        [None],
        [[1]],
        [{"id": 1}],
    ],
)
def test_objects_wrong_types(client: Client, city: CityDb, ids: list[Any]) -> None:
    body = assert_error(post_ids(client, city, ids), 422, "ids[0]")
    assert body["detail"][0]["index"] == 0


@pytest.mark.parametrize(
    ("content", "ctype", "status", "needle"),
    [
        (b"", "application/json", 400, "empty"),
        (b"{not json", "application/json", 400, "not valid JSON"),
        (b"[" * 50_000 + b"]" * 50_000, "application/json", 413, "limit"),
        (b"[" * 30_000 + b"]" * 30_000, "application/json", 400, "JSON"),
        (b"\xc1", "application/msgpack", 400, "msgpack"),
        (b"\x92\x01", "application/msgpack", 400, "msgpack"),
        (b"[1, 2]", "application/json", 422, "ids"),
        (b'{"id": [1]}', "application/json", 422, "ids"),
        (b'{"ids": 5}', "application/json", 422, "array"),
        (b'{"ids": "1,2"}', "application/json", 422, "array"),
        (b'{"ids": [1]}', "text/plain", 415, "text/plain"),
        (b'{"ids": [NaN]}', "application/json", 422, "ids[0]"),
        (b'{"ids": [' + b"9" * 5000 + b"]}", "application/json", 400, "JSON"),
    ],
)
def test_objects_malformed_bodies(
    client: Client, city: CityDb, content: bytes, ctype: str, status: int, needle: str
) -> None:
    r = client.post(scene_url(city, "/objects"), content=content, headers={"content-type": ctype})
    assert_error(r, status, needle)


# ---------------------------------------------------------------------------
# errors
# ---------------------------------------------------------------------------


def test_unknown_things_are_404_and_named(client: Client, city: CityDb) -> None:
    body = assert_error(client.get("/v1/scenes/atlantis"), 404, "atlantis")
    assert body["detail"]["known"] == [city.name]
    assert_error(client.get("/v1/scenes/atlantis/cells/0"), 404, "atlantis")
    assert_error(client.post("/v1/scenes/atlantis/objects", json={"ids": [1]}), 404, "atlantis")
    assert_error(client.get(scene_url(city, "/cells/99999")), 404, "99999")
    assert_error(client.get(scene_url(city, "/cells/-1")), 404, "-1")
    assert_error(client.get(scene_url(city, f"/cells/{2**70}")), 404, str(2**70))
    assert_error(client.get(scene_url(city, "/paths/a%20b")), 404, "'a b'")
    assert_error(client.get("/v2/nothing"), 404, "/v2/nothing")
    assert_error(client.get(scene_url(city, "/cells/zero")), 422, "cell")
    assert_error(client.request("DELETE", scene_url(city)), 405)


def test_metrics(client: Client, city: CityDb) -> None:
    client.get(scene_url(city))
    client.get("/v1/scenes/atlantis")
    post_ids(client, city, [city.object_ids[0]])
    r = client.get("/metrics")
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/plain")
    text = r.text
    assert 'walkstream_requests_total{method="GET",route="/v1/scenes/{scene}",status="200"}' in text
    assert 'walkstream_requests_total{method="GET",route="/v1/scenes/{scene}",status="404"}' in text
    assert 'route="/v1/scenes/{scene}/objects",status="200"' in text
    assert 'walkstream_response_bytes_total{route="/v1/scenes/{scene}"}' in text
    assert (
        'walkstream_request_duration_seconds_bucket{route="/v1/scenes/{scene}",le="+Inf"}' in text
    )
    assert f'walkstream_scene_info{{scene="{city.name}",version="{city.version}"}} 1' in text
    for line in text.splitlines():  # every sample line is "name{labels} number"
        if not line.startswith("#"):
            float(line.rsplit(" ", 1)[1])


# ---------------------------------------------------------------------------
# start-up
# ---------------------------------------------------------------------------


def test_create_app_refuses_bad_databases(city: CityDb, tmp_path: Path) -> None:
    missing = tmp_path / "missing.db"
    with pytest.raises(StoreError, match="missing.db: no such file"):
        create_app([missing])
    junk = tmp_path / "junk.db"
    junk.write_bytes(b"not a database at all" * 100)
    with pytest.raises(StoreError, match="junk.db: not an SQLite database"):
        create_app([junk])
    newer = tmp_path / "newer.db"
    data = bytearray(city.path.read_bytes())
    data[60:64] = (99).to_bytes(4, "big")  # PRAGMA user_version lives in the header
    newer.write_bytes(bytes(data))
    with pytest.raises(StoreError, match="newer.db: schema version 99"):
        create_app([newer])
    damaged = tmp_path / "damaged.db"
    data = bytearray(city.path.read_bytes())
    page = 4096
    data[2 * page : len(data) - page] = os.urandom(len(data) - 3 * page)
    damaged.write_bytes(bytes(data))
    with pytest.raises(StoreError, match="damaged.db"):
        create_app([damaged])
    with pytest.raises(StoreError, match="no scene database"):
        create_app([])
    twin = tmp_path / "twin.db"
    shutil.copyfile(city.path, twin)
    with pytest.raises(StoreError, match="already served"):
        create_app([city.path, twin])
    # all or nothing: a good file next to a bad one does not start either
    with pytest.raises(StoreError, match="missing.db"):
        create_app([city.path, missing])


def test_two_scenes(city: CityDb, tmp_path: Path) -> None:
    other = build_city_db(tmp_path / "other.db", name="other", k=5)
    app = create_app([city.path, other.path])
    c = Client(app)
    try:
        names = [s["name"] for s in c.get("/v1/scenes", headers=JSON_ACCEPT).json()]
        assert names == sorted([city.name, "other"])
        cell = c.get("/v1/scenes/other/cells/0", headers=JSON_ACCEPT).json()
        assert len(cell_from_wire(cell, "cell").pvs) == 5
    finally:
        c.close()
        app.state.scenes.close()


def test_serve_validates_before_starting(
    city: CityDb, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    calls: list[tuple[Any, dict[str, Any]]] = []
    monkeypatch.setattr(serve_mod.uvicorn, "run", lambda app, **kw: calls.append((app, kw)))
    monkeypatch.delenv(serve_mod.ENV_PATHS, raising=False)
    with pytest.raises(StoreError, match="nope.db: no such file"):
        serve_mod.serve([tmp_path / "nope.db"])
    assert calls == []  # nothing started
    with pytest.raises(ValueError, match="workers"):
        serve_mod.serve([city.path], workers=0)
    with pytest.raises(ValueError, match="port"):
        serve_mod.serve([city.path], port=70000)

    serve_mod.serve([city.path], host="0.0.0.0", port=8123)
    app, kw = calls.pop()
    assert isinstance(app, FastAPI) and (kw["host"], kw["port"]) == ("0.0.0.0", 8123)

    serve_mod.serve([city.path], workers=2)
    target, kw = calls.pop()
    assert target == "walkstream.server.service.run:app_from_env" and kw["factory"] and kw["workers"] == 2
    assert json.loads(os.environ[serve_mod.ENV_PATHS]) == [str(city.path.resolve())]
    worker_app = serve_mod.app_from_env()  # what each worker process builds
    worker_app.state.scenes.close()

    monkeypatch.setenv(serve_mod.ENV_PATHS, "not json")
    with pytest.raises(StoreError, match="not JSON"):
        serve_mod.app_from_env()


# ---------------------------------------------------------------------------
# schemathesis: every answer is one the OpenAPI promises
# ---------------------------------------------------------------------------


def test_schemathesis_finds_no_answer_outside_the_schema(city: CityDb) -> None:
    from walkstream.benchmarks.apifuzz import CHECKS, format_table, run_fuzz

    # every check of the benchmark (no 5xx, only documented answers, no valid request
    # rejected, no invalid one accepted) on every operation, both modes, with fewer examples
    # per operation and mode (10: the same routes and checks, each check on every case, at
    # 2/5 of the requests; the draws are derandomized); the benchmark runs more, on every
    # scene kind
    report = run_fuzz([city.path], examples=10)
    assert len(CHECKS) == 7
    assert all(r.examples > 0 for r in report.rows)  # each operation and mode was called
    operations = {r.operation for r in report.rows}
    assert len(operations) == 25  # and the interiors' topology, topology/packed, topology/compact,
    # rooms/{cell}, rooms/{cell}/contents, POST rooms/contents (a batch), a crossing's entrances;
    # impostors/{image} and POST impostors, walls, walls/textures/{texture} and POST
    # walls/textures (this scene has none: their 404s)
    assert {r.mode for r in report.rows} == {"positive", "negative"}
    assert not report.total(), format_table(report)


# ---------------------------------------------------------------------------
# a real server
# ---------------------------------------------------------------------------


@pytest.fixture
def live_server(app: FastAPI) -> Iterator[str]:
    """uvicorn serving the app on a free loopback port, in a thread; yields the base URL."""
    with serve_in_thread(app, timeout_keep_alive=5) as url:
        yield url


def _raw_post(port: int, path: str, body: bytes) -> socket.socket:
    s = socket.create_connection(("127.0.0.1", port), timeout=5)
    head = (
        f"POST {path} HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
        f"Content-Length: {len(body)}\r\n\r\n"
    ).encode()
    s.sendall(head + body)
    return s


def test_real_server_streams_and_survives_vanishing_clients(live_server: str, city: CityDb) -> None:
    url = live_server + scene_url(city, "/objects")
    ids = [city.object_ids[(7 * i) % len(city.object_ids)] for i in range(MAX_IDS)]

    # the frames decode one by one as the bytes arrive, in the order asked
    got: list[int] = []
    unpacker = msgpack.Unpacker(raw=False)
    with httpx.Client(timeout=10) as http:
        plain = {"accept-encoding": "identity"}
        with http.stream("POST", url, json={"ids": ids}, headers=plain) as r:
            assert r.status_code == 200
            assert r.headers.get("transfer-encoding") == "chunked"
            pieces = 0
            for chunk in r.iter_raw():
                pieces += 1
                unpacker.feed(chunk)
                got += [f["id"] for f in unpacker]
        assert got == ids and pieces > 1

        # clients that vanish mid-stream, or never read, do not break the server
        port = int(live_server.rsplit(":", 1)[1])
        body = json.dumps({"ids": ids}).encode()
        for _ in range(5):
            s = _raw_post(port, scene_url(city, "/objects"), body)
            assert s.recv(64).startswith(b"HTTP/1.1 200")
            s.close()
        stalled = [_raw_post(port, scene_url(city, "/objects"), body) for _ in range(3)]
        half = socket.create_connection(("127.0.0.1", port), timeout=5)
        half.sendall(
            b"POST /v1/scenes/x/objects HTTP/1.1\r\nHost: x\r\nContent-Length: 100\r\n\r\n{"
        )
        t = time.perf_counter()
        r = http.post(url, json={"ids": ids[:3]})
        assert r.status_code == 200 and [f["id"] for f in frames(r.content)] == ids[:3]
        assert http.get(live_server + scene_url(city, "/cells/0")).status_code == 200
        assert time.perf_counter() - t < 2
        for s in (*stalled, half):
            s.close()

    # the compose healthcheck's probe works against a real server
    with urllib.request.urlopen(live_server + "/v1/health", timeout=3) as resp:
        assert resp.status == 200


def test_documented_shapes_match_the_wire_records() -> None:
    """The pydantic models of /docs describe exactly what shared/wire.py sends."""
    from walkstream.server.service import models
    from walkstream.shared.cells import TileGrid
    from walkstream.shared.impostorwire import CellImpostors, ImpostorRow
    from walkstream.shared.records import Viewpoint
    from walkstream.shared.wire import (
        CellIndex,
        CellRecord,
        Manifest,
        locate_answer,
    )

    manifest = Manifest(
        "s", "v", 1, "EPSG:32633", (0.0, 0.0), (0.0,) * 6, (), "g", "text",
        (Viewpoint("a", 0.0, 0.0, 1.7, 0.0, None),), (), 0, 0, 1000,
        index=TileGrid((0.0, 0.0), 100.0, (2, 3), 5.0), offers=("cell-index",),
    ).to_wire()
    assert list(manifest) == list(models.Manifest.model_fields)
    assert list(manifest["grammar"]) == list(models.GrammarOut.model_fields)
    assert list(manifest["viewpoints"][0]) == list(models.ViewpointOut.model_fields)
    assert list(manifest["limits"]) == list(models.LimitsOut.model_fields)
    assert list(manifest["index"]) == list(models.TileGridOut.model_fields)
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]])
    cell = CellRecord(3, "street", np.array([1]), np.array([1.0]))
    ring = ("far", "fach", "fsh")
    assert list(cell.to_wire()) == [k for k in models.CellOut.model_fields if k != "imp" and k not in ring]
    row = ImpostorRow(1, 0, 2, 1, 3, 1, (0.0, 0.0, 0.0, 1.0, 1.0, 1.0), (1,))
    imp = CellRecord(3, "street", np.array([1]), np.array([1.0]), impostors=CellImpostors(250.0, 0.03, (row,)),
                     far=np.array([2]), far_ach=np.array([1.0]), far_share=0.5)
    assert list(imp.to_wire()) == list(models.CellOut.model_fields)
    assert list(imp.to_wire()["imp"]) == list(models.ImpostorsOut.model_fields)
    index = CellIndex((0, 1), [3], ["street"], [1.5], [2.0], [square], [[4]])
    assert list(index.to_wire()) == list(models.CellIndexOut.model_fields)
    assert set(locate_answer(None)) == set(models.LocateOut.model_fields)


def test_a_file_replaced_by_a_new_version_is_served_without_a_restart(
    city: CityDb, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import walkstream.server.service.registry as registry_mod
    from walkstream.server.store.edit import write_path

    monkeypatch.setattr(registry_mod, "RECHECK_S", 0.0)
    db = tmp_path / "copy.db"
    shutil.copyfile(city.path, db)
    app = create_app([db])
    c = Client(app)
    try:
        v1 = c.get(scene_url(city), headers=JSON_ACCEPT).json()["version"]
        assert c.get(scene_url(city, "/paths/later")).status_code == 404
        blob = msgpack.packb({**PATH_DATA, "name": "later"})
        write_path(db, "later", blob)  # a new version, renamed over the served file
        m = c.get(scene_url(city), headers=JSON_ACCEPT).json()
        assert m["version"] != v1 and "later" in m["paths"]
        assert c.get(scene_url(city, "/paths/later")).status_code == 200
        listed = c.get("/v1/scenes", headers=JSON_ACCEPT).json()
        assert {"name": city.name, "version": m["version"]} in listed
        # a damaged replacement leaves the last good version served, never a 500
        junk = tmp_path / "junk.db"
        junk.write_bytes(b"SQLite format 3\x00" + b"\x00" * 4096)
        os.replace(junk, db)
        again = c.get(scene_url(city), headers=JSON_ACCEPT)
        assert again.status_code == 200 and again.json()["version"] == m["version"]
    finally:
        c.close()
        app.state.scenes.close()
