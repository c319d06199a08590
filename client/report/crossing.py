"""A crossing's figures of a replay's summary: the model switches, the door, both streamers' requests."""

from __future__ import annotations

from typing import Any

import numpy as np

from walkstream.client.config import ReplayConfig
from walkstream.client.report.framelog import FrameLog
from walkstream.client.stream.cache import Cache
from walkstream.client.stream.rooms import RoomStreamer
from walkstream.client.stream.streamer import Streamer
from walkstream.client.walk.figures import MODEL_PORTALS, MODEL_PVS, WalkFrames
from walkstream.shared.paths import RecordedPath
from walkstream.shared.roomwire import Entrance
from walkstream.shared.wire import Manifest

__all__ = ["crossing_summary"]


def crossing_summary(
    config: ReplayConfig,
    log: FrameLog,
    frames: WalkFrames,
    city: Streamer,
    rooms: RoomStreamer,
    cache: Cache,
    e: Entrance,
    setup_s: float,
    path: RecordedPath,
    manifest: Manifest | None,
) -> dict[str, Any]:
    """The crossing's figures of a replay's summary (beyond the frame log's and the link's)."""
    wt = np.asarray(log.t, np.float64) - (float(log.t[0]) if len(log.t) else 0.0)
    room = np.asarray(frames.room)
    inside = np.flatnonzero((room >= 0) & (room != e.doorway))
    first_in = int(inside[0]) if len(inside) else None
    first_room = int(room[first_in]) if first_in is not None else None
    # the doorway's frames on the way in: each must already hold the first room's contents
    door_in = [k for k in frames.loaded if first_in is None or k < first_in]
    lacking = [k for k in door_in if first_room is not None and first_room not in frames.loaded[k]]
    door_t = float(wt[min(frames.loaded)]) if frames.loaded else None
    return {
        "kind": "crossing",
        "scene_version": None if manifest is None else manifest.version,
        "path_duration_s": path.duration,
        "walk_s": float(wt[-1]) if len(wt) else 0.0,
        "setup_s": setup_s,
        "entrance": e.to_wire(),
        "model_switches": [[round(t, 3), m] for t, m in frames.switches(wt)],
        "frames_pvs": int(sum(1 for m in frames.model if m == MODEL_PVS)),
        "frames_portals": int(sum(1 for m in frames.model if m == MODEL_PORTALS)),
        "first_room": first_room,
        "door_frames": len(door_in),
        "door_frames_without_first_room": len(lacking),
        "door_reached_s": door_t,
        "interior_prefetch_from_s": frames.prefetch_from,
        "rooms_visible_max": max(frames.rooms_visible, default=0),
        "objects_visible_max": max(frames.objects_visible, default=0),
        "fog_m_min": float(min(frames.fog_m)) if frames.fog_m else None,
        "object_requests": city.stats.object_requests,
        "objects_received": city.stats.objects_received,
        "cell_requests": city.stats.cell_requests,
        "index_requests": city.stats.tile_requests,
        "object_bytes": int(sum(city.stats.object_bytes.values())),
        "cell_bytes": int(sum(city.stats.cell_bytes.values())),
        "contents_requests": rooms.stats.requests,
        "contents_bytes": rooms.stats.bytes_received,
        "cells_fetched": len(rooms.stats.fetched),
        "contents_redownloads": rooms.stats.refetched,
        "cache_bytes": config.cache_bytes,
        "cache_peak_bytes": int(cache.peak_bytes),
        "cache_entries": cache.stats()["entries"],
    }
