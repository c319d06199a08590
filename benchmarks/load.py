"""Load benchmark of the HTTP service: simulated walkers against a real server process.

:func:`run_server_bench` starts ``walkstream serve`` (through :func:`walkstream.server.service.serve`)
in a subprocess on a free loopback port, pinned to core 0, and drives it from this
process, pinned to core 1, with an asyncio load generator on raw sockets (hand-written
HTTP/1.1 keep-alive requests, one connection per walker).  Each walker asks for what a
real walk needs: the manifest once, then for every cell it enters along the cell
adjacency graph at walking pace, ``locate`` at a point in the cell, the cell record, and
the objects of the cell's PVS it does not hold yet (in batches of at most 1,000 ids).

Walkers start spread over a ramp; only requests *started* in the measuring window after
the ramp count.  Each row reports requests/s, p50/p99 latency (write of the request to
the last byte of the response), errors (non-2xx, connection errors, timeouts) and the
generator's own CPU use (process time over wall time of the window): near 100 % of its
core means the generator, not the server, may be the bottleneck (``gen_saturated``).

``walkstream bench server DB [--walkers 10,100,1000] [--workers 1,2] [--ramp 60]
[--duration 30]`` prints the table.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import os
import random
import resource
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import msgpack
import numpy as np

from walkstream.server.service.process import server_process
from walkstream.server.store import SceneReader
from walkstream.shared.errors import InputError, ServiceError

__all__ = ["run_server_bench", "format_table"]

MAX_IDS = 1000
REQUEST_TIMEOUT_S = 10.0
GEN_CORE = 1
SERVER_CORE = 0
SATURATED = 0.9
"""Generator CPU share (of one core) from which a row is flagged ``gen_saturated``."""


# ---------------------------------------------------------------------------
# scene model the walkers walk on (read locally, not over HTTP)
# ---------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class _Cell:
    id: int
    x: float
    y: float
    length: float
    neighbours: tuple[int, ...]
    pvs: tuple[int, ...]


@dataclass(frozen=True, slots=True)
class _Scene:
    name: str
    cells: dict[int, _Cell]
    starts: tuple[int, ...]


def _load_scene(db: str) -> _Scene:
    with SceneReader.open(db) as reader:
        name = str(reader.meta.name)
        cells: dict[int, _Cell] = {}
        for c in reader.cells():
            b = np.asarray(c.boundary, dtype=np.float64)
            centre = b.mean(axis=0)
            length = float(np.max(np.ptp(b, axis=0))) if len(b) else 1.0
            cells[int(c.id)] = _Cell(
                int(c.id),
                float(centre[0]),
                float(centre[1]),
                length,
                tuple(int(n) for n in c.neighbours),
                tuple(int(i) for i in c.pvs),
            )
        starts = tuple(
            int(v.cell) for v in reader.viewpoints() if v.cell is not None and v.cell in cells
        )
    if not cells:
        raise InputError(f"{db}: the scene has no cells to walk")
    return _Scene(name, cells, starts or tuple(sorted(cells)))


# ---------------------------------------------------------------------------
# raw HTTP/1.1 client
# ---------------------------------------------------------------------------


class _HttpError(Exception):
    pass


async def _read_response(reader: asyncio.StreamReader) -> tuple[int, bytes]:
    head = await reader.readuntil(b"\r\n\r\n")
    lines = head.split(b"\r\n")
    parts = lines[0].split(b" ", 2)
    if len(parts) < 2 or not parts[0].startswith(b"HTTP/1."):
        raise _HttpError(f"bad status line {lines[0][:80]!r}")
    status = int(parts[1])
    length = -1
    chunked = False
    for line in lines[1:]:
        if not line:
            continue
        key, _, value = line.partition(b":")
        key = key.strip().lower()
        if key == b"content-length":
            length = int(value.strip())
        elif key == b"transfer-encoding" and b"chunked" in value.lower():
            chunked = True
    if chunked:
        pieces: list[bytes] = []
        while True:
            size_line = await reader.readuntil(b"\r\n")
            size = int(size_line.split(b";", 1)[0].strip(), 16)
            if size == 0:
                while (await reader.readuntil(b"\r\n")) != b"\r\n":  # trailers
                    pass
                break
            pieces.append(await reader.readexactly(size))
            await reader.readexactly(2)
        return status, b"".join(pieces)
    if length < 0:
        if status in (204, 304) or 100 <= status < 200:
            return status, b""
        raise _HttpError("response without Content-Length (connection-delimited)")
    return status, await reader.readexactly(length)


@dataclass(slots=True)
class _Stats:
    window_start: float = math.inf
    window_end: float = math.inf
    latencies: list[float] = field(default_factory=list)
    errors: int = 0
    error_kinds: dict[str, int] = field(default_factory=dict)

    def counts(self, started: float) -> bool:
        return self.window_start <= started < self.window_end

    def error(self, started: float, kind: str) -> None:
        if self.counts(started):
            self.errors += 1
            self.error_kinds[kind] = self.error_kinds.get(kind, 0) + 1


class _Conn:
    """One keep-alive connection; reopened after an error."""

    def __init__(self, host: str, port: int) -> None:
        self.host = host
        self.port = port
        self.reader: asyncio.StreamReader | None = None
        self.writer: asyncio.StreamWriter | None = None

    async def _open(self) -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
        if self.reader is None or self.writer is None:
            self.reader, self.writer = await asyncio.open_connection(self.host, self.port)
        return self.reader, self.writer

    def close(self) -> None:
        if self.writer is not None:
            self.writer.close()
        self.reader = self.writer = None

    async def request(self, stats: _Stats, method: str, path: str, body: bytes = b"") -> bytes:
        """Send one request and read the answer; record latency or error. Returns the body."""
        head = (
            f"{method} {path} HTTP/1.1\r\nHost: {self.host}:{self.port}\r\n"
            f"Accept: application/msgpack\r\n"
        )
        if method == "POST":
            head += f"Content-Type: application/msgpack\r\nContent-Length: {len(body)}\r\n"
        data = (head + "\r\n").encode("ascii") + body
        started = time.perf_counter()
        try:
            async with asyncio.timeout(REQUEST_TIMEOUT_S):
                reader, writer = await self._open()
                started = time.perf_counter()
                writer.write(data)
                status, content = await _read_response(reader)
        except TimeoutError:
            self.close()
            stats.error(started, "timeout")
            return b""
        except (OSError, asyncio.IncompleteReadError, asyncio.LimitOverrunError, _HttpError) as e:
            self.close()
            stats.error(started, type(e).__name__)
            return b""
        if stats.counts(started):
            stats.latencies.append(time.perf_counter() - started)
        if not 200 <= status < 300:
            stats.error(started, f"http{status}")
            return b""
        return content


# ---------------------------------------------------------------------------
# walkers
# ---------------------------------------------------------------------------


async def _walker(
    index: int,
    scene: _Scene,
    host: str,
    port: int,
    stats: _Stats,
    start_at: float,
    stop_at: float,
    speed_ms: float,
) -> None:
    rng = random.Random(index)
    await asyncio.sleep(max(0.0, start_at - time.perf_counter()))
    conn = _Conn(host, port)
    base = f"/v1/scenes/{scene.name}"
    have: set[int] = set()
    try:
        await conn.request(stats, "GET", base)
        cell = scene.cells[scene.starts[index % len(scene.starts)]]
        prev = -1
        first = True
        while time.perf_counter() < stop_at:
            entered = time.perf_counter()
            # a point in the cell, jittered so locate answers are not all the same
            x = cell.x + rng.uniform(-0.1, 0.1) * cell.length
            y = cell.y + rng.uniform(-0.1, 0.1) * cell.length
            await conn.request(stats, "GET", f"{base}/locate?x={x:.3f}&y={y:.3f}")
            await conn.request(stats, "GET", f"{base}/cells/{cell.id}")
            need = [i for i in cell.pvs if i not in have]
            for k in range(0, len(need), MAX_IDS):
                batch = need[k : k + MAX_IDS]
                body = await conn.request(
                    stats, "POST", f"{base}/objects", msgpack.packb({"ids": batch})
                )
                if body:
                    have.update(batch)
            # time to cross the cell at walking pace, kept to one visit every 1-3 s
            dwell = min(3.0, max(1.0, cell.length / speed_ms))
            if first:  # the walk starts anywhere along the first cell
                dwell *= rng.random()
                first = False
            choices = [n for n in cell.neighbours if n in scene.cells and n != prev]
            if not choices:
                choices = [n for n in cell.neighbours if n in scene.cells]
            if choices:
                prev = cell.id
                cell = scene.cells[rng.choice(choices)]
            await asyncio.sleep(max(0.0, entered + dwell - time.perf_counter()))
    finally:
        conn.close()


async def _drive(
    scene: _Scene,
    host: str,
    port: int,
    walkers: int,
    ramp_s: float,
    duration_s: float,
    speed_ms: float,
) -> tuple[_Stats, float, float]:
    stats = _Stats()
    t0 = time.perf_counter() + 0.05
    stats.window_start = t0 + ramp_s
    stats.window_end = stats.window_start + duration_s
    tasks = [
        asyncio.create_task(
            _walker(
                i,
                scene,
                host,
                port,
                stats,
                t0 + ramp_s * i / walkers,
                stats.window_end,
                speed_ms,
            )
        )
        for i in range(walkers)
    ]
    await asyncio.sleep(max(0.0, stats.window_start - time.perf_counter()))
    cpu0, wall0 = time.process_time(), time.perf_counter()
    await asyncio.sleep(max(0.0, stats.window_end - time.perf_counter()))
    cpu1, wall1 = time.process_time(), time.perf_counter()
    # requests started in the window may still be completing: give them their timeout
    _done, pending = await asyncio.wait(tasks, timeout=REQUEST_TIMEOUT_S + 1)
    for t in pending:
        t.cancel()
    await asyncio.gather(*tasks, return_exceptions=True)
    for t in tasks:
        if not t.cancelled() and t.exception() is not None:
            stats.errors += 1
            kind = f"walker:{type(t.exception()).__name__}"
            stats.error_kinds[kind] = stats.error_kinds.get(kind, 0) + 1
    return stats, cpu1 - cpu0, wall1 - wall0


# ---------------------------------------------------------------------------
# server process
# ---------------------------------------------------------------------------


@contextlib.contextmanager
def _server(db: str, port: int, workers: int, pin: bool) -> Iterator[tuple[str, int]]:
    # every walker is a connection from 127.0.0.1: no per-address cap here
    with server_process([db], port, workers, SERVER_CORE if pin else -1, per_client=0) as where:
        yield where


def _raise_nofile() -> int:
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if hard != resource.RLIM_INFINITY and soft < hard:
        with contextlib.suppress(ValueError, OSError):
            resource.setrlimit(resource.RLIMIT_NOFILE, (hard, hard))
    return resource.getrlimit(resource.RLIMIT_NOFILE)[0]


# ---------------------------------------------------------------------------
# public API
# ---------------------------------------------------------------------------


def run_server_bench(
    db: str,
    *,
    walkers: Sequence[int] = (10, 100, 1000),
    workers: Sequence[int] = (1, 2),
    ramp_s: float = 60.0,
    duration_s: float | None = None,
    speed_kmh: float = 15.0,
    port: int = 0,
    pin: bool = True,
    progress: Callable[[dict[str, Any]], None] | None = None,
) -> list[dict[str, Any]]:
    """Benchmark the server on ``db`` for every (walkers, workers) pair.

    Returns one dict per row: ``walkers``, ``workers``, ``requests`` (in the window),
    ``duration_s``, ``rps``, ``p50_ms``, ``p99_ms``, ``max_ms``, ``errors``,
    ``error_kinds``, ``gen_cpu`` (generator CPU seconds / wall seconds of the window,
    1.0 = one full core), ``gen_saturated`` and ``pinned``.  ``progress`` is called
    with each row as it is done.
    """
    if duration_s is None:
        duration_s = 30.0
    if ramp_s < 0 or duration_s <= 0 or speed_kmh <= 0:
        raise InputError("ramp_s must be >= 0, duration_s and speed_kmh > 0")
    scene = _load_scene(db)
    nofile = _raise_nofile()
    pinned = False
    old_affinity: set[int] | None = None
    if pin and hasattr(os, "sched_setaffinity"):
        old_affinity = os.sched_getaffinity(0)
        if {SERVER_CORE, GEN_CORE} <= old_affinity:
            os.sched_setaffinity(0, {GEN_CORE})
            pinned = True
    rows: list[dict[str, Any]] = []
    try:
        for w in workers:
            for n in walkers:
                if n + 64 > nofile:
                    raise ServiceError(f"open-file limit {nofile} is too low for {n} walkers")
                with _server(db, port, w, pinned) as (host, p):
                    stats, cpu, wall = asyncio.run(
                        _drive(scene, host, p, n, ramp_s, duration_s, speed_kmh / 3.6)
                    )
                lat = np.asarray(stats.latencies, dtype=np.float64) * 1000.0
                share = cpu / wall if wall > 0 else 0.0
                row: dict[str, Any] = {
                    "walkers": n,
                    "workers": w,
                    "requests": int(lat.size),
                    "duration_s": duration_s,
                    "rps": lat.size / duration_s,
                    "p50_ms": float(np.percentile(lat, 50)) if lat.size else math.nan,
                    "p99_ms": float(np.percentile(lat, 99)) if lat.size else math.nan,
                    "max_ms": float(lat.max()) if lat.size else math.nan,
                    "errors": stats.errors,
                    "error_kinds": dict(stats.error_kinds),
                    "gen_cpu": share,
                    "gen_saturated": share >= SATURATED,
                    "pinned": pinned,
                }
                rows.append(row)
                if progress is not None:
                    progress(row)
    finally:
        if old_affinity is not None and pinned:
            os.sched_setaffinity(0, old_affinity)
    return rows


def format_table(rows: Sequence[dict[str, Any]]) -> str:
    """The rows as a fixed-width text table."""
    head = (
        f"{'walkers':>7} {'workers':>7} {'requests':>9} {'req/s':>8} {'p50 ms':>8} "
        f"{'p99 ms':>8} {'max ms':>8} {'errors':>6} {'gen CPU':>8}"
    )
    lines = [head, "-" * len(head)]
    for r in rows:
        flag = " SATURATED" if r["gen_saturated"] else ""
        lines.append(
            f"{r['walkers']:>7} {r['workers']:>7} {r['requests']:>9} {r['rps']:>8.1f} "
            f"{r['p50_ms']:>8.2f} {r['p99_ms']:>8.2f} {r['max_ms']:>8.1f} {r['errors']:>6} "
            f"{r['gen_cpu'] * 100:>7.0f}%{flag}"
        )
        if r["error_kinds"]:
            kinds = ", ".join(f"{k}={v}" for k, v in sorted(r["error_kinds"].items()))
            lines.append(f"{'':>16}errors: {kinds}")
    if rows:
        pinned = rows[0]["pinned"]
        lines.append(
            "server pinned to core 0, generator to core 1"
            if pinned
            else "not pinned (pin=False or fewer than 2 cores available)"
        )
    return "\n".join(lines) + "\n"
