"""Impostor quads composed farthest first: a farther image never painted over a nearer one."""

from __future__ import annotations

import numpy as np

from walkstream.client.draw.quads import back_to_front
from walkstream.shared.camera import look_at, perspective


def _quad(centre: tuple[float, float, float], tag: int) -> tuple[np.ndarray, int, np.ndarray, float]:
    c = np.asarray(centre, np.float64)
    corners = c + np.array([[-1.0, 0.0, -1.0], [1.0, 0.0, -1.0], [1.0, 0.0, 1.0], [-1.0, 0.0, 1.0]])
    return corners, tag, np.zeros((1, 1, 4), np.uint8), 1.0


def test_farthest_first_whatever_the_order_given() -> None:
    view_proj = perspective(60.0, 4 / 3, 0.5, 1000.0) @ look_at((0.0, 0.0, 1.7), (0.0, 100.0, 1.7))
    # by object id the near building came first: its image was painted under the far one's
    quads = [_quad((0.0, 70.0, 10.0), 1), _quad((3.0, 140.0, 10.0), 2), _quad((-4.0, 90.0, 12.0), 3)]
    assert [q[1] for q in back_to_front(quads, view_proj)] == [2, 3, 1]
    # two images of one building cross-fading share a centre: the old stays under the new
    pair = [_quad((0.0, 80.0, 10.0), 10), _quad((0.0, 80.0, 10.0), 11), _quad((0.0, 200.0, 10.0), 12)]
    assert [q[1] for q in back_to_front(pair, view_proj)] == [12, 10, 11]
    assert back_to_front([], view_proj) == []
