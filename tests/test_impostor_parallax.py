"""The parallax an orthographic impostor image shows a perspective viewer from its own direction."""

from __future__ import annotations

import math

import numpy as np

from walkstream.shared.impostors import image_basis, orthographic_parallax


def _seen_against_image(radius: float, distance: float, n: int = 20000) -> np.ndarray:
    """Angles (radians) between each of ``n`` points on a sphere of ``radius`` at the origin
    as a viewer at ``distance`` along a slanted direction sees it and as the orthographic
    image along that direction places it (in the plane through the centre)."""
    rng = np.random.default_rng(3)
    u = np.array([0.6, -0.3, 0.2])
    u /= np.linalg.norm(u)
    p = rng.normal(size=(n, 3))
    p = p / np.linalg.norm(p, axis=1, keepdims=True) * radius
    right, up = image_basis(u)
    img = np.outer(p @ right, right) + np.outer(p @ up, up)
    eye = u * distance
    a, b = p - eye, img - eye
    cos = np.sum(a * b, axis=1) / np.linalg.norm(a, axis=1) / np.linalg.norm(b, axis=1)
    return np.arccos(np.clip(cos, -1.0, 1.0))


def test_bounds_and_reaches_the_projection_of_the_sphere() -> None:
    for radius, distance in ((14.0, 70.0), (20.0, 65.0), (14.0, 260.0)):
        seen = _seen_against_image(radius, distance)
        bound = float(orthographic_parallax(radius, distance))
        assert seen.max() <= bound * 1.001
        assert seen.max() >= bound * 0.97  # the sampled sphere comes close: a bound, not a guess


def test_falls_with_the_square_of_distance_and_is_degrees_at_60_m() -> None:
    near, far = orthographic_parallax([14.0, 14.0], [70.0, 280.0])
    assert 14.0 < near / far < 18.0  # about R^2 / (2 d^2)
    assert 1.0 < math.degrees(near) < 1.6  # a median demo building just past D 60 m: 2-3 pixels at 160 x 120
    assert math.degrees(far) < 0.1


def test_inside_the_sphere_is_a_right_angle() -> None:
    assert float(orthographic_parallax(10.0, 5.0)) == math.pi / 2.0
