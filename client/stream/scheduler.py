"""The request scheduler: one owner of the link's request slots, serving every content kind by need time.

A walk has one link, and several kinds of content want it: a city's index tiles, cell
records and objects (:class:`~walkstream.client.stream.streamer.Streamer`), an
interior's cell contents (:class:`~walkstream.client.stream.rooms.RoomStreamer`).  Each
streamer is a :class:`Lane` of one :class:`RequestScheduler`: it knows its own wants
and how it batches them, and when asked (:meth:`Lane.offer`) names the one request it
would start next and when the first thing in it is needed (seconds from now).  The
scheduler (:meth:`RequestScheduler.dispatch`) starts, while the link has a free slot
(:attr:`RequestScheduler.slots`, counted over every lane), the offer needed soonest;
lanes that tie go in the order they joined.  A lane keeps its own flow control (the
city's cover of a round trip of bytes, the rooms' requests in flight), so a lane alone
on the link makes exactly the decisions it made before there was a scheduler.  What the
scheduler adds is the choice between kinds, the one count of slots, and, once two lanes
share the link, a wait (:meth:`RequestScheduler.waits`): a request not due yet stays
back while the bytes on the link, every lane's, cover a few round trips of transfer, so
that what comes up meanwhile (a room coming into view through a door) is not queued
behind another kind's prefetch, and what goes later is picked from fresher wants.

One slot beyond :attr:`RequestScheduler.slots` is kept for an **urgent** offer
(:attr:`Offer.urgent`): content needed now that came up suddenly, such as the textures
of the virtual walls a walker turning at a corner sees only then.  It goes out at once
with every slot taken, and while it is on the link nothing needed later than
:data:`HOLD_S` starts (a prefetch or a texture far ahead would take a share of the
link from it); what is needed sooner still does.

Every request a lane starts through :meth:`RequestScheduler.launch` is a
:class:`Flight` (its items, those not yet received, its task) until the lane says it
:meth:`~RequestScheduler.landed`; :meth:`RequestScheduler.cancel_unwanted` cancels a
lane's flights none of whose remaining items is wanted any more.

The scheduler never blocks the frame loop: it starts tasks and returns.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Collection, Coroutine, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

__all__ = ["HOLD_S", "Flight", "Lane", "Offer", "RequestScheduler"]


@dataclass(frozen=True)
class Offer:
    """The request a lane would start next.

    Attributes
    ----------
    need_s
        Seconds from now until the first of its items is needed (0: now).
    start
        Starts it (called once, by the scheduler, when it goes out).
    """

    need_s: float
    start: Callable[[], object]
    urgent: bool = False
    """It may go out when every slot is taken, in one slot kept beyond
    :attr:`RequestScheduler.slots` for such requests (a lane offers it for content
    needed now that came up suddenly, such as the texture of a wall the walker turns
    to, and never has two of them on the link)."""


HOLD_S = 1.0
"""While an urgent request (:attr:`Offer.urgent`) is on the link, offers needed later
than this many seconds wait.  Perfect frames at 56 kbit/s on the production hall's tour
(60 s) / the seed-5 hall's (30 s) / the small test hall's walk: 1 s 96.4 / 92.7 /
100 %; 0 (all but what is needed now wait) 97.8 / 91.9 / 98.1 % (the small hall's
prefetch stalled behind its second textures request); none waiting 96.3 / 88.3 %;
without the urgent slot 97.0 / 89.4 / 100 %."""


class Lane(Protocol):
    """One content kind's side of the link (a streamer)."""

    def offer(self) -> Offer | None:
        """The request this lane would start now, by its own rules, or None."""

    def in_flight(self) -> int:
        """Requests of this lane on the link now (those started outside the scheduler too)."""

    def outstanding_bytes(self) -> float:
        """Bytes this lane asked for and has not received yet (estimated)."""


@dataclass(eq=False)
class Flight:
    """One request on the link.

    Attributes
    ----------
    lane
        The lane that started it.
    kind
        What it asks for, in the lane's words (``objects``, ``cells``, ``contents``).
    ids
        Its items, in the order asked.
    left
        The items not received yet.
    task
        The task running it.
    """

    lane: Lane
    kind: str
    ids: list[int]
    left: set[int] = field(default_factory=set)
    task: asyncio.Task[None] | None = None
    urgent: bool = False
    """Started from an :attr:`Offer.urgent` offer."""


class RequestScheduler:
    """Owns the link's request slots; starts the wants of every lane by need time.

    Parameters
    ----------
    slots
        Most requests on the link at once, over every lane.
    cover
        Between lanes, a request not due yet waits while the bytes asked for and not
        received, every lane's, cover this many round trips of transfer (on the
        crossing walk ``enter`` 3 gave 98.7 and 98.0 % perfect frames at 56 kbit/s and
        over GPRS, against 97.0 and 98.0 % with each streamer scheduling its own
        requests; on a 400 m city 99.9 and 99.9 % against 98.9 and 99.9 %; 1 and 2,
        tried before the rooms' streamer offered at its own tick only, gave 96.5 and
        97.1 % at 56 kbit/s, 99.6 % over GPRS).
    margin_s
        A request is due when its need is within two round trips, the transfer of what
        is on the link, and this margin.
    """

    def __init__(self, slots: int = 4, cover: float = 3.0, margin_s: float = 1.5) -> None:
        self.slots = slots
        self.cover = cover
        self.margin_s = margin_s
        self.measure: Callable[[], tuple[float, float]] | None = None
        """The link's bandwidth (bit/s) and round trip (s) as measured (set by the
        first lane that measures them); without it no request waits for the cover."""
        self.lanes: list[Lane] = []
        """The lanes, in the order they joined (the order of ties)."""
        self._flights: dict[asyncio.Task[None], Flight] = {}
        self._urgent = False  # the offer being started is urgent
        self.hold_s = HOLD_S
        """While an urgent request is on the link, offers needed later than this many
        seconds wait (:data:`HOLD_S`)."""
        self.started: dict[int, int] = {}
        """Requests started, by lane (its index in :attr:`lanes`)."""

    def join(self, lane: Lane) -> None:
        """Add a lane (once)."""
        if all(lane is not x for x in self.lanes):
            self.lanes.append(lane)

    def in_flight(self) -> int:
        """Requests on the link now, every lane's."""
        return sum(lane.in_flight() for lane in self.lanes)

    def outstanding_bytes(self) -> float:
        """Bytes asked for and not received yet, every lane's."""
        return sum(lane.outstanding_bytes() for lane in self.lanes)

    def dispatch(self) -> int:
        """Start requests while the link has a free slot: each time the offer needed
        soonest (the earlier lane on a tie), unless it :meth:`waits`; with every slot
        taken, one more for an :attr:`Offer.urgent` offer.  Returns how many were
        started."""
        n = 0
        while True:
            urgent = self.urgent_in_flight()
            free = self.in_flight() - int(urgent) < self.slots  # the urgent one has its own slot
            if not free and urgent:
                break
            best: tuple[float, int, Offer] | None = None
            for k, lane in enumerate(self.lanes):
                o = lane.offer()
                if o is None or not (free or (o.urgent and not urgent)):
                    continue  # every slot taken: the one beyond is kept for an urgent offer
                if best is None or o.need_s < best[0]:
                    best = (o.need_s, k, o)
            if best is None or self.waits(best[0]):
                break
            if best[0] > self.hold_s and urgent:
                break  # what is not needed soon waits for the urgent request (it has the link)
            self._urgent = best[2].urgent
            try:
                best[2].start()
            finally:
                self._urgent = False
            self.started[best[1]] = self.started.get(best[1], 0) + 1
            n += 1
        return n

    def urgent_in_flight(self) -> bool:
        """Whether an urgent request (:attr:`Offer.urgent`) is on the link."""
        return any(f.urgent for f in self._flights.values())

    def waits(self, need_s: float) -> bool:
        """Whether a request needed in ``need_s`` seconds waits: with more than one lane,
        while the link's outstanding bytes cover :attr:`cover` round trips and it is not
        due (its need beyond two round trips, the transfer of those bytes and
        :attr:`margin_s`).  Asking later keeps the link free for a need that comes up
        meanwhile (a room that comes into view), and what is asked later is chosen
        from fresher wants; a lane alone keeps only its own flow control."""
        if len(self.lanes) < 2 or self.measure is None or not self.in_flight():
            return False
        bps, rtt = self.measure()
        bps8 = max(bps, 1.0) / 8.0
        out = self.outstanding_bytes()
        if out < self.cover * bps8 * rtt:
            return False
        return need_s > 2.0 * rtt + out / bps8 + self.margin_s

    # -- flights ---------------------------------------------------------------

    def launch(
        self,
        lane: Lane,
        kind: str,
        ids: Sequence[int],
        run: Callable[[Flight], Coroutine[Any, Any, None]],
    ) -> Flight:
        """Start ``run(flight)`` as a task for a request of ``ids``; the lane calls
        :meth:`landed` when it ends, however it ends."""
        f = Flight(lane, kind, list(ids), set(ids), urgent=self._urgent)
        f.task = asyncio.ensure_future(run(f))
        self._flights[f.task] = f
        return f

    def landed(self, flight: Flight) -> None:
        """``flight`` ended (whole, cut, refused or cancelled)."""
        if flight.task is not None:
            self._flights.pop(flight.task, None)

    def flights(self, lane: Lane | None = None) -> list[Flight]:
        """The requests on the link started through :meth:`launch` (``lane``'s only,
        when given), in the order they started."""
        return [f for f in self._flights.values() if lane is None or f.lane is lane]

    def cancel_unwanted(self, lane: Lane, wanted: Mapping[str, Collection[int]]) -> int:
        """Cancel ``lane``'s flights none of whose remaining items is in ``wanted[kind]``
        (what already arrived is kept); returns how many."""
        n = 0
        for f in self.flights(lane):
            want = wanted.get(f.kind, ())
            if f.task is not None and not any(i in want for i in f.left):
                f.task.cancel()
                n += 1
        return n
