"""Hostile clients against a real server: does ``/v1/health`` still answer in time?

Issue 25's figure: during a mid-body disconnect, 1,000 slow connections and 20
concurrent maximal batches, ``/v1/health`` answers within 100 ms p99 throughout.
:func:`run_hostile` starts ``walkstream serve`` (:func:`~walkstream.server.service.process.server_process`,
the settings and guard the CLI uses) and, from one asyncio loop in this process:

* probes ``GET /v1/health`` every 50 ms on a new connection from 127.0.0.1 (blocking
  sockets in a thread of its own), timing each answer, first alone (the baseline),
  then during the attack;
* opens 1,000 connections from 127.0.0.2 that send half a request head and then one
  byte a second (a slowloris), counting those refused at once, those the server
  closes and those still open at the end;
* runs 20 workers from 127.0.0.3, each posting ``form=lod2`` batches of as many ids
  as the server's 413 says fit (the largest batch it accepts), over the scene's
  objects in turn so meshes are rebuilt, not served from the cache;
* sends, every 200 ms from 127.0.0.4, an ``objects`` request that announces 5,000
  body bytes, sends 11 and hangs up.

Each kind of client comes from its own loopback address because the server caps
connections per address: an attack from one address cannot crowd out another.

``python -m walkstream.benchmarks.hostile scene.db [--seconds 20]`` prints the table.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import socket
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from walkstream.server.service.process import server_process
from walkstream.server.service.scenes import MAX_IDS
from walkstream.server.store import SceneReader

__all__ = ["HostileReport", "format_table", "run_hostile"]

HEALTH_EVERY_S = 0.05
SLOW_CONNECTIONS = 1000
BATCH_WORKERS = 20
DISCONNECT_EVERY_S = 0.2


@dataclass
class HostileReport:
    """What :func:`run_hostile` measured (milliseconds for latencies)."""

    baseline_ms: list[float] = field(default_factory=list)
    attack_ms: list[float] = field(default_factory=list)
    health_failures: int = 0
    slow_refused: int = 0
    slow_closed: int = 0
    slow_open_at_end: int = 0
    batches_ok: int = 0
    batches_413: int = 0
    batches_other: int = 0
    batch_ids: int = 0
    batch_bytes: int = 0
    disconnects: int = 0
    seconds: float = 0.0


async def _request(
    host: str, port: int, raw: bytes, source: str, timeout: float = 30.0
) -> tuple[int, bytes]:
    """Send ``raw`` from ``source`` and read the answer to the end (``Connection: close``)."""
    reader, writer = await asyncio.wait_for(
        asyncio.open_connection(host, port, local_addr=(source, 0)), timeout
    )
    try:
        writer.write(raw)
        await writer.drain()
        data = await asyncio.wait_for(reader.read(-1), timeout)
    finally:
        writer.close()
    status = int(data.split(b" ", 2)[1]) if data.startswith(b"HTTP/1.1 ") else 0
    return status, data


def _post(path: str, body: bytes) -> bytes:
    return (
        f"POST {path} HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
        f"Content-Length: {len(body)}\r\nConnection: close\r\n\r\n"
    ).encode() + body


def _health(host: str, port: int, out: list[float], rep: HostileReport, until: float) -> None:
    """Probe ``/v1/health`` until ``until`` with blocking sockets (run in its own thread,
    so the attack's event loop in this process does not delay the probe's clock)."""
    raw = b"GET /v1/health HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n"
    while time.monotonic() < until:
        t0 = time.perf_counter()
        data = b""
        try:
            with socket.create_connection((host, port), timeout=5.0, source_address=("127.0.0.1", 0)) as s:
                s.sendall(raw)
                while chunk := s.recv(4096):
                    data += chunk
        except OSError:
            pass
        if data.startswith(b"HTTP/1.1 200"):
            out.append((time.perf_counter() - t0) * 1000)
        else:
            rep.health_failures += 1
        time.sleep(HEALTH_EVERY_S)


async def _slow_one(host: str, port: int, rep: HostileReport, until: float) -> None:
    try:
        reader, writer = await asyncio.open_connection(host, port, local_addr=("127.0.0.2", 0))
    except OSError:
        rep.slow_refused += 1
        return
    try:
        writer.write(b"GET /v1/health HTTP/1.1\r\nHost: x\r\nX-Slow: ")
        while time.monotonic() < until:
            try:
                got = await asyncio.wait_for(reader.read(4096), 1.0)
            except TimeoutError:
                writer.write(b"a")  # one more byte of a head that never ends
                continue
            if got.startswith(b"HTTP/1.1 503"):
                rep.slow_refused += 1
            else:
                rep.slow_closed += 1
            return
        rep.slow_open_at_end += 1
    except OSError:
        rep.slow_closed += 1
    finally:
        writer.close()


async def _batches(host: str, port: int, scene: str, ids: list[int], rep: HostileReport, until: float, k: int) -> None:
    path = f"/v1/scenes/{scene}/objects?form=lod2"
    n = min(len(ids), MAX_IDS)  # the first answer says how many fit
    pos = (k * 97) % len(ids)
    while time.monotonic() < until:
        ask = [ids[(pos + j) % len(ids)] for j in range(n)]
        try:
            status, data = await _request(host, port, _post(path, json.dumps({"ids": ask}).encode()), "127.0.0.3")
        except (TimeoutError, OSError):
            rep.batches_other += 1
            continue
        if status == 413:
            rep.batches_413 += 1
            body = data.split(b"\r\n\r\n", 1)[1]
            n = max(1, int(json.loads(body)["detail"]["ids_that_fit"]))
        elif status == 200:
            rep.batches_ok += 1
            rep.batch_ids += len(ask)
            rep.batch_bytes += len(data)
            pos = (pos + n) % len(ids)
        else:
            rep.batches_other += 1


async def _disconnects(host: str, port: int, scene: str, rep: HostileReport, until: float) -> None:
    head = (
        f"POST /v1/scenes/{scene}/objects HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
        "Content-Length: 5000\r\n\r\n"
    ).encode()
    while time.monotonic() < until:
        try:
            _, writer = await asyncio.open_connection(host, port, local_addr=("127.0.0.4", 0))
            writer.write(head + b'{"ids": [1, ')
            await writer.drain()
            await asyncio.sleep(0.05)
            writer.close()
            rep.disconnects += 1
        except OSError:
            pass
        await asyncio.sleep(DISCONNECT_EVERY_S)


async def _run(host: str, port: int, scene: str, ids: list[int], seconds: float, baseline_s: float) -> HostileReport:
    rep = HostileReport(seconds=seconds)
    _health(host, port, rep.baseline_ms, rep, time.monotonic() + baseline_s)
    until = time.monotonic() + seconds
    probe = threading.Thread(target=_health, args=(host, port, rep.attack_ms, rep, until))
    probe.start()
    tasks = [asyncio.create_task(_slow_one(host, port, rep, until)) for _ in range(SLOW_CONNECTIONS)]
    tasks += [asyncio.create_task(_batches(host, port, scene, ids, rep, until, k)) for k in range(BATCH_WORKERS)]
    tasks.append(asyncio.create_task(_disconnects(host, port, scene, rep, until)))
    await asyncio.gather(*tasks)
    await asyncio.to_thread(probe.join)
    return rep


def run_hostile(db: str, seconds: float = 20.0, baseline_s: float = 3.0) -> HostileReport:
    """Attack a server on ``db`` for ``seconds`` and time ``/v1/health`` (see the module docs)."""
    with SceneReader.open(db) as reader:
        scene = reader.meta.name
        ids = [int(i) for i in reader.object_ids().tolist()]
    with server_process([db]) as (host, port):
        return asyncio.run(_run(host, port, scene, ids, seconds, baseline_s))


def _pct(ms: Sequence[float], q: float) -> float:
    return float(np.percentile(ms, q)) if len(ms) else float("nan")


def format_table(rep: HostileReport) -> str:
    """The report as a text table."""
    rows = [
        f"{'phase':<8} {'probes':>6} {'p50 ms':>7} {'p99 ms':>7} {'max ms':>7}",
        *(
            f"{name:<8} {len(ms):>6} {_pct(ms, 50):>7.1f} {_pct(ms, 99):>7.1f} {max(ms, default=float('nan')):>7.1f}"
            for name, ms in (("alone", rep.baseline_ms), ("attacked", rep.attack_ms))
        ),
        f"health probes failed: {rep.health_failures}",
        f"slow connections ({SLOW_CONNECTIONS}): {rep.slow_refused} refused at once (503), "
        f"{rep.slow_closed} closed by the server, {rep.slow_open_at_end} still open after {rep.seconds:.0f} s",
        f"lod2 batches ({BATCH_WORKERS} at once): {rep.batches_ok} answered ({rep.batch_ids} meshes, "
        f"{rep.batch_bytes / 1e6:.1f} MB), {rep.batches_413} 413 (size advice), {rep.batches_other} other",
        f"mid-body disconnects: {rep.disconnects}",
    ]
    return "\n".join(rows)


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m walkstream.benchmarks.hostile DB [--seconds S]``: print the table."""
    ap = argparse.ArgumentParser(prog="python -m walkstream.benchmarks.hostile", description=__doc__.split("\n\n")[0])
    ap.add_argument("db")
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--json", action="store_true", help="print the report as JSON too")
    args = ap.parse_args(argv)
    rep = run_hostile(args.db, args.seconds)
    print(format_table(rep))
    if args.json:
        d: dict[str, Any] = dict(rep.__dict__)
        d["baseline_p99_ms"], d["attack_p99_ms"] = _pct(rep.baseline_ms, 99), _pct(rep.attack_ms, 99)
        del d["baseline_ms"], d["attack_ms"]
        print(json.dumps(d))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
