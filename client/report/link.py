"""The link's figures of a replay: bytes over time and the summary's link fields.

One home for what every walk's summary says of its link (a city, an interior or a
crossing walk): what was configured, what went down and up, what was retried.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["bytes_series", "link_figures"]


def bytes_series(stats: Any, t_start: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(t, cumulative bytes)`` of the link's downloads, ``t`` from ``t_start``.

    Parameters
    ----------
    stats:
        The link's :class:`~walkstream.client.net.link.LinkStats` (its ``down_log``).
    t_start:
        The walk's start on the link's clock.
    """
    return (
        np.array([t for t, _ in stats.down_log], dtype=np.float64) - t_start,
        np.array([b for _, b in stats.down_log], dtype=np.float64),
    )


def link_figures(config: Any, stats: Any, api: Any) -> dict[str, Any]:
    """The summary's link fields of a walk that streams no objects of its own
    (an interior's or a crossing's; the city's are the replay's).

    Parameters
    ----------
    config:
        The :class:`~walkstream.client.replay.ReplayConfig`.
    stats:
        The link's statistics.
    api:
        The walk's :class:`~walkstream.client.net.api.SceneClient` (retries, cut streams).
    """
    return {
        "scene": api.scene,
        "path": config.path,
        "clock": config.clock,
        "device": config.device,
        "prefetch": config.prefetch,
        "stream": config.stream,
        "bandwidth_bps": config.link.down_bps,
        "rtt_s": config.link.rtt_s,
        "loss": config.link.loss,
        "bytes_received": int(stats.bytes_down),
        "bytes_sent": int(stats.bytes_up),
        "overfetch_ratio": 0.0,
        "redownloads": 0,
        "rebuilds": 0,
        "duplicates": 0,
        "retries": api.stats.retries,
        **api.stats.outage_figures(api.clock.now()),  # outages survived or not (issue 25)
        "cut_streams": api.stats.cut_streams,
        "responses_cut_by_link": stats.responses_cut,
        "requests": stats.requests, "start_bundle": config.start_bundle,
    }
