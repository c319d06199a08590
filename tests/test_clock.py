"""Real and simulated clocks (client.clock)."""

from __future__ import annotations

import asyncio
import math
import threading
import time

import pytest

from walkstream.client.clock import Clock, RealClock, SimClock
from walkstream.shared.errors import SimulationStalled, WalkstreamError


def test_both_clocks_are_clocks() -> None:
    assert isinstance(SimClock(), Clock) and SimClock().simulated
    assert isinstance(RealClock(), Clock) and not RealClock().simulated


def test_sleepers_wake_in_deadline_order_at_their_deadline() -> None:
    clock = SimClock()
    log: list[tuple[str, float]] = []

    async def sleeper(name: str, seconds: float) -> None:
        await clock.sleep(seconds)
        log.append((name, clock.now()))

    async def main() -> float:
        await asyncio.gather(
            sleeper("c", 3.0), sleeper("a", 1.0), sleeper("d", 1e6), sleeper("b", 2.5)
        )
        return clock.now()

    assert clock.run(main()) == 1e6
    assert log == [("a", 1.0), ("b", 2.5), ("c", 3.0), ("d", 1e6)]


def test_equal_deadlines_wake_first_in_first_out() -> None:
    clock = SimClock()
    order: list[int] = []

    async def sleeper(i: int) -> None:
        await clock.sleep_until(5.0)
        order.append(i)

    async def main() -> None:
        tasks = []
        for i in (4, 1, 3, 0, 2, 7, 6, 5):
            tasks.append(asyncio.create_task(sleeper(i)))
            await asyncio.sleep(0)  # registered in this order
        await asyncio.gather(*tasks)

    clock.run(main())
    assert order == [4, 1, 3, 0, 2, 7, 6, 5]


def test_simulations_are_deterministic() -> None:
    def once() -> list[tuple[int, float]]:
        clock = SimClock()
        log: list[tuple[int, float]] = []

        async def worker(i: int) -> None:
            for k in range(20):
                await clock.sleep(((i * 7 + k * 3) % 5) * 0.1)
                log.append((i, clock.now()))

        async def main() -> None:
            await asyncio.gather(*(worker(i) for i in range(6)))

        clock.run(main())
        return log

    first = once()
    assert len(first) == 120 and first == once()


def test_non_positive_sleeps_only_yield() -> None:
    clock = SimClock()

    async def main() -> float:
        await clock.sleep(0)
        await clock.sleep(-3)
        await clock.sleep(2)
        await clock.sleep_until(1.0)  # in the past
        return clock.now()

    assert clock.run(main()) == 2.0


def test_advance_charges_work_to_virtual_time() -> None:
    clock = SimClock(start=10.0)

    async def main() -> float:
        await clock.advance(0.25)
        return clock.now()

    assert clock.run(main()) == 10.25


def test_fifteen_thousand_frames_simulate() -> None:
    # a 10-minute walk at 25 fps; only the virtual result is asserted
    clock = SimClock()

    async def main() -> tuple[int, float]:
        frames = 0
        for _ in range(15_000):
            await clock.sleep(0.04)
            frames += 1
        return frames, clock.now()

    frames, now = clock.run(main())
    assert frames == 15_000 and now == pytest.approx(600.0, abs=1e-6)


def test_stall_is_detected_and_names_the_tasks() -> None:
    clock = SimClock()
    cancelled: list[str] = []

    async def waits_forever(event: asyncio.Event) -> None:
        try:
            await event.wait()
        except asyncio.CancelledError:
            cancelled.append("helper")
            raise

    async def main() -> None:
        event = asyncio.Event()
        helper = asyncio.create_task(waits_forever(event), name="helper")
        await clock.sleep(3)
        await helper

    with pytest.raises(SimulationStalled, match=r"t=3 s: 2 task\(s\) wait") as info:
        clock.run(main())
    assert "helper" in str(info.value) and isinstance(info.value, WalkstreamError)
    assert cancelled == ["helper"]


def test_real_time_sleep_inside_a_simulation_stalls() -> None:
    clock = SimClock()

    async def main() -> None:
        await asyncio.sleep(3600)  # real time: nothing the clock can wake

    with pytest.raises(SimulationStalled, match=r"1 task\(s\)"):
        clock.run(main())


def test_everything_asleep_forever_is_a_stall() -> None:
    clock = SimClock()

    async def main() -> None:
        await clock.sleep_until(math.inf)

    with pytest.raises(SimulationStalled, match="1 of them sleep forever"):
        clock.run(main())


def test_infinite_sleepers_never_wake_and_are_cancelled_at_the_end() -> None:
    clock = SimClock()
    events: list[str] = []

    async def forever() -> None:
        try:
            await clock.sleep(math.inf)
            events.append("woke")
        except asyncio.CancelledError:
            events.append(f"cancelled at {clock.now()}")
            raise

    async def main() -> float:
        asyncio.create_task(forever())
        await clock.sleep(60)
        return clock.now()

    assert clock.run(main()) == 60.0
    assert events == ["cancelled at 60.0"]


def test_leftover_tasks_are_cancelled_and_may_clean_up_on_the_clock() -> None:
    clock = SimClock()
    events: list[tuple[str, float]] = []

    async def background(name: str) -> None:
        try:
            await clock.sleep(1e9)
        finally:
            await clock.sleep(0.5)  # cleanup that itself takes virtual time
            events.append((name, clock.now()))

    async def main() -> str:
        for name in ("x", "y"):
            asyncio.create_task(background(name))
        await clock.sleep(2)
        return "done"

    assert clock.run(main()) == "done"
    assert events == [("x", 2.5), ("y", 2.5)]


def test_cancelled_sleepers_do_not_wake_or_pile_up() -> None:
    clock = SimClock()
    woke: list[int] = []

    async def sleeper(i: int) -> None:
        await clock.sleep(10 + i)
        woke.append(i)

    async def main() -> int:
        tasks = [asyncio.create_task(sleeper(i)) for i in range(500)]
        await clock.sleep(1)
        for t in tasks[1:]:
            t.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        return len(clock._heap)

    left = clock.run(main())
    assert woke == [0] and left < 500


def test_main_exception_propagates_after_clean_shutdown() -> None:
    clock = SimClock()
    stopped: list[bool] = []

    async def background() -> None:
        try:
            await clock.sleep(100)
        except asyncio.CancelledError:
            stopped.append(True)
            raise

    async def main() -> None:
        asyncio.create_task(background())
        await clock.sleep(1)
        raise KeyError("boom")

    with pytest.raises(KeyError, match="boom"):
        clock.run(main())
    assert stopped == [True]


def test_busy_sections_freeze_virtual_time_until_they_close() -> None:
    clock = SimClock()
    log: list[tuple[str, float]] = []

    def slow_work(x: int) -> int:
        time.sleep(0.05)  # real work in a thread
        return x * 2

    async def ticker() -> None:
        for _ in range(3):
            await clock.sleep(1)
            log.append(("tick", clock.now()))

    async def main() -> None:
        tick = asyncio.create_task(ticker())
        assert await clock.run_busy(slow_work, 21) == 42
        log.append(("thread", clock.now()))
        with clock.busy():
            await asyncio.sleep(0.02)  # stand-in for real socket I/O
        log.append(("io", clock.now()))
        await tick

    clock.run(main())
    assert log == [("thread", 0.0), ("io", 0.0), ("tick", 1.0), ("tick", 2.0), ("tick", 3.0)]


def test_busy_may_close_from_another_thread() -> None:
    clock = SimClock()

    async def main() -> float:
        section = clock.busy()
        section.__enter__()
        threading.Timer(0.02, section.__exit__, (None, None, None)).start()
        await clock.sleep(1)  # may only run once the section closed
        return clock.now()

    assert clock.run(main()) == 1.0


def test_sleeping_outside_a_simulation_is_refused() -> None:
    clock = SimClock()
    with pytest.raises(WalkstreamError, match="outside SimClock.run"):
        asyncio.run(clock.sleep(1))


def test_nan_is_not_a_time() -> None:
    clock = SimClock()

    async def main() -> None:
        await clock.sleep(math.nan)

    with pytest.raises(WalkstreamError, match="not a time"):
        clock.run(main())


def test_drive_runs_inside_an_existing_loop_once_at_a_time() -> None:
    clock = SimClock()

    async def inner() -> float:
        await clock.sleep(4)
        return clock.now()

    async def nested() -> float:
        return await clock.drive(inner())

    async def outer() -> float:
        got = await clock.drive(inner())
        with pytest.raises(WalkstreamError, match="already"):
            await clock.drive(nested())
        return got

    assert asyncio.run(outer()) == 4.0
    assert clock.run(inner()) == 8.0  # the clock goes on where it stopped


def test_real_clock() -> None:
    clock = RealClock()

    async def main() -> tuple[float, float, int]:
        t0 = clock.now()
        await clock.sleep(0.01)
        await clock.sleep_until(clock.now() + 0.01)
        await clock.advance(5.0)  # real work already took its time: no sleep
        with clock.busy():
            pass
        with pytest.raises(TimeoutError):
            await asyncio.wait_for(clock.sleep_until(math.inf), 0.01)
        value = await clock.run_busy(lambda a, b: a + b, 2, 3)
        return t0, clock.now(), value

    t0, t1, value = asyncio.run(main())
    assert 0 <= t0 and t1 >= t0 + 0.02 and value == 5
