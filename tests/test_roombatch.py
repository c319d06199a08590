"""Many interior cells' contents in one answer (``POST .../rooms/contents``) and the
RoomStreamer asking for them that way.

The small generated office of test_portals.py / test_roomstream.py (``office_db``).
"""

from __future__ import annotations

import asyncio
import csv
import json
import zlib
from pathlib import Path
from typing import Any

import httpx
import msgpack
import numpy as np
import pytest

from walkstream.cli import main
from walkstream.client.clock import SimClock
from walkstream.client.net.api import SceneClient
from walkstream.client.stream.cache import Cache
from walkstream.client.stream.rooms import RoomStreamConfig, RoomStreamer
from walkstream.server.service.main import create_app
from walkstream.shared.camera import camera, perspective
from walkstream.shared.codec.cellbatch import (
    CELLBATCH_MAX_CELLS,
    check_contents_part,
    pack_contents_part,
)
from walkstream.shared.codec.cellmesh import CellMesh, decode_cell_mesh, inflate_cell_mesh
from walkstream.shared.errors import CodecError, InputError, StreamCut
from walkstream.shared.roomwire import decode_topology


def _call(app: Any, method: str, url: str, body: bytes | None = None, **headers: str) -> httpx.Response:
    async def go() -> httpx.Response:
        async with httpx.AsyncClient(transport=httpx.ASGITransport(app=app), base_url="http://t") as c:
            return await c.request(method, url, content=body, headers=headers)

    return asyncio.run(go())


def _batch(app: Any, scene: str, ids: Any, gzip: bool = True) -> httpx.Response:
    return _call(app, "POST", f"/v1/scenes/{scene}/rooms/contents", json.dumps({"ids": ids}).encode(),
                 **{"Content-Type": "application/json", "Accept-Encoding": "gzip" if gzip else "identity"})


def _unpack(data: bytes) -> list[Any]:
    u = msgpack.Unpacker(raw=False)
    u.feed(data)
    return list(u)


def _same(a: CellMesh, b: CellMesh) -> bool:
    return len(a.parts) == len(b.parts) and all(
        p.element == q.element and p.material == q.material
        and np.array_equal(p.positions, q.positions) and np.array_equal(p.indices, q.indices)
        for p, q in zip(a.parts, b.parts, strict=True)
    )


def _cells(app: Any, scene: str) -> list[int]:
    topo = decode_topology(_call(app, "GET", f"/v1/scenes/{scene}/topology").content, "t")
    return [c.id for c in topo.cells]


def test_batch_is_the_single_answers_in_the_order_asked(office_db: Path) -> None:
    app, scene = create_app([office_db]), office_db.stem
    ids = _cells(app, scene)[::-1][:9]  # not sorted: the order asked is kept
    singles = {c: _call(app, "GET", f"/v1/scenes/{scene}/rooms/{c}/contents") for c in ids}
    zipped = _batch(app, scene, ids)
    assert zipped.status_code == 200 and zipped.headers["content-encoding"] == "gzip"
    assert zipped.headers["x-cell-count"] == str(len(ids))
    parts = [check_contents_part(o, "part") for o in _unpack(zipped.content)]
    assert [p[0] for p in parts] == ids
    for cid, etag, body in parts:
        one = singles[cid]
        assert etag == one.headers["etag"]
        # inflated to the N form, to be compressed with the others, or as stored where
        # that is cheaper in the stream (contentsform.py); decodes to the same mesh
        assert body[:1] == b"N" or body == one.content
        assert _same(decode_cell_mesh(body, "batch"), decode_cell_mesh(one.content, "single"))
    # without gzip the stored blobs go as they are, byte for byte
    plain = _batch(app, scene, ids, gzip=False)
    assert "content-encoding" not in plain.headers
    assert [(c, e, b) for c, e, b in (check_contents_part(o, "p") for o in _unpack(plain.content))] == [
        (c, singles[c].headers["etag"], singles[c].content) for c in ids]
    # msgpack request bodies too
    mp = _call(app, "POST", f"/v1/scenes/{scene}/rooms/contents", msgpack.packb({"ids": ids[:2]}),
               **{"Content-Type": "application/msgpack"})
    assert [p["cell"] for p in _unpack(mp.content)] == ids[:2]


def test_the_gzip_stream_is_smaller_and_each_part_decodes_as_it_comes(office_db: Path) -> None:
    app, scene = create_app([office_db]), office_db.stem
    ids = _cells(app, scene)[:12]
    stored = sum(len(_call(app, "GET", f"/v1/scenes/{scene}/rooms/{c}/contents").content) for c in ids)

    async def wire() -> bytes:
        async with httpx.AsyncClient(transport=httpx.ASGITransport(app=app), base_url="http://t") as c:
            async with c.stream("POST", f"/v1/scenes/{scene}/rooms/contents", json={"ids": ids},
                                headers={"Accept-Encoding": "gzip"}) as r:
                return b"".join([b async for b in r.aiter_raw()])

    body = asyncio.run(wire())
    assert len(body) < 0.95 * stored
    # each cell in its cheaper form: never more than every cell inflated (the old stream)
    co = zlib.compressobj(9, zlib.DEFLATED, 31)
    singles = [_call(app, "GET", f"/v1/scenes/{scene}/rooms/{c}/contents") for c in ids]
    inflated = [pack_contents_part(c, one.headers["etag"], inflate_cell_mesh(one.content))
                for c, one in zip(ids, singles, strict=True)]
    old = sum(len(co.compress(p) + co.flush(zlib.Z_SYNC_FLUSH)) for p in inflated) + len(co.flush())
    assert len(body) <= old
    # flushed after each part: every prefix that ends on a flush gives its parts whole
    d = zlib.decompressobj(31)
    got = _unpack(d.decompress(body[: len(body) // 2]))
    assert 0 < len(got) < len(ids) and [g["cell"] for g in got] == ids[: len(got)]


@pytest.mark.parametrize(
    ("body", "status", "says"),
    [
        ({"ids": [1, 99999]}, 404, "has no cell 99999"),
        ({"ids": [2, 3, 2]}, 422, "cell 2 asked more than once"),
        ({"ids": list(range(CELLBATCH_MAX_CELLS + 1))}, 422, f"at most {CELLBATCH_MAX_CELLS} per batch"),
        ({"ids": 5}, 422, "ids: expected an array"),
        ([1, 2], 422, 'expected an object {"ids"'),
        ({"ids": ["a"]}, 422, "ids[0] = 'a'"),
    ],
)
def test_bad_batches_are_clear_4xx(office_db: Path, body: Any, status: int, says: str) -> None:
    app, scene = create_app([office_db]), office_db.stem
    r = _call(app, "POST", f"/v1/scenes/{scene}/rooms/contents", json.dumps(body).encode(),
              **{"Content-Type": "application/json"})
    assert r.status_code == status, r.text
    assert says in r.json()["error"] and "\n" not in r.json()["error"]
    r = _call(app, "POST", f"/v1/scenes/{scene}/rooms/contents", b"{not json", **{"Content-Type": "application/json"})
    assert r.status_code == 400 and "not valid JSON" in r.json()["error"]


def test_bad_parts_are_codec_errors() -> None:
    with pytest.raises(CodecError, match="p: expected a map of cell, etag and body"):
        check_contents_part([1, 2], "p")
    with pytest.raises(CodecError, match="p: cell must be an integer"):
        check_contents_part({"cell": -1, "etag": "", "body": b""}, "p")
    with pytest.raises(InputError, match="contents batch of -1 bytes"):
        RoomStreamConfig(batch_bytes=-1)
    with pytest.raises(InputError, match="flush fill 1.5"):
        RoomStreamConfig(flush_fill=1.5)


class _Cut(httpx.AsyncBaseTransport):
    """The real app behind a link that breaks every batch answer after ``keep`` bytes."""

    def __init__(self, app: Any, keep: int) -> None:
        self.inner = httpx.ASGITransport(app=app)
        self.keep = keep
        self.batches = 0

    async def handle_async_request(self, request: httpx.Request) -> httpx.Response:
        r = await self.inner.handle_async_request(request)
        if not request.url.path.endswith("/rooms/contents"):
            return r
        self.batches += 1
        data = b"".join([b async for b in r.stream])  # type: ignore[union-attr]
        return httpx.Response(r.status_code, headers=r.headers,
                              stream=httpx.ByteStream(data[: self.keep] if self.batches == 1 else data))


def _walker(office_db: Path, transport: httpx.AsyncBaseTransport, config: RoomStreamConfig) -> Any:
    async def go() -> tuple[RoomStreamer, list[list[int]], list[int]]:
        clock = SimClock()
        async with httpx.AsyncClient(transport=transport, base_url="http://t") as http:
            api = SceneClient(http, clock, office_db.stem)
            topo = await api.topology()
            s = RoomStreamer(api, clock, Cache(64 << 20), topo, config)
            asked: list[list[int]] = []
            real = api.contents_batch

            def spy(ids: Any) -> Any:
                asked.append(list(ids))
                return real(ids)

            api.contents_batch = spy  # type: ignore[method-assign]
            size = (160, 120)
            proj = perspective(60.0, size[0] / size[1], 0.1, 80.0).astype(np.float64)
            room = next(c for c in topo.cells if c.kind == "room")
            lo, hi = room.outline.min(axis=0), room.outline.max(axis=0)
            eye = np.array([*(lo + hi) / 2, room.zmin + 1.6])
            view = camera(eye, 0.3, 0.0).astype(np.float64)
            vis: list[int] = []
            for k in range(40):
                vis = s.tick(0.1 * k, eye, proj @ view, view, proj, size)
                in_flight = set(s._tasks.values())
                assert len(in_flight) <= config.max_in_flight + 1
                await asyncio.sleep(0)
                await asyncio.sleep(0.001)
            while s._tasks:
                await asyncio.gather(*set(s._tasks.values()))
            await s.close()
            return s, asked, vis

    return asyncio.run(go())


def test_streamer_asks_each_cell_once_visible_first(office_db: Path) -> None:
    app = create_app([office_db])
    s, asked, vis = _walker(office_db, httpx.ASGITransport(app=app), RoomStreamConfig(batch_bytes=3000))
    flat = [c for b in asked for c in b]
    assert len(flat) == len(set(flat)), asked  # no cell asked twice
    assert asked[0][: len(vis)] == vis  # the visible cells lead the first batch, in their order
    assert s.stats.requests == len(asked) > 1 and s.stats.refetched == 0 and s.stats.errors == 0
    assert all(s.mesh(c) is not None for c in flat)
    # prefetch batches stop at batch_bytes (one cell at least)
    for b in asked[1:]:
        sizes = [s.cells[c].contents.nbytes for c in b]
        assert len(b) == 1 or sum(sizes[:-1]) <= 3000


def test_a_batch_cut_short_leaves_its_other_cells_to_ask_again(office_db: Path) -> None:
    app = create_app([office_db])
    cut = _Cut(app, keep=5000)
    s, asked, vis = _walker(office_db, cut, RoomStreamConfig(batch_bytes=3000))
    first = asked[0]
    got_first = [c for c in first if c not in {x for b in asked[1:] for x in b}]
    assert 0 < len(got_first) < len(first)  # the cut batch brought some cells ...
    assert asked[1][: len(first) - len(got_first)] == [c for c in first if c not in got_first]  # ... the rest again
    assert s.stats.errors == 1 and s.stats.refetched == 0
    assert all(s.mesh(c) is not None for c in vis)


def test_client_batch_raises_streamcut_on_a_short_answer(office_db: Path) -> None:
    app = create_app([office_db])

    async def go() -> list[int]:
        got: list[int] = []
        async with httpx.AsyncClient(transport=_Cut(app, keep=800), base_url="http://t") as http:
            api = SceneClient(http, SimClock(), office_db.stem)
            ids = [c.id for c in (await api.topology()).cells][:6]
            with pytest.raises(StreamCut, match=r"ended after \d of 6 cells"):
                async for cid, mesh in api.contents_batch(ids):
                    assert mesh.nbytes > 0
                    got.append(cid)
            return got

    assert len(asyncio.run(go())) < 6


def _replay(db: Path, out: Path, *extra: str) -> dict[str, Any]:
    assert main(["replay", str(db), "--path", "tour", "--device", "pda", "--bandwidth", "56kbit", "--rtt", "200ms",
                 "--duration", "10", "--report", str(out), "--no-plots", *extra]) == 0
    s = json.loads((out / "report.json").read_text())
    return dict(s.get("summary", s))


def _imperfect(report: Path) -> int:
    with (report / "frames.csv").open() as f:
        return sum(float(r["download_quality"]) < 1.0 for r in csv.DictReader(f))


def test_batches_from_the_cli_beat_one_request_per_cell(office_db: Path, tmp_path: Path) -> None:
    batch = _replay(office_db, tmp_path / "batch")
    single = _replay(office_db, tmp_path / "single", "--contents-batch", "0")
    plain = _replay(office_db, tmp_path / "plain", "--no-gzip")
    assert batch["contents_requests"] < single["contents_requests"] / 2
    assert batch["bytes_received"] < single["bytes_received"]
    assert batch["time_to_first_perfect_frame_s"] < single["time_to_first_perfect_frame_s"]
    assert batch["redownloads"] == single["redownloads"] == 0
    # the ratio counts from each walk's own first perfect frame: compare the frames short of perfect
    assert _imperfect(tmp_path / "batch") < _imperfect(tmp_path / "single")
    # --no-gzip: a plain batch, the stored blobs one by one
    assert plain["contents_requests"] < single["contents_requests"] and plain["cut_streams"] == 0
