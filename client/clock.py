"""Two clocks for the client: real time, and simulated time that runs only when idle.

All client code asks a :class:`Clock` for the time and sleeps on it, never on
:func:`asyncio.sleep` or :func:`time.monotonic` directly.  That one indirection lets
the same streamer, link and frame loop run

- under :class:`RealClock`: wall-clock seconds, ``sleep`` is :func:`asyncio.sleep`;
- under :class:`SimClock`: virtual seconds that jump from one pending sleeper to the
  next as soon as the whole program is waiting on the clock.  A 10-minute walk
  replays in seconds, and the order of events is deterministic.

Real work inside a simulation (network I/O to a real server, a thread that rebuilds
geometry) is wrapped in :meth:`Clock.busy`: while a busy section is open the virtual
clock stands still and the driver really waits for it, so that work costs no virtual
time unless the code charges it explicitly with :meth:`Clock.advance` (how frames
and rewrites account for the CPU time they really took).

Examples
--------
>>> clock = SimClock()
>>> async def walk() -> float:
...     for _ in range(3):
...         await clock.sleep(0.5)
...     return clock.now()
>>> clock.run(walk())
1.5
"""

from __future__ import annotations

import asyncio
import contextlib
import heapq
import math
import threading
import time
import weakref
from collections.abc import Callable, Coroutine
from types import TracebackType
from typing import Any, Protocol, TypeVar, runtime_checkable

from walkstream.client.tasks import reap
from walkstream.shared.errors import SimulationStalled, WalkstreamError

__all__ = ["Clock", "RealClock", "SimClock", "within"]

T = TypeVar("T")

# Without CPython's ``loop._ready`` (another loop implementation) settling falls back
# to this many bare yields, enough for the chains of callbacks asyncio and anyio make.
_FALLBACK_YIELDS = 32




@runtime_checkable
class Clock(Protocol):
    """What client code needs from a clock; see :class:`RealClock` and :class:`SimClock`."""

    #: True for virtual time (:class:`SimClock`).
    simulated: bool

    def now(self) -> float:
        """Seconds since the clock started."""
        ...

    async def sleep(self, seconds: float) -> None:
        """Wait ``seconds`` of clock time (<= 0: just yield to other tasks)."""
        ...

    async def sleep_until(self, t: float) -> None:
        """Wait until :meth:`now` >= ``t``; ``math.inf`` waits until cancelled."""
        ...

    async def advance(self, seconds: float) -> None:
        """Charge ``seconds`` of CPU work that already happened to the clock."""
        ...

    def busy(self) -> contextlib.AbstractContextManager[None]:
        """Mark real work in progress that the simulated clock must wait for."""
        ...

    async def run_busy(self, fn: Callable[..., T], *args: Any) -> T:
        """Run the sync ``fn(*args)`` in the default thread executor under :meth:`busy`."""
        ...


def _check_seconds(seconds: float, what: str) -> float:
    seconds = float(seconds)
    if math.isnan(seconds):
        raise WalkstreamError(f"{what}: {seconds!r} is not a time")
    return seconds


class RealClock:
    """Wall-clock time from :func:`time.monotonic`, counted from construction.

    ``busy()`` is a no-op and ``advance()`` only yields: real work takes real time
    already.
    """

    simulated = False

    def __init__(self) -> None:
        self._t0 = time.monotonic()

    def now(self) -> float:
        """Seconds since this clock was made."""
        return time.monotonic() - self._t0

    async def sleep(self, seconds: float) -> None:
        """:func:`asyncio.sleep` (``seconds`` <= 0 yields once, ``inf`` never returns)."""
        seconds = _check_seconds(seconds, "RealClock.sleep")
        if seconds == math.inf:
            await asyncio.get_running_loop().create_future()
        await asyncio.sleep(max(0.0, seconds))

    async def sleep_until(self, t: float) -> None:
        """Sleep until :meth:`now` >= ``t``; ``math.inf`` waits until cancelled."""
        t = _check_seconds(t, "RealClock.sleep_until")
        if t == math.inf:
            await asyncio.get_running_loop().create_future()
        await asyncio.sleep(max(0.0, t - self.now()))

    async def advance(self, seconds: float) -> None:
        """Yield only: under real time the work has already taken its time."""
        await asyncio.sleep(0)

    def busy(self) -> contextlib.AbstractContextManager[None]:
        """A no-op context manager."""
        return contextlib.nullcontext()

    async def run_busy(self, fn: Callable[..., T], *args: Any) -> T:
        """Run ``fn(*args)`` in the default thread executor."""
        return await asyncio.get_running_loop().run_in_executor(None, fn, *args)


class _Busy:
    """One open busy section of a :class:`SimClock` (re-entrant-safe counter)."""

    __slots__ = ("_clock",)

    def __init__(self, clock: SimClock) -> None:
        self._clock = clock

    def __enter__(self) -> None:
        self._clock._enter_busy()

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self._clock._exit_busy()


class SimClock:
    """Virtual time that moves only when the whole program waits on the clock.

    :meth:`run` runs a main coroutine in a fresh event loop next to a driver.  The
    driver repeatedly (1) lets the event loop settle until nothing but the driver is
    ready to run, (2) if a :meth:`busy` section is open, really waits for all of them
    to close and starts over, (3) otherwise jumps virtual time to the earliest
    deadline and wakes every sleeper due then, in the order they went to sleep.

    Sleepers at ``math.inf`` never wake.  When nothing sleeps with a finite deadline,
    nothing is busy and main has not finished, :class:`SimulationStalled` is raised.
    When main finishes, every other task is cancelled and awaited before the loop
    closes.

    Parameters
    ----------
    start
        Virtual time at which the clock starts, seconds.
    """

    simulated = True

    def __init__(self, start: float = 0.0) -> None:
        self._now = float(start)
        # (deadline, sequence, future): the sequence makes equal deadlines FIFO and
        # keeps futures out of tuple comparisons.
        self._heap: list[tuple[float, int, asyncio.Future[None]]] = []
        self._seq = 0
        self._dead = 0  # cancelled entries still in the heap
        self._forever = 0  # tasks sleeping until math.inf
        self._busy = 0
        self._busy_lock = threading.Lock()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._loop_thread: int | None = None
        self._wake: asyncio.Event | None = None
        self._running = False
        # Creation order of the simulation's tasks: all_tasks() is a set, and the
        # shutdown must cancel in a reproducible order.
        self._order: weakref.WeakKeyDictionary[asyncio.Task[Any], int] = weakref.WeakKeyDictionary()
        self._created = 0

    # -- the Clock interface -------------------------------------------------------

    def now(self) -> float:
        """Virtual seconds."""
        return self._now

    async def sleep(self, seconds: float) -> None:
        """Wait ``seconds`` of virtual time (<= 0: just yield to other tasks)."""
        seconds = _check_seconds(seconds, "SimClock.sleep")
        if seconds <= 0.0:
            await asyncio.sleep(0)
            return
        await self.sleep_until(self._now + seconds)

    async def sleep_until(self, t: float) -> None:
        """Wait until virtual time ``t``; ``math.inf`` waits until cancelled.

        A deadline that has passed yields once and returns.

        Raises
        ------
        WalkstreamError
            When called outside :meth:`run` (nothing would ever wake the sleeper).
        """
        t = _check_seconds(t, "SimClock.sleep_until")
        loop = self._loop
        if loop is None or not self._running:
            raise WalkstreamError(
                "SimClock.sleep outside SimClock.run: nothing would advance virtual time"
            )
        if t <= self._now:
            await asyncio.sleep(0)
            return
        fut: asyncio.Future[None] = loop.create_future()
        if t == math.inf:
            self._forever += 1
            try:
                await fut
            finally:
                self._forever -= 1
            return
        self._seq += 1
        heapq.heappush(self._heap, (t, self._seq, fut))
        try:
            await fut
        except asyncio.CancelledError:
            if fut.cancelled():  # still in the heap: the driver will skip it
                self._dead += 1
                self._compact()
            raise

    async def advance(self, seconds: float) -> None:
        """Charge ``seconds`` of CPU work to virtual time (same as :meth:`sleep`)."""
        await self.sleep(seconds)

    def busy(self) -> contextlib.AbstractContextManager[None]:
        """Context manager: while open, virtual time stands still and the driver waits.

        Enter it from the event loop's thread before handing work to real I/O or a
        thread (``with clock.busy(): data = await real_socket_read()``); it may be
        exited from any thread.
        """
        return _Busy(self)

    async def run_busy(self, fn: Callable[..., T], *args: Any) -> T:
        """Run ``fn(*args)`` in the default thread executor; virtual time waits for it."""
        loop = asyncio.get_running_loop()
        with self.busy():
            return await loop.run_in_executor(None, fn, *args)

    # -- running -------------------------------------------------------------------

    def run(self, main: Coroutine[Any, Any, T]) -> T:
        """Run ``main`` under virtual time in a fresh event loop (like :func:`asyncio.run`).

        Returns
        -------
        T
            What ``main`` returns; its exception propagates.

        Raises
        ------
        SimulationStalled
            When the program waits but nothing it waits for can happen.
        """
        return asyncio.run(self.drive(main))

    async def drive(self, main: Coroutine[Any, Any, T]) -> T:
        """Run ``main`` under virtual time inside the running event loop.

        The coroutine form of :meth:`run`, for callers that already have a loop; every
        other task of that loop counts as part of the simulation.
        """
        if self._running:
            main.close()  # never to be awaited: close it instead of leaking a warning
            raise WalkstreamError("SimClock is already driving a simulation")
        loop = asyncio.get_running_loop()
        self._loop = loop
        self._loop_thread = threading.get_ident()
        self._wake = asyncio.Event()
        self._running = True
        previous_factory = loop.get_task_factory()
        loop.set_task_factory(self._task_factory(previous_factory))
        task = loop.create_task(main)
        try:
            await self._drive_until(task, shutting_down=False)
        finally:
            try:
                await self._shutdown()
            finally:
                self._running = False
                loop.set_task_factory(previous_factory)
        return task.result()

    def _task_factory(self, previous: Any) -> Any:
        def factory(
            loop: asyncio.AbstractEventLoop, coro: Any, **kwargs: Any
        ) -> asyncio.Future[Any]:
            if previous is None:
                task: asyncio.Future[Any] = asyncio.Task(coro, loop=loop, **kwargs)
            else:
                task = previous(loop, coro, **kwargs)
            if isinstance(task, asyncio.Task):
                self._created += 1
                self._order[task] = self._created
            return task

        return factory

    def _others(self) -> list[asyncio.Task[Any]]:
        """Unfinished tasks other than the driver, oldest first."""
        me = asyncio.current_task()
        tasks = [t for t in asyncio.all_tasks() if t is not me and not t.done()]
        tasks.sort(key=lambda t: self._order.get(t, 0))
        return tasks

    async def _shutdown(self) -> None:
        """Cancel and await every other task, still driving the clock for them."""
        for _ in range(3):  # main first, if a stall left it unfinished
            others = self._others()
            if not others:
                return
            for t in others:
                t.cancel()
            gathered = asyncio.gather(*others, return_exceptions=True)
            await self._drive_until(gathered, shutting_down=True)

    async def _settle(self, loop: asyncio.AbstractEventLoop) -> None:
        """Yield until no other callback is ready to run."""
        ready = getattr(loop, "_ready", None)
        await asyncio.sleep(0)
        if ready is None:
            for _ in range(_FALLBACK_YIELDS):
                await asyncio.sleep(0)
            return
        while ready:
            await asyncio.sleep(0)

    async def _drive_until(self, done: asyncio.Future[Any], *, shutting_down: bool) -> None:
        loop = asyncio.get_running_loop()
        wake = self._wake
        assert wake is not None
        heap = self._heap
        # Finishing must wake a driver that waits for busy sections to close.
        done.add_done_callback(lambda _: wake.set())
        while not done.done():
            await self._settle(loop)
            if done.done():
                return
            if self._busy:
                # Real work in progress: wait for it, really, then settle again.
                while self._busy and not done.done():
                    wake.clear()
                    if self._busy:
                        await wake.wait()
                continue
            while heap and heap[0][2].done():  # cancelled sleepers
                heapq.heappop(heap)
                self._dead -= 1
            if not heap:
                if shutting_down:
                    return
                raise self._stalled()
            deadline = heap[0][0]
            if deadline > self._now:
                self._now = deadline
            while heap and heap[0][0] <= deadline:
                fut = heapq.heappop(heap)[2]
                if fut.done():
                    self._dead -= 1
                else:
                    fut.set_result(None)

    def _stalled(self) -> SimulationStalled:
        waiting = self._others()
        names = ", ".join(_describe(t) for t in waiting[:5])
        more = f" and {len(waiting) - 5} more" if len(waiting) > 5 else ""
        forever = f"; {self._forever} of them sleep forever" if self._forever else ""
        return SimulationStalled(
            f"simulation stalled at t={self._now:.6g} s: {len(waiting)} task(s) wait, but none "
            f"sleeps on the clock with a finite deadline and no busy() section is open"
            f"{forever} (tasks: {names}{more})"
        )

    def _compact(self) -> None:
        # Cancelled sleepers (timeouts that did not fire) would otherwise pile up.
        if self._dead > 64 and self._dead * 2 > len(self._heap):
            self._heap[:] = [e for e in self._heap if not e[2].done()]
            heapq.heapify(self._heap)
            self._dead = 0

    # -- busy bookkeeping ------------------------------------------------------------

    def _enter_busy(self) -> None:
        with self._busy_lock:
            self._busy += 1

    def _exit_busy(self) -> None:
        with self._busy_lock:
            self._busy -= 1
            idle = self._busy == 0
        if idle and self._wake is not None and self._loop is not None:
            if threading.get_ident() == self._loop_thread:
                self._wake.set()
            elif not self._loop.is_closed():
                self._loop.call_soon_threadsafe(self._wake.set)


def _describe(task: asyncio.Task[Any]) -> str:
    coro = task.get_coro()
    name = getattr(coro, "__qualname__", None) or type(coro).__name__
    return f"{task.get_name()}:{name}"


async def within(clock: Clock, seconds: float, coro: Any) -> Any:
    """``await coro``, or ``None`` when it takes longer than ``seconds`` on ``clock``."""
    task = asyncio.ensure_future(coro)
    timer = asyncio.ensure_future(clock.sleep(seconds))
    try:
        await asyncio.wait({task, timer}, return_when=asyncio.FIRST_COMPLETED)
    except asyncio.CancelledError:
        await reap([task, timer])
        raise
    await reap([timer])
    if task.done():
        return task.result()
    await reap([task])
    return None
