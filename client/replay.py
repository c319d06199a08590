"""Replay a recorded path through a scene over a shaped link: the client's main loop.

Setup (the start bundle: path, first cell, index tiles, manifest and the first
cell's objects in one round trip; against a server without one, the scene, its
manifest and the path, fetched concurrently) is followed by the walk: a frame loop that ticks at ``fps`` and never waits for the network.  Each
frame it moves the viewer along the path, lets the :class:`~walkstream.client.stream.streamer.Streamer`
follow it (locate, predict, prefetch), measures download and rewrite quality of the
current cell, culls and allocates the polygon budget by ACH, draws (really, with
moderngl, on the ``gl`` device; from a cost model on the simulated ones), feeds the
frame time to the budget controller and logs the frame.  When the frame finished
before the next tick the loop waits for the tick; a frame that took longer is shown
late (the frame rate drops) and the next one starts at once.

Under the simulated clock (:class:`~walkstream.client.clock.SimClock`) the same code runs on
virtual time: link transfers, round trips and backoff sleeps are virtual, frames
advance it by their (modelled or really measured) duration and rewrites by the CPU
time they really took, so a ten-minute walk replays in seconds, deterministically
for the simulated devices.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx
import numpy as np
from numpy.typing import NDArray

from walkstream.client.clock import Clock, RealClock, SimClock, within
from walkstream.client.config import STREAM_FORMS, ReplayConfig
from walkstream.client.draw.allocate import allocate_ach, allocate_distance
from walkstream.client.draw.budget import BudgetController
from walkstream.client.draw.devices import make_device
from walkstream.client.draw.phases import FramePhases
from walkstream.client.draw.present import present, save_snapshot
from walkstream.client.net.api import SceneClient
from walkstream.client.net.link import ShapedTransport
from walkstream.client.report.link import bytes_series, link_figures
from walkstream.client.report.metrics import (
    FrameLog,
    FrameLogBuilder,
    first_perfect_index,
    link_utilisation,
    summarise,
)
from walkstream.client.report.truth import summarise_truth
from walkstream.client.rewrite.geometry import ObjectGeometry
from walkstream.client.rewrite.pool import RewriteOptions
from walkstream.client.stream.cache import Cache
from walkstream.client.stream.diskcache import DiskCache
from walkstream.client.stream.predict import MotionPredictor
from walkstream.client.stream.streamer import Streamer, StreamerConfig
from walkstream.client.stream.walkstart import (
    StartContents,
    bundle_start,
    interior_start,
    manifest_task,
)
from walkstream.client.truth.recorder import TruthRecorder, TruthResult
from walkstream.shared.camera import look_at, perspective
from walkstream.shared.frustum import frustum_cull
from walkstream.shared.lsystem.grammar import parse_grammar
from walkstream.shared.paths import RecordedPath
from walkstream.shared.roomview import RoomView
from walkstream.shared.roomwire import Topology
from walkstream.shared.wire import Manifest

__all__ = ["ReplayResult", "run_replay", "replay"]

@dataclass
class ReplayResult:
    """What a replay produced."""

    summary: dict[str, Any]
    log: FrameLog
    bytes_log: tuple[NDArray[np.float64], NDArray[np.float64]]
    snapshots: list[Path] = field(default_factory=list)
    spikes: NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, bool))
    """Per frame: the simulated device stalled (its occasional 2x spike)."""
    truth: TruthResult | None = None
    """The frames compared with the ground truth (``truth_every``)."""
    phases: NDArray[np.float64] | None = None
    """Per frame, seconds of the loop's :data:`~walkstream.client.draw.phases.PHASES`."""
    interior: dict[str, NDArray[np.float64]] | None = None
    """Interiors, per frame: visible cells, portals opened, triangles, culling ms, fog m."""


def run_replay(
    transport: httpx.AsyncBaseTransport,
    base_url: str,
    config: ReplayConfig,
    progress: Callable[[float, float], None] | None = None,
    truth_progress: Callable[[int, int], None] | None = None,
) -> ReplayResult:
    """Run a replay to the end on the configured clock (blocking).

    Parameters
    ----------
    transport:
        How to reach the server: ``httpx.AsyncHTTPTransport()`` for real sockets,
        or any other httpx transport.
    base_url:
        The server's URL (any URL for an in-process transport).
    config:
        The replay settings.
    progress:
        Called with ``(walk seconds done, walk seconds in total)`` now and then.
    truth_progress:
        Called with ``(frames compared, frames to compare)`` after the walk
        (``truth_every``).
    """
    if config.clock == "sim":
        sim = SimClock()
        return sim.run(replay(transport, base_url, config, sim, progress, truth_progress))
    return asyncio.run(_real(transport, base_url, config, progress, truth_progress))


async def _real(
    transport: httpx.AsyncBaseTransport,
    base_url: str,
    config: ReplayConfig,
    progress: Callable[[float, float], None] | None,
    truth_progress: Callable[[int, int], None] | None,
) -> ReplayResult:
    return await replay(transport, base_url, config, RealClock(), progress, truth_progress)


def _projection(config: ReplayConfig) -> NDArray[np.float32]:
    """The camera's projection: ``fov_deg`` vertical, the frame's aspect, 0.5 m to 2 km."""
    w, h = config.size
    return perspective(config.fov_deg, w / h, 0.5, 2000.0)


def _view(xyz: NDArray[np.float64], yaw: float, pitch: float) -> NDArray[np.float32]:
    d = np.array(
        [math.cos(yaw) * math.cos(pitch), math.sin(yaw) * math.cos(pitch), math.sin(pitch)]
    )
    return look_at(xyz, xyz + d)


class _FrameInputs:
    """Per-cell arrays for culling and allocation, rebuilt only when something changed."""

    def __init__(self) -> None:
        self.key: tuple[int, int, int] | None = None
        self.ids: NDArray[np.int64] = np.zeros(0, np.int64)
        self.ach = np.zeros(0)
        self.tri = np.zeros((0, 3), np.int64)
        self.avail = np.zeros((0, 3), bool)
        self.lo = np.zeros((0, 3))
        self.hi = np.zeros((0, 3))
        self.geoms: list[ObjectGeometry] = []
        self.dq = 0.0
        self.rq = 0.0

    def update(self, cid: int | None, streamer: Streamer, cache: Cache) -> None:
        rec = streamer.cells.get(cid) if cid is not None else None
        key = (
            -1 if cid is None or rec is None else cid,
            streamer.geometry_version,
            sum(cache.evictions.values()),
        )
        if key == self.key:
            return
        self.key = key
        if rec is None or len(rec.pvs) == 0:
            self.ids = np.zeros(0, np.int64)
            self.geoms = []
            self.dq = self.rq = 0.0 if rec is None else 1.0
            self.ach = np.zeros(0)
            self.tri = np.zeros((0, 3), np.int64)
            self.avail = np.zeros((0, 3), bool)
            self.lo = self.hi = np.zeros((0, 3))
            return
        pvs = rec.pvs.tolist()
        have = sum(1 for i in pvs if streamer.has_object(i))
        geoms: list[ObjectGeometry] = []
        ach: list[float] = []
        for oid, a in zip(pvs, rec.ach.tolist(), strict=True):
            g = cache.peek("geom", oid)
            if g is not None:
                geoms.append(g)
                ach.append(a)
        self.dq = have / len(pvs)
        self.rq = len(geoms) / len(pvs)
        self.geoms = geoms
        self.ids = np.array([g.id for g in geoms], dtype=np.int64)
        self.ach = np.array(ach)
        if geoms:
            self.tri = np.stack([g.triangles for g in geoms])
            self.avail = np.stack([g.available for g in geoms])
            self.lo = np.stack([g.bbox_min for g in geoms])
            self.hi = np.stack([g.bbox_max for g in geoms])
        else:
            self.tri = np.zeros((0, 3), np.int64)
            self.avail = np.zeros((0, 3), bool)
            self.lo = self.hi = np.zeros((0, 3))


async def replay(
    transport: httpx.AsyncBaseTransport,
    base_url: str,
    config: ReplayConfig,
    clock: Clock,
    progress: Callable[[float, float], None] | None = None,
    truth_progress: Callable[[int, int], None] | None = None,
) -> ReplayResult:
    """The replay coroutine (see :func:`run_replay` to run it on a clock)."""
    link = ShapedTransport(transport, config.link, clock)
    renderer: Any = None
    phases = FramePhases()
    truth: TruthResult | None = None
    streamer: Streamer | None = None
    disk: DiskCache | None = None
    async with httpx.AsyncClient(
        transport=link, base_url=base_url, timeout=httpx.Timeout(30.0)
    ) as http:
        api = SceneClient(http, clock, config.scene, seed=config.seed, compress=config.gzip)
        t_start = clock.now()
        loop = asyncio.get_running_loop()
        manifest_fut: asyncio.Future[Manifest] = loop.create_future()
        tasks: list[asyncio.Task[Any]] = []
        try:
            disk = DiskCache(config.cache_dir) if config.cache_dir is not None else None
            cache = Cache(config.cache_bytes)
            scfg = StreamerConfig(
                prefetch=config.prefetch, form=STREAM_FORMS[config.stream], workers=config.workers,
                rewrite=RewriteOptions(config.rewrite, config.shm_bytes),
            )
            streamer = Streamer(api, clock, cache, scfg)
            streamer.start()

            def manifest_arrived(m: Manifest) -> None:
                if manifest_fut.done():
                    return
                assert streamer is not None
                grammar = parse_grammar(m.grammar_text) if streamer.rewrite is not None and m.kind != "interior" else None
                usable = disk is not None and disk.use(m.name, m.version)
                streamer.on_manifest(m.max_ids, grammar, disk if usable else None, m.index)
                manifest_fut.set_result(m)

            got, topology, first_view = None, None, None
            if config.start_bundle and config.kind == "interior":  # path, topology, first view at once
                got, topology, first_view = await interior_start(
                    config.path, config.setup_timeout_s, clock, api, disk, manifest_arrived, tasks,
                    _room_view(config) if config.start_contents else None)
            elif config.start_bundle:
                got = await bundle_start(
                    config.path, config.setup_timeout_s, clock, api, streamer, disk,
                    manifest_arrived, manifest_fut, tasks,
                )
            if got is None:
                # no start bundle (or it failed before the path): scene list, manifest, path
                if await within(clock, config.setup_timeout_s, api.resolve_scene()) is None:
                    api.scene = config.scene or "?"
                if not manifest_fut.done():
                    tasks.append(manifest_task(api, disk, manifest_arrived))
                got = await within(clock, config.setup_timeout_s, api.path(config.path))
            setup_s = clock.now() - t_start
            if got is None:  # no path, no walk: an empty report that says why
                stats = link.stats
                log = FrameLogBuilder().build(fps_cap=config.fps)
                summary = summarise(
                    log, fps_target=config.fps_target, fps_cap=config.fps, t_start=0.0
                )
                summary.update(link_figures(config, stats, api))
                summary["error"] = (
                    f"the scene, manifest or path {config.path!r} did not arrive within "
                    f"{config.setup_timeout_s:g} s"
                )
                return ReplayResult(summary, log, bytes_series(stats, t_start))
            path, _path_bytes = got
            kind = config.kind
            if kind is None:
                m0 = await within(clock, config.setup_timeout_s, asyncio.shield(manifest_fut))
                kind = "city" if m0 is None else m0.kind
            if kind == "crossing":  # streets and rooms: one loop, this link, this cache, this streamer
                from walkstream.client.walk.crossing import replay_crossing

                summary, log, snapshots, spikes = await replay_crossing(
                    api, link, clock, config, path, streamer, cache, manifest_fut, t_start, setup_s, progress,
                    (transport, base_url))
                return ReplayResult(summary, log, bytes_series(link.stats, t_start), snapshots, spikes)
            if kind == "interior":
                return await _replay_interior(
                    api, link, clock, config, path, manifest_fut, t_start, setup_s, progress, (transport, base_url),
                    topology, first_view)
            device = make_device(config.device, config.seed)
            if not device.simulated or config.snapshot_every:
                from walkstream.client.draw.frames import FrameRenderer

                renderer = FrameRenderer(
                    size=config.size, fov_deg=config.fov_deg, batched=config.batched_draws
                )

            def on_evict(kind: str, oid: int) -> None:
                assert streamer is not None
                streamer.evicted(kind, oid)
                if kind == "geom" and renderer is not None:
                    renderer.forget_object(oid)

            cache.on_evict = on_evict
            recorder = (
                TruthRecorder(config.truth_every, config.size, _projection(config))
                if config.truth_every
                else None
            )
            log, snapshots, spikes = await _walk(
                config, clock, path, streamer, cache, device, renderer, progress, t_start, link,
                recorder,
                phases,
            )
            if recorder is not None:
                # after the walk, with the streamer stopped (nothing more goes down the
                # link), on the inner transport; busy(): no simulated time passes
                await streamer.close()
                first = first_perfect_index(log)
                with clock.busy():
                    truth = await recorder.finish(
                        transport,
                        base_url,
                        api.scene or "",
                        t_first_perfect=None if first is None else float(log.t[first]),
                        progress=truth_progress,
                    )
            manifest = manifest_fut.result() if manifest_fut.done() else None
            disk_state = (disk.available, disk.last_error) if disk is not None else (False, None)
            t_end = clock.now()
        finally:
            for task in tasks:
                if not task.done():
                    task.cancel()
                    with contextlib.suppress(asyncio.CancelledError, Exception):
                        await task
            if streamer is not None:
                await streamer.close()
            if renderer is not None:
                renderer.release()
            if disk is not None:
                disk.close()
    stats = link.stats
    bytes_log = bytes_series(stats, t_start)
    entered = {int(c) for c in np.unique(log.cell) if c >= 0}
    over = _overfetch(streamer, entered)
    bytes_received = int(stats.bytes_down)
    step = None
    if config.cost_step_at_s is not None and len(log.t):
        step = int(np.searchsorted(log.t - log.t[0], config.cost_step_at_s))
    # the device's own 2x spikes are no controller's doing: left out of the recovery
    # figures (a spike on an on-target frame is 50 % slow by construction)
    summary = summarise(
        log,
        fps_target=config.fps_target,
        fps_cap=config.fps,
        t_start=0.0,
        cost_step=step,
        recovery_ignore=spikes,
    )
    busy = np.array(streamer.busy_intervals(), dtype=np.float64).reshape(-1, 2) - t_start
    summary.update(
        {
            "scene": api.scene,
            "scene_version": None if manifest is None else manifest.version,
            "path": config.path,
            "path_duration_s": path.duration,
            "walk_s": float(log.t[-1] - log.t[0]) if len(log.t) else 0.0,
            "setup_s": setup_s,
            "clock": config.clock,
            "device": config.device,
            "prefetch": config.prefetch,
            "stream": config.stream,
            "lod_select": config.lod_select,
            "bandwidth_bps": config.link.down_bps,
            "rtt_s": config.link.rtt_s,
            "loss": config.link.loss,
            "bytes_received": bytes_received,
            "bytes_sent": int(stats.bytes_up),
            "object_bytes": int(sum(streamer.stats.object_bytes.values())),
            "cell_bytes": int(sum(streamer.stats.cell_bytes.values())),
            "index_bytes": int(sum(streamer.stats.tile_bytes.values())),
            "overfetch_ratio": sum(over.values()) / bytes_received if bytes_received else 0.0,
            "overfetch_bytes": over,
            "link_utilisation": link_utilisation(
                bytes_log, config.link.down_bps, [[0.0, t_end - t_start]]
            ),
            "link_utilisation_busy": link_utilisation(bytes_log, config.link.down_bps, busy),
            "link_busy_s": float(np.sum(busy[:, 1] - busy[:, 0])) if len(busy) else 0.0,
            "redownloads": int(cache.redownloads),
            "duplicates": int(
                sum(n - 1 for n in streamer.stats.object_counts.values()) - cache.redownloads
            ),
            "rebuilds": int(cache.rebuilds),
            "objects_received": streamer.stats.objects_received,
            "object_requests": streamer.stats.object_requests,
            "cell_requests": streamer.stats.cell_requests,
            "cells_received": streamer.stats.cells_received,
            "index_requests": streamer.stats.tile_requests,
            "locate_requests": streamer.stats.locate_requests,
            "requests": stats.requests,
            "start_bundle": config.start_bundle,
            "gzip": config.gzip,
            "bundle_bytes": streamer.stats.bundle_bytes,
            "cancelled_batches": streamer.stats.cancelled_batches,
            "retries": api.stats.retries,
            **api.stats.outage_figures(api.clock.now()),  # outages survived or not (issue 25)
            "cut_streams": api.stats.cut_streams,
            "responses_cut_by_link": stats.responses_cut,
            "disk_hits": streamer.stats.disk_hits,
            "measured_bandwidth_bps": _finite(api.stats.bandwidth_bps),
            "measured_rtt_s": _finite(api.stats.rtt_s),
            "cache_bytes": config.cache_bytes,
            "cache_peak_bytes": int(cache.peak_bytes),
            "cache_over_budget_events": int(cache.over_budget_events),
            "rewrite_cpu_s": streamer.rewrite.cpu_s if streamer.rewrite is not None else 0.0,
            "cells_entered": len(entered),
        }
    )
    summary["spike_frames"] = int(spikes.sum())
    if config.clock == "real":  # wall-clock figures: a simulated run's summary stays reproducible
        summary.update(phases.summary(config.fps_target), batched_draws=config.batched_draws)
        if streamer.rewrite is not None:
            summary["rewrite"] = streamer.rewrite.describe()
    if truth is not None:
        first = first_perfect_index(log)
        summary["truth"] = summarise_truth(
            truth.log, None if first is None else float(log.t[first])
        )
        if truth.error:
            summary["truth_error"] = truth.error
    if config.cache_dir is not None:
        # the disk cache never raises: say here whether it was usable
        summary["disk_cache"] = {
            "dir": str(config.cache_dir),
            "available": disk_state[0],
            "error": disk_state[1],
        }
    return ReplayResult(summary, log, bytes_log, snapshots, spikes, truth, phases.array())


def _room_view(config: ReplayConfig) -> RoomView:
    """How the walk views an interior (what the server culls the start bundle's first view with)."""
    depth = config.rooms.get("max_depth", RoomView.max_depth)
    return RoomView(config.size, config.fov_deg, config.fog_m, int(depth))


async def _replay_interior(
    api: SceneClient,
    link: ShapedTransport,
    clock: Clock,
    config: ReplayConfig,
    path: RecordedPath,
    manifest_fut: asyncio.Future[Manifest],
    t_start: float,
    setup_s: float,
    progress: Callable[[float, float], None] | None,
    inner: tuple[httpx.AsyncBaseTransport, str] | None = None,
    topology: Topology | None = None,
    first_view: StartContents | None = None,
) -> ReplayResult:
    """The walk through an interior (:mod:`walkstream.client.roomreplay`); ``inner``
    (the unshaped transport and URL) is where the ground truth fetches the cells;
    ``topology`` the one the start bundle brought (None: fetch it), ``first_view`` the
    first view's contents still coming in it."""
    from walkstream.client.roomreplay import InteriorFrames, interior_summary, walk_interior
    from walkstream.client.stream.rooms import RoomStreamConfig, RoomStreamer

    topology = topology or await api.topology()
    setup_s = clock.now() - t_start  # the walk starts once the topology is in too
    cache = Cache(config.cache_bytes)
    streamer = RoomStreamer(
        api, clock, cache, topology,
        RoomStreamConfig(prefetch=config.prefetch, fog_m=config.fog_m, culling=config.culling, **config.rooms),
    )
    if first_view is not None:
        streamer.adopt(first_view.cells, first_view.parts)
    frames = InteriorFrames()
    device = make_device(config.device, config.seed)
    renderer: Any = None
    try:
        if not device.simulated or config.snapshot_every:
            from walkstream.client.draw.frames import FrameRenderer

            renderer = FrameRenderer(size=config.size, fov_deg=config.fov_deg, near=0.1)
        log, snapshots, spikes = await walk_interior(
            config, clock, path, streamer, device, renderer, progress, t_start,
            lambda: int(link.stats.bytes_down), frames,
        )
    finally:
        await streamer.close()
        if renderer is not None:
            renderer.release()
    truth_figures = None
    if config.truth_every and inner is not None:
        from walkstream.client.truth.interior import interior_truth

        with clock.busy():
            truth_figures = await interior_truth(
                inner[0], inner[1], api.scene or "", [c.id for c in topology.cells], frames.notes,
                config.size, config.fov_deg, clock,
            )
    manifest = manifest_fut.result() if manifest_fut.done() and not manifest_fut.cancelled() else None
    stats = link.stats
    step = None
    if config.cost_step_at_s is not None and len(log.t):
        step = int(np.searchsorted(log.t - log.t[0], config.cost_step_at_s))
    summary = summarise(log, fps_target=config.fps_target, fps_cap=config.fps, t_start=0.0, cost_step=step,
                        recovery_ignore=spikes)
    summary.update(link_figures(config, stats, api))
    summary.update(interior_summary(config, log, streamer, frames, topology, cache, setup_s, path, manifest))
    summary["truth"] = truth_figures
    return ReplayResult(summary, log, bytes_series(stats, t_start), snapshots, spikes, interior=frames.series(log))


def _overfetch(streamer: Streamer, entered: set[int]) -> dict[str, int]:
    """Bytes fetched and never needed for a frame, by kind.

    Objects never in the PVS of a cell the walk entered, records of cells it never
    entered, index tiles none of whose cells it entered.
    """
    in_pvs: set[int] = set()
    for c in entered:
        pvs = streamer.pvs_seen.get(c)
        if pvs is not None:
            in_pvs.update(pvs.tolist())
    st = streamer.stats
    return {
        "objects": sum(n for oid, n in st.object_bytes.items() if oid not in in_pvs),
        "cells": sum(n for cid, n in st.cell_bytes.items() if cid not in entered),
        "index": sum(
            n
            for key, n in st.tile_bytes.items()
            if not (streamer.tile_members.get(key, frozenset()) & entered)
        ),
    }


def _finite(x: float) -> float | None:
    return x if math.isfinite(x) else None


async def _walk(
    config: ReplayConfig,
    clock: Clock,
    path: RecordedPath,
    streamer: Streamer,
    cache: Cache,
    device: Any,
    renderer: Any,
    progress: Callable[[float, float], None] | None,
    t_start: float,
    link: ShapedTransport,
    recorder: TruthRecorder | None = None,
    phases: FramePhases | None = None,
) -> tuple[FrameLog, list[Path], NDArray[np.bool_]]:
    ph = FramePhases() if phases is None else phases
    tick = 1.0 / config.fps
    total = path.duration if config.duration_s is None else min(config.duration_s, path.duration)
    proj = _projection(config)
    controller = BudgetController(config.fps_target, k=config.budget_frames)
    predictor = MotionPredictor()
    inputs = _FrameInputs()
    builder = FrameLogBuilder()
    snapshots: list[Path] = []
    spikes: list[bool] = []
    t_walk0 = clock.now()
    streamer.walk_end = t_walk0 + total
    frame = 0
    stepped = False
    last_progress = -math.inf
    while True:
        t = clock.now()
        wt = t - t_walk0
        if wt > total:
            break
        ph.begin()
        if progress is not None and wt - last_progress >= 1.0:
            last_progress = wt
            progress(wt, total)
        xyz, yaw, pitch = path.at(wt)
        xyz = np.asarray(xyz, dtype=np.float64)
        predictor.observe(wt, xyz[:2])
        cur = streamer.tick(t, xyz[:2], predictor)
        inputs.update(cur, streamer, cache)
        if streamer.rewrite is not None and inputs.rq < inputs.dq:
            rec = streamer.cells.get(cur) if cur is not None else None
            if rec is not None:
                streamer.ensure_geometry(rec.pvs.tolist())
        ph.mark("stream")
        view = _view(xyz, float(yaw), float(pitch))
        vp = proj.astype(np.float64) @ view.astype(np.float64)
        visible = frustum_cull(inputs.lo, inputs.hi, vp) if len(inputs.ids) else np.zeros(0, bool)
        ph.mark("cull")
        budget = int(controller.budget)
        if config.lod_select == "ach":
            alloc = allocate_ach(
                inputs.ach, inputs.tri, inputs.avail, visible, budget, reserve_floor=True
            )
        else:
            centre = (inputs.lo + inputs.hi) / 2.0
            dist = np.hypot(centre[:, 0] - xyz[0], centre[:, 1] - xyz[1])
            alloc = allocate_distance(dist, inputs.tri, inputs.avail, visible, config.lod_distances)
        if config.cost_step_at_s is not None and not stepped and wt >= config.cost_step_at_s:
            device.cost_scale = device.cost_scale * config.cost_step_factor
            stepped = True
        ph.mark("allocate")
        draw_keys: list[tuple[int, int]] = []
        if renderer is not None:
            for g, lod in zip(inputs.geoms, alloc.lod.tolist(), strict=True):
                if lod >= 0:
                    key = (g.id, int(lod))
                    if not renderer.has(key):
                        mesh = g.meshes[lod]
                        if mesh is None:
                            continue
                        renderer.upload(key, mesh)
                    draw_keys.append(key)
        ph.mark("upload")
        snap = config.snapshot_every and frame % config.snapshot_every == 0
        frame_time, spike = present(device, renderer, draw_keys, view, proj, int(alloc.triangles), int((alloc.lod >= 0).sum()), bool(snap))
        spikes.append(spike)
        ph.mark("draw")
        if renderer is not None and (snap or not device.simulated):
            ph.move("draw", "finish", renderer.last_finish_s)
        shot = save_snapshot(renderer, config.report_dir, frame) if snap else None
        if shot is not None:
            snapshots.append(shot)
        if recorder is not None and recorder.due(frame):
            rec = streamer.cells.get(cur) if cur is not None else None
            recorder.record(
                frame=frame,
                t=t - t_start,
                eye=xyz,
                view=view,
                cell=cur,
                pvs=None if rec is None else rec.pvs,
                received=cache.ids(streamer.kind) + cache.ids("geom"),
                built=cache.ids("geom"),
                geoms=inputs.geoms,
                lods=alloc.lod,
            )
        controller.observe(frame_time, int(alloc.triangles))
        builder.append(
            t=t - t_start,
            frame_time=frame_time,
            cell=-1 if cur is None else int(cur),
            pvs=len(streamer.cells[cur].pvs) if cur is not None and cur in streamer.cells else 0,
            download_quality=inputs.dq,
            rewrite_quality=inputs.rq,
            bytes_down=int(link.stats.bytes_down),
            budget=budget,
            triangles=int(alloc.triangles),
            visible=int(np.count_nonzero(visible)),
            floor_limited=bool(alloc.floor_limited),
            all_lod2=bool(alloc.all_max),
        )
        frame += 1
        ph.end()
        await clock.sleep_until(t + max(frame_time, tick))
    if progress is not None:
        progress(total, total)
    return builder.build(fps_cap=config.fps), snapshots, np.array(spikes, dtype=bool)
