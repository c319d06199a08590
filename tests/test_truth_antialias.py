"""The truth's anti-aliased colour (client/truth/antialias.py, ``replay --truth-samples``)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from walkstream.client.truth.antialias import POINT, Sampling, check_sampling, parse_sampling
from walkstream.client.truth.render import TruthRenderer
from walkstream.shared.camera import look_at, orthographic
from walkstream.shared.errors import InputError
from walkstream.shared.records import Mesh

SIZE = (32, 24)
RADIUS = 12.0  # the orthographic view is 24 m high: one metre a pixel, 24 rows


def _quads(squares: list[tuple[float, float, float, int]]) -> Mesh:
    """Squares in the plane y = 0 facing -y (toward the camera): ``(x, z, side, material)``."""
    pos, idx, mat = [], [], []
    for x, z, s, m in squares:
        k = len(pos)
        pos += [(x, 0.0, z), (x + s, 0.0, z), (x + s, 0.0, z + s), (x, 0.0, z + s)]
        idx += [(k, k + 1, k + 2), (k, k + 2, k + 3)]
        mat += [m] * 4
    p = np.array(pos, np.float32)
    return Mesh(p, np.tile(np.float32([0.0, -1.0, 0.0]), (len(p), 1)), np.array(idx, np.uint32), np.array(mat, np.uint8))


def _camera() -> tuple[np.ndarray[Any, Any], np.ndarray[Any, Any], np.ndarray[Any, Any]]:
    """An orthographic camera 50 m in front of the plane, looking at (0, 0, 0): one metre a pixel."""
    eye = np.array([0.0, -50.0, 0.0])
    proj = orthographic(RADIUS, 1.0, 200.0)
    proj[0, 0] = 1.0 / (RADIUS * SIZE[0] / SIZE[1])  # 32 m across, 24 m high
    return eye, look_at(eye, (0.0, 0.0, 0.0)).astype(np.float64), proj


def test_parse_sampling() -> None:
    assert parse_sampling("1") == POINT
    assert parse_sampling("4") == parse_sampling("4x4") == Sampling(grid=4)
    assert parse_sampling("msaa4") == Sampling(msaa=4)
    assert str(Sampling(grid=2)) == "2x2" and str(Sampling(msaa=4)) == "msaa4" and str(POINT) == "1"
    for bad in ("0", "9", "2x3", "msaa1", "four", ""):
        with pytest.raises(InputError, match="--truth-samples"):
            parse_sampling(bad)


class _NoGL:
    """A context that fails if anything of it is read."""

    def __getattr__(self, name: str) -> Any:
        raise AssertionError(f"the GL was asked for {name}")


@pytest.mark.gl
def test_a_multisample_count_the_gl_lacks_is_refused_before_the_walk(gl: Any) -> None:
    most = int(gl.max_samples)
    check_sampling(Sampling(msaa=most), ctx=gl)
    with pytest.raises(InputError, match=rf"--picture-samples msaa{most * 2}: .*at most {most}"):
        check_sampling(Sampling(msaa=most * 2), "--picture-samples", ctx=gl)
    for other in (POINT, Sampling(grid=8)):  # nothing of the GL needed
        check_sampling(other, ctx=_NoGL())


@pytest.mark.gl
@pytest.mark.parametrize("sampling", [Sampling(grid=4), Sampling(msaa=4)], ids=str)
def test_a_flat_quad_is_the_same_inside_and_blends_at_its_edges(gl: Any, sampling: Sampling) -> None:
    # a 10.25 m square from x = -5: its right edge covers a quarter of the column [5, 6],
    # whose centre (5.5) is outside it
    mesh = _quads([(-5.0, -5.0, 10.25, 1)])
    eye, view, proj = _camera()
    with TruthRenderer({1: mesh}, SIZE, ctx=gl) as truth:
        ids, _ = truth.render(eye, view, proj=proj)
        point = truth.colour()
        ids_aa, _ = truth.render(eye, view, proj=proj, samples=sampling)
        smooth = truth.colour()
    assert np.array_equal(ids, ids_aa)  # the keys stay point-sampled
    inside = np.zeros(ids.shape, bool)
    inside[1:-1, 1:-1] = (ids[:-2, 1:-1] >= 0) & (ids[2:, 1:-1] >= 0) & (ids[1:-1, :-2] >= 0) & (ids[1:-1, 2:] >= 0) & (ids[1:-1, 1:-1] >= 0)
    assert inside.sum() >= 64
    assert np.array_equal(point[inside], smooth[inside])  # inside: the same colour, to the bit
    quad_rgb = point[inside][0].astype(float)
    sky = point[0, 0].astype(float)
    rows = np.flatnonzero(inside.any(axis=1))
    col = 16 + 5  # the column from x = 5 to 6
    assert np.all(ids[rows, col] < 0) and np.all(ids[rows, col - 1] >= 0)
    assert np.all(point[rows, col] == sky)  # one sample a pixel: all sky
    quarter = sky + 0.25 * (quad_rgb - sky)
    assert np.abs(smooth[rows, col] - quarter).max() <= 2.0  # a quarter covered: a quarter of the way


@pytest.mark.gl
@pytest.mark.parametrize("sampling", [Sampling(grid=4), Sampling(msaa=4)], ids=str)
def test_a_checkerboard_finer_than_a_pixel_resolves_to_its_mean(gl: Any, sampling: Sampling) -> None:
    # quarter-metre squares of two materials: 4 x 4 of them a pixel, half of each
    side, n = 0.25, 40
    squares = [(-5.0 + i * side, -5.0 + j * side, side, 1 if (i + j) % 2 else 2) for i in range(n) for j in range(n)]
    alone = {m: _quads([(-5.0, -5.0, 10.0, m)]) for m in (1, 2)}
    eye, view, proj = _camera()
    with TruthRenderer({1: _quads(squares), 2: alone[1], 3: alone[2]}, SIZE, ctx=gl) as truth:
        plain = []
        for oid in (2, 3):
            truth.render(eye, view, truth.flags([(-1 - oid, 0)]), proj=proj)
            plain.append(truth.colour()[12, 16].astype(float))
        ids, _ = truth.render(eye, view, truth.flags([(-2, 0)]), proj=proj)
        point = truth.colour()
        truth.render(eye, view, truth.flags([(-2, 0)]), proj=proj, samples=sampling)
        smooth = truth.colour()
    board = np.zeros(ids.shape, bool)
    board[8:16, 12:20] = True  # well inside the 10 m board
    assert np.all(ids[board] == 0)
    mean = (plain[0] + plain[1]) / 2.0
    assert np.abs(plain[0] - plain[1]).max() > 40  # two colours far apart
    assert np.abs(smooth[board] - mean).max() <= 3.0
    # one sample a pixel lands on one of the two colours, never their mean
    far = np.abs(point[board].astype(float) - mean).max(axis=1)
    assert far.min() > 15.0


@pytest.mark.gl
def test_quads_painted_over_an_anti_aliased_frame_go_into_its_target(gl: Any) -> None:
    mesh = _quads([(-5.0, -5.0, 10.5, 1)])
    eye, view, proj = _camera()
    with TruthRenderer({1: mesh}, SIZE, ctx=gl) as truth:
        truth.render(eye, view, proj=proj, samples=Sampling(grid=2))
        before = truth.colour()
        assert np.array_equal(truth.paint_quads([], view, proj), before)
        truth.render(eye, view, proj=proj)
        assert not np.array_equal(truth.colour(), before)  # point-sampled again
