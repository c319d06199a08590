"""Stopping the client's own asyncio tasks without losing a cancellation meant for the caller.

The client starts tasks beside its walk (requests, rebuilds, the walk itself) and stops
them when the walk ends, a timeout fires or the user presses Ctrl-C.  Stopping one is
``task.cancel()`` then ``await task``, and that await raises :class:`asyncio.CancelledError`
for two different reasons: the task ended cancelled (expected, to be swallowed), or the
*caller* was cancelled while it waited (Ctrl-C arriving just then, which must go on, or
the replay walks on and exits 0).  :func:`reap` tells the two apart by the caller's own
pending cancellations (:meth:`asyncio.Task.cancelling`), so it is the one way the client
stops tasks.
"""

from __future__ import annotations

import asyncio
from collections.abc import Iterable
from typing import Any

__all__ = ["reap"]


async def reap(tasks: Iterable[asyncio.Future[Any]]) -> None:
    """Cancel ``tasks`` and wait until each has ended, ignoring how each ended.

    A task's own cancellation or error is swallowed (the caller no longer wants its
    result); a cancellation of the calling task that arrives meanwhile is raised once
    every task has ended, so an interrupt during a clean-up is never lost.

    Parameters
    ----------
    tasks
        Tasks or futures to stop; those already done are only awaited.

    Raises
    ------
    asyncio.CancelledError
        When the calling task was cancelled while waiting.
    """
    pending = list(tasks)
    for t in pending:
        t.cancel()
    current = asyncio.current_task()
    before = current.cancelling() if current is not None else 0
    for t in pending:
        while not t.done():
            # shield: a cancellation of the caller must not abandon a task half-stopped
            try:
                await asyncio.shield(t)
            except asyncio.CancelledError:
                continue
            except Exception:  # noqa: BLE001, S110 - the task's own failure is not the caller's
                break
        if not t.cancelled():
            t.exception()  # retrieved: no "exception was never retrieved" at exit
    if current is not None and current.cancelling() > before:
        raise asyncio.CancelledError
