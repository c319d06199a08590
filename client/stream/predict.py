"""Motion prediction from recent positions, over time rather than per frame.

The velocity is the least-squares slope of the positions seen in the last
``window_s`` seconds (not the difference of the last two frames), so a frame-rate
change or a jittery frame does not change the prediction, and a stop is seen as a
stop.  Prediction is linear; where the viewer goes next along the streets is the
cell graph's business (:mod:`.route`), which takes the :meth:`MotionPredictor.heading`
from here: the way the viewer last went, kept while it stands still.
"""

from __future__ import annotations

from collections import deque

import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.shared.errors import InputError

__all__ = ["MotionPredictor"]


class MotionPredictor:
    """Velocity over a time window and linear extrapolation.

    Parameters
    ----------
    window_s:
        Positions older than this (relative to the newest) are forgotten.
    """

    def __init__(self, window_s: float = 1.0, moving: float = 0.3) -> None:
        if not window_s > 0:
            raise InputError(f"window_s must be > 0, got {window_s!r}")
        self.window_s = float(window_s)
        self.moving = float(moving)
        """Below this speed (m/s) the viewer counts as standing still."""
        self._t: deque[float] = deque()
        self._xy: deque[tuple[float, float]] = deque()
        self._heading: NDArray[np.float64] | None = None

    def observe(self, t: float, xy: ArrayLike) -> None:
        """Add the position at time ``t`` (times must not go backwards)."""
        p = np.asarray(xy, dtype=np.float64).reshape(-1)
        if self._t and t < self._t[-1]:
            raise InputError(f"time went backwards: {t} after {self._t[-1]}")
        self._t.append(float(t))
        self._xy.append((float(p[0]), float(p[1])))
        while self._t and self._t[0] < t - self.window_s:
            self._t.popleft()
            self._xy.popleft()
        v = self.velocity()
        speed = float(np.hypot(*v))
        if speed > self.moving:
            self._heading = v / speed

    @property
    def position(self) -> NDArray[np.float64]:
        """The newest position (zeros before the first observation)."""
        return np.array(self._xy[-1] if self._xy else (0.0, 0.0))

    def velocity(self) -> NDArray[np.float64]:
        """Least-squares velocity (m/s) over the window; zero with fewer than 2 samples."""
        n = len(self._t)
        if n < 2:
            return np.zeros(2)
        t = np.fromiter(self._t, dtype=np.float64, count=n)
        span = t[-1] - t[0]
        if span <= 1e-9:
            return np.zeros(2)
        xy = np.array(self._xy, dtype=np.float64)
        tc = t - t.mean()
        v: NDArray[np.float64] = (tc @ (xy - xy.mean(axis=0))) / float(tc @ tc)
        return v

    def heading(self) -> NDArray[np.float64] | None:
        """Unit vector of the way the viewer last went faster than ``moving`` (None before).

        Kept while the viewer stands still, so that a stop at a junction does not
        forget which way it came.
        """
        return None if self._heading is None else self._heading.copy()

    def speed(self) -> float:
        """Magnitude of :meth:`velocity`, m/s."""
        return float(np.hypot(*self.velocity()))

    def predict(self, dts: ArrayLike) -> NDArray[np.float64]:
        """Positions ``dts`` seconds after the newest observation, shape (m, 2)."""
        d = np.asarray(dts, dtype=np.float64).reshape(-1, 1)
        out: NDArray[np.float64] = self.position[None, :] + d * self.velocity()[None, :]
        return out
