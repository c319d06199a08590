"""The replay of a crossing scene: from a street through the door into the rooms and back, one loop."""

from __future__ import annotations

from pathlib import Path
from typing import Any, NamedTuple

import httpx
import numpy as np
import pytest

from walkstream.client.config import ReplayConfig
from walkstream.client.net.link import LinkProfile
from walkstream.client.replay import ReplayResult, run_replay
from walkstream.client.stream.cache import CITY_KINDS, Cache
from walkstream.server.service.main import create_app
from walkstream.server.store import SceneReader
from walkstream.shared.scene.placement import ContentsPlacement, placement_for

LINK_56K = LinkProfile(down_bps=56_000.0, up_bps=56_000.0, rtt_s=0.2)


class _Counting(httpx.AsyncBaseTransport):
    """The server's side of the link: counts the requests that reach it."""

    def __init__(self, inner: httpx.AsyncBaseTransport) -> None:
        self.inner = inner
        self.requests = 0

    async def handle_async_request(self, request: httpx.Request) -> httpx.Response:
        self.requests += 1
        return await self.inner.handle_async_request(request)


@pytest.fixture(scope="module")
def scene(crossing_scene: tuple[Path, dict[str, Any], Path]) -> Path:
    """The crossing bake shared with tests/test_crossing.py (tests/conftest.py): read only."""
    return crossing_scene[0]


@pytest.fixture(scope="module")
def walked(scene: Path) -> ReplayResult:
    """The walk ``enter`` at 56 kbit/s, 200 ms, every 25th frame compared with the truth."""
    cfg = ReplayConfig(link=LINK_56K, path="enter", device="desktop2003", truth_every=25, kind="crossing")
    return run_replay(httpx.ASGITransport(app=create_app([scene])), "http://t", cfg)


class _Counted(NamedTuple):
    summary: dict[str, Any]
    #: the requests that reached the server
    requests: int
    #: each dispatch of a request scheduler: (the scheduler's id, its lanes, requests in flight)
    dispatches: list[tuple[int, int, int]]


@pytest.fixture(scope="module")
def counted(scene: Path) -> _Counted:
    """The first 15 s of ``enter`` without the truth (whose own requests for the full scene
    reach the server too), through a server side that counts the requests, every
    scheduler dispatch recorded: one replay for the two tests that count."""
    from walkstream.client.stream.scheduler import RequestScheduler

    seen: list[tuple[int, int, int]] = []
    real = RequestScheduler.dispatch

    def spy(self: RequestScheduler) -> int:
        n = real(self)
        seen.append((id(self), len(self.lanes), self.in_flight()))
        return n

    server = _Counting(httpx.ASGITransport(app=create_app([scene])))
    cfg = ReplayConfig(link=LINK_56K, path="enter", device="desktop2003", kind="crossing", duration_s=15.0)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(RequestScheduler, "dispatch", spy)
        got = run_replay(server, "http://t", cfg).summary
    return _Counted(got, server.requests, seen)


def test_the_replay_walks_the_crossing_end_to_end(scene: Path, walked: ReplayResult) -> None:
    s = walked.summary
    with SceneReader.open(scene) as r:
        (e,) = r.entrances()
        rooms = r.rooms()
    assert s["kind"] == "crossing" and s["entrance"]["doorway"] == e.doorway
    assert s["walk_s"] == pytest.approx(s["path_duration_s"], abs=0.1)
    cells = walked.log.cell[walked.log.cell >= 0]
    # the frame log's cells: streets (by the city's map) and rooms (by their planes)
    assert {int(c) for c in cells} & set(rooms) and {int(c) for c in cells} - set(rooms)
    assert s["perfect_frame_ratio"] > 0.9


def test_the_visible_set_switches_model_at_the_door_and_back(walked: ReplayResult) -> None:
    s = walked.summary
    assert [m for _, m in s["model_switches"]] == ["pvs", "portals", "pvs"]
    t_in, t_out = s["model_switches"][1][0], s["model_switches"][2][0]
    assert s["door_reached_s"] == pytest.approx(t_in, abs=0.1) and t_out > t_in
    assert s["frames_pvs"] > 0 and s["frames_portals"] > 0


def test_the_first_room_has_arrived_before_the_door(walked: ReplayResult) -> None:
    s = walked.summary
    assert s["first_room"] is not None and s["door_frames"] > 0
    assert s["door_frames_without_first_room"] == 0
    assert s["interior_prefetch_from_s"] is not None and s["interior_prefetch_from_s"] < s["door_reached_s"]


def test_the_truth_finds_no_culled_pixel(walked: ReplayResult) -> None:
    truth = walked.summary["truth"]
    assert set(truth) == {
        "frames", "unknown", "culled_pixels", "culled_frames", "pinholes", "worst_frame", "refused_poses", "colour"
    }
    # the colour error against the full scene without fog, on the frames that knew their visible set
    assert 0 < truth["colour"]["frames"] <= truth["frames"] - truth["unknown"]
    # poses with the eye within a hand of a wall are refused, not compared: a few at most
    assert truth["refused_poses"] <= 0.1 * truth["frames"]
    assert truth["frames"] - truth["unknown"] - truth["refused_poses"] >= 40
    assert truth["culled_pixels"] == 0 and truth["culled_frames"] == 0


def test_one_link_one_cache_no_collision(scene: Path, walked: ReplayResult, counted: _Counted) -> None:
    s = walked.summary
    entries: dict[str, Any] = s["cache_entries"]
    # room contents and city objects side by side in the one cache, under their own kinds
    assert entries["cellmesh"] == s["cells_fetched"] > 0 and entries["params"] > 0 and entries["mesh"] == 0
    with SceneReader.open(scene) as r:
        shared_ids = set(r.rooms()) & set(r.object_ids().tolist())
    assert shared_ids  # ids overlap: the kinds keep them apart
    got = counted.summary
    assert got["requests"] == counted.requests  # every request went down the one link, once
    assert got["contents_requests"] + got["object_requests"] + got["cell_requests"] < got["requests"]


def test_each_streamer_pins_its_own_kinds() -> None:
    c = Cache(100)
    c.put("params", 7, "object 7", 40)
    c.put("cellmesh", 7, "cell 7", 40)
    c.set_pins([("cellmesh", 7)], kinds=("cellmesh",))
    c.set_pins([("params", 7)], kinds=CITY_KINDS)
    assert c.pinned == {("cellmesh", 7), ("params", 7)}
    c.put("geom", 1, "big", 60)  # over budget: only the unpinned entry can go
    assert c.peek("params", 7) == "object 7" and c.peek("cellmesh", 7) == "cell 7"
    assert not c.has("geom", 1)
    c.set_pins([])
    assert c.pinned == frozenset()


def test_a_street_walk_of_a_crossing_stays_on_the_streets(scene: Path) -> None:
    """The crossing's rooms do not enter the city's cell map: the city's walk SE stays on the streets."""
    cfg = ReplayConfig(link=LINK_56K, path="SE", device="desktop2003", duration_s=10.0, kind="crossing")
    got = run_replay(httpx.ASGITransport(app=create_app([scene])), "http://t", cfg)
    with SceneReader.open(scene) as r:
        rooms = set(r.rooms())
    assert got.summary["frames_portals"] == 0
    assert not rooms & set(np.unique(got.log.cell).tolist())
    assert got.summary["perfect_frame_ratio"] > 0.9


def test_the_service_names_the_entrances(scene: Path) -> None:
    import asyncio
    import json

    from walkstream.shared.roomwire import decode_entrances

    async def get(accept: str) -> httpx.Response:
        async with httpx.AsyncClient(transport=httpx.ASGITransport(app=create_app([scene])), base_url="http://t") as c:
            return await c.get("/v1/scenes/scene/entrances", headers={"accept": accept})

    with SceneReader.open(scene) as r:
        want = [(e.portal, e.building, e.street, e.doorway, e.shell) for e in r.entrances()]
        placed = [e.placement for e in r.entrances()]
    packed = asyncio.run(get("application/msgpack"))
    assert packed.status_code == 200 and packed.headers["etag"]
    got = decode_entrances(packed.content, "entrances")
    assert [(e.portal, e.building, e.street, e.doorway, e.shell) for e in got] == want
    assert [e.placement for e in got] == placed and placed[0] is not None  # exact: float64 on the wire
    keys = ("portal", "building", "street", "doorway", "shell")
    sent = json.loads(asyncio.run(get("application/json")).text)
    assert [tuple(e[k] for k in keys) for e in sent] == want
    assert [ContentsPlacement.from_wire(e["placement"], "json") for e in sent] == placed


def test_an_entrance_without_a_placement_and_bad_placements() -> None:
    import msgpack

    from walkstream.shared.errors import CodecError
    from walkstream.shared.roomwire import Entrance, decode_entrances

    plain = Entrance(1, 2, 3, 4, 5)
    assert "placement" not in plain.to_wire()  # as a crossing scene baked before sends it
    assert decode_entrances(msgpack.packb([plain.to_wire()]), "e") == (plain,)
    p = ContentsPlacement(0.5, (10.0, -3.0), 0.25, (7, 9))
    assert decode_entrances(msgpack.packb([Entrance(1, 2, 3, 4, 5, p).to_wire()]), "e")[0].placement == p
    for bad in ({"angle": 0.5, "shift": [1.0], "dz": 0.0, "cells": [0, 1]},
                {"angle": float("nan"), "shift": [1.0, 2.0], "dz": 0.0, "cells": [0, 1]},
                {"angle": 0.5, "shift": [1.0, 2.0], "dz": 0.0, "cells": [3, 1]},
                {"angle": 0.5, "shift": [1.0, 2.0], "cells": [0, 1]}, [1, 2]):
        with pytest.raises(CodecError):
            decode_entrances(msgpack.packb([plain.to_wire() | {"placement": bad}]), "e")
    # the move: a quarter turn, then the shift and the lift; a cell outside the range is not the placement's
    assert np.allclose(ContentsPlacement(np.pi / 2, (10.0, 0.0), 1.0, (7, 9)).xyz([[1.0, 0.0, 0.0]]), [[10.0, 1.0, 1.0]])
    assert p.holds(7) and p.holds(9) and not p.holds(10) and placement_for([p], 6) is None
    assert np.allclose(p.matrix() @ [1.0, 2.0, 3.0, 1.0], [*p.xyz([[1.0, 2.0, 3.0]])[0], 1.0])


def _placed_before(scene: Path, out: Path) -> Path:
    """``scene`` as a crossing bake stored it before contents kept their own frame: the
    contents encoded after the move into the city, no placements table."""
    import shutil
    import sqlite3

    from walkstream.server.bake.interior import interior_parts, room_contents
    from walkstream.server.bake.placement import Placement
    from walkstream.server.sources.interior import InteriorScene
    from walkstream.server.sources.read import read_source
    from walkstream.shared.codec.cellmesh import decode_cell_mesh, encode_cell_mesh, raw_bytes

    with SceneReader.open(scene) as r:
        (e,) = r.entrances()
        offset = min(r.rooms())
    p = e.placement
    assert p is not None
    src = scene.parent / "office.json"
    inner = read_source(src)
    assert isinstance(inner, InteriorScene)
    turn = Placement(p.angle, p.shift, p.dz)
    parts = {c: [(e, m, turn.xyz(v), t) for e, m, v, t in ps]
             for c, ps in room_contents(inner, interior_parts(inner, src).layout).items()}
    shutil.copyfile(scene, out)
    db = sqlite3.connect(out)
    with db:
        db.execute("DROP TABLE placements")
        for (cid,) in db.execute("SELECT cell FROM contents").fetchall():
            blob = encode_cell_mesh([q for q in parts.get(cid - offset, []) if len(q[3])])
            m = decode_cell_mesh(blob, "placed")
            db.execute("UPDATE contents SET data = ?, triangles = ?, vertices = ?, raw_bytes = ? WHERE cell = ?",
                       (blob, m.triangles, m.vertices, raw_bytes(m.vertices, m.triangles), cid))
    db.close()
    return out


def test_a_crossing_baked_before_placements_still_replays(scene: Path, walked: ReplayResult, tmp_path: Path) -> None:
    """A crossing scene whose contents are stored placed (no placement: the identity) replays
    as before: the rooms where they were, nothing culled against its truth."""
    old = _placed_before(scene, tmp_path / "before.db")
    with SceneReader.open(old) as r:
        assert r.entrances()[0].placement is None
        stored = sum(c.nbytes for c in r.contents_info().values())
    with SceneReader.open(scene) as r:
        assert sum(c.nbytes for c in r.contents_info().values()) < 0.7 * stored  # the turn cost the boxes
    # every 50th frame: the walk's own test compares every 25th
    cfg = ReplayConfig(link=LINK_56K, path="enter", device="desktop2003", truth_every=50, kind="crossing",
                       size=(320, 240))  # the culled pixels at a quarter of the pixels: the rooms in place or not
    got = run_replay(httpx.ASGITransport(app=create_app([old])), "http://t", cfg).summary
    assert got["entrance"] == {k: v for k, v in walked.summary["entrance"].items() if k != "placement"}
    assert got["truth"]["culled_pixels"] == 0 and got["truth"]["frames"] - got["truth"]["unknown"] >= 20
    assert got["door_frames_without_first_room"] == 0 and got["perfect_frame_ratio"] > 0.9
    assert got["contents_bytes"] > walked.summary["contents_bytes"]


def test_the_room_streamer_places_contents_in_the_city(scene: Path) -> None:
    """Contents come in the office's own frame; the room streamer stores them placed: every
    part of a room or doorway cell lies in its cell's outline (in the city's frame), which
    the unplaced parts of the turned office do not."""
    import asyncio

    import shapely

    from walkstream.client.clock import RealClock
    from walkstream.client.net.api import SceneClient
    from walkstream.client.stream.rooms import RoomStreamConfig, RoomStreamer

    async def fetch() -> tuple[Any, dict[int, Any], dict[int, Any]]:
        async with httpx.AsyncClient(transport=httpx.ASGITransport(app=create_app([scene])), base_url="http://t") as http:
            clock = RealClock()
            api = SceneClient(http, clock, "scene")
            topo, entrances = await asyncio.gather(api.topology(), api.entrances())
            rooms = RoomStreamer(api, clock, Cache(1 << 30), topo, RoomStreamConfig(),
                                 placements=[e.placement for e in entrances if e.placement is not None])
            cells = [c.id for c in topo.cells]
            rooms.adopt(cells, api.contents_batch(cells))
            while any(rooms.mesh(c) is None for c in cells):
                await asyncio.sleep(0.01)
            raw = {c: await api.contents(c) for c in cells}
            await rooms.close()
            return topo, {c: rooms.mesh(c) for c in cells}, raw

    topo, placed, raw = asyncio.run(fetch())
    outside = 0
    for rec in topo.cells:
        if rec.kind == "outside":
            continue
        plan = shapely.Polygon(rec.outline).buffer(0.35, join_style="mitre")  # walls reach half their thickness out
        for p, q in zip(placed[rec.id].parts, raw[rec.id].parts, strict=True):
            assert plan.contains(shapely.Point(0.5 * (p.bbox[0] + p.bbox[1])[:2]))
            outside += not plan.contains(shapely.Point(0.5 * (q.bbox[0] + q.bbox[1])[:2]))
    assert outside > 0


def test_one_scheduler_owns_the_link_for_both_streamers(counted: _Counted) -> None:
    """The city's and the rooms' requests go out through one scheduler, whose slots bound
    them together (each streamer alone would allow its own limit)."""
    got = counted.summary
    assert got["contents_requests"] > 0 and got["object_requests"] > 0
    shared = [x for x in counted.dispatches if x[1] == 2]
    assert shared and len({x[0] for x in shared}) == 1  # one scheduler with both lanes
    assert max(x[2] for x in shared) <= 4  # StreamerConfig.max_requests: the link's slots
