"""Rebuilding in worker processes, off the frame loop's interpreter.

:class:`ProcessWorkers` starts one process per rewrite worker with the ``spawn`` start
method (a fresh interpreter: nothing of the client, least of all its GL context, is
forked).  Each process imports the building code once at start-up, parses the grammar
once when the client first sends it, and then rebuilds the batches it is sent with
:func:`~walkstream.client.rewrite.geometry.rebuild_batch`.  Its geometry comes back through
the client's bounded shared-memory segment when the region reserved for the batch holds
it, else through the pipe (see :mod:`walkstream.client.rewrite.shm`); either way the
client's meshes are views of the bytes the worker wrote.

Workers run at a lower scheduling priority than the client (:data:`NICE`).  Replies
are read on the event loop (``add_reader`` on each pipe), so the frame loop only
unpacks a finished batch's small header.  Worker processes ignore Ctrl-C (the client
stops them) and leave when their pipe closes, so none outlives the client.
"""

from __future__ import annotations

import asyncio
import contextlib
import multiprocessing as mp
import os
import signal
import time
from collections.abc import Sequence
from multiprocessing.connection import Connection
from typing import Any

import numpy as np

from walkstream.client.rewrite.geometry import ObjectGeometry, rebuild_batch
from walkstream.client.rewrite.shm import ShmArena, pack_layout, unpack, write_packed
from walkstream.shared.errors import WorkerGone
from walkstream.shared.lsystem.grammar import Grammar, parse_grammar
from walkstream.shared.records import AreaParams, BuildingParams, StreetParams

__all__ = ["NICE", "ProcessWorkers", "worker_main"]

Job = tuple[int, BuildingParams | StreetParams | AreaParams]

NICE = 5
"""How much lower the workers' scheduling priority is than the client's: where cores are
few, the frame loop (and the GL driver's threads) come first, rebuilding takes the rest."""


def worker_main(conn: Connection, shm_name: str | None) -> None:
    """A worker process: rebuild the batches ``conn`` sends until it says stop or closes."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    from multiprocessing import shared_memory

    shm = shared_memory.SharedMemory(shm_name) if shm_name else None
    conn.send(("ready", os.getpid()))
    grammar: Grammar | None = None
    while True:
        try:
            msg = conn.recv()
        except (EOFError, OSError):
            break
        if msg[0] == "stop":
            break
        if msg[0] == "grammar":
            grammar = parse_grammar(msg[1])
            continue
        _, jobs, offset, size = msg
        try:
            assert grammar is not None
            layout, meshes = pack_layout(rebuild_batch(jobs, grammar))
            total = layout[2]
            if shm is not None and 0 < total <= size:
                dst = np.frombuffer(shm.buf, np.uint8, count=total, offset=offset)  # type: ignore[arg-type]
                write_packed(dst, layout, meshes)
                del dst  # the segment may close only without views
                conn.send(("shm", layout))
            else:
                buf = np.empty(total, np.uint8)
                write_packed(buf, layout, meshes)
                conn.send(("pipe", layout))
                conn.send_bytes(buf.data)
        except Exception as e:  # the client raises it where the batch was awaited
            try:
                conn.send(("error", e))
            except Exception:
                conn.send(("error", RuntimeError(f"{type(e).__name__}: {e}")))
    if shm is not None:
        shm.close()


class ProcessWorkers:
    """``workers`` rewrite processes and the shared-memory arena they write into.

    Parameters
    ----------
    workers:
        Number of processes (one batch each at a time).
    shm_bytes:
        Bound on the shared memory the client holds (0: every batch through the pipe).
    """

    def __init__(self, workers: int, shm_bytes: int) -> None:
        self.workers = workers
        self.arena = ShmArena(shm_bytes)
        self.shm_batches = 0
        self.pipe_batches = 0
        self.started_at = 0.0
        self.ready_s: float | None = None
        """Seconds from :meth:`start` until every worker was ready."""
        self._procs: list[Any] = []
        self._conns: list[Connection] = []
        self._ready: list[asyncio.Future[None]] = []
        self._pending: list[tuple[asyncio.Future[list[ObjectGeometry]], int, int] | None] = []
        self._grammar: list[str | None] = []
        self._loop: asyncio.AbstractEventLoop | None = None
        self._dead: set[int] = set()

    def start(self) -> None:
        """Start the processes (returns at once; they import the building code meanwhile)."""
        loop = self._loop = asyncio.get_running_loop()
        ctx = mp.get_context("spawn")
        self.started_at = time.perf_counter()
        for k in range(self.workers):
            ours, theirs = ctx.Pipe()
            p = ctx.Process(
                target=worker_main, args=(theirs, self.arena.name), name=f"rewrite-{k}", daemon=True
            )
            self._ready.append(loop.create_future())
            self._pending.append(None)
            self._grammar.append(None)
            self._procs.append(p)
            self._conns.append(ours)
            try:
                p.start()
            except Exception as e:  # no processes here: the pool runs threads
                self._gone(k, f"could not start: {e}")
                continue
            finally:
                theirs.close()
            if p.pid is not None:  # (at once: it is importing)
                with contextlib.suppress(OSError, AttributeError):
                    os.setpriority(os.PRIO_PROCESS, p.pid, os.getpriority(os.PRIO_PROCESS, 0) + NICE)
            loop.add_reader(ours.fileno(), self._readable, k)
        self._check_all_ready()

    def alive(self, k: int) -> bool:
        """Whether worker ``k`` is (or may still become) usable."""
        f = self._ready[k]
        return k not in self._dead and (not f.done() or f.exception() is None)

    async def wait_ready(self) -> None:
        """Until every worker has started (or failed to)."""
        await asyncio.wait(self._ready)

    def ready(self, k: int) -> bool:
        """Whether worker ``k`` has started and is usable now."""
        f = self._ready[k]
        return k not in self._dead and f.done() and not f.cancelled() and f.exception() is None

    def _check_all_ready(self) -> None:
        if all(f.done() for f in self._ready):
            self.arena.unlink()  # every live worker has attached: nothing left in /dev/shm
            if self.ready_s is None:
                self.ready_s = time.perf_counter() - self.started_at

    def _gone(self, k: int, why: str) -> None:
        self._dead.add(k)
        if self._loop is not None:
            with contextlib.suppress(Exception):
                self._loop.remove_reader(self._conns[k].fileno())
        err = WorkerGone(f"rewrite worker {k}: {why}")
        if not self._ready[k].done():
            self._ready[k].set_exception(err)
            self._ready[k].exception()  # retrieved: the pool falls back to threads
        pend = self._pending[k]
        if pend is not None:
            self._pending[k] = None
            self.arena.release(pend[1], pend[2])
            if not pend[0].done():
                pend[0].set_exception(err)
        self._check_all_ready()

    def _readable(self, k: int) -> None:
        conn = self._conns[k]
        try:
            while conn.poll():
                msg = conn.recv()
                if msg[0] == "ready":
                    if not self._ready[k].done():
                        self._ready[k].set_result(None)
                    self._check_all_ready()
                    continue
                data = conn.recv_bytes() if msg[0] == "pipe" else None
                pend, self._pending[k] = self._pending[k], None
                if pend is None:
                    continue
                fut, off, size = pend
                if msg[0] == "error":
                    self.arena.release(off, size)
                    if not fut.done():
                        fut.set_exception(msg[1])
                    continue
                layout = msg[1]
                if msg[0] == "shm":
                    base = self.arena.view(off, size, layout[2])
                    self.shm_batches += 1
                else:
                    self.arena.release(off, size)
                    assert data is not None
                    base = np.frombuffer(data, np.uint8)
                    self.pipe_batches += 1
                if not fut.done():  # (a cancelled batch's region goes with its views)
                    fut.set_result(unpack(base, layout))
        except (EOFError, OSError) as e:
            self._gone(k, f"exited ({type(e).__name__})")

    async def run(
        self, k: int, jobs: Sequence[Job], grammar: Grammar, cap: int
    ) -> list[ObjectGeometry]:
        """Rebuild ``jobs`` on worker ``k``, writing at most ``cap`` bytes into shared memory.

        Raises
        ------
        WorkerGone
            Worker ``k`` could not start or died (the batch was not rebuilt).
        """
        await self._ready[k]
        assert self._loop is not None and self._pending[k] is None
        conn = self._conns[k]
        try:
            if self._grammar[k] != grammar.text:
                conn.send(("grammar", grammar.text))
                self._grammar[k] = grammar.text
            off, size = self.arena.reserve(cap)
            fut: asyncio.Future[list[ObjectGeometry]] = self._loop.create_future()
            self._pending[k] = (fut, off, size)
            conn.send(("batch", list(jobs), off, size))
        except OSError as e:
            self._gone(k, f"pipe closed ({e})")
            raise WorkerGone(f"rewrite worker {k}: pipe closed") from e
        return await fut

    def close(self) -> None:
        """Stop the processes (a worker still busy is terminated after a moment) and the arena."""
        for k, conn in enumerate(self._conns):
            if self._loop is not None and self.alive(k):
                with contextlib.suppress(Exception):
                    self._loop.remove_reader(conn.fileno())
            with contextlib.suppress(OSError, ValueError):
                conn.send(("stop",))
        deadline = time.monotonic() + 2.0
        for p in self._procs:
            if p.pid is None:
                continue
            p.join(max(0.0, deadline - time.monotonic()))
            if p.is_alive():
                p.terminate()
                p.join(1.0)
            if p.is_alive():
                p.kill()
                p.join(1.0)
        for k, conn in enumerate(self._conns):
            pend = self._pending[k]
            if pend is not None and not pend[0].done():
                pend[0].cancel()
            self._pending[k] = None
            conn.close()
        for f in self._ready:
            if not f.done():
                f.cancel()
        self.arena.close()
