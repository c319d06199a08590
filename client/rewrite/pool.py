"""Rewriting: rebuild object geometry from parameters, highest priority first.

A pool of workers takes rebuild jobs from a priority queue (the objects of the
current cell first, then by the time a cell is needed, then by ACH, highest
first) and turns each object's parameters into its three LODs with the grammar the
manifest named (a street is one flat surface used at every LOD).  A worker takes
the jobs at the head of the queue together, up to :data:`BATCH` (and no more than
its share when several workers are idle), and rebuilds their buildings in one call
(:func:`~walkstream.client.rewrite.geometry.rebuild_batch`), so the per-building
interpreter overhead is paid once per batch; when few jobs wait, a batch is small
and a job waits no longer than before.

Under the real clock the jobs run, concurrently with the frame loop, in worker
processes (``mode="process"``: :mod:`walkstream.client.rewrite.procpool`, geometry
back through bounded shared memory, else the pipe; a worker that cannot start or dies
leaves its lane to a thread, as does one still starting) or in a thread pool (``mode="thread"``, under the frame
loop's interpreter lock).  There, :meth:`RewritePool.prune` drops queued jobs the
walker no longer needs (it turned away) before they are rebuilt.  Under the
simulated clock a job runs at once on the event loop (virtual time is frozen while
it runs) and then its worker sleeps the CPU time the job
really took, so each worker is a lane of virtual time and the results appear when
they would have on a machine with that many cores.
"""

from __future__ import annotations

import asyncio
import heapq
import itertools
import os
from collections.abc import Callable, Iterable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from walkstream.client.clock import Clock
from walkstream.client.rewrite.geometry import ObjectGeometry, rebuild_batch
from walkstream.client.rewrite.procpool import ProcessWorkers
from walkstream.client.tasks import reap
from walkstream.shared.errors import InputError
from walkstream.shared.lsystem.grammar import Grammar
from walkstream.shared.records import AreaParams, BuildingParams, StreetParams

__all__ = [
    "BATCH",
    "MODES",
    "auto_mode",
    "SHM_BYTES",
    "RewriteOptions",
    "RewritePool",
]

BATCH = 32
"""Most jobs one worker rebuilds in one call."""

MODES = ("process", "thread")
"""Where real-clock rebuilds run (``auto`` picks one: :func:`auto_mode`)."""


def auto_mode(workers: int) -> str:
    """``process`` when this machine has a core for every worker besides two for the frame
    loop and the GL driver, else ``thread``.

    Measured on 2 cores with llvmpipe (docs/benchmarks.md): worker processes compete with the
    loop and the rasteriser for the cores, and their start-up delays the first perfect
    frame, while threads cost the loop little there; with a spare core a worker process
    leaves the loop's time per pass as it is alone, and threads do not.
    """
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # (not on Linux)
        cores = os.cpu_count() or 1
    return "process" if cores >= workers + 2 else "thread"

SHM_BYTES = 16 << 20
"""Default bound on the shared memory the process pool holds (a container's /dev/shm is
often 64 MB)."""


@dataclass(frozen=True)
class RewriteOptions:
    """How the real clock's rebuilds run (the simulated clock always rebuilds inline)."""

    mode: str = "thread"
    """``process``, ``thread`` or ``auto`` (:func:`auto_mode`)."""
    shm_bytes: int = SHM_BYTES
    """Bound on shared memory (process mode; 0: geometry comes through the pipe)."""

    def __post_init__(self) -> None:
        if self.mode not in (*MODES, "auto"):
            raise InputError(f"--rewrite {self.mode!r}: choose one of auto, {', '.join(MODES)}")
        if self.shm_bytes < 0:
            raise InputError(f"--shm {self.shm_bytes}: must not be negative")


Priority = tuple[float, float]
"""(seconds until needed, -ACH): smaller is sooner."""


class RewritePool:
    """Rebuild jobs in priority order on ``workers`` workers.

    Parameters
    ----------
    clock:
        Real: jobs run in threads; simulated: inline, charged as virtual time.
    grammar:
        The parsed building grammar from the manifest; ``None`` until the manifest
        arrives (jobs wait; see :meth:`set_grammar`).
    on_built:
        Called on the event loop with each finished :class:`ObjectGeometry`.
    workers:
        Number of concurrent workers.
    batch:
        Most jobs a worker rebuilds in one call (1: one object per call, as before batching).
    options:
        Processes or threads under the real clock, and the shared-memory bound.
    """

    def __init__(
        self,
        clock: Clock,
        grammar: Grammar | None,
        on_built: Callable[[ObjectGeometry], None],
        workers: int = 2,
        batch: int = BATCH,
        options: RewriteOptions | None = None,
    ) -> None:
        if workers < 1:
            raise InputError(f"workers must be >= 1, got {workers}")
        if batch < 1:
            raise InputError(f"batch must be >= 1, got {batch}")
        self.clock = clock
        self.grammar = grammar
        self.on_built = on_built
        self.workers = workers
        self.batch = batch
        self._busy = 0
        self.batches = 0
        self._heap: list[tuple[Priority, int, int]] = []
        self._jobs: dict[int, tuple[BuildingParams | StreetParams | AreaParams, Priority]] = {}
        self._seq = itertools.count()
        self._wake = asyncio.Event()
        self._tasks: list[asyncio.Task[None]] = []
        self._running: set[int] = set()
        self._executor: ThreadPoolExecutor | None = None
        self.options = options or RewriteOptions()
        self._procs: ProcessWorkers | None = None
        self.built = 0
        self.cpu_s = 0.0
        self.dropped = 0
        """Queued jobs dropped by :meth:`prune` (never rebuilt)."""
        self.thread_batches = 0

    def set_grammar(self, grammar: Grammar) -> None:
        """Give the pool its grammar (the manifest arrived); waiting jobs start."""
        self.grammar = grammar
        self._wake.set()

    def submit(self, oid: int, params: BuildingParams | StreetParams | AreaParams, priority: Priority) -> None:
        """Queue (or re-prioritise) the rebuild of ``oid``."""
        old = self._jobs.get(oid)
        if old is not None and old[1] <= priority:
            return
        self._jobs[oid] = (params, priority)
        heapq.heappush(self._heap, (priority, next(self._seq), oid))
        self._wake.set()

    def bump(self, oid: int, priority: Priority) -> None:
        """Raise the priority of a queued job (no-op when it is not queued)."""
        job = self._jobs.get(oid)
        if job is not None:
            self.submit(oid, job[0], priority)

    def queued(self, oid: int) -> bool:
        """Whether ``oid`` waits for a worker or is being rebuilt."""
        return oid in self._jobs or oid in self._running

    @property
    def pending(self) -> int:
        """Jobs waiting for a worker."""
        return len(self._jobs)

    def prune(self, pvs: Iterable[NDArray[np.int64]]) -> int:
        """Drop the queued jobs of objects in none of ``pvs`` (the cells still needed).

        Real clock only: a simulated run keeps every job, so its figures stay as they
        were.  Returns the number dropped.
        """
        if self.clock.simulated or not self._jobs:
            return 0
        keep: set[int] = set()
        for p in pvs:
            keep.update(np.asarray(p, np.int64).tolist())
        gone = [oid for oid in self._jobs if oid not in keep]
        for oid in gone:
            del self._jobs[oid]  # its heap entry is skipped by _pop
        self.dropped += len(gone)
        return len(gone)

    def _pop(self) -> tuple[int, BuildingParams | StreetParams | AreaParams] | None:
        while self._heap:
            prio, _, oid = heapq.heappop(self._heap)
            job = self._jobs.get(oid)
            if job is not None and job[1] == prio:
                del self._jobs[oid]
                return oid, job[0]
        return None

    def _take(self) -> list[tuple[int, BuildingParams | StreetParams | AreaParams]]:
        """The jobs at the head of the queue, in priority order: at most :data:`BATCH`, and
        no more than an equal share of what waits among the workers not busy."""
        idle = max(1, self.workers - self._busy)
        want = min(self.batch, max(1, -(-len(self._jobs) // idle)))
        out: list[tuple[int, BuildingParams | StreetParams | AreaParams]] = []
        while len(out) < want:
            job = self._pop()
            if job is None:
                break
            out.append(job)
        return out

    def start(self) -> None:
        """Start the workers on the running event loop."""
        if not self.clock.simulated:
            if self.options.mode == "auto":
                self.options = replace(self.options, mode=auto_mode(self.workers))
            if self.options.mode == "process":
                self._procs = ProcessWorkers(self.workers, self.options.shm_bytes)
                self._procs.start()
            else:
                self._threads()
        self._tasks = [asyncio.create_task(self._worker(k)) for k in range(self.workers)]

    def _threads(self) -> ThreadPoolExecutor:
        if self._executor is None:
            self._executor = ThreadPoolExecutor(self.workers, thread_name_prefix="rewrite")
        return self._executor

    def describe(self) -> dict[str, Any]:
        """Which path the rebuilds took: for the report."""
        out: dict[str, Any] = {
            "mode": "inline" if self.clock.simulated else self.options.mode,
            "batches": self.batches,
            "thread_batches": self.thread_batches,
            "dropped_jobs": self.dropped,
        }
        p = self._procs
        if p is not None:
            out.update(
                shm_bytes=p.arena.nbytes,
                shm_error=p.arena.error,
                shm_batches=p.shm_batches,
                pipe_batches=p.pipe_batches,
                shm_peak_bytes=p.arena.peak,
                workers_ready_s=p.ready_s,
            )
        return out

    async def _run(self, k: int, jobs: list[tuple[int, BuildingParams | StreetParams | AreaParams]]) -> list[ObjectGeometry]:
        assert self.grammar is not None
        if self._procs is not None and self._procs.ready(k):
            from walkstream.shared.errors import WorkerGone

            # each lane's batches may hold an equal share of the bound
            cap = self._procs.arena.nbytes // (2 * self.workers)
            try:
                return await self._procs.run(k, jobs, self.grammar, cap)
            except WorkerGone:
                pass  # this lane goes on in a thread
        # (also while the lane's process is still starting: its start-up must not delay
        # the first cell's rebuilds)
        self.thread_batches += 1
        loop = asyncio.get_running_loop()
        return await loop.run_in_executor(self._threads(), rebuild_batch, jobs, self.grammar)

    async def _worker(self, k: int) -> None:
        while True:
            jobs = self._take() if self.grammar is not None else []
            if not jobs:
                self._wake.clear()
                await self._wake.wait()
                continue
            assert self.grammar is not None
            self._running.update(oid for oid, _ in jobs)
            self._busy += 1
            try:
                if self.clock.simulated:
                    geoms = rebuild_batch(jobs, self.grammar)
                    await self.clock.sleep(sum(g.cpu_s for g in geoms))
                else:
                    geoms = await self._run(k, jobs)
            finally:
                self._busy -= 1
                self._running.difference_update(oid for oid, _ in jobs)
            self.batches += 1
            for geom in geoms:
                self.built += 1
                self.cpu_s += geom.cpu_s
                self.on_built(geom)

    async def close(self) -> None:
        """Stop the workers (jobs in progress in threads finish on their own; worker
        processes are stopped, and terminated when they do not stop at once)."""
        await reap(self._tasks)
        self._tasks = []
        if self._procs is not None:
            self._procs.close()
        if self._executor is not None:
            self._executor.shutdown(wait=True, cancel_futures=True)
            self._executor = None
