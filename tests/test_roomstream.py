"""Interior streaming: the packed topology, the flush policy, prefetch in the
order the predicted motion needs the cells.

One small generated office (two storeys), shared with test_portals.py (``office_db``).
"""

from __future__ import annotations

import asyncio
import gzip
import json
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest

from walkstream.cli import main
from walkstream.client.clock import SimClock
from walkstream.client.stream.cache import Cache
from walkstream.client.stream.roommotion import predicted_view, turned_view
from walkstream.client.stream.rooms import RoomStreamConfig, RoomStreamer
from walkstream.server.service.main import create_app
from walkstream.shared.camera import camera, perspective
from walkstream.shared.errors import CodecError, InputError
from walkstream.shared.roomwire import Topology, decode_topology, decode_topology_packed
from walkstream.shared.screenrects import TOUCH_MARGIN_PX


def _get(app: Any, url: str, **headers: str) -> httpx.Response:
    async def go() -> httpx.Response:
        async with httpx.AsyncClient(transport=httpx.ASGITransport(app=app), base_url="http://t") as c:
            return await c.get(url, headers=headers)

    return asyncio.run(go())


def _topology(db: Path) -> Topology:
    return decode_topology(_get(create_app([db]), f"/v1/scenes/{db.stem}/topology").content, "t")


def test_packed_topology_is_the_same_record_for_a_fraction_of_the_bytes(office_db: Path) -> None:
    app = create_app([office_db])
    plain = _get(app, f"/v1/scenes/{office_db.stem}/topology")
    packed = _get(app, f"/v1/scenes/{office_db.stem}/topology/packed")
    assert packed.status_code == 200 and packed.headers["content-type"] == "application/vnd.walkstream.topology+gzip"
    assert "immutable" in packed.headers["cache-control"] and packed.headers["etag"] != plain.headers["etag"]
    assert len(packed.content) < len(plain.content) / 3
    a, b = decode_topology(plain.content, "plain"), decode_topology_packed(packed.content, "packed")
    assert b.nbytes == len(packed.content)
    assert [c.id for c in a.cells] == [c.id for c in b.cells]
    assert all(np.array_equal(x.planes, y.planes) for x, y in zip(a.cells, b.cells, strict=True))
    assert all(np.array_equal(x[4], y[4]) for x, y in zip(a.portals, b.portals, strict=True))
    again = _get(app, f"/v1/scenes/{office_db.stem}/topology/packed", **{"If-None-Match": packed.headers["etag"]})
    assert again.status_code == 304
    # the same bytes from a second start of the service (immutable means immutable)
    assert _get(create_app([office_db]), f"/v1/scenes/{office_db.stem}/topology/packed").content == packed.content


def test_bad_packed_topology_is_a_clear_error(office_db: Path) -> None:
    body = _get(create_app([office_db]), f"/v1/scenes/{office_db.stem}/topology/packed").content
    with pytest.raises(CodecError, match="topo: corrupt gzip body"):
        decode_topology_packed(b"plain text", "topo")
    with pytest.raises(CodecError, match="topo: truncated"):
        decode_topology_packed(body[: len(body) // 2], "topo")
    with pytest.raises(CodecError, match="topo: gzip body inflates to more than"):
        decode_topology_packed(gzip.compress(b"\0" * ((64 << 20) + 10), 1), "topo")
    with pytest.raises(CodecError, match="topo: expected a map"):
        decode_topology_packed(gzip.compress(b"\x01"), "topo")


def _replay(db: Path, out: Path, *extra: str) -> dict[str, Any]:
    assert main(["replay", str(db), "--path", "tour", "--device", "pda", "--bandwidth", "56kbit", "--rtt", "200ms",
                 "--report", str(out), "--no-plots", *extra]) == 0
    s = json.loads((out / "report.json").read_text())
    return dict(s.get("summary", s))


def test_packed_topology_brings_the_first_perfect_frame_forward(office_db: Path, tmp_path: Path) -> None:
    plain_bytes = len(_get(create_app([office_db]), f"/v1/scenes/{office_db.stem}/topology").content)
    # the topology on its own request (the start bundle always brings the compact one)
    packed = _replay(office_db, tmp_path / "packed", "--duration", "12", "--no-start-bundle")
    plain = _replay(office_db, tmp_path / "plain", "--duration", "12", "--no-gzip", "--no-start-bundle")
    assert packed["topology_bytes"] < plain["topology_bytes"] == plain_bytes
    # the first perfect frame comes earlier by (most of) the time the bytes saved take at 56 kbit/s
    saved = (plain_bytes - packed["topology_bytes"]) * 8 / 56_000
    assert saved > 1.0
    assert packed["time_to_first_perfect_frame_s"] < plain["time_to_first_perfect_frame_s"] - 0.8 * saved
    # and no fewer perfect frames over the walk (not the ratio: that counts from each run's own
    # first perfect frame, and an earlier one can be followed by a frame or two still waiting)
    assert packed["perfect_frames"] >= plain["perfect_frames"]


def _streamer(topo: Topology, config: RoomStreamConfig, budget: int = 64 << 20) -> RoomStreamer:
    # the network is not used: the tests below drive the policy and the order only
    return RoomStreamer(None, SimClock(), Cache(budget), topo, config)  # type: ignore[arg-type]


def test_flush_after_is_honoured_by_both_policies(office_db: Path) -> None:
    topo = _topology(office_db)
    rooms = [c.id for c in topo.cells if c.kind == "room"][:4]
    for policy, fill_flushes in (("paper", True), ("crowded", False)):
        s = _streamer(topo, RoomStreamConfig(flush_s=5.0, flush_policy=policy))
        for k, c in enumerate(rooms):
            s.cache.put("cellmesh", c, object(), 1000)
            s.last_visible[c] = float(k)  # seen last at 0, 1, 2, 3 s
        s._flush(7.5, [])
        # the cache is nearly empty: only the paper's policy flushes, what is older than 5 s
        gone = [c for c in rooms if not s.cache.has("cellmesh", c)]
        assert gone == (rooms[:3] if fill_flushes else []), policy
        assert s.stats.flushed == len(gone)
    # crowded: the same once the cache is more than 90 % full; a wanted cell stays
    s = _streamer(topo, RoomStreamConfig(flush_s=5.0), budget=2100)
    for k, c in enumerate(rooms[:2]):
        s.cache.put("cellmesh", c, object(), 1000)
        s.last_visible[c] = float(k)
    s._flush(10.0, [rooms[1]])
    assert not s.cache.has("cellmesh", rooms[0]) and s.cache.has("cellmesh", rooms[1])
    with pytest.raises(InputError, match="flush policy 'never'"):
        RoomStreamConfig(flush_policy="never")
    with pytest.raises(InputError, match="flush after -1"):
        RoomStreamConfig(flush_s=-1.0)


def test_flush_after_from_the_cli(office_db: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    quick = _replay(office_db, tmp_path / "quick", "--duration", "16", "--flush-after", "2", "--flush-policy", "paper")
    # an interior manifest has no grammar: nothing may try to parse one (it logged a traceback)
    assert not [r for r in caplog.records if r.exc_info], caplog.text
    assert quick["flush_policy"] == "paper" and quick["flush_after_s"] == 2.0 and quick["cells_flushed"] > 0
    kept = _replay(office_db, tmp_path / "kept", "--duration", "16", "--flush-after", "2")
    assert kept["flush_policy"] == "crowded" and kept["cells_flushed"] == 0 and kept["redownloads"] == 0


def test_prefetch_follows_the_predicted_motion_in_order(office_db: Path) -> None:
    topo = _topology(office_db)
    s = _streamer(topo, RoomStreamConfig(turns_deg=()))
    size = (160, 120)
    proj = perspective(60.0, size[0] / size[1], 0.1, 80.0).astype(np.float64)
    # the longest corridor cell: walk along it, looking along it
    corridors = [c for c in topo.cells if "corridor" in c.name]
    c = max(corridors, key=lambda c: np.ptp(c.outline, axis=0).max())
    lo, hi = c.outline.min(axis=0), c.outline.max(axis=0)
    axis = int(np.argmax(hi - lo))
    start = np.array([*(lo + hi) / 2, c.zmin + 1.6])
    start[axis] = lo[axis] + 0.5
    step = np.zeros(3)
    step[axis] = 1.4  # m/s
    yaw = 0.0 if axis == 0 else np.pi / 2
    for k in range(3):
        eye = start + 0.25 * k * step
        view = camera(eye, yaw, 0.0).astype(np.float64)
        s.locate(eye)
        s.observe(0.25 * k, eye)
        vis = s.visible_cells(eye, proj @ view, view, proj, size)
    assert np.allclose(s.velocity(), step)
    want = s.wanted(10.0, eye, vis, proj @ view, view, proj, size)
    ahead = s.predicted(eye, proj @ view, view, proj, size)
    # the visible cells first, then the predicted ones in the order the motion reaches them
    assert want[: len(vis)] == vis
    new = [x for x in ahead if x not in vis]
    assert want[len(vis) : len(vis) + len(new)] == new
    # each horizon's cells come before those first seen at a farther one
    first_seen: dict[int, float] = {}
    for h in s.config.lookahead_s:
        e2 = eye + h * step
        v2 = predicted_view(view, eye, e2)
        cell = s._where.locate(e2, s.current)
        assert cell is not None
        for x in s._cells_from(cell, e2, proj @ v2, v2, proj, size, margin_px=TOUCH_MARGIN_PX)[1]:
            first_seen.setdefault(x, h)
    times = [first_seen[x] for x in ahead]
    assert times == sorted(times) and len(set(times)) > 1
    # the turned views: from where the eye is, the other way round, after the motion's cells
    turned = _streamer(topo, RoomStreamConfig(turns_deg=(180.0,)))
    turned._track, turned.current = list(s._track), s.current
    both = turned.predicted(eye, proj @ view, view, proj, size)
    back = turned_view(view, eye, 180.0)
    behind = s._cells_from(s.current, eye, proj @ back, back, proj, size)[1]
    assert both[: len(ahead)] == ahead and set(both) == set(ahead) | set(behind)
    assert behind and s.current in behind
    assert np.allclose(back[:3, :3] @ step, -(view[:3, :3] @ step)) and np.allclose(back @ [*eye, 1], view @ [*eye, 1])
    # no prefetch beyond its share of the cache
    small = _streamer(topo, RoomStreamConfig(prefetch_share=0.5), budget=20_000)
    small._track = list(s._track)
    small.current = s.current
    got = small.wanted(0.0, eye, vis, proj @ view, view, proj, size)
    extra = [x for x in got if x not in vis]
    assert small.visible_bytes(extra) <= 0.5 * 20_000 - small.visible_bytes(vis) or not extra
    assert len(got) < len(want)


def test_a_walker_turning_on_the_spot_is_predicted_to_go_on_turning(office_db: Path) -> None:
    topo = _topology(office_db)
    s = _streamer(topo, RoomStreamConfig())
    size = (160, 120)
    proj = perspective(60.0, size[0] / size[1], 0.1, 80.0).astype(np.float64)
    # the room cell with the most neighbours, the eye in its middle, turning left at 90 degrees a second
    c = max((c for c in topo.cells if c.kind == "room"), key=lambda c: len(c.neighbours))
    eye = np.array([*c.outline.mean(axis=0), c.zmin + 1.6])
    rate = np.pi / 2
    for k in range(3):
        t = 0.25 * k
        view = camera(eye, rate * t, 0.0).astype(np.float64)
        s.locate(eye)
        s.observe(t, eye)
        s._observe_heading(t, view)
    assert s.turn_rate() == pytest.approx(rate)
    vis = s.visible_cells(eye, proj @ view, view, proj, size)
    ahead = s.predicted(eye, proj @ view, view, proj, size)
    # the cells of the headings the turn reaches, half a turn at most, nearest in time first
    expect: list[int] = []
    for h in s.config.lookahead_s:
        v2 = camera(eye, 0.5 * rate + min(rate * h, np.pi), 0.0).astype(np.float64)
        expect.extend(s._cells_from(s.current, eye, proj @ v2, v2, proj, size)[1])  # type: ignore[arg-type]
    assert ahead == list(dict.fromkeys(expect))
    assert set(ahead) - set(vis), "the turn shows cells the view does not yet"
    # standing still, looking one way: nothing predicted (as before)
    still = _streamer(topo, RoomStreamConfig())
    for k in range(3):
        still.locate(eye)
        still.observe(0.25 * k, eye)
        still._observe_heading(0.25 * k, view)
    assert still.turn_rate() == 0.0 and still.predicted(eye, proj @ view, view, proj, size) == []


def test_prefetch_reaches_cells_portals_beyond_and_refuses_a_negative_reach(office_db: Path) -> None:
    topo = _topology(office_db)
    c = max((c for c in topo.cells if c.kind == "room"), key=lambda c: len(c.neighbours))
    one = _streamer(topo, RoomStreamConfig(beyond_portals=1))._beyond([c.id], 1)
    three = _streamer(topo, RoomStreamConfig(beyond_portals=3))._beyond([c.id], 3)
    assert set(one) == set(c.neighbours) - {c.id} and three[: len(one)] == one and len(three) > len(one)
    with pytest.raises(InputError, match="portals beyond"):
        RoomStreamConfig(beyond_portals=-1)


def test_the_outside_cell_comes_last_in_the_prefetch(office_db: Path) -> None:
    topo = _topology(office_db)
    outside = next(c.id for c in topo.cells if c.kind == "outside")
    # a room with a window (the outside one portal beyond), the walker standing still in it
    c = next(c for c in topo.cells if c.kind == "room" and outside in c.neighbours)
    s = _streamer(topo, RoomStreamConfig())
    eye = np.array([*c.outline.mean(axis=0), c.zmin + 1.6])
    s.locate(eye)
    view = camera(eye, 0.0, 0.0).astype(np.float64)
    size = (160, 120)
    proj = perspective(60.0, size[0] / size[1], 0.1, 80.0).astype(np.float64)
    want = s.wanted(0.0, eye, [c.id], proj @ view, view, proj, size)
    # the rooms one portal beyond first, then the shell seen through any window: it comes
    # when the link has carried everything else (it was never asked for before it showed)
    assert want[0] == c.id and want[-1] == outside
    assert set(want) == {c.id, *c.neighbours} and len(want) > 2



def _plain_and_turned(
    topo: Any, eye: np.ndarray, step: np.ndarray, view: np.ndarray, proj: np.ndarray, size: tuple[int, int]
) -> tuple[Any, list[int], list[int]]:
    """A streamer without turns ahead and one with them (+-90 degrees), both walked up to
    ``eye`` along ``step``: the plain one and what each predicts from there."""
    plain, turned = (_streamer(topo, RoomStreamConfig(turns_ahead_deg=t)) for t in ((), (90.0, -90.0)))
    for s in (plain, turned):
        for k in range(3):
            s.locate(eye - 0.25 * (2 - k) * step)
            s.observe(0.25 * k, eye - 0.25 * (2 - k) * step)
        s.locate(eye)
    return (plain, plain.predicted(eye, proj @ view, view, proj, size),
            turned.predicted(eye, proj @ view, view, proj, size))

def test_a_walker_through_a_door_is_predicted_to_look_both_ways(office_db: Path) -> None:
    topo = _topology(office_db)
    cells = {c.id: c for c in topo.cells}
    size = (160, 120)
    proj = perspective(60.0, size[0] / size[1], 0.1, 80.0).astype(np.float64)
    found = 0
    # each doorway of each room, the walker in it at 1.4 m/s on its way out of the room
    for c in (c for c in topo.cells if c.kind == "room"):
        for d in (cells[n] for n in c.neighbours if cells[n].kind == "doorway"):
            eye = np.array([*d.outline.mean(axis=0), c.zmin + 1.6])
            came = np.array([*c.outline.mean(axis=0), c.zmin + 1.6])
            if np.linalg.norm(eye - came) < 0.5:
                continue
            step = 1.4 * (eye - came) / np.linalg.norm(eye - came)
            view = camera(eye, float(np.arctan2(step[1], step[0])), 0.0).astype(np.float64)
            plain, a, b = _plain_and_turned(topo, eye, step, view, proj, size)
            # where the predicted eye first enters another cell, the views turned both ways
            entered = None
            cell = plain.current
            for h in plain.config.lookahead_s:
                e2 = eye + h * step
                nxt = plain._where.locate(e2, cell, anywhere=False)
                if nxt is None or not plain._where.holds(nxt, e2):
                    break
                cell = nxt
                if cell != plain.current:
                    entered = (cell, e2)
                    break
            if entered is None:
                assert b == a  # no door passed: nothing more
                continue
            cell, e2 = entered
            v2 = predicted_view(view, eye, e2)
            extra: set[int] = set()
            for deg in (90.0, -90.0):
                v3 = turned_view(v2, e2, deg)
                extra |= set(plain._cells_from(cell, e2, proj @ v3, v3, proj, size, margin_px=TOUCH_MARGIN_PX)[1])
            assert set(a) | extra <= set(b)
            found += bool(extra - set(a))
    assert found, "some door shows cells sideways that the walk straight on does not"


def test_a_walker_facing_a_wall_is_predicted_to_turn_before_it(office_db: Path) -> None:
    topo = _topology(office_db)
    size = (160, 120)
    proj = perspective(60.0, size[0] / size[1], 0.1, 80.0).astype(np.float64)
    found = 0
    for c in (c for c in topo.cells if c.kind == "room"):
        for yaw in np.radians([0.0, 90.0, 180.0, 270.0]):
            eye = np.array([*c.outline.mean(axis=0), c.zmin + 1.6])
            step = 1.4 * np.array([np.cos(yaw), np.sin(yaw), 0.0])
            view = camera(eye, float(yaw), 0.0).astype(np.float64)
            plain, a, b = _plain_and_turned(topo, eye, step, view, proj, size)
            # the last predicted pose still in the room before the walk would leave it through a wall
            last = None
            for h in plain.config.lookahead_s:
                e2 = eye + h * step
                nxt = plain._where.locate(e2, c.id, anywhere=False)
                if nxt is None or not plain._where.holds(nxt, e2):
                    break  # through a wall
                if nxt != c.id:
                    last = None  # through a door: not this case
                    break
                last = e2
            else:
                continue
            if last is None:
                continue
            v2 = predicted_view(view, eye, last)
            extra: set[int] = set()
            for deg in (90.0, -90.0):
                v3 = turned_view(v2, last, deg)
                extra |= set(plain._cells_from(c.id, last, proj @ v3, v3, proj, size, margin_px=TOUCH_MARGIN_PX)[1])
            assert set(a) | extra == set(b)
            found += bool(extra - set(a))
    assert found, "some wall ahead turns the view onto cells the walk straight on does not show"
