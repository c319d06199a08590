"""What the cache must keep for the next seconds of the walk: the streamer's pins.

Evicting what the next seconds need would only download it again, so the streamer pins
the current cell with its PVS (downloads and geometry), the records and downloads of the
cells about to be entered (their geometry too when they are entered within
``geometry_s``), and the index tiles the prediction needs.  Geometry can be rebuilt,
so only that of the cells entered soon is pinned.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping

from walkstream.shared.wire import CellRecord

__all__ = ["Pins"]


class Pins:
    """The pinned keys of one streamer, with hysteresis on the cells needed.

    Parameters
    ----------
    hold_s:
        A cell's keys stay pinned this long after it was last needed: the prediction
        wobbles at 10 Hz, and a cell that drops out of it for a moment keeps its pins.
    geometry_s:
        The geometry of the cells needed within this many seconds is pinned too.
    """

    def __init__(self, hold_s: float, geometry_s: float) -> None:
        self.hold_s = hold_s
        self.geometry_s = geometry_s
        self.needed_at: dict[int, float] = {}
        """Cell id -> clock time at which it was last needed."""

    def keys(
        self,
        now: float,
        need: Mapping[int, float],
        current: int | None,
        cells: Mapping[int, CellRecord],
        kind: str,
        tiles: Iterable[int],
    ) -> list[tuple[str, int]]:
        """The cache keys to pin now.

        Parameters
        ----------
        now:
            Clock time.
        need:
            Cells needed -> seconds until needed (the last plan).
        current:
            The viewer's cell, if any.
        cells:
            The cell records held.
        kind:
            The cache kind of an object's download (``params`` or ``mesh``).
        tiles:
            Keys of the index tiles the prediction needs.
        """
        rec = cells.get(current) if current is not None else None
        for c in need:
            self.needed_at[c] = now
        for c in [c for c, t in self.needed_at.items() if now - t > self.hold_s]:
            del self.needed_at[c]
        # (a key not cached yet is pinned when it arrives)
        keys: list[tuple[str, int]] = [("cell", c) for c in self.needed_at]
        if rec is not None:
            keys += [(kind, i) for i in rec.streamed()[0].tolist()]
            keys += [("geom", i) for i in rec.streamed()[0].tolist()]
        for c in self.needed_at:
            r = cells.get(c)
            if r is not None and c != current:
                keys += [(kind, i) for i in r.streamed()[0].tolist()]
                if need.get(c, math.inf) <= self.geometry_s:
                    # about to be entered: its geometry too, or a frame shows the gap
                    keys += [("geom", i) for i in r.streamed()[0].tolist()]
        # every tile the prediction needs: one evicted would be asked for again at once
        keys += [("index", t) for t in tiles]
        return keys
