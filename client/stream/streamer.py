"""The streaming scheduler: what to fetch next, given where the viewer is going.

Each planning step (a few times a second, driven by the frame loop) works out the
cells the viewer will need and when:

* the current cell, needed now;
* with prefetch, the cells the predicted motion enters within the *horizon*, at
  the time the prediction enters them, and the neighbours of those cells (where
  the viewer may turn) that are within the horizon at the current speed;
* the horizon covers the request round trips plus the transfer of a cell's worth
  of new objects at the bandwidth the client *measured*, with a margin.

Wanted cell records and the wanted objects of known cells' PVS are ordered by
the time they are needed, then by ACH (highest first).  Requests go out while
fewer than ``max_in_flight`` are in flight; an object batch is sized to about
half a second of transfer at the measured bandwidth, so a new prediction can
re-order the queue soon.  What a new prediction no longer needs is dropped from
the queue, and an in-flight batch none of whose remaining objects is wanted is
cancelled (the objects already received are kept).  Nothing cached or in flight
is asked for again; an object comes again only after the cache evicted it
(counted as a re-download).

The scheduler never blocks the frame loop: it starts tasks and returns.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
from dataclasses import dataclass, field

import msgpack
import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.client.clock import Clock
from walkstream.client.net.api import SceneClient
from walkstream.client.rewrite.pool import ObjectGeometry, RewritePool, geometry_of
from walkstream.client.stream.cache import Cache, Kind
from walkstream.client.stream.cellmap import CellMap
from walkstream.client.stream.diskcache import DiskCache
from walkstream.client.stream.predict import MotionPredictor
from walkstream.shared.codec import decode_mesh, decode_object, unpack_bounded
from walkstream.shared.errors import ApiError, CodecError, StreamCut
from walkstream.shared.lsystem.grammar import Grammar
from walkstream.shared.wire import CellRecord, ObjectFrame, decode_cell

__all__ = ["StreamerConfig", "Streamer"]


@dataclass(frozen=True)
class StreamerConfig:
    """Scheduling knobs."""

    prefetch: bool = True
    form: str = "params"
    """``params`` (rebuild locally) or ``lod2`` (download LOD2 meshes)."""
    workers: int = 2
    """Rewrite workers (with ``params``)."""
    max_in_flight: int = 3
    max_object_requests: int = 2
    plan_interval_s: float = 0.1
    batch_seconds: float = 0.5
    """An object batch is about this much transfer at the measured bandwidth."""
    horizon_min_s: float = 2.0
    horizon_max_s: float = 30.0
    horizon_margin: float = 2.0
    assumed_bps: float = 40_000.0
    """Bandwidth assumed before anything was measured (conservative: GPRS class)."""
    assumed_rtt_s: float = 0.5
    pin_hold_s: float = 5.0
    """A cell's objects stay pinned this long after it was last needed."""


@dataclass
class StreamStats:
    """Counters of what was fetched."""

    cell_requests: int = 0
    locate_requests: int = 0
    object_requests: int = 0
    objects_received: int = 0
    object_bytes: dict[int, int] = field(default_factory=dict)
    """Frame bytes received per object id (re-downloads add up)."""
    object_counts: dict[int, int] = field(default_factory=dict)
    """Times each object id was received."""
    cancelled_batches: int = 0
    disk_hits: int = 0
    cells_revalidated: int = 0


class Streamer:
    """Keeps the cache filled ahead of the viewer, and the geometry built.

    With ``config.form == "params"`` the streamer owns a
    :class:`~walkstream.client.rewrite.pool.RewritePool` that rebuilds each object as
    its parameters arrive (highest priority first); the pool's jobs wait for the
    grammar, which comes with the manifest (:meth:`on_manifest`).  With ``lod2`` the
    downloaded meshes are the geometry and nothing is rebuilt.  Call :meth:`start`
    once on the event loop and :meth:`close` at the end.

    Parameters
    ----------
    api:
        Access to the scene.
    clock:
        The replay's clock.
    cache:
        The byte-budget cache (cells, downloads, geometry).
    config:
        Scheduling knobs.
    """

    def __init__(
        self,
        api: SceneClient,
        clock: Clock,
        cache: Cache,
        config: StreamerConfig,
    ) -> None:
        self.api = api
        self.clock = clock
        self.cache = cache
        self.config = config
        self.kind: Kind = "params" if config.form == "params" else "mesh"
        """The cache kind of what is downloaded per object."""
        self.rewrite: RewritePool | None = (
            RewritePool(clock, None, self.on_built, config.workers) if self.kind == "params" else None
        )
        self.disk: DiskCache | None = None
        """The persistent cache, once the manifest says which scene version it is for."""
        self.api_max_ids = 1000
        """Most ids one objects request may ask for (the manifest's limit, once known)."""
        self.cellmap = CellMap()
        self.stats = StreamStats()
        self.cells: dict[int, CellRecord] = {}
        """Every cell record fetched (small; also counted in the cache)."""
        self.need: dict[int, float] = {}
        """Cells wanted now -> seconds until needed (from the last plan)."""
        self._cell_tasks: dict[int, asyncio.Task[None]] = {}
        self._locate_task: asyncio.Task[None] | None = None
        self._batches: dict[asyncio.Task[None], list[int]] = {}
        self._in_flight_ids: set[int] = set()
        self._urgent: set[int] = set()
        self._urgent_batches: set[asyncio.Task[None]] = set()
        self._wanted: dict[int, tuple[float, float]] = {}
        self._last_plan = -math.inf
        self._last_locate = -math.inf
        self._xy = np.zeros(2)
        self._velocity = np.zeros(2)
        self._cell_bytes = 3000.0  # EWMA of object bytes a newly entered cell needed
        self._frame_bytes = 80.0  # EWMA of one object frame
        self.geometry_version = 0
        self.walk_end = math.inf
        """Clock time at which the walk ends (the replay sets it; prefetch stops short of it)."""
        self._now = 0.0
        self._needed_at: dict[int, float] = {}
        self._closed = False

    # -- the frame loop's side -------------------------------------------------

    def tick(self, now: float, xy: ArrayLike, predictor: MotionPredictor) -> int | None:
        """Follow the viewer to ``xy``; plan and dispatch when due.  Returns the current cell."""
        self._now = now
        self._xy = np.asarray(xy, dtype=np.float64).reshape(2)
        self._velocity = predictor.velocity()
        before = self.cellmap.current
        cur, found = self.cellmap.update(self._xy)
        if cur != before and cur is not None:
            self._entered(cur)
        if not found and self._locate_task is None and now - self._last_locate >= 1.0:
            self._last_locate = now
            self._locate_task = asyncio.create_task(self._locate(self._xy.copy()))
        if now - self._last_plan >= self.config.plan_interval_s or cur != before:
            self._last_plan = now
            self._plan()
            self._dispatch()
        return cur

    def _pin(self, need: dict[int, float]) -> None:
        """Pin the current cell with its PVS (params and geometry), and the records and
        params of the cells about to be entered: evicting what the next seconds need
        would only download it again (geometry can be rebuilt, so it is not pinned)."""
        cur = self.cellmap.current
        rec = self.cells.get(cur) if cur is not None else None
        # hysteresis: a cell that drops out of the prediction for a moment (the
        # prediction wobbles at 10 Hz) keeps its pins for pin_hold_s
        for c in need:
            self._needed_at[c] = self._now
        hold = self.config.pin_hold_s
        for c in [c for c, t in self._needed_at.items() if self._now - t > hold]:
            del self._needed_at[c]
        keys: list[tuple[str, int]] = [("cell", c) for c in self._needed_at if c in self.cells]
        if rec is not None:
            keys += [(self.kind, i) for i in rec.pvs.tolist()]
            keys += [("geom", i) for i in rec.pvs.tolist()]
        for c in self._needed_at:
            r = self.cells.get(c)
            if r is not None and c != cur:
                keys += [(self.kind, i) for i in r.pvs.tolist()]
        self.cache.set_pins(keys)

    def _entered(self, cid: int) -> None:
        rec = self.cells.get(cid)
        self._pin({**self.need, cid: 0.0})
        if rec is not None and self.rewrite is not None:
            for oid, a in zip(rec.pvs.tolist(), rec.ach.tolist(), strict=True):
                self.rewrite.bump(oid, (0.0, -a))

    def horizon(self) -> float:
        """Seconds of predicted motion to prefetch for (see the module docs)."""
        c = self.config
        rtt = self.api.stats.rtt_s if math.isfinite(self.api.stats.rtt_s) else c.assumed_rtt_s
        bps = (
            self.api.stats.bandwidth_bps
            if math.isfinite(self.api.stats.bandwidth_bps)
            else c.assumed_bps
        )
        transfer = (self._cell_bytes + 1000.0) * 8.0 / max(bps, 1.0)
        h = c.horizon_margin * (2.0 * rtt + transfer) + 1.0
        return float(min(c.horizon_max_s, max(c.horizon_min_s, h)))

    def _plan(self) -> None:
        need: dict[int, float] = {}
        cur = self.cellmap.current
        if cur is not None:
            need[cur] = 0.0
        if self.config.prefetch and cur is not None:
            # a recorded walk ends: nothing is needed after its last frame
            h = min(self.horizon(), max(0.0, self.walk_end - self._now))
            v = self._velocity
            speed = float(np.hypot(*v))
            if speed > 0.2:
                step = max(0.05, min(0.5, 2.0 / speed))
                dts = np.arange(step, h + 1e-9, step)
                track = self._xy[None, :] + dts[:, None] * v[None, :]
                for dt, c in zip(dts.tolist(), self.cellmap.find_along(track, cur), strict=True):
                    if c is not None and c not in need:
                        need[c] = dt
            reach = max(speed, 1.0)
            for c in list(need):
                for n in self.cellmap.neighbours.get(c, ()):
                    if n in need:
                        continue
                    t = self.cellmap.distance_to(n, self._xy) / reach
                    if t <= h:
                        need[n] = max(t, need[c])
        self.need = need
        self._pin(need)
        wanted: dict[int, tuple[float, float]] = {}
        for c, t in need.items():
            rec = self.cells.get(c)
            if rec is None:
                continue
            for oid, a in zip(rec.pvs.tolist(), rec.ach.tolist(), strict=True):
                if self.has_object(oid):
                    continue
                key = (t, -a)
                old = wanted.get(oid)
                if old is None or key < old:
                    wanted[oid] = key
        self._wanted = wanted
        # cancel in-flight batches nobody needs any more
        for task, ids in list(self._batches.items()):
            if not any(i in wanted for i in ids):
                task.cancel()
                self.stats.cancelled_batches += 1

    def _dispatch(self) -> None:
        """Start requests, soonest needed first, while the in-flight bounds allow."""
        if self._closed:
            return
        c = self.config
        cells = sorted(
            (t, cid)
            for cid, t in self.need.items()
            if cid not in self.cells and cid not in self._cell_tasks
        )
        k = 0
        while self._in_flight() < c.max_in_flight:
            obj_t = self._best_object_time()
            can_batch = obj_t is not None and len(self._batches) < c.max_object_requests
            if k < len(cells) and (not can_batch or cells[k][0] <= obj_t):  # type: ignore[operator]
                t, cid = cells[k]
                if t > 0 and self._urgent_in_flight():
                    return  # what is needed now gets the whole link
                k += 1
                self._cell_tasks[cid] = asyncio.create_task(self._fetch_cell(cid))
                if t <= 0:
                    self._urgent.add(cid)
            elif can_batch:
                assert obj_t is not None
                if obj_t > 0 and self._urgent_in_flight():
                    return
                ids = self._next_batch()
                if not ids:
                    return
                task = asyncio.create_task(self._fetch_objects(ids))
                self._batches[task] = ids
                self._in_flight_ids.update(ids)
                if obj_t <= 0:
                    self._urgent_batches.add(task)
            else:
                return

    def _urgent_in_flight(self) -> bool:
        """Whether a request for the current cell (needed now) is still in flight."""
        self._urgent &= set(self._cell_tasks)
        self._urgent_batches &= set(self._batches)
        return bool(self._urgent or self._urgent_batches)

    def _best_object_time(self) -> float | None:
        best: float | None = None
        for oid, (t, _a) in self._wanted.items():
            if oid not in self._in_flight_ids and (best is None or t < best):
                best = t
        return best

    def _in_flight(self) -> int:
        return len(self._cell_tasks) + len(self._batches) + (self._locate_task is not None)

    def _next_batch(self) -> list[int]:
        todo = [(k, oid) for oid, k in self._wanted.items() if oid not in self._in_flight_ids]
        if not todo:
            return []
        todo.sort()
        # everything needed now goes in one request; later needs in slices of about
        # batch_seconds of transfer, so that a new prediction can re-order them soon
        now = sum(1 for k, _ in todo if k[0] <= 0)
        bps = self.api.stats.bandwidth_bps
        if not math.isfinite(bps):
            bps = self.config.assumed_bps
        n = int(bps / 8.0 * self.config.batch_seconds / max(self._frame_bytes, 16.0))
        n = max(8, now, min(n, self.api_max_ids))
        n = min(n, self.api_max_ids)
        return [oid for _, oid in todo[:n]]


    # -- requests --------------------------------------------------------------

    def _done(self) -> None:
        if not self._closed:
            self._plan()
            self._dispatch()

    async def _locate(self, xy: NDArray[np.float64]) -> None:
        try:
            self.stats.locate_requests += 1
            cid = await self.api.locate(float(xy[0]), float(xy[1]))
            if cid is not None and self.cellmap.current is None:
                self.cellmap.current = cid
                self._entered(cid)
            if cid is not None and cid not in self.cells and cid not in self._cell_tasks:
                self._cell_tasks[cid] = asyncio.create_task(self._fetch_cell(cid))
        except ApiError:
            pass  # outside the scene or refused: keep the last cell
        finally:
            self._locate_task = None
        self._done()

    async def _fetch_cell(self, cid: int) -> None:
        try:
            rec: CellRecord | None = None
            cached = self.disk.get_cell(cid) if self.disk is not None else None
            self.stats.cell_requests += 1
            if cached is not None:
                etag, body = cached
                fresh = await self.api.cell(cid, etag=etag)
                if fresh is None:
                    self.stats.cells_revalidated += 1
                    with contextlib.suppress(CodecError):
                        rec = decode_cell(body, f"cell {cid} (disk cache)", etag)
                else:
                    rec = fresh
            if rec is None:
                rec = await self.api.cell(cid)
            assert rec is not None
            self._add_cell(rec)
        except ApiError:
            pass  # refused (4xx): nothing to wait for
        finally:
            self._cell_tasks.pop(cid, None)
        self._done()

    def _add_cell(self, rec: CellRecord) -> None:
        self.cells[rec.id] = rec
        self.cache.put("cell", rec.id, rec, max(rec.nbytes, 64))
        self.cellmap.add_record(rec.id, rec.boundary, rec.neighbours)
        if self.disk is not None and rec.etag:
            self.disk.put_cell(rec.id, rec.etag, rec.body)
        if self.cellmap.current == rec.id:
            self._entered(rec.id)
            new = sum(1 for i in rec.pvs.tolist() if not self.cache.has(self.kind, i))
            self._cell_bytes = 0.8 * self._cell_bytes + 0.2 * new * self._frame_bytes

    async def _fetch_objects(self, ids: list[int]) -> None:
        task = asyncio.current_task()
        remaining = list(ids)
        try:
            if self.disk is not None:
                found = self.disk.get_objects(remaining, self.config.form)
                for oid, blob in found.items():
                    try:
                        kind, payload = unpack_bounded(
                            blob, f"object {oid} (disk cache)", max_array_len=2, max_str_len=64
                        )
                    except (CodecError, ValueError, TypeError):
                        continue  # damaged on disk: fetched from the server instead
                    self.stats.disk_hits += 1
                    self._add_object(ObjectFrame(oid, kind, payload, self.config.form, 0))
                found = {i: b for i, b in found.items() if self.has_object(i)}
                remaining = [i for i in remaining if i not in found]
            if remaining:
                self.stats.object_requests += 1
                got: list[ObjectFrame] = []
                try:
                    async for frame in self.api.objects(remaining, self.config.form):
                        got.append(frame)
                        self._add_object(frame)
                finally:
                    if self.disk is not None and got:
                        self.disk.put_objects(
                            [(f.id, msgpack.packb([f.kind, f.payload])) for f in got],
                            self.config.form,
                        )
        except StreamCut:
            pass  # the ids not received are wanted again at the next plan
        except ApiError:
            pass
        finally:
            if task is not None:
                self._batches.pop(task, None)
            self._in_flight_ids.difference_update(ids)
        self._done()

    def _add_object(self, frame: ObjectFrame) -> None:
        oid = frame.id
        self.geometry_version += 1  # download quality may change
        if frame.nbytes:
            self.stats.objects_received += 1
            self.stats.object_bytes[oid] = self.stats.object_bytes.get(oid, 0) + frame.nbytes
            self.stats.object_counts[oid] = self.stats.object_counts.get(oid, 0) + 1
            self._frame_bytes = 0.95 * self._frame_bytes + 0.05 * frame.nbytes
            self.cache.note_download(oid)
        what = f"object {oid}"
        try:
            if frame.form == "params":
                params = decode_object(frame.payload, what)
                self.cache.put("params", oid, params, max(len(frame.payload), 16))
                self._submit_rewrite(oid, params)
            else:
                mesh = decode_mesh(frame.payload, what)
                self.cache.put("mesh", oid, frame.payload, max(len(frame.payload), 16))
                self._geometry_ready(geometry_of(oid, (None, None, mesh)))
        except CodecError:
            return  # a bad record: not cached, so it is wanted (and fetched) again

    def _submit_rewrite(self, oid: int, params: object) -> None:
        if self.rewrite is None:
            return
        key = self._wanted.get(oid)
        if key is None:
            key = (math.inf, 0.0)
            cur = self.cellmap.current
            rec = self.cells.get(cur) if cur is not None else None
            if rec is not None:
                hit = np.flatnonzero(rec.pvs == oid)
                if len(hit):
                    key = (0.0, -float(rec.ach[hit[0]]))
        self.rewrite.submit(oid, params, key)  # type: ignore[arg-type]

    def has_object(self, oid: int) -> bool:
        """Whether ``oid`` arrived and is still usable (its download or its geometry is cached)."""
        return self.cache.has(self.kind, oid) or self.cache.has("geom", oid)

    def on_built(self, geom: ObjectGeometry) -> None:
        """Rewrite pool callback: geometry of one object is ready."""
        self.cache.note_build(geom.id)
        self._geometry_ready(geom)

    def _geometry_ready(self, geom: ObjectGeometry) -> None:
        self.cache.put("geom", geom.id, geom, max(geom.nbytes, 64))
        self.geometry_version += 1

    def ensure_geometry(self, ids: list[int]) -> None:
        """Queue rebuilds for objects whose params are cached but geometry was evicted."""
        if self.rewrite is None:
            return
        for oid in ids:
            if self.cache.has("geom", oid) or self.rewrite.queued(oid):
                continue
            params = self.cache.peek("params", oid)
            if params is not None:
                self._submit_rewrite(oid, params)

    def start(self) -> None:
        """Start the rewrite workers (on the running event loop)."""
        if self.rewrite is not None:
            self.rewrite.start()

    def on_manifest(self, max_ids: int, grammar: Grammar | None, disk: DiskCache | None) -> None:
        """The manifest arrived: the request limit, the grammar, the disk cache to use.

        ``disk`` is a disk cache already bound to the manifest's scene version (or
        None); ``grammar`` lets the rewrite jobs start (ignored when nothing is rebuilt).
        """
        self.api_max_ids = max_ids
        if self.rewrite is not None and grammar is not None:
            self.rewrite.set_grammar(grammar)
        self.disk = disk

    async def close(self) -> None:
        """Cancel everything in flight and stop the rewrite workers."""
        self._closed = True
        tasks = list(self._cell_tasks.values()) + list(self._batches)
        if self._locate_task is not None:
            tasks.append(self._locate_task)
        for t in tasks:
            t.cancel()
        for t in tasks:
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await t
        if self.rewrite is not None:
            await self.rewrite.close()
