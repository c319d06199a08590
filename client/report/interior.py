"""An interior's figures of a replay's summary: its cells, contents, culling and fog."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from walkstream.client.config import ReplayConfig
from walkstream.client.report.framelog import FrameLog
from walkstream.client.report.metrics import first_perfect_index
from walkstream.client.stream.cache import Cache
from walkstream.client.stream.rooms import RoomStreamer
from walkstream.client.walk.figures import WalkFrames
from walkstream.shared.paths import RecordedPath
from walkstream.shared.roomwire import Topology
from walkstream.shared.wire import Manifest

__all__ = ["interior_summary"]


def interior_summary(
    config: ReplayConfig,
    log: FrameLog,
    streamer: RoomStreamer,
    frames: WalkFrames,
    topology: Topology,
    cache: Cache,
    setup_s: float,
    path: RecordedPath,
    manifest: Manifest | None,
    t_start: float = 0.0,
) -> dict[str, Any]:
    """The interior figures of a replay's summary (beyond the frame log's and the link's);
    ``t_start``: the walk's clock at the replay's start (``late_cells`` counts from it;
    they are the frames from the first perfect one on, as the perfect-frame share)."""
    entered = {int(c) for c in np.unique(log.cell) if c >= 0}
    first = first_perfect_index(log)
    return {
        "kind": "interior",
        "scene_version": None if manifest is None else manifest.version,
        "path_duration_s": path.duration,
        "walk_s": float(log.t[-1] - log.t[0]) if len(log.t) else 0.0,
        "setup_s": setup_s,
        "cells_entered": len(entered),
        "cells_in_scene": len(topology.cells),
        "topology_bytes": topology.nbytes,
        "visible_cells_mean": float(np.mean(log.pvs)) if len(log.pvs) else 0.0,
        "visible_cells_max": int(np.max(log.pvs)) if len(log.pvs) else 0,
        "contents_requests": streamer.stats.requests,
        "start_contents_cells": streamer.stats.bundled,
        "start_head_cells": streamer.stats.heads,
        "contents_bytes": streamer.stats.bytes_received,
        "cells_fetched": len(streamer.stats.fetched),
        "cells_flushed": streamer.stats.flushed,
        "redownloads": streamer.stats.refetched,
        "flush_policy": streamer.config.flush_policy, "flush_after_s": streamer.config.flush_s,
        "fog_m": config.fog_m,
        "culling": config.culling,
        **frames.figures(),
        "fog_budget": config.fog_budget,
        "fog_m_median": float(np.median(frames.fog_m)) if frames.fog_m else config.fog_m,
        "fog_m_min": float(np.min(frames.fog_m)) if frames.fog_m else config.fog_m,
        "fog_tightened_frames": frames.tightened,
        "fog_below_portal_frames": frames.fog_below_portal,
        "triangle_cull": config.triangle_cull,
        # --cull-cache: the frames culled through a guard made for them (misses) or reused (hits)
        **({} if streamer.cull_cache is None else {
            "cull_cache_hits": streamer.cull_cache.cache.hits, "cull_cache_misses": streamer.cull_cache.cache.misses}),
        "triangle_culled_parts": frames.triangle_culled,
        "path_wait_s": frames.path_wait_s,
        "start_hold_s": frames.start_hold_s,
        "late_cells": streamer.late.figures(
            t_start, -math.inf if first is None else t_start + float(log.t[first])),
        "cache_bytes": config.cache_bytes,
        "cache_peak_bytes": int(cache.peak_bytes),
    }
