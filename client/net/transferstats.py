"""What the client observes of its link: the smoothed round trip and throughput, retries,
cut streams and the outages it lived through (it is never told the link's settings).

:class:`~walkstream.client.net.api.SceneClient` feeds it as requests go and come; the
report (:mod:`~walkstream.client.report`) reads its figures.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

__all__ = ["TransferStats"]


@dataclass
class TransferStats:
    """What the client observed of the link (it is never told the link's settings)."""

    rtt_s: float = math.nan
    """Smoothed time from sending a small request to its answer's headers."""
    bandwidth_bps: float = math.nan
    """Smoothed body throughput of object streams, bits per second."""
    retries: int = 0
    cut_streams: int = 0
    samples: list[tuple[float, float]] = field(default_factory=list)
    outages: int = 0
    """Times the server could not be reached (a refused or timed-out connection, or a
    5xx) until it answered again."""
    outage_s: float = 0.0
    """Seconds (the walk's clock) from each outage's first failure to the next answer;
    an outage still going on at the end counts up to :meth:`outage_figures`' ``now``."""
    longest_outage_s: float = 0.0
    _down_since: float | None = None

    def failed(self, now: float) -> None:
        """A request found no server (transport error, 5xx): an outage starts, unless one has."""
        if self._down_since is None:
            self._down_since = now

    def reached(self, now: float) -> None:
        """The server answered (any status below 500): an outage going on ends."""
        if self._down_since is not None:
            self._end_outage(now)

    def _end_outage(self, now: float) -> None:
        assert self._down_since is not None
        lasted = max(0.0, now - self._down_since)
        self.outages += 1
        self.outage_s += lasted
        self.longest_outage_s = max(self.longest_outage_s, lasted)
        self._down_since = None

    def outage_figures(self, now: float) -> dict[str, Any]:
        """``outages``, ``outage_s``, ``longest_outage_s`` and ``down_at_end`` as of ``now``."""
        down = self._down_since is not None
        if down:
            self._end_outage(now)
        return {
            "outages": self.outages,
            "outage_s": round(self.outage_s, 3),
            "longest_outage_s": round(self.longest_outage_s, 3),
            "down_at_end": down,
        }

    def observe_rtt(self, seconds: float) -> None:
        """Fold one request/headers time into the estimate."""
        if seconds > 0 and math.isfinite(seconds):
            self.rtt_s = seconds if math.isnan(self.rtt_s) else 0.7 * self.rtt_s + 0.3 * seconds

    def observe_transfer(self, nbytes: int, seconds: float) -> None:
        """Fold one body transfer (bytes after the first chunk, and its duration) in."""
        if nbytes >= 512 and seconds > 1e-6 and math.isfinite(seconds):
            bps = nbytes * 8.0 / seconds
            self.bandwidth_bps = (
                bps if math.isnan(self.bandwidth_bps) else 0.7 * self.bandwidth_bps + 0.3 * bps
            )
