"""The request scheduler's decisions: one owner of the link's slots, every lane's wants by need time.

Fake lanes stand for the streamers: each holds a queue of ``(need_s, name)`` requests and
its own limit of requests in flight, as a streamer's own flow control would.
"""

from __future__ import annotations

import asyncio
from pathlib import Path

import pytest

from walkstream.client.stream.scheduler import Flight, Offer, RequestScheduler


class _Lane:
    """A content kind's wants: requests by need time, at most ``own`` in flight."""

    def __init__(self, sched: RequestScheduler, name: str, wants: list[float], own: int = 99) -> None:
        self.name = name
        self.wants = sorted(wants)
        self.own = own
        self.flying: list[str] = []
        self.sched = sched
        self.started: list[str] = []
        sched.join(self)

    def offer(self) -> Offer | None:
        if not self.wants or len(self.flying) >= self.own:
            return None
        need = self.wants[0]

        def start() -> None:
            self.wants.pop(0)
            tag = f"{self.name}{need:g}"
            self.flying.append(tag)
            self.sched.started_order.append(tag)  # type: ignore[attr-defined]

        return Offer(need, start)

    def in_flight(self) -> int:
        return len(self.flying)

    def outstanding_bytes(self) -> float:
        return 1000.0 * len(self.flying)


def _sched(slots: int) -> RequestScheduler:
    s = RequestScheduler(slots)
    s.started_order = []  # type: ignore[attr-defined]
    return s


def test_the_soonest_need_goes_first_across_lanes() -> None:
    s = _sched(slots=5)
    _Lane(s, "city", [0.0, 3.0, 9.0])
    _Lane(s, "rooms", [1.0, 2.0])
    assert s.dispatch() == 5
    assert s.started_order == ["city0", "rooms1", "rooms2", "city3", "city9"]  # type: ignore[attr-defined]


def test_a_tie_goes_to_the_lane_that_joined_first() -> None:
    s = _sched(slots=2)
    _Lane(s, "rooms", [0.0])
    _Lane(s, "city", [0.0])
    s.dispatch()
    assert s.started_order == ["rooms0", "city0"]  # type: ignore[attr-defined]


def test_the_slots_are_counted_over_every_lane() -> None:
    s = _sched(slots=3)
    city = _Lane(s, "city", [0.0, 1.0, 2.0, 3.0])
    rooms = _Lane(s, "rooms", [0.5, 1.5])
    assert s.dispatch() == 3 and s.in_flight() == 3
    assert s.started_order == ["city0", "rooms0.5", "city1"]  # type: ignore[attr-defined]
    assert s.dispatch() == 0  # full: nothing more until a request ends
    city.flying.pop(0)  # one landed: the slot goes to the soonest need, whichever lane
    assert s.dispatch() == 1
    assert s.started_order[-1] == "rooms1.5"  # type: ignore[attr-defined]
    assert rooms.wants == [] and city.wants == [2.0, 3.0]


def test_a_lane_at_its_own_limit_leaves_the_slot_to_the_others() -> None:
    s = _sched(slots=4)
    _Lane(s, "rooms", [0.0, 0.1, 0.2], own=1)  # one request in flight at most
    _Lane(s, "city", [5.0, 6.0, 7.0])
    assert s.dispatch() == 4
    assert s.started_order == ["rooms0", "city5", "city6", "city7"]  # type: ignore[attr-defined]


def test_a_lane_alone_decides_as_it_would_without_the_scheduler() -> None:
    """One lane: its own rules alone decide (the scheduler's slots are its own limit)."""
    s = _sched(slots=4)
    lane = _Lane(s, "city", [3.0, 1.0, 2.0, 0.0, 4.0], own=4)
    assert s.dispatch() == 4
    assert s.started_order == ["city0", "city1", "city2", "city3"]  # type: ignore[attr-defined]
    assert lane.wants == [4.0]
    s2 = _sched(slots=4)
    _Lane(s2, "city", [3.0, 1.0], own=4)
    assert s2.dispatch() == 2  # nothing more wanted: nothing more started


def test_a_lane_joins_once() -> None:
    s = _sched(slots=2)
    lane = _Lane(s, "city", [0.0])
    s.join(lane)
    assert s.lanes == [lane] and s.dispatch() == 1


def test_flights_are_cancelled_when_none_of_their_remaining_items_is_wanted() -> None:
    async def go() -> tuple[list[bool], int, list[Flight]]:
        s = RequestScheduler(4)
        city = _Lane(s, "city", [])
        rooms = _Lane(s, "rooms", [])
        gate = asyncio.Event()

        async def run(f: Flight) -> None:
            try:
                await gate.wait()
            finally:
                s.landed(f)

        a = s.launch(city, "objects", [1, 2, 3], run)
        b = s.launch(city, "objects", [4, 5], run)
        c = s.launch(city, "cells", [7], run)
        d = s.launch(rooms, "contents", [1, 2], run)  # another lane: its ids are its own
        a.left -= {1, 2}  # 1 and 2 arrived; 3 is still on its way
        await asyncio.sleep(0)
        n = s.cancel_unwanted(city, {"objects": {1, 2, 5}, "cells": {8}})
        await asyncio.sleep(0)
        left = s.flights()
        gate.set()
        await asyncio.gather(*(f.task for f in (a, b, c, d) if f.task is not None), return_exceptions=True)
        return [f.task is not None and f.task.cancelled() for f in (a, b, c, d)], n, left

    cancelled, n, left = asyncio.run(go())
    # a: only 3 is left and nobody wants it; b: 5 is wanted; c: cell 7 is not; d: not the city's
    assert cancelled == [True, False, True, False] and n == 2
    assert [f.ids for f in left] == [[4, 5], [1, 2]]


def test_a_landed_flight_frees_its_slot() -> None:
    async def go() -> list[int]:
        s = RequestScheduler(1)
        counts: list[int] = []

        class Lane:
            def __init__(self) -> None:
                self.todo = [[1], [2]]
                s.join(self)

            def offer(self) -> Offer | None:
                if not self.todo or s.flights(self):
                    return None
                ids = self.todo[0]

                def start() -> None:
                    self.todo.pop(0)
                    s.launch(self, "objects", ids, run)

                return Offer(0.0, start)

            def in_flight(self) -> int:
                return len(s.flights(self))

            def outstanding_bytes(self) -> float:
                return 0.0

        async def run(f: Flight) -> None:
            try:
                await asyncio.sleep(0)
            finally:
                s.landed(f)

        Lane()
        counts.append(s.dispatch())
        counts.append(s.dispatch())  # the one slot is taken
        while s.flights():
            await asyncio.sleep(0)
        counts.append(s.dispatch())
        return counts

    assert asyncio.run(go()) == [1, 0, 1]


@pytest.mark.parametrize("slots", [1, 2, 4])
def test_never_more_in_flight_than_the_slots(slots: int) -> None:
    s = _sched(slots)
    lanes = [_Lane(s, n, [float(k) for k in range(6)]) for n in ("a", "b", "c")]
    for _ in range(10):
        s.dispatch()
        assert s.in_flight() <= slots
        for lane in lanes:
            if lane.flying:
                lane.flying.pop(0)
                break
    assert s.in_flight() <= slots


def test_between_lanes_a_request_not_due_waits_while_the_link_is_covered() -> None:
    """56 kbit/s, 100 ms: a round trip of transfer is 700 B, the cover (3 of them) 2100 B;
    each fake request holds 1000 B."""
    s = _sched(slots=4)
    s.measure = lambda: (56_000.0, 0.1)
    city = _Lane(s, "city", [0.0, 30.0])
    rooms = _Lane(s, "rooms", [0.5, 1.0, 20.0])
    s.dispatch()
    # the needs due now go out; once 3 kB (more than the cover) are on the link, the
    # requests needed in 20 s and 30 s wait
    assert s.started_order == ["city0", "rooms0.5", "rooms1"]  # type: ignore[attr-defined]
    assert s.in_flight() == 3 and s.waits(20.0) and not s.waits(1.0)
    city.flying.clear()
    rooms.flying.pop(0)  # 1 kB left on the link: less than the cover, so the next ones may go
    s.dispatch()
    assert s.started_order[3:] == ["rooms20", "city30"]  # type: ignore[attr-defined]
    assert s.waits(40.0)  # 3 kB on the link again


def test_a_lane_alone_never_waits_for_the_cover() -> None:
    """Alone, a lane's own flow control decides (a scene of one kind: the decisions it made
    before the scheduler)."""
    s = _sched(slots=4)
    s.measure = lambda: (56_000.0, 0.2)
    _Lane(s, "rooms", [0.0, 10.0, 20.0, 30.0])
    assert s.dispatch() == 4 and not s.waits(99.0)


def test_the_rooms_lane_shares_the_slots_and_offers_at_its_own_tick_only(office_db: Path) -> None:
    """A room streamer on a shared scheduler: while the other lane holds the one slot its
    tick starts nothing; when the slot frees between its ticks it offers nothing (its
    wants are a frame's), and its next tick takes the slot."""
    import httpx
    import numpy as np

    from walkstream.client.clock import SimClock
    from walkstream.client.net.api import SceneClient
    from walkstream.client.stream.cache import Cache
    from walkstream.client.stream.rooms import RoomStreamConfig, RoomStreamer
    from walkstream.server.service.main import create_app
    from walkstream.shared.camera import camera, perspective

    async def go() -> list[tuple[int, int]]:
        clock = SimClock()
        s = _sched(slots=1)
        other = _Lane(s, "city", [])
        other.flying.append("city-bundle")  # the one slot, taken by the other lane
        transport = httpx.ASGITransport(app=create_app([office_db]))
        async with httpx.AsyncClient(transport=transport, base_url="http://t") as http:
            api = SceneClient(http, clock, office_db.stem)
            topo = await api.topology()
            rooms = RoomStreamer(api, clock, Cache(64 << 20), topo, RoomStreamConfig(), scheduler=s)
            size = (160, 120)
            proj = perspective(60.0, size[0] / size[1], 0.1, 80.0).astype(np.float64)
            room = next(c for c in topo.cells if c.kind == "room")
            lo, hi = room.outline.min(axis=0), room.outline.max(axis=0)
            eye = np.array([*(lo + hi) / 2, room.zmin + 1.6])
            view = camera(eye, 0.3, 0.0).astype(np.float64)
            seen: list[tuple[int, int]] = []
            rooms.tick(0.0, eye, proj @ view, view, proj, size)
            seen.append((rooms.in_flight(), s.in_flight()))  # the slot is taken: nothing
            other.flying.clear()
            s.dispatch()  # the other lane's request ended: a dispatch between the rooms' ticks
            seen.append((rooms.in_flight(), s.in_flight()))
            rooms.tick(0.04, eye, proj @ view, view, proj, size)
            seen.append((rooms.in_flight(), s.in_flight()))  # its tick: the visible cells go
            await rooms.close()
            return seen

    assert asyncio.run(go()) == [(0, 1), (0, 0), (1, 1)]
