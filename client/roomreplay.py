"""The replay's frame loop on an interior scene (what :func:`~walkstream.client.replay.replay`
runs when the manifest's kind is ``interior``).

Setup fetches the topology (one request: every cell's planes and every portal).  Then,
frame by frame: move the eye along the path, let the
:class:`~walkstream.client.stream.rooms.RoomStreamer` locate it by the cells' planes,
find the visible cells (through portals in the frustum, within the fog distance) and
fetch their contents; draw the parts of the visible cells' contents whose boxes meet
the frustum (frustum culling of the visible cells' contents; the portal culling with
visible screen areas is Interiors II).  Indoors there is one LOD per part, so no
polygon budget is shared; the budget column of the log stays 0.

Per frame, download quality is the share of the visible cells whose contents are in
memory and rewrite quality the share that is also on the GPU (the same here: decoded
contents are uploaded in the frame they are drawn), so a perfect frame is one where
everything visible has arrived.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Hashable
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from walkstream.client.clock import Clock
from walkstream.client.draw.culling import frustum_cull
from walkstream.client.draw.frames import camera
from walkstream.client.report.metrics import FrameLog, FrameLogBuilder
from walkstream.client.stream.rooms import RoomStreamer
from walkstream.shared.camera import perspective
from walkstream.shared.paths import RecordedPath
from walkstream.shared.records import Mesh

__all__ = ["walk_interior"]


async def walk_interior(
    config: Any,
    clock: Clock,
    path: RecordedPath,
    streamer: RoomStreamer,
    device: Any,
    renderer: Any,
    progress: Callable[[float, float], None] | None,
    t_start: float,
    bytes_down: Callable[[], int],
) -> tuple[FrameLog, list[Path], NDArray[np.bool_]]:
    """Walk ``path`` through an interior (see the module docstring).

    Returns the frame log, the snapshot files and the per-frame spike flags, like
    the city's walk.
    """
    tick = 1.0 / config.fps
    total = path.duration if config.duration_s is None else min(config.duration_s, path.duration)
    w, h = config.size
    proj = perspective(config.fov_deg, w / h, 0.1, max(2.0 * streamer.config.fog_m, 50.0))
    builder = FrameLogBuilder()
    snapshots: list[Path] = []
    spikes: list[bool] = []
    meshes: dict[tuple[int, int], Mesh] = {}
    t_walk0 = clock.now()
    frame = 0
    last_progress = -math.inf
    while True:
        t = clock.now()
        wt = t - t_walk0
        if wt > total:
            break
        if progress is not None and wt - last_progress >= 1.0:
            last_progress = wt
            progress(wt, total)
        xyz, yaw, pitch = path.at(wt)
        eye = np.asarray(xyz, dtype=np.float64)
        view = camera(eye, float(yaw), float(pitch))
        vp = proj.astype(np.float64) @ view.astype(np.float64)
        vis = streamer.tick(t, eye, vp)
        draw_keys: list[Hashable] = []
        triangles = 0
        parts = 0
        have = 0
        for cid in vis:
            cm = streamer.mesh(cid)
            if cm is None:
                continue
            have += 1
            if not cm.parts:
                continue
            boxes = [p.bbox for p in cm.parts]
            keep = frustum_cull(np.array([b[0] for b in boxes]), np.array([b[1] for b in boxes]), vp)
            for k, (part, ok) in enumerate(zip(cm.parts, keep.tolist(), strict=True)):
                if not ok:
                    continue
                triangles += part.triangles
                parts += 1
                if renderer is not None:
                    key: tuple[int, int] = (cid, k)
                    if not renderer.has(key):
                        m = meshes.get(key)
                        if m is None:
                            m = meshes[key] = part.mesh()
                        renderer.upload(key, m)
                    draw_keys.append(key)
        quality = have / len(vis) if vis else 0.0
        snap = config.snapshot_every and frame % config.snapshot_every == 0
        if device.simulated:
            frame_time = float(device.frame_time(triangles, parts))
            spikes.append(bool(getattr(device, "last_spike", False)))
            if snap and renderer is not None:
                renderer.draw(draw_keys, view, proj)
        else:
            frame_time = float(renderer.draw(draw_keys, view, proj))
            spikes.append(False)
        if snap and renderer is not None and config.report_dir is not None:
            out = Path(config.report_dir) / "frames" / f"frame_{frame:06d}.png"
            out.parent.mkdir(parents=True, exist_ok=True)
            renderer.save_png(out)
            snapshots.append(out)
        builder.append(
            t=t - t_start,
            frame_time=frame_time,
            cell=-1 if streamer.current is None else int(streamer.current),
            pvs=len(vis),
            download_quality=quality,
            rewrite_quality=quality,
            bytes_down=bytes_down(),
            budget=0,
            triangles=triangles,
            visible=parts,
        )
        frame += 1
        if renderer is not None and frame % 25 == 0:
            # a flushed cell's GPU buffers go with it
            for key in [k for k in meshes if streamer.mesh(k[0]) is None]:
                if renderer.has(key):
                    renderer.forget(key)
                del meshes[key]
        await clock.sleep_until(t + max(frame_time, tick))
    if renderer is not None:
        for key in list(meshes):
            if renderer.has(key):
                renderer.forget(key)
    if progress is not None:
        progress(total, total)
    return builder.build(fps_cap=config.fps), snapshots, np.array(spikes, dtype=bool)
