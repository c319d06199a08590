"""Why an interior frame was not perfect: each late cell's wait, from wanted to arrived.

A frame of an interior walk is perfect when every cell its portal walk shows (at the
default fog) has its contents in memory.  When one does not, the question is which
cell, and where its time went: was it wanted (in the streamer's list, visible or
predicted) only when it showed, was it wanted early but asked late (other requests
ahead of it on the link), or was it asked in time and still on the link (too many
bytes for the time the prediction gave)?  :class:`LateCells` keeps, for every cell
while it is not in memory, when it was first wanted, first asked for (a request
launched, or the start bundle), when it arrived, and the frames it was missing from;
:meth:`LateCells.figures` lists the cells that were missing from a frame after the
walk's first perfect frame (the frames the perfect-frame share counts), worst first,
each with its cause (:data:`CAUSES`).  The replay's summary holds them as
``late_cells`` (:func:`~walkstream.client.report.interior.interior_summary`).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

__all__ = ["CAUSES", "LateCell", "LateCells"]

CAUSES: tuple[str, ...] = ("unforeseen", "queued", "on the link")
"""Why a cell was missing when it showed: ``unforeseen`` (not wanted before the first
frame it was missing from: the prediction did not see it coming), ``queued`` (wanted
before, asked for only at or after that frame: the link was busy with other requests),
``on the link`` (asked for before it showed, its bytes still coming)."""


@dataclass
class LateCell:
    """One wait of one cell (from wanted to arrived); times are the walk's clock, seconds."""

    cell: int
    wanted_s: float
    asked_s: float | None = None
    arrived_s: float | None = None
    nbytes: int = 0
    missing: list[tuple[float, float]] = field(default_factory=list)
    """Each frame the cell was missing from: its time and the bytes on the link then
    (asked, not received)."""

    def cause(self, t: float) -> str:
        """One of :data:`CAUSES` for a cell first missing at ``t``."""
        if self.wanted_s >= t:
            return CAUSES[0]
        if self.asked_s is None or self.asked_s >= t:
            return CAUSES[1]
        return CAUSES[2]


class LateCells:
    """The waits of cells not in memory, and those that made a frame imperfect (module docs)."""

    def __init__(self) -> None:
        self._open: dict[int, LateCell] = {}
        self.late: list[LateCell] = []
        """Closed waits during which the cell was missing from a frame, in arrival order."""

    def wanted(self, t: float, cells: Iterable[int]) -> None:
        """Cells ``cells`` (not in memory) are wanted at ``t``: a wait starts for each new
        one; a cell not asked for yet that is no longer wanted starts again when it is
        (its wanted time is the start of the latest unbroken stretch)."""
        now = set(cells)
        for c, w in list(self._open.items()):
            if c not in now and w.asked_s is None and not w.missing:
                del self._open[c]
        for c in now:
            if c not in self._open:
                self._open[c] = LateCell(c, t)

    def asked(self, t: float, cells: Iterable[int], nbytes: Iterable[int]) -> None:
        """A request for ``cells`` (of ``nbytes`` stored bytes each) went out at ``t``."""
        for c, n in zip(cells, nbytes, strict=True):
            w = self._open.setdefault(c, LateCell(c, t))
            if w.asked_s is None:
                w.asked_s, w.nbytes = t, int(n)

    def missing(self, t: float, cells: Iterable[int], busy_bytes: float) -> None:
        """Cells ``cells`` were shown by the frame at ``t`` without their contents;
        ``busy_bytes`` were on the link then."""
        for c in cells:
            self._open.setdefault(c, LateCell(c, t)).missing.append((t, float(busy_bytes)))

    def arrived(self, t: float, cell: int) -> None:
        """Cell ``cell``'s contents arrived at ``t``: its wait ends."""
        w = self._open.pop(cell, None)
        if w is not None and w.missing:
            w.arrived_s = t
            self.late.append(w)

    def figures(self, t0: float = 0.0, from_s: float = -math.inf, top: int = 20) -> dict[str, Any]:
        """The cells missing from frames at ``from_s`` or later (the walk's first perfect
        frame: the start-up before it is measured apart), worst first (at most ``top``),
        times from ``t0``; and the frames missing a cell summed by cause (a frame missing
        two cells counts twice)."""
        by_cause = {k: 0 for k in CAUSES}
        rows = []
        for w in [*self.late, *self._open.values()]:
            frames = [m for m in w.missing if m[0] >= from_s]
            if not frames:
                continue
            (t, busy), cause = frames[0], w.cause(frames[0][0])
            by_cause[cause] += len(frames)
            rows.append((len(frames), w, t, busy, cause))

        def rel(x: float | None) -> float | None:
            return None if x is None else round(x - t0, 3)

        rows.sort(key=lambda r: (-r[0], r[1].wanted_s))
        return {
            "cells": len(rows),
            "cell_frames_by_cause": by_cause,
            "worst": [{
                "cell": w.cell, "frames": n, "cause": cause, "wanted_s": rel(w.wanted_s),
                "asked_s": rel(w.asked_s), "missing_s": rel(t), "arrived_s": rel(w.arrived_s),
                "bytes": w.nbytes, "busy_bytes": round(busy),
            } for n, w, t, busy, cause in rows[:top]],
        }
