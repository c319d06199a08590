"""Stopping tasks: a Ctrl-C that lands while the client stops its tasks is never lost."""

from __future__ import annotations

import asyncio

import pytest

from walkstream.client.clock import RealClock, within
from walkstream.client.tasks import reap


async def _slow_to_stop(stopping: asyncio.Event) -> None:
    """A task that takes a moment to wind down once cancelled (a request closing its socket)."""
    try:
        await asyncio.sleep(30)
    except asyncio.CancelledError:
        stopping.set()
        await asyncio.sleep(0.05)
        raise


def test_a_cancellation_of_the_caller_during_reap_goes_on() -> None:
    async def main() -> tuple[bool, bool]:
        stopping = asyncio.Event()
        child = asyncio.ensure_future(_slow_to_stop(stopping))
        await asyncio.sleep(0)

        async def caller() -> str:
            await reap([child])
            return "walked on"  # what a swallowed Ctrl-C looks like

        outer = asyncio.ensure_future(caller())
        await stopping.wait()
        outer.cancel()  # Ctrl-C while the child is still stopping
        with pytest.raises(asyncio.CancelledError):
            await outer
        return child.done(), child.cancelled()

    assert asyncio.run(main()) == (True, True)  # and the child was not abandoned half-stopped


def test_reap_swallows_the_tasks_own_ending() -> None:
    async def main() -> str:
        async def fails() -> None:
            raise ValueError("the task's own failure")

        stopping = asyncio.Event()
        failed = asyncio.ensure_future(fails())
        await asyncio.sleep(0)
        await reap([failed, asyncio.ensure_future(_slow_to_stop(stopping))])
        return "went on"

    assert asyncio.run(main()) == "went on"


def test_within_passes_a_cancellation_on_and_stops_what_it_waited_for() -> None:
    async def main() -> bool:
        stopping = asyncio.Event()
        inner = asyncio.ensure_future(_slow_to_stop(stopping))
        outer = asyncio.ensure_future(within(RealClock(), 30.0, inner))
        await asyncio.sleep(0.01)
        outer.cancel()
        with pytest.raises(asyncio.CancelledError):
            await outer
        return inner.cancelled()

    assert asyncio.run(main())
