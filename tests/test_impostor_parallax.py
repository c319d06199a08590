"""The parallax an orthographic impostor image shows a perspective viewer from its own direction."""

from __future__ import annotations

import dataclasses
import math
import subprocess
import sys

import numpy as np
import pytest

from walkstream.client.config import ReplayConfig
from walkstream.client.draw.impostors import choose_impostors
from walkstream.client.net.link import LinkProfile
from walkstream.shared.errors import InputError
from walkstream.shared.impostors import (
    MAX_LEVEL,
    bin_of,
    directions,
    image_basis,
    orthographic_parallax,
)
from walkstream.shared.impostorwire import ImpostorRow


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


def _near_row() -> tuple[ImpostorRow, float, float]:
    """A building just past D 60 m with its image at the finest level in the eye's bin;
    its bounding radius and the eye's distance to its centre."""
    box = (70.0, -5.0, 0.0, 80.0, 5.0, 20.0)
    lo, hi = np.array(box[:3]), np.array(box[3:])
    az, el = directions(np.array(EYE), (lo + hi) / 2.0)
    ia, ie = bin_of(MAX_LEVEL, az, el)
    row = ImpostorRow(9, MAX_LEVEL, int(ia), 1, int(ie), 1, box, (5,))
    return row, float(np.linalg.norm(hi - lo)) / 2.0, float(np.linalg.norm((lo + hi) / 2.0 - np.array(EYE)))


EYE = (0.0, 0.0, 1.7)


def test_the_choice_counts_the_parallax_only_when_asked() -> None:
    row, radius, span = _near_row()
    parallax = float(orthographic_parallax(radius, span))
    # the building is 9 degrees across at 75 m: no size limit here, the parallax alone is tested
    (plain,) = choose_impostors([row], EYE, 60.0, math.radians(4.0), max_size_deg=math.inf)
    (held,) = choose_impostors([row], EYE, 60.0, math.radians(4.0), perspective=True, max_size_deg=math.inf)
    assert held.error == pytest.approx(plain.error + parallax)
    assert plain.alpha == 1.0 and held.alpha == 1.0, "well within a loose bound: the image either way"
    # a bound the direction's error keeps and the parallax breaks: geometry when counted
    bound = plain.error + 0.9 * parallax
    (plain,) = choose_impostors([row], EYE, 60.0, bound, max_size_deg=math.inf)
    (held,) = choose_impostors([row], EYE, 60.0, bound, perspective=True, max_size_deg=math.inf)
    assert plain.image == 5 and plain.alpha == 1.0
    assert held.image is None and held.alpha == 0.0


def test_a_building_large_on_the_screen_is_drawn_as_geometry() -> None:
    # 9.2 degrees across (radius 12 m at 75 m): over the limit, geometry; under a looser
    # limit the image; in the fade's last quarter part of each
    row, radius, span = _near_row()
    size = math.degrees(math.asin(radius / span))
    assert 9.0 < size < 9.5
    (big,) = choose_impostors([row], EYE, 60.0, math.radians(4.0))  # the default limit, 6 degrees
    assert big.image is None and big.alpha == 0.0
    (loose,) = choose_impostors([row], EYE, 60.0, math.radians(4.0), max_size_deg=12.0 * 4.0 / 3.0)
    assert loose.image == 5 and loose.alpha == 1.0
    (fading,) = choose_impostors([row], EYE, 60.0, math.radians(4.0), max_size_deg=size / 0.875)
    assert fading.image == 5 and 0.0 < fading.alpha < 1.0
    link = LinkProfile(56_000.0, 56_000.0, 0.2)
    for bad in (0.0, -1.0, math.nan, 91.0):
        with pytest.raises(InputError, match="--impostor-max-size"):
            ReplayConfig(link, impostor_max_size_deg=bad)
    assert ReplayConfig(link, impostor_max_size_deg=math.inf).impostor_max_size_deg == math.inf


def test_the_replay_flag_is_offered_and_off_by_default() -> None:
    out = subprocess.run([sys.executable, "-m", "walkstream", "replay", "--help"], capture_output=True, text=True, check=True)
    assert "--impostor-perspective" in out.stdout
    field = {f.name: f for f in dataclasses.fields(ReplayConfig)}["impostor_perspective"]
    assert field.default is False
