"""Device cost models: the paper rows, extrapolation, cost_scale, noise statistics."""

from __future__ import annotations

import math

import numpy as np
import pytest

from walkstream.client.draw.devices import (
    DESKTOP2003_POINTS,
    DEVICES,
    MIN_FRAME_TIME_S,
    NOISE_SIGMA,
    PDA_TABLE,
    SPIKE_FACTOR,
    SPIKE_PROBABILITY,
    CostModelDevice,
    Device,
    GlDevice,
    make_device,
)
from walkstream.shared.errors import InputError


def test_pda_table_is_mulloni_table_1_without_fog() -> None:
    assert PDA_TABLE == ((188, 56.4), (532, 35.8), (766, 22.6), (1156, 19.4))


@pytest.mark.parametrize(("triangles", "fps"), PDA_TABLE)
def test_pda_reproduces_table_rows(triangles: int, fps: float) -> None:
    dev = make_device("pda", noise=False)
    assert 1.0 / dev.frame_time(triangles) == pytest.approx(fps, rel=1e-12)


def test_pda_interpolates_frame_time_linearly_between_rows() -> None:
    dev = make_device("pda", noise=False)
    for (n0, f0), (n1, f1) in zip(PDA_TABLE, PDA_TABLE[1:], strict=False):
        mid = (n0 + n1) / 2
        assert dev.frame_time(mid) == pytest.approx((1 / f0 + 1 / f1) / 2, rel=1e-12)


def test_pda_extrapolates_with_end_segments_and_stays_positive() -> None:
    dev = make_device("pda", noise=False)
    (n0, f0), (n1, f1) = PDA_TABLE[0], PDA_TABLE[1]
    slope_lo = (1 / f1 - 1 / f0) / (n1 - n0)
    assert dev.frame_time(0) == pytest.approx(1 / f0 - n0 * slope_lo, rel=1e-12)
    assert dev.frame_time(0) == pytest.approx(0.01215, abs=1e-4)
    (m0, g0), (m1, g1) = PDA_TABLE[-2], PDA_TABLE[-1]
    slope_hi = (1 / g1 - 1 / g0) / (m1 - m0)
    assert dev.frame_time(5_000) == pytest.approx(1 / g1 + (5_000 - m1) * slope_hi, rel=1e-12)
    # About 3,740 triangles give 10 fps.
    assert 1.0 / dev.frame_time(3_740) == pytest.approx(10.0, rel=0.01)
    for n in (-10, 0, 1, 10**9):
        t = dev.frame_time(n)
        assert math.isfinite(t) and t >= MIN_FRAME_TIME_S


def test_desktop2003_reproduces_figure_4_and_fit() -> None:
    dev = make_device("desktop2003", noise=False)
    for n, fps in DESKTOP2003_POINTS:
        assert 1.0 / dev.frame_time(n) == pytest.approx(fps, rel=1e-12)
    a = dev.frame_time(0)
    b = dev.frame_time(1_000_000) - dev.frame_time(999_999)
    assert a == pytest.approx(22.4e-3, abs=0.05e-3)
    assert b == pytest.approx(2.81e-7, rel=0.01)


@pytest.mark.parametrize("name", ["pda", "desktop2003"])
def test_cost_scale_multiplies_the_triangle_part_only(name: str) -> None:
    dev = make_device(name, noise=False)
    overhead = dev.frame_time(0)
    for n in (100, 1_000, 50_000):
        base = dev.frame_time(n)
        dev.cost_scale = 10.0
        assert dev.frame_time(n) == pytest.approx(overhead + 10.0 * (base - overhead), rel=1e-12)
        assert dev.frame_time(0) == pytest.approx(overhead, rel=1e-12)
        dev.cost_scale = 1.0


def test_object_cost_is_added_per_object_and_zero_by_default() -> None:
    dev = make_device("desktop2003", noise=False)
    assert isinstance(dev, CostModelDevice)
    assert dev.frame_time(1000, objects=50) == dev.frame_time(1000)
    dev.object_cost_s = 1e-5
    assert dev.frame_time(1000, objects=50) == pytest.approx(dev.frame_time(1000) + 5e-4)


@pytest.mark.parametrize("name", ["pda", "desktop2003"])
def test_noise_statistics(name: str) -> None:
    dev = make_device(name, seed=7)
    model = make_device(name, noise=False).frame_time(800)
    frames = 40_000
    times = np.empty(frames)
    spikes = np.empty(frames, dtype=bool)
    for i in range(frames):
        times[i] = dev.frame_time(800)
        spikes[i] = dev.last_spike
    log_ratio = np.log(times / model)
    jitter = log_ratio - np.where(spikes, math.log(SPIKE_FACTOR), 0.0)
    assert abs(float(jitter.mean())) < 0.002
    assert float(jitter.std()) == pytest.approx(NOISE_SIGMA, rel=0.03)
    assert float(spikes.mean()) == pytest.approx(SPIKE_PROBABILITY, abs=0.002)
    # Spikes really are 2x: their log ratio sits around log 2, the others around 0.
    assert float(np.median(log_ratio[spikes])) == pytest.approx(math.log(2.0), abs=0.02)
    assert float(np.abs(log_ratio[~spikes]).max()) < 6 * NOISE_SIGMA


def test_noise_is_deterministic_per_seed() -> None:
    def series(seed: int) -> list[float]:
        dev = make_device("pda", seed=seed)
        return [dev.frame_time(n) for n in range(0, 3000, 7)]

    assert series(3) == series(3)
    assert series(3) != series(4)


def test_noise_off_is_exact_and_never_spikes() -> None:
    dev = make_device("desktop2003", seed=1, noise=False)
    ts = {dev.frame_time(5_703) for _ in range(500)}
    assert len(ts) == 1 and not dev.last_spike
    assert ts.pop() == pytest.approx(1 / 41.7, rel=1e-12)


def test_gl_is_a_marker_whose_frame_time_raises() -> None:
    dev = make_device("gl")
    assert isinstance(dev, GlDevice)
    assert dev.name == "gl" and dev.simulated is False
    with pytest.raises(NotImplementedError, match="measured by the renderer"):
        dev.frame_time(100)


@pytest.mark.parametrize("name", DEVICES)
def test_every_device_satisfies_the_protocol(name: str) -> None:
    dev = make_device(name, seed=1)
    assert isinstance(dev, Device)
    assert dev.name == name
    assert dev.simulated is (name != "gl")
    dev.cost_scale = 2.5
    assert dev.cost_scale == 2.5


def test_unknown_device_names_the_known_ones() -> None:
    with pytest.raises(InputError) as err:
        make_device("nokia3310")
    msg = str(err.value)
    assert "nokia3310" in msg
    for name in DEVICES:
        assert name in msg


@pytest.mark.parametrize(
    ("knots_n", "knots_t"),
    [((0,), (0.01,)), ((0, 0), (0.01, 0.02)), ((10, 5), (0.01, 0.02)), ((0, 1), (0.01, -1.0))],
)
def test_bad_knots_are_input_errors(knots_n: tuple[int, ...], knots_t: tuple[float, ...]) -> None:
    with pytest.raises(InputError, match="custom"):
        CostModelDevice("custom", knots_n, knots_t)
