"""Where a frame loop's wall time goes: per-frame phase timing.

:class:`FramePhases` splits each pass of the frame loop (:mod:`walkstream.client.walk.loop`)
into :data:`PHASES` with ``time.perf_counter`` marks (real seconds under either clock);
the first are the loop's steps (:data:`~walkstream.client.walk.loop.STEPS`):

``locate``    which cell holds the eye (the streamers' ticks that follow it)
``wants``     what the walk asks for beyond the streamers' plans (an entrance's interior)
``visible``   the visible set by the cell's model (PVS or portal walk; the rooms' requests)
``build``     rebuilds the visible PVS lacks
``allocate``  the room parts' culling, the frustum test and the LOD or fog choice under the budget
``upload``    making GPU buffers of newly drawn meshes
``draw``      clear, uniforms and draw calls (issuing the frame), the snapshot
``finish``    ``ctx.finish()``: waiting until the device has drawn it (on llvmpipe
              this is the rasterisation itself, on a GPU the GPU's time)
``measure``   the frame log, the walk's figures, the ground truth's notes, the controller
``rest``      everything else in the loop (forgetting flushed rooms' buffers)
``other``     from the end of one pass to the start of the next: the event loop's
              other work (downloads, decoding) and threads holding the interpreter
              lock (rebuilding), plus the wait for the next tick.

The figures go into ``report.json`` (:meth:`FramePhases.summary`) and ``phases.csv``
/ ``phases.png`` of the report.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["PHASES", "FramePhases"]

#: Phase names, in loop order; ``other`` is derived from the frame starts.
PHASES: tuple[str, ...] = (
    "locate",
    "wants",
    "visible",
    "build",
    "allocate",
    "upload",
    "draw",
    "finish",
    "measure",
    "rest",
    "other",
)
_INDEX = {name: k for k, name in enumerate(PHASES)}


class FramePhases:
    """Per-frame seconds spent in each of :data:`PHASES`.

    Usage per frame: :meth:`begin`, then :meth:`mark` after each phase (the time since
    the previous mark goes to that phase), :meth:`end` at the end of the pass.
    """

    def __init__(self) -> None:
        self._rows: list[NDArray[np.float64]] = []
        self._starts: list[float] = []
        self._ends: list[float] = []
        self._cur = np.zeros(len(PHASES))
        self._last = 0.0

    def begin(self) -> None:
        """Start a frame's pass."""
        self._last = time.perf_counter()
        self._starts.append(self._last)
        self._cur = np.zeros(len(PHASES))

    def mark(self, phase: str) -> None:
        """Charge the time since the last mark (or :meth:`begin`) to ``phase``."""
        now = time.perf_counter()
        self._cur[_INDEX[phase]] += now - self._last
        self._last = now

    def move(self, src: str, dst: str, seconds: float) -> None:
        """Move ``seconds`` (at most what ``src`` holds) from ``src`` to ``dst``."""
        s = min(max(float(seconds), 0.0), float(self._cur[_INDEX[src]]))
        self._cur[_INDEX[src]] -= s
        self._cur[_INDEX[dst]] += s

    def end(self) -> None:
        """Charge the rest of the pass to ``rest`` and file the frame."""
        self.mark("rest")
        self._ends.append(self._last)
        self._rows.append(self._cur)

    def __len__(self) -> int:
        return len(self._rows)

    def array(self) -> NDArray[np.float64]:
        """``(frames, len(PHASES))`` seconds; ``other`` of the last frame is 0."""
        if not self._rows:
            return np.zeros((0, len(PHASES)))
        a = np.vstack(self._rows)
        starts, ends = np.asarray(self._starts[: len(a)]), np.asarray(self._ends)
        a[:-1, _INDEX["other"]] = np.maximum(starts[1:] - ends[:-1], 0.0)
        return a

    def summary(self, fps_target: float | None = None) -> dict[str, Any]:
        """``report.json`` keys: median and mean milliseconds per phase and in all.

        Parameters
        ----------
        fps_target : float, optional
            Adds ``frame_period_within_10pct_ratio``: the share of frames whose period
            (start to next start, the rate the loop really shows frames at) is at
            least 90 % of this rate.

        Returns
        -------
        dict
            ``frame_phases_median_ms`` and ``frame_phases_mean_ms`` (phase -> ms),
            ``frame_loop_median_ms`` (median of the per-frame sum of the phases
            without ``other``: the loop's own work), ``frame_period_median_ms``
            (median time from one frame's start to the next) and, with a target,
            ``frame_period_within_10pct_ratio``.
        """
        a = 1000.0 * self.array()
        if not len(a):
            return {}
        busy = a[:, : _INDEX["other"]].sum(axis=1)
        period = np.diff(np.asarray(self._starts)) * 1000.0
        out: dict[str, Any] = {}
        if fps_target and len(period):
            out["frame_period_within_10pct_ratio"] = float(np.mean(period <= 1000.0 / (0.9 * fps_target)))
        return out | {
            "frame_phases_median_ms": {
                p: round(float(v), 3) for p, v in zip(PHASES, np.median(a, axis=0), strict=True)
            },
            "frame_phases_mean_ms": {
                p: round(float(v), 3) for p, v in zip(PHASES, a.mean(axis=0), strict=True)
            },
            "frame_loop_median_ms": round(float(np.median(busy)), 3),
            "frame_period_median_ms": round(float(np.median(period)), 3) if len(period) else None,
        }
