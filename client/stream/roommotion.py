"""The interior walker's motion as the streamer predicts it: where the eye moves and
how fast the view turns over the last moments, and the views that motion leads to.

:class:`~walkstream.client.stream.rooms.RoomStreamer` notes each frame's eye and view
here (:meth:`RoomMotion.observe`); its prefetch (``predicted``), the wall textures
ahead (:mod:`~walkstream.client.walk.walls`) and the entrance's look through a door
(:mod:`~walkstream.client.stream.entrance`) ask it where the walker will be and look.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from walkstream.shared.camera import camera

__all__ = ["RoomMotion", "predicted_view", "turned_view"]

_TURNING = np.radians(20.0)
"""A heading turning this fast (radians a second) is predicted to go on turning."""


def predicted_view(view: NDArray[np.float64], eye: NDArray[np.float64], eye2: NDArray[np.float64]) -> NDArray[np.float64]:
    """The ``(4, 4)`` view matrix ``view`` moved from ``eye`` ``(3,)`` to ``eye2`` ``(3,)``,
    looking the same way."""
    out = np.array(view, dtype=np.float64)
    out[:3, 3] -= out[:3, :3] @ (np.asarray(eye2, np.float64) - np.asarray(eye, np.float64))
    return out


def turned_view(view: NDArray[np.float64], eye: NDArray[np.float64], deg: float) -> NDArray[np.float64]:
    """The ``(4, 4)`` view matrix ``view`` turned by ``deg`` degrees about the vertical
    through ``eye`` ``(3,)``."""
    a = np.radians(deg)
    rot = np.eye(4)
    rot[:2, :2] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
    move, back = np.eye(4), np.eye(4)
    move[:3, 3] = eye
    back[:3, 3] = -np.asarray(eye, np.float64)
    return np.asarray(view, np.float64) @ move @ rot @ back


class RoomMotion:
    """The eye's track and the view's headings over the last ``velocity_s`` seconds."""

    def __init__(self, velocity_s: float) -> None:
        self._velocity_s = float(velocity_s)
        self._track: list[tuple[float, NDArray[np.float64]]] = []
        self._headings: list[tuple[float, float, float]] = []  # (t, yaw, pitch) of the frames' views

    def observe(self, t: float, eye: NDArray[np.float64]) -> None:
        """Note the eye at time ``t`` (for :meth:`velocity`)."""
        self._track.append((t, np.array(eye, dtype=np.float64).reshape(3)))
        while len(self._track) > 2 and t - self._track[1][0] >= self._velocity_s:
            self._track.pop(0)

    def _observe_heading(self, t: float, view: NDArray[np.float64]) -> None:
        """Note the view's heading at time ``t`` (for :meth:`turn_rate`)."""
        f = -np.asarray(view, np.float64)[2, :3]  # the camera looks down its -z
        self._headings.append((t, float(np.arctan2(f[1], f[0])), float(np.arcsin(np.clip(f[2], -1.0, 1.0)))))
        while len(self._headings) > 2 and t - self._headings[1][0] >= self._velocity_s:
            self._headings.pop(0)

    def turn_rate(self) -> float:
        """The heading's turn over the last ``velocity_s`` seconds (radians a second,
        counter-clockwise positive)."""
        if len(self._headings) < 2:
            return 0.0
        (t0, y0, _), (t1, y1, _) = self._headings[0], self._headings[-1]
        turn = (y1 - y0 + np.pi) % (2 * np.pi) - np.pi
        return float(turn / (t1 - t0)) if t1 > t0 else 0.0

    def turning(self) -> bool:
        """Whether the heading turns fast enough (20 degrees a second) to be predicted
        to go on turning."""
        return len(self._headings) >= 2 and abs(self.turn_rate()) >= _TURNING

    def velocity(self) -> NDArray[np.float64]:
        """``(3,)`` the eye's velocity over the last ``velocity_s`` seconds (m/s)."""
        if len(self._track) < 2:
            return np.zeros(3)
        (t0, e0), (t1, e1) = self._track[0], self._track[-1]
        return (e1 - e0) / (t1 - t0) if t1 > t0 else np.zeros(3)

    def view_ahead(
        self, eye: NDArray[np.float64], view: NDArray[np.float64], h: float
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The eye ``(3,)`` and view ``(4, 4)`` predicted ``h`` seconds ahead: moved on at
        :meth:`velocity`, looking the same way, or, while :meth:`turn_rate` is 20 degrees
        a second or more, turned on at that rate (half a turn at most)."""
        e2 = np.asarray(eye, np.float64).reshape(3) + h * self.velocity()
        w = self.turn_rate()
        if self.turning():  # a walker turning goes on turning
            _, yaw, pitch = self._headings[-1]
            return e2, camera(e2, yaw + float(np.clip(w * h, -np.pi, np.pi)), pitch).astype(np.float64)
        return e2, predicted_view(view, eye, e2)
