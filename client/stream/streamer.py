"""The streaming scheduler: what to fetch next, given where the viewer is going.

What the client knows of the scene's layout comes from the cell index (tiles of
outlines, heights and adjacency, :class:`~walkstream.shared.wire.CellIndex`); per
cell it fetches only the cell's own record (PVS and ACH) and the objects of the
PVS it does not hold.  Each planning step (a few times a second, driven by the
frame loop, and whenever a request ends) works out what is needed and when:

* the index tiles that may hold cells within the records' horizon of the viewer,
  the tile under the viewer needed now;
* along the cell graph (:func:`~walkstream.client.stream.route.predict_route`):
  the viewer's cell (needed now), the cells ahead on the street, the continuations
  at the next junctions weighted by turn cost, the way back last, each needed at
  its cost over the speed.  Objects are wanted for the cells within the *horizon*
  (a distance that grows with speed: the request round trips plus the transfer of
  a cell's new objects at the *measured* bandwidth, with a margin, times the
  speed, and at least ``horizon_min_m``); cell records further, to
  ``record_factor`` times that (they are small);
* outside every cell (or before the index arrived), the cells the straight
  least-squares extrapolation of the motion enters.

Requests go out most urgent first -- an index tile, a batch of cell records, or a
batch of objects ordered by the time each is needed and then by ACH (highest
first) -- through the link's :class:`~walkstream.client.stream.scheduler.RequestScheduler`
(the streamer is one of its lanes: a crossing walk's room streamer is another, and
the scheduler starts whichever lane's next request is needed sooner), while fewer
than ``max_requests`` are in flight and the bytes asked for
but not yet received cover less than ``cover`` round trips of transfer at the
measured bandwidth: enough to keep the link busy across a round trip, no more, so
that a new prediction can still re-order what is not yet asked for.  An object
batch is about ``batch_seconds`` of transfer.  What a new prediction no longer
needs is dropped from the queue, and an in-flight batch none of whose remaining
items is wanted is cancelled (what already arrived is kept).  Nothing cached or in
flight is asked for again; an item comes again only after the cache evicted it
(counted as a re-download).

The start: the streamer's :class:`~walkstream.client.stream.startfeed.StartFeed`
(:attr:`Streamer.start_feed`) asks for the start bundle (path, first cell, index
tiles, manifest, the first cell's objects in one round trip) and feeds its parts in
as they arrive.

The scheduler never blocks the frame loop: it starts tasks and returns.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any, cast

import msgpack
import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.client.clock import Clock
from walkstream.client.content.registry import client_content_for_form
from walkstream.client.net.api import SceneClient
from walkstream.client.rewrite.geometry import ObjectGeometry, geometry_of
from walkstream.client.rewrite.pool import RewriteOptions, RewritePool
from walkstream.client.stream.cache import CITY_KINDS, Cache, Kind
from walkstream.client.stream.cellmap import CellMap
from walkstream.client.stream.diskcache import DiskCache
from walkstream.client.stream.pins import Pins
from walkstream.client.stream.plan import Tile, plan_needs, tile_key, tile_of_key, wanted_objects
from walkstream.client.stream.predict import MotionPredictor
from walkstream.client.stream.route import horizon_m, turn_cost_m
from walkstream.client.stream.scheduler import Flight, Offer, RequestScheduler
from walkstream.client.stream.startfeed import StartFeed
from walkstream.client.stream.stats import StreamStats
from walkstream.client.tasks import reap
from walkstream.shared.cells import TileGrid
from walkstream.shared.codec import unpack_bounded
from walkstream.shared.errors import ApiError, CodecError, StreamCut
from walkstream.shared.lsystem.grammar import Grammar
from walkstream.shared.wire import (
    CellIndex,
    CellRecord,
    ObjectFrame,
    decode_cell,
    decode_cell_index,
)

__all__ = ["StreamerConfig", "Streamer"]


@dataclass(frozen=True)
class StreamerConfig:
    """Scheduling knobs."""

    prefetch: bool = True
    form: str = "params"
    """``params`` (rebuild locally) or ``lod2`` (download LOD2 meshes)."""
    workers: int = 2
    """Rewrite workers (with ``params``)."""
    rewrite: RewriteOptions = RewriteOptions()
    """Processes or threads for the real clock's rebuilds, and their shared-memory bound."""
    max_requests: int = 4
    """Most requests in flight at once."""
    cover: float = 1.0
    """Bytes asked for but not received may cover this many round trips of transfer."""
    plan_interval_s: float = 0.1
    batch_seconds: float = 0.5
    """An object batch is about this much transfer at the measured bandwidth."""
    horizon_min_s: float = 2.0
    horizon_max_s: float = 30.0
    horizon_margin: float = 2.0
    horizon_min_m: float = 60.0
    """The horizon in distance is at least this (a walker still sees the next junction)."""
    record_ahead_m: float = 20.0
    """Cell records are fetched this much (or two round trips and a second at the
    speed, if more) beyond the objects' horizon."""
    turn_base_m: float = 10.0
    turn_s: float = 3.0
    """Turning back costs ``turn_base_m + speed * turn_s`` metres (see route.py)."""
    min_speed: float = 1.5
    """Need times assume at least this speed, m/s (a stopped viewer still moves on)."""
    assumed_bps: float = 40_000.0
    """Bandwidth assumed before anything was measured (conservative: GPRS class)."""
    assumed_rtt_s: float = 0.5
    pin_hold_s: float = 5.0
    """A cell's objects stay pinned this long after it was last needed."""
    pin_geometry_s: float = 3.0
    """The geometry of the cells entered within this many seconds is pinned and, when
    the cache evicted it, rebuilt ahead."""


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
        The byte-budget cache (index tiles, cells, downloads, geometry); the
        streamer forgets what it evicts (chain :meth:`evicted` into its ``on_evict``).
    config:
        Scheduling knobs.
    scheduler:
        The link's request scheduler, shared with the walk's other streamers (by
        default one of its own, with ``config.max_requests`` slots).
    """

    def __init__(
        self,
        api: SceneClient,
        clock: Clock,
        cache: Cache,
        config: StreamerConfig,
        *,
        scheduler: RequestScheduler | None = None,
    ) -> None:
        self.api = api
        self.scheduler = scheduler if scheduler is not None else RequestScheduler(config.max_requests)
        """The link's request scheduler (this streamer is one of its lanes)."""
        self.scheduler.join(self)
        if self.scheduler.measure is None:
            self.scheduler.measure = lambda: (self._bps(), self._rtt())
        self.clock = clock
        self.cache = cache
        self.config = config
        self.kind: Kind = cast(Kind, client_content_for_form(config.form).kind.cache_kind)
        """The cache kind of what is downloaded per object."""
        self.rewrite: RewritePool | None = None
        if self.kind == "params":
            self.rewrite = RewritePool(clock, None, self.on_built, config.workers, options=config.rewrite)
        self.disk: DiskCache | None = None
        """The persistent cache, once the manifest says which scene version it is for."""
        self.api_max_ids = 1000
        """Most ids one objects request may ask for (the manifest's limit, once known)."""
        self.grid: TileGrid | None = None
        """The tiles of the cell index (from the manifest)."""
        self.cellmap = CellMap()
        self.stats = StreamStats()
        self.cells: dict[int, CellRecord] = {}
        """The cell records held (mirrors the cache)."""
        self.pvs_seen: dict[int, NDArray[np.int64]] = {}
        """The PVS of every cell record ever received (for the overfetch figure)."""
        self.start_feed = StartFeed(self, config.form, self.cellmap)
        """The start bundle and what it brought besides cells and objects."""
        self.tiles_held: set[Tile] = set()
        self.tile_members: dict[int, frozenset[int]] = {}
        """The cell ids of every index tile ever received, by :func:`tile_key`."""
        self.need: dict[int, float] = {}
        """Cells whose objects are wanted now -> seconds until needed (from the last plan)."""
        self.need_records: dict[int, float] = {}
        """Cells whose records are wanted -> seconds until needed."""
        self.need_tiles: dict[Tile, float] = {}
        self._tile_tasks: dict[Tile, asyncio.Task[None]] = {}
        self._locate_task: asyncio.Task[None] | None = None
        self._in_flight_ids: set[int] = set()
        self._in_flight_cells: set[int] = set()
        self._wanted: dict[int, tuple[float, float]] = {}
        self._last_plan = -math.inf
        self._last_locate = -math.inf
        self._xy = np.zeros(2)
        self._velocity = np.zeros(2)
        self._heading: NDArray[np.float64] | None = None
        self._cell_bytes = 3000.0  # EWMA of object bytes a newly entered cell needed
        self._frame_bytes = 80.0  # EWMA of one object frame
        self._record_bytes = 200.0  # EWMA of one cell record
        self._tile_bytes = 1500.0  # EWMA of one index tile
        self._head_bytes = 200.0  # a response's status line and headers
        self.geometry_version = 0
        self.walk_end = math.inf
        """Clock time at which the walk ends (the replay sets it; prefetch stops short of it)."""
        self._now = 0.0
        self.pins = Pins(config.pin_hold_s, config.pin_geometry_s)
        self._busy_since: float | None = None
        self._closed = False

    # -- the frame loop's side -------------------------------------------------

    def tick(self, now: float, xy: ArrayLike, predictor: MotionPredictor) -> int | None:
        """Follow the viewer to ``xy``; plan and dispatch when due.  Returns the current cell."""
        self._now = now
        self._xy = np.asarray(xy, dtype=np.float64).reshape(2)
        self._velocity = predictor.velocity()
        self._heading = predictor.heading()
        before = self.cellmap.current
        cur, found = self.cellmap.update(self._xy)
        if cur != before and cur is not None:
            self._entered(cur)
        if (
            not found
            and self.grid is None
            and self.start_feed.bundle is None
            and self._locate_task is None
            and now - self._last_locate >= 1.0
        ):
            # no cell index to look in: ask the server where we are
            self._last_locate = now
            self._locate_task = asyncio.create_task(self._locate(self._xy.copy()))
        if now - self._last_plan >= self.config.plan_interval_s or cur != before:
            self._last_plan = now
            self._plan()
            self.scheduler.dispatch()
        self._note_busy()
        return cur

    def _note_busy(self) -> None:
        busy = self._in_flight() > 0
        if busy and self._busy_since is None:
            self._busy_since = self.clock.now()
        elif not busy and self._busy_since is not None:
            self.stats.busy.append((self._busy_since, self.clock.now()))
            self._busy_since = None

    def busy_intervals(self) -> list[tuple[float, float]]:
        """The intervals during which a request was in flight, to now."""
        out = list(self.stats.busy)
        if self._busy_since is not None:
            out.append((self._busy_since, self.clock.now()))
        return out

    def _pin(self, need: dict[int, float]) -> None:
        """Pin what the next seconds need (see :class:`~walkstream.client.stream.pins.Pins`)."""
        cur = self.cellmap.current
        tiles = [tile_key(t) for t in self.need_tiles]
        if self.grid is not None:
            tiles.append(tile_key(self.grid.tile_of(self._xy)))
        self.cache.set_pins(self.pins.keys(self._now, need, cur, self.cells, self.kind, tiles), kinds=CITY_KINDS)

    def _entered(self, cid: int) -> None:
        rec = self.cells.get(cid)
        self._pin({**self.need, cid: 0.0})
        if rec is not None and self.rewrite is not None:
            for oid, a in zip(*(v.tolist() for v in rec.streamed()), strict=True):
                self.rewrite.bump(oid, (0.0, -a))

    def _bps(self) -> float:
        b = self.api.stats.bandwidth_bps
        return b if math.isfinite(b) else self.config.assumed_bps

    def _rtt(self) -> float:
        r = self.api.stats.rtt_s
        return r if math.isfinite(r) else self.config.assumed_rtt_s

    @property
    def velocity(self) -> np.ndarray:
        """``(2,)`` the viewer's velocity as last predicted, m/s (what :attr:`need` was planned with)."""
        return self._velocity

    def horizon(self) -> float:
        """Seconds of predicted motion to prefetch objects for (see the module docs)."""
        c = self.config
        transfer = (self._cell_bytes + 1000.0) * 8.0 / max(self._bps(), 1.0)
        h = c.horizon_margin * (2.0 * self._rtt() + transfer) + 1.0
        return float(min(c.horizon_max_s, max(c.horizon_min_s, h)))

    def horizon_distance(self) -> float:
        """The objects' horizon in metres at the current speed (see the module docs)."""
        return horizon_m(
            float(np.hypot(*self._velocity)), self.horizon(), self.config.horizon_min_m
        )

    def _plan(self) -> None:
        c = self.config
        speed = float(np.hypot(*self._velocity))
        v_eff = max(speed, c.min_speed)
        left = max(0.0, self.walk_end - self._now)  # a recorded walk ends: nothing after it
        reach = min(self.horizon_distance(), left * v_eff) if c.prefetch else 0.0
        # records (and index tiles) a little further: objects can be asked for only
        # once a cell's record is in, a round trip later
        extra = max(c.record_ahead_m, speed * (2.0 * self._rtt() + 1.0))
        needs = plan_needs(
            self.cellmap,
            self.grid,
            self._xy,
            self._velocity,
            self._heading,
            reach_m=reach,
            reach_records_m=reach + extra if c.prefetch else 0.0,
            turn_m=turn_cost_m(speed, c.turn_base_m, c.turn_s),
            min_speed=c.min_speed,
            prefetch=c.prefetch,
        )
        need, records, tiles = needs.need, needs.records, needs.tiles
        self.need = need
        self.need_records = records
        self.need_tiles = tiles
        self._pin(need)
        wanted = wanted_objects(need, self.cells, self.has_object)
        self._wanted = wanted
        if self.rewrite is not None:
            # what the cache evicted and the next seconds need is rebuilt ahead
            for cell, t in need.items():
                rec = self.cells.get(cell)
                if rec is not None and t <= c.pin_geometry_s:
                    self.ensure_geometry(rec.streamed()[0].tolist(), t)
            self.rewrite.prune(
                [r.streamed()[0] for x in (*need, self.cellmap.current or -1) if (r := self.cells.get(x))]
            )
        # cancel in-flight batches nobody needs any more
        self.stats.cancelled_batches += self.scheduler.cancel_unwanted(self, {"objects": wanted, "cells": records})

    def _missing_records(self) -> list[tuple[float, int]]:
        return sorted(
            (t, cid)
            for cid, t in self.need_records.items()
            if cid not in self.cells and cid not in self._in_flight_cells
        )

    def _missing_tiles(self) -> list[tuple[float, Tile]]:
        return sorted(
            (
                (t, tile)
                for tile, t in self.need_tiles.items()
                if tile not in self.tiles_held and tile not in self._tile_tasks
            ),
            key=lambda x: (x[0], tile_key(x[1])),
        )

    def outstanding_bytes(self) -> float:
        """Bytes asked for and not yet received (estimated; the scheduler's cover counts them)."""
        return self._outstanding()

    def _outstanding(self) -> float:
        """Bytes asked for and not yet received (estimated)."""
        n = self.start_feed.left()
        for b in self.scheduler.flights(self):
            each = self._frame_bytes if b.kind == "objects" else self._record_bytes
            n += len(b.left) * each + self._head_bytes
        n += len(self._tile_tasks) * (self._tile_bytes + self._head_bytes)
        return n

    def offer(self) -> Offer | None:
        """The request to start next, most urgent first, while the in-flight bounds
        allow (the scheduler's :meth:`~walkstream.client.stream.scheduler.Lane.offer`).

        A batch waits while it is small and nothing in it is due soon: a request
        costs a round trip and its headers, so several small ones cost more than
        one full one (see the module docs).
        """
        c = self.config
        if self._closed or self._in_flight() >= c.max_requests:
            return None
        bps8 = self._bps() / 8.0
        rtt = self._rtt()
        out = self._outstanding()
        if self._in_flight() and out >= c.cover * bps8 * rtt:
            return None
        # an item is due when asking later would bring it too late: a round trip,
        # the transfer of what is ahead of it, and a margin
        due = 2.0 * rtt + out / bps8 + c.batch_seconds + 1.0
        full = bps8 * c.batch_seconds
        records = self._missing_records()
        tiles = self._missing_tiles()
        options: list[tuple[float, int, str]] = []
        if tiles:
            options.append((tiles[0][0], 0, "tile"))
        # a record is due a round trip before its cell's objects are
        if records and (
            records[0][0] <= due + 2.0 * rtt or len(records) * self._record_bytes >= full
        ):
            options.append((records[0][0], 1, "cells"))
        todo = self._todo_objects()
        if todo and (todo[0][0][0] <= due or len(todo) * self._frame_bytes >= full):
            options.append((todo[0][0][0], 2, "objects"))
        if not options:
            return None
        need, _, what = min(options)
        if what == "tile":
            tile = tiles[0][1]
            return Offer(need, lambda: self._start_tile(tile))
        if what == "cells":
            n = max(4, int(full / max(self._record_bytes, 16.0)))
            cells = [cid for _, cid in records[:n]]
            return Offer(need, lambda: self._start_batch("cells", cells))
        ids = self._next_batch(todo)
        if not ids:
            return None
        return Offer(need, lambda: self._start_batch("objects", ids))

    def _start_tile(self, tile: Tile) -> None:
        self._tile_tasks[tile] = asyncio.create_task(self._fetch_tile(tile))

    @contextlib.contextmanager
    def _running(self, b: Flight) -> Iterator[None]:
        """Scope of one batch's request: however it ends (whole, cut, refused or
        cancelled), the batch leaves the in-flight sets, so what it did not bring is
        wanted again at the next plan (made here unless cancelled)."""
        try:
            yield
        except (StreamCut, ApiError):
            pass  # what was not received is wanted again at the next plan
        finally:
            self.scheduler.landed(b)
            in_flight = self._in_flight_ids if b.kind == "objects" else self._in_flight_cells
            in_flight.difference_update(b.ids)
        self.replan()

    def _start_batch(self, kind: str, ids: list[int]) -> None:
        if kind == "objects":
            self._in_flight_ids.update(ids)
            self.scheduler.launch(self, kind, ids, self._fetch_objects)
        else:
            self._in_flight_cells.update(ids)
            self.scheduler.launch(self, kind, ids, self._fetch_cells)

    def _todo_objects(self) -> list[tuple[tuple[float, float], int]]:
        """Wanted objects not asked for yet, most urgent first: ``((t, -ach), id)``."""
        todo = [(k, oid) for oid, k in self._wanted.items() if oid not in self._in_flight_ids]
        todo.sort()
        return todo

    def in_flight(self) -> int:
        """Requests of this streamer on the link now (the scheduler counts its slots by them)."""
        return self._in_flight()

    def _in_flight(self) -> int:
        return (
            len(self._tile_tasks)
            + len(self.scheduler.flights(self))
            + (self._locate_task is not None)
            + (self.start_feed.task is not None)
        )

    def _next_batch(self, todo: list[tuple[tuple[float, float], int]]) -> list[int]:
        if not todo:
            return []
        # everything needed now goes in one request; later needs in slices of about
        # batch_seconds of transfer, so that a new prediction can re-order them soon
        now = sum(1 for k, _ in todo if k[0] <= 0)
        n = int(self._bps() / 8.0 * self.config.batch_seconds / max(self._frame_bytes, 16.0))
        n = max(8, now, min(n, self.api_max_ids))
        n = min(n, self.api_max_ids)
        return [oid for _, oid in todo[:n]]

    # -- requests --------------------------------------------------------------

    def replan(self) -> None:
        """Plan and dispatch again (something arrived or ended)."""
        if not self._closed:
            self._plan()
            self.scheduler.dispatch()
            self._note_busy()

    async def _locate(self, xy: NDArray[np.float64]) -> None:
        try:
            self.stats.locate_requests += 1
            cid = await self.api.locate(float(xy[0]), float(xy[1]))
            if cid is not None and self.cellmap.current is None:
                self.cellmap.current = cid
                self._entered(cid)
        except ApiError:
            pass  # outside the scene or refused: keep the last cell
        finally:
            self._locate_task = None
        self.replan()

    async def _fetch_tile(self, tile: Tile) -> None:
        try:
            idx: CellIndex | None = None
            cached = self.disk.get_index(tile_key(tile)) if self.disk is not None else None
            if cached is not None:
                with contextlib.suppress(CodecError):
                    idx = decode_cell_index(cached, f"index tile {tile} (disk cache)")
                    self.stats.disk_hits += 1
            if idx is None:
                self.stats.tile_requests += 1
                idx = await self.api.cell_index(tile)
            self.add_index(idx)
        except ApiError:
            pass  # refused (4xx): nothing to wait for
        finally:
            self._tile_tasks.pop(tile, None)
        self.replan()

    async def _fetch_cells(self, b: Flight) -> None:
        with self._running(b):
            remaining = list(b.ids)
            if self.disk is not None:
                for cid in list(remaining):
                    body = self.disk.get_cell(cid)
                    if body is None:
                        continue
                    with contextlib.suppress(CodecError):
                        self.add_cell(decode_cell(body, f"cell {cid} (disk cache)"), from_disk=True)
                        self.stats.disk_hits += 1
                        remaining.remove(cid)
                        b.left.discard(cid)
            if remaining:
                self.stats.cell_requests += 1
                async for rec in self.api.cells(remaining):
                    b.left.discard(rec.id)
                    self.add_cell(rec)

    def add_index(self, idx: CellIndex) -> None:
        """Learn an index tile (from a request, the bundle or the disk cache)."""
        tile = idx.tile
        self.tile_members[tile_key(tile)] = frozenset(idx.ids.tolist())
        self.cellmap.add_cells(
            idx.ids.tolist(), idx.outlines, [n.tolist() for n in idx.neighbours], idx.kinds, tile
        )
        self.tiles_held.add(tile)
        key = tile_key(tile)
        if idx.nbytes:
            self.stats.tile_bytes[key] = self.stats.tile_bytes.get(key, 0) + idx.nbytes
            self._tile_bytes = 0.7 * self._tile_bytes + 0.3 * idx.nbytes
        self.cache.put("index", key, idx, max(idx.nbytes, 64 + 48 * len(idx)))
        if self.disk is not None and idx.body:
            self.disk.put_index(key, idx.body)

    def add_cell(self, rec: CellRecord, *, from_disk: bool = False) -> None:
        """Learn a cell record (from a request, the bundle or the disk cache)."""
        self.cells[rec.id] = rec
        self.pvs_seen[rec.id] = rec.pvs
        if rec.nbytes and not from_disk:
            self.stats.cells_received += 1
            self.stats.cell_bytes[rec.id] = self.stats.cell_bytes.get(rec.id, 0) + rec.nbytes
            self._record_bytes = 0.9 * self._record_bytes + 0.1 * rec.nbytes
            if self.disk is not None:
                self.disk.put_cell(
                    rec.id, rec.body or msgpack.packb(rec.to_wire(), use_bin_type=True)
                )
        self.cache.put("cell", rec.id, rec, max(rec.nbytes, 64))
        if self.cellmap.current == rec.id:
            self._entered(rec.id)
            new = sum(1 for i in rec.pvs.tolist() if not self.cache.has(self.kind, i))
            self._cell_bytes = 0.8 * self._cell_bytes + 0.2 * new * self._frame_bytes

    def evicted(self, kind: str, key: int) -> None:
        """Cache hook: forget an evicted index tile or cell record."""
        if kind == "index":
            tile = tile_of_key(key)
            self.tiles_held.discard(tile)
            self.cellmap.forget_tile(tile)
        elif kind == "cell":
            self.cells.pop(key, None)

    async def _fetch_objects(self, b: Flight) -> None:
        remaining = list(b.ids)
        with self._running(b):
            found = self.objects_from_disk(remaining)
            b.left -= found
            remaining = [i for i in remaining if i not in found]
            if remaining:
                self.stats.object_requests += 1
                got: list[ObjectFrame] = []
                try:
                    async for frame in self.api.objects(remaining, self.config.form):
                        got.append(frame)
                        b.left.discard(frame.id)
                        self.add_object(frame)
                finally:
                    self.store_objects(got)

    def objects_from_disk(self, ids: list[int]) -> set[int]:
        """Take what the disk cache holds of ``ids``; the ids taken."""
        if self.disk is None or not ids:
            return set()
        got: set[int] = set()
        for oid, blob in self.disk.get_objects(ids, self.config.form).items():
            try:
                kind, payload = unpack_bounded(
                    blob, f"object {oid} (disk cache)", max_array_len=2, max_str_len=64
                )
            except (CodecError, ValueError, TypeError):
                continue  # damaged on disk: fetched from the server instead
            self.stats.disk_hits += 1
            self.add_object(ObjectFrame(oid, kind, payload, self.config.form, 0))
            if self.has_object(oid):
                got.add(oid)
        return got

    def store_objects(self, frames: list[ObjectFrame]) -> None:
        if self.disk is not None and frames:
            self.disk.put_objects(
                [(f.id, msgpack.packb([f.kind, f.payload])) for f in frames], self.config.form
            )

    def add_object(self, frame: ObjectFrame) -> None:
        oid = frame.id
        self.geometry_version += 1  # download quality may change
        if frame.nbytes:
            self.stats.objects_received += 1
            self.stats.object_bytes[oid] = self.stats.object_bytes.get(oid, 0) + frame.nbytes
            self.stats.object_counts[oid] = self.stats.object_counts.get(oid, 0) + 1
            self._frame_bytes = 0.95 * self._frame_bytes + 0.05 * frame.nbytes
            self.cache.note_download(oid)
        what = f"object {oid}"
        content = client_content_for_form(frame.form)
        try:
            decoded = content.kind.decode(frame.payload, what)
            self.cache.put(content.kind.cache_kind, oid, *content.cache_entry(frame.payload, decoded))
            if content.kind.name == "params":
                self._submit_rewrite(oid, decoded)
            else:  # a downloaded mesh is the LOD2 geometry
                self._geometry_ready(geometry_of(oid, (None, None, decoded)))
        except CodecError:
            return  # a bad record: not cached, so it is wanted (and fetched) again

    # -- the start bundle's side ------------------------------------------------

    def expect(self, ids: set[int], coming: bool = True) -> None:
        """Mark objects as on their way (``coming``) or no longer so (the start bundle's)."""
        if coming:
            self._in_flight_ids |= ids
        else:
            self._in_flight_ids -= ids

    @property
    def frame_bytes(self) -> float:
        """The mean bytes of an object frame on the wire (a running estimate)."""
        return self._frame_bytes

    # -- geometry --------------------------------------------------------------

    def _submit_rewrite(self, oid: int, params: object, t: float | None = None) -> None:
        if self.rewrite is None:
            return
        key = self._wanted.get(oid)
        if key is None:
            key = (math.inf if t is None else t, 0.0)
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

    def ensure_geometry(self, ids: list[int], t: float = 0.0) -> None:
        """Queue rebuilds (needed in ``t`` s) for objects whose params are cached but
        geometry was evicted."""
        if self.rewrite is None:
            return
        for oid in ids:
            if self.cache.has("geom", oid) or self.rewrite.queued(oid):
                continue
            params = self.cache.peek("params", oid)
            if params is not None:
                self._submit_rewrite(oid, params, t)

    def start(self) -> None:
        """Start the rewrite workers (on the running event loop)."""
        if self.rewrite is not None:
            self.rewrite.start()

    def on_manifest(
        self,
        max_ids: int,
        grammar: Grammar | None,
        disk: DiskCache | None,
        grid: TileGrid | None = None,
    ) -> None:
        """The manifest arrived: the request limit, the grammar, the disk cache, the tile grid.

        ``disk`` is a disk cache already bound to the manifest's scene version (or
        None); ``grammar`` lets the rewrite jobs start (ignored when nothing is
        rebuilt); ``grid`` says which index tiles to ask for.
        """
        self.api_max_ids = max_ids
        if self.rewrite is not None and grammar is not None:
            self.rewrite.set_grammar(grammar)
        self.disk = disk
        self.grid = grid

    async def close(self) -> None:
        """Cancel everything in flight and stop the rewrite workers."""
        self._closed = True
        tasks: list[asyncio.Task[Any]] = list(self._tile_tasks.values()) + [
            f.task for f in self.scheduler.flights(self) if f.task is not None
        ]
        if self._locate_task is not None:
            tasks.append(self._locate_task)
        if self.start_feed.task is not None:
            tasks.append(self.start_feed.task)
        await reap(tasks)
        if self.rewrite is not None:
            await self.rewrite.close()
