"""What the streamer fetched: requests, records, objects and their bytes, link busy time."""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["StreamStats"]


@dataclass
class StreamStats:
    """Counters of what was fetched."""

    cell_requests: int = 0
    """Requests for cell records (single or batched)."""
    cells_received: int = 0
    cell_bytes: dict[int, int] = field(default_factory=dict)
    """Record bytes received per cell id (re-downloads add up)."""
    tile_requests: int = 0
    tile_bytes: dict[int, int] = field(default_factory=dict)
    """Index bytes received per tile (:func:`tile_key`)."""
    locate_requests: int = 0
    object_requests: int = 0
    objects_received: int = 0
    object_bytes: dict[int, int] = field(default_factory=dict)
    """Frame bytes received per object id (re-downloads add up)."""
    object_counts: dict[int, int] = field(default_factory=dict)
    """Times each object id was received."""
    cancelled_batches: int = 0
    disk_hits: int = 0
    bundle_bytes: int = 0
    """Bytes of the start bundle's path, cell, index, manifest and objects parts."""
    busy: list[tuple[float, float]] = field(default_factory=list)
    """Intervals (clock times) during which a request was in flight."""
