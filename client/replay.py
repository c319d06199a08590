"""Replay a recorded path through a scene over a shaped link: the setup, the wiring, the summary.

Setup (the start bundle: path, first cell, index tiles, manifest and the first
cell's objects in one round trip; for an interior the path, the topology and the
first view's contents; against a server without one, the scene, its manifest and the
path, fetched concurrently) is followed by the walk: one frame loop for every scene
(:func:`~walkstream.client.walk.loop.walk`, a pipeline of named steps), on one link
and one :class:`~walkstream.client.stream.cache.Cache`, with the streamers of the cell
models the scene holds: the city :class:`~walkstream.client.stream.streamer.Streamer`
for street cells, the :class:`~walkstream.client.stream.rooms.RoomStreamer` for room
cells, both for a crossing.  The city streamer (and its rewrite workers) is started
only when the scene may have street cells.  After the walk the ground truth compares
the noted frames (``--truth-every``) and the summary is written per scene kind
(``client/report/city.py``, ``interior.py``, ``crossing.py``).

Under the simulated clock (:class:`~walkstream.client.clock.SimClock`) the same code runs on
virtual time: link transfers, round trips and backoff sleeps are virtual, frames
advance it by their (modelled or really measured) duration and rewrites by the CPU
time they really took, so a ten-minute walk replays in seconds, deterministically
for the simulated devices.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Coroutine
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

import httpx
import numpy as np
from numpy.typing import NDArray

from walkstream.client.clock import Clock, RealClock, SimClock, within
from walkstream.client.config import STREAM_FORMS, ReplayConfig
from walkstream.client.draw.budget import BudgetController
from walkstream.client.draw.devices import make_device
from walkstream.client.draw.phases import FramePhases
from walkstream.client.net.api import SceneClient
from walkstream.client.net.link import ShapedTransport
from walkstream.client.report.city import city_summary
from walkstream.client.report.crossing import crossing_summary
from walkstream.client.report.framelog import FrameLog, FrameLogBuilder
from walkstream.client.report.interior import interior_summary
from walkstream.client.report.link import bytes_series, link_figures
from walkstream.client.report.metrics import summarise
from walkstream.client.rewrite.pool import RewriteOptions
from walkstream.client.stream.cache import Cache
from walkstream.client.stream.diskcache import DiskCache
from walkstream.client.stream.images import ImpostorImages
from walkstream.client.stream.ringsides import RingSides
from walkstream.client.stream.rooms import RoomStreamConfig, RoomStreamer
from walkstream.client.stream.startwalls import StartWalls
from walkstream.client.stream.streamer import Streamer, StreamerConfig
from walkstream.client.stream.walkstart import (
    PATH_LEAD_S,
    bundle_start,
    interior_start,
    manifest_task,
    whole_path_when_idle,
)
from walkstream.client.tasks import reap
from walkstream.client.truth.recorder import TruthRecorder, TruthResult, interior_far_m
from walkstream.client.walk.crossing import crossing_topology
from walkstream.client.walk.facades import FacadeState, release_facades
from walkstream.client.walk.figures import WalkFrames
from walkstream.client.walk.loop import walk
from walkstream.client.walk.measure import compare_truth
from walkstream.client.walk.scene import STREET_FAR_M, STREET_NEAR_M, WalkScene, walk_projection
from walkstream.client.walk.state import WalkState
from walkstream.client.walk.walls import add_ring_sides
from walkstream.shared.cullkernels import warm_up as warm_up_culling
from walkstream.shared.errors import ApiError
from walkstream.shared.ground import GROUND_Z
from walkstream.shared.lsystem.grammar import parse_grammar
from walkstream.shared.paths import RecordedPath
from walkstream.shared.roomview import VIEW_NEAR_M, RoomView
from walkstream.shared.trianglekernels import warm_up as warm_up_triangle_test
from walkstream.shared.walls import WallTable
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

_T = TypeVar("_T")


async def _virtual_walls(scene: WalkScene, api: SceneClient, topology: Any, rooms: RoomStreamer,
                         start: StartWalls | None = None) -> None:
    """An interior's textured virtual walls, when it was baked with them: the wall sides
    (from the start bundle, else one request before the walk), the wall portals' cells
    and the textures' lane on the rooms' scheduler, holding the bundle's textures.  A
    scene without walls leaves the scene as it was (one 404 more, only when the
    topology lists a ``wall`` portal, so older scenes ask nothing)."""
    cells = {int(p[0]): (int(p[2]), int(p[3])) for p in topology.portals if p[1] == "wall"}
    if not cells:
        return
    sides = start.sides if start is not None else None
    if sides is None:
        try:
            sides = await api.walls()
        except ApiError:
            return
    scene.walls = tuple(s for s in sides if s.portal in cells)
    scene.wall_cells = cells
    scene.wall_table = WallTable(scene.walls)
    corners = np.array([s.corners() for s in scene.walls], np.float64).reshape(-1, 4, 3)
    scene.wall_boxes = np.stack([corners.min(axis=1), corners.max(axis=1)], axis=1)
    scene.wall_images = ImpostorImages(api, scene.cache, rooms.scheduler, kind="walltex")
    if start is not None:
        start.attach(scene.wall_images)


async def _ring_walls(scene: WalkScene, api: SceneClient, streamer: Streamer,
                      start: StartWalls | None = None) -> None:
    """A city's rings of textured virtual walls (its manifest lists the ``walls``
    feature): the rings fetched as the walk comes to their cells
    (:class:`~walkstream.client.stream.ringsides.RingSides`, merged into the scene by
    :func:`~.walk.walls.add_ring_sides`) and the textures' lane on the streamer's
    scheduler; the start cell's ring and the textures its first pose sees come in the
    start bundle (``start``).  (Every side in one request before the walk held West
    Oakland's first frame back by six seconds of the link.)"""
    scene.wall_images = ImpostorImages(api, scene.cache, streamer.scheduler, kind="walltex")
    feed = streamer.start_feed
    bundled = start is not None and feed.walls is start
    # while the start bundle still brings the start cell's ring the walker stands at its start
    waiting = (lambda: feed.starting and start.sides is None) if bundled and start is not None else None
    loader = scene.ring_sides = RingSides(api, lambda sides: add_ring_sides(scene, sides), waiting)
    if bundled and start is not None:  # the start bundle's ring and textures
        start.on_sides(loader.adopt)
        start.attach(scene.wall_images)


def _walls_summary(scene: WalkScene, frames: Any) -> dict[str, Any]:
    """The replay summary's ``walls`` (a scene drawn with virtual walls)."""
    walls = scene.wall_images
    assert walls is not None
    figs = frames.wall_figures()
    n_walls = len({s.portal for s in scene.walls})
    return {
        **figs,
        "wall_sides": len(scene.walls),
        # both sides' zones: the paper's "textures per wall"
        "textures_per_wall": sum(len(s.textures) for s in scene.walls) / n_walls if n_walls else 0.0,
        # decoded RGBA of the textures the busiest frame drew
        "texture_memory_bytes": int(figs.get("wall_texture_bytes_max", 0)),
        "textures_received": walls.received,
        "texture_bytes": walls.bytes_received,
        "texture_requests": walls.requests,
        # outdoors: the requests for rings the walk came to (the start bundle brings the first)
        **({"ring_requests": scene.ring_sides.requests} if scene.ring_sides is not None else {}),
    }


async def _real(
    transport: httpx.AsyncBaseTransport,
    base_url: str,
    config: ReplayConfig,
    progress: Callable[[float, float], None] | None,
    truth_progress: Callable[[int, int], None] | None,
) -> ReplayResult:
    return await replay(transport, base_url, config, RealClock(), progress, truth_progress)


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
    rooms: RoomStreamer | None = None
    disk: DiskCache | None = None
    streamer_closed = False
    state: WalkState | None = None
    async with httpx.AsyncClient(
        transport=link, base_url=base_url, timeout=httpx.Timeout(30.0)
    ) as http:
        api = SceneClient(http, clock, config.scene, seed=config.seed, compress=config.gzip)
        if config.kind != "city" and config.culling == "portals":
            # the culling's compiled kernels made (a cold cache: seconds) or loaded before the
            # walk's clock starts, never inside a timed frame; a city walk uses none of them
            warm_up_culling()
            if config.triangle_cull:
                warm_up_triangle_test()
        t_start = clock.now()
        loop = asyncio.get_running_loop()
        manifest_fut: asyncio.Future[Manifest] = loop.create_future()
        tasks: list[asyncio.Task[Any]] = []
        try:
            disk = DiskCache(config.cache_dir) if config.cache_dir is not None else None
            cache = Cache(config.cache_bytes)  # the one cache of every content kind
            if config.kind != "interior":  # street cells, or not known yet: the start bundle goes through it
                scfg = StreamerConfig(
                    prefetch=config.prefetch, form=STREAM_FORMS[config.stream], workers=config.workers,
                    rewrite=RewriteOptions(config.rewrite, config.shm_bytes),
                )
                streamer = Streamer(api, clock, cache, scfg)
                streamer.start()

            def manifest_arrived(m: Manifest) -> None:
                if manifest_fut.done():
                    return
                usable = disk is not None and disk.use(m.name, m.version)
                if streamer is not None:
                    grammar = parse_grammar(m.grammar_text) if streamer.rewrite is not None and m.kind != "interior" else None
                    streamer.on_manifest(m.max_ids, grammar, disk if usable else None, m.index)
                manifest_fut.set_result(m)

            def manifest_failed(exc: BaseException) -> None:
                # a manifest that does not decode: the walk would rebuild no building,
                # so the replay ends with the error (the walk below stops on it)
                if not manifest_fut.done():
                    manifest_fut.set_exception(exc)

            got, topology, first_view = None, None, None
            whole: dict[str, Any] = {}  # the whole path, when the bundle sent its head first

            def path_arrived(p: RecordedPath) -> None:
                whole["path"] = p
                st = whole.get("state")
                if st is not None:
                    st.path, st.path_pending = p, False

            def fetch_whole(head: RecordedPath) -> None:
                # the whole path when the link is idle, at the latest PATH_LEAD_S before the head ends
                if "fetch" not in whole and rooms is not None:
                    whole["fetch"] = asyncio.create_task(whole_path_when_idle(
                        api, clock, config.path, head, clock.now() + head.duration - PATH_LEAD_S, rooms.busy,
                        path_arrived))
                    tasks.append(whole["fetch"])

            def head_arrived(p: RecordedPath | None) -> None:
                # the path's head after the first pose's view (None: the bundle ended without it)
                whole["head"] = p
                st = whole.get("state")
                if st is not None and st.path_pending:
                    st.path = p or st.path
                    fetch_whole(st.path)

            headed = False
            # an interior's wall sides and first view's textures in the bundle (a scene without walls sends none)
            start_walls = StartWalls() if config.start_walls and config.virtual_walls else None
            if config.start_bundle and config.kind == "interior":  # path, topology, first view at once
                got, topology, first_view = await interior_start(
                    config.path, config.setup_timeout_s, clock, api, disk, manifest_arrived, tasks,
                    _room_view(config) if config.start_contents else None, manifest_failed,
                    config.path_head_s, path_arrived, heads=config.start_heads, walls=start_walls,
                    head_arrived=head_arrived if config.posed_start else None)
                headed = got is not None
            elif config.start_bundle and streamer is not None:
                if start_walls is not None and config.kind == "city" and config.street_hold:
                    streamer.start_feed.walls = start_walls  # the start cell's ring and first textures
                got = await bundle_start(
                    config.path, config.setup_timeout_s, clock, api, streamer, disk,
                    manifest_arrived, manifest_fut, tasks, manifest_failed,
                    # a city walker stands at its start for its first view: that view's objects first
                    view=_room_view(config) if config.kind == "city" and config.street_hold else None,
                )
            if got is None:
                # no start bundle (or it failed before the path): scene list, manifest, path
                if await within(clock, config.setup_timeout_s, api.resolve_scene()) is None:
                    api.scene = config.scene or "?"
                if not manifest_fut.done():
                    tasks.append(manifest_task(api, disk, manifest_arrived, manifest_failed))
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
            entrance = None
            if kind == "interior" and streamer is not None:  # the kind came late: no street cells after all
                await streamer.close()
                streamer = None
            if kind == "crossing":  # streets and rooms: this link, this cache, this streamer
                inside, entrances = await asyncio.gather(api.topology(), api.entrances())
                topology = inside
                if not entrances:
                    raise ApiError(f"scene {api.scene!r} is a crossing without an entrance")
                entrance = entrances[0]
                assert streamer is not None  # a crossing has street cells: made above
                setup_s = clock.now() - t_start  # the walk starts once the rooms' topology is in too
                rooms = RoomStreamer(
                    api, clock, cache, crossing_topology(inside, entrances),
                    RoomStreamConfig(prefetch=config.prefetch, fog_m=config.fog_m, culling=config.culling, **config.rooms),
                    foreign=[x.street for x in entrances],
                    placements=[x.placement for x in entrances if x.placement is not None],
                    scheduler=streamer.scheduler,  # one scheduler owns the link: both kinds' requests
                )
            elif kind == "interior":
                topology = topology or await api.topology()
                setup_s = clock.now() - t_start  # the walk starts once the topology is in too
                rooms = RoomStreamer(
                    api, clock, cache, topology,
                    RoomStreamConfig(prefetch=config.prefetch, fog_m=config.fog_m, culling=config.culling, **config.rooms),
                )
                if first_view is not None:
                    rooms.adopt(first_view.cells, first_view.parts)
            scene = WalkScene(cache, streets=streamer, rooms=rooms, entrance=entrance,
                              unknown_quality=1.0 if kind == "crossing" else 0.0)
            if streamer is not None and config.impostors:
                scene.images = ImpostorImages(api, cache, streamer.scheduler)
            if kind == "interior" and rooms is not None and topology is not None and config.virtual_walls:
                await _virtual_walls(scene, api, topology, rooms, start_walls)
            elif kind == "city" and streamer is not None and config.virtual_walls:
                m1 = await within(clock, config.setup_timeout_s, asyncio.shield(manifest_fut))
                if m1 is not None and "walls" in m1.features:
                    await _ring_walls(scene, api, streamer, start_walls)
            proj = walk_projection(config, scene)
            near = VIEW_NEAR_M if rooms is not None else STREET_NEAR_M  # the projection's near plane
            # the truth draws as far as the streets reach, or the rooms beyond any fog
            far = STREET_FAR_M if streamer is not None or topology is None else interior_far_m(topology)
            # a scene with street cells has outdoor space: the ground plane under it
            ground_z = GROUND_Z if streamer is not None else None
            device = make_device(config.device, config.seed)
            if not device.simulated or config.snapshot_every:
                from walkstream.client.draw.frames import FrameRenderer

                renderer = FrameRenderer(
                    size=config.size, fov_deg=config.fov_deg, batched=config.batched_draws,
                    near=near, facade_filter=config.facade_filter,
                )
                renderer.ground_z = ground_z

            def on_evict(kind: str, oid: int) -> None:
                assert streamer is not None
                streamer.evicted(kind, oid)
                if kind == "geom" and renderer is not None:
                    renderer.forget_object(oid)

            if streamer is not None:
                cache.on_evict = on_evict
            recorder = (  # the one ground truth, at the walk's near and far planes
                TruthRecorder(config.truth_every, config.size, config.fov_deg, near=near, far=far, ground_z=ground_z,
                              viewer_ppd=config.viewer_ppd, truth_samples=config.truth_samples,
                              picture_samples=config.picture_samples, facade_filter=config.facade_filter)
                if config.truth_every
                else None
            )
            state = WalkState(
                config, clock, path, scene, device, renderer, proj, t_start,
                lambda: int(link.stats.bytes_down), WalkFrames(), recorder,
                BudgetController(config.fps_target, k=config.budget_frames),
            )
            if rooms is not None and rooms.cull_cache is not None:  # --cull-cache culls the walk's own boxes
                rooms.cull_cache.boxes = state.boxes
            facades = device.simulated if config.facades is None else config.facades
            if facades and scene.streets is not None:  # boxes carrying their LOD2's facades
                state.facades = FacadeState()
            if headed:  # walking the path's head until the whole path is in
                head = whole.get("head") or path  # the first pose alone until its head comes (start_pose)
                state.path, state.path_pending = whole.get("path", head), "path" not in whole
                whole["state"] = state
                if state.path_pending and (not config.posed_start or "head" in whole):
                    fetch_whole(head)  # fetched when the link is idle
            log, snapshots, spikes = await _walk_unless_manifest_fails(walk(state, phases, progress), manifest_fut)
            t_end = clock.now()
            release_facades(state)
            # the streamers stopped (nothing more goes down the link) before the truth
            if scene.images is not None:
                await scene.images.close()
            if scene.wall_images is not None:
                await scene.wall_images.close()
            if scene.ring_sides is not None:
                await scene.ring_sides.close()
            await _close(streamer, rooms)
            streamer_closed = True
            truth = await compare_truth(
                state, log, (transport, base_url), api.scene or "", topology, clock, truth_progress)
            manifest = manifest_fut.result() if manifest_fut.done() and not manifest_fut.cancelled() else None
            disk_state = (disk.available, disk.last_error) if disk is not None else (False, None)
        finally:
            await reap(t for t in tasks if not t.done())
            if state is not None:
                release_facades(state)
            if not streamer_closed:  # closed once: the rewrite workers' pool is not closed twice
                await _close(streamer, rooms)
            if renderer is not None:
                renderer.release()
            if disk is not None:
                disk.close()
    stats = link.stats
    bytes_log = bytes_series(stats, t_start)
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
    assert state is not None  # the walk ran (an error before it is raised)
    frames = state.frames
    if kind == "crossing":
        assert streamer is not None and rooms is not None and entrance is not None
        summary.update(link_figures(config, stats, api))
        summary.update(crossing_summary(config, log, frames, streamer, rooms, cache, entrance, setup_s, path, manifest))
    elif kind == "interior":
        assert rooms is not None and topology is not None
        summary.update(link_figures(config, stats, api))
        summary.update(interior_summary(config, log, rooms, frames, topology, cache, setup_s, state.path, manifest,
                                        t_start))
        if scene.wall_images is not None:  # only then: a scene without walls keeps its summary
            summary["walls"] = _walls_summary(scene, frames)
    else:
        assert streamer is not None
        summary.update(city_summary(config, log, streamer, cache, stats, api, bytes_log, t_end - t_start,
                                    t_start, setup_s, path, manifest))
        summary["spike_frames"] = int(spikes.sum())
        summary.update(frames.geometry_figures())  # objects drawn as geometry, whatever the quads
        summary.update(frames.lod_figures())  # LOD changes frame to frame (pops of their own)
        # a walker standing at its start for its first view: how long, and the boxes that stood in
        summary["start_hold_s"] = frames.start_hold_s
        summary["start_boxes"] = len(streamer.start_feed.stand_ins)
        if scene.wall_images is not None:  # a city's rings of walls
            summary["walls"] = _walls_summary(scene, frames)
        if state.facades is not None:  # boxes with their facades (--no-facades: none)
            fs = state.facades
            summary["facades"] = {
                **frames.facade_figures(),
                "buildings_baked": fs.baked_buildings,
                "faces_baked": fs.baked_faces,
                "bake_triangles": fs.bake_triangles,
                "slack_triangles": fs.slack_triangles,
                "dropped": fs.dropped,
                **({"error": fs.error} if fs.error else {}),
            }
        images = scene.images
        if images is not None and images.requests:  # only then: a scene without impostors keeps its summary
            summary["impostors"] = {
                **frames.impostor_figures(),
                "images_received": images.received,
                "image_bytes": images.bytes_received,
                "image_requests": images.requests,
            }
    if config.clock == "real":  # wall-clock figures: a simulated run's summary stays reproducible
        summary.update(phases.summary(config.fps_target), batched_draws=config.batched_draws)
        if streamer is not None and streamer.rewrite is not None:
            summary["rewrite"] = streamer.rewrite.describe()
    if truth is not None:
        summary["truth"] = truth.figures
        if truth.error:
            summary["truth_error"] = truth.error
    elif rooms is not None:
        summary["truth"] = None
    if config.cache_dir is not None and rooms is None:
        # the disk cache never raises: say here whether it was usable
        summary["disk_cache"] = {
            "dir": str(config.cache_dir),
            "available": disk_state[0],
            "error": disk_state[1],
        }
    return ReplayResult(summary, log, bytes_log, snapshots, spikes, truth, phases.array(),
                        interior=frames.series(log) if kind == "interior" else None)


async def _walk_unless_manifest_fails(walking: Coroutine[Any, Any, _T], manifest: asyncio.Future[Manifest]) -> _T:
    """Await the walk; a manifest that fails to decode meanwhile stops it with that error."""
    task: asyncio.Future[Any] = asyncio.ensure_future(walking)
    both: set[asyncio.Future[Any]] = {task, manifest}
    try:
        await asyncio.wait(both, return_when=asyncio.FIRST_EXCEPTION)
    except asyncio.CancelledError:
        # Ctrl-C (asyncio.run cancels the main task): asyncio.wait does not pass the
        # cancellation on, so the walk would go on to its end and the replay exit 0
        await reap([task])
        raise
    if manifest.done() and not manifest.cancelled() and manifest.exception() is not None and not task.done():
        await reap([task])
        raise manifest.exception()  # type: ignore[misc]
    return await task


async def _close(streamer: Streamer | None, rooms: RoomStreamer | None) -> None:
    """Stop the streamers: nothing more in flight, the rewrite workers stopped."""
    if streamer is not None:
        await streamer.close()
    if rooms is not None:
        await rooms.close()


def _room_view(config: ReplayConfig) -> RoomView:
    """How the walk views an interior (what the server culls the start bundle's first view with)."""
    depth = config.rooms.get("max_depth", RoomView.max_depth)
    return RoomView(config.size, config.fov_deg, config.fog_m, None if depth is None else int(depth))
