"""The city's figures of a replay's summary: what its streamer fetched, for which frames, over which link."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from walkstream.client.config import ReplayConfig
from walkstream.client.report.framelog import FrameLog
from walkstream.client.report.metrics import link_utilisation
from walkstream.client.stream.cache import Cache
from walkstream.client.stream.streamer import Streamer
from walkstream.shared.paths import RecordedPath
from walkstream.shared.wire import Manifest

__all__ = ["city_summary", "overfetch"]


def city_summary(
    config: ReplayConfig,
    log: FrameLog,
    streamer: Streamer,
    cache: Cache,
    link_stats: Any,
    api: Any,
    bytes_log: tuple[NDArray[np.float64], NDArray[np.float64]],
    walk_span_s: float,
    t_start: float,
    setup_s: float,
    path: RecordedPath,
    manifest: Manifest | None,
) -> dict[str, Any]:
    """The city's figures of a replay's summary (beyond the frame log's).

    Parameters
    ----------
    link_stats:
        The link's :class:`~walkstream.client.net.link.LinkStats`.
    api:
        The walk's :class:`~walkstream.client.net.api.SceneClient`.
    bytes_log:
        The link's ``(t, cumulative bytes)`` from the replay's start.
    walk_span_s:
        From the replay's start to the walk's end, seconds (the link's utilisation).
    """
    stats = link_stats
    entered = {int(c) for c in np.unique(log.cell) if c >= 0}
    over = overfetch(streamer, entered)
    bytes_received = int(stats.bytes_down)
    busy = np.array(streamer.busy_intervals(), dtype=np.float64).reshape(-1, 2) - t_start
    return {
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
        "link_utilisation": link_utilisation(bytes_log, config.link.down_bps, [[0.0, walk_span_s]]),
        "link_utilisation_busy": link_utilisation(bytes_log, config.link.down_bps, busy),
        "link_busy_s": float(np.sum(busy[:, 1] - busy[:, 0])) if len(busy) else 0.0,
        "redownloads": int(cache.redownloads),
        "duplicates": int(sum(n - 1 for n in streamer.stats.object_counts.values()) - cache.redownloads),
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
        **api.stats.outage_figures(api.clock.now()),  # outages survived or not
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


def overfetch(streamer: Streamer, entered: set[int]) -> dict[str, int]:
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
