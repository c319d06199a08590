"""Tests of walkstream.client.report.metrics: the frame log and every figure computed from it."""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np
import pytest

from walkstream.client.report.framelog import FrameLog, FrameLogBuilder, displayed_fps
from walkstream.client.report.metrics import (
    Recovery,
    first_perfect_index,
    perfect_mask,
    recovery_frames,
    summarise,
    within_target_mask,
)
from walkstream.shared.errors import InputError


def make_log(n: int | None = None, *, fps_cap: float = 25.0, **cols: Any) -> FrameLog:
    """A hand-made log: frames 0.04 s apart and full quality unless given."""
    if n is None:
        n = len(next(iter(cols.values())))
    cols.setdefault("t", np.arange(n) * 0.04)
    cols.setdefault("frame_time", np.full(n, 0.04))
    cols.setdefault("download_quality", np.ones(n))
    cols.setdefault("rewrite_quality", np.ones(n))
    cols.setdefault("cell", np.zeros(n, np.int64))
    cols.setdefault("visible", np.full(n, 10))
    return FrameLog.from_columns(fps_cap=fps_cap, **cols)


def strict_json(d: dict[str, Any]) -> dict[str, Any]:
    out: dict[str, Any] = json.loads(json.dumps(d, allow_nan=False))
    return out


# --------------------------------------------------------------------------- log


def test_displayed_fps_is_capped_by_the_tick() -> None:
    fps = displayed_fps([0.001, 0.04, 0.1, 0.0, -1.0], 25.0)
    np.testing.assert_allclose(fps, [25.0, 25.0, 10.0, 25.0, 25.0])
    np.testing.assert_allclose(displayed_fps([0.001], 1000.0), [1000.0])


@pytest.mark.parametrize("cap", [0.0, -5.0, math.inf, math.nan])
def test_displayed_fps_rejects_a_bad_cap(cap: float) -> None:
    with pytest.raises(InputError, match="fps_cap"):
        displayed_fps([0.04], cap)
    with pytest.raises(InputError, match="fps_cap"):
        FrameLogBuilder(cap)


def test_builder_takes_20000_rows_and_computes_fps() -> None:
    b = FrameLogBuilder(fps_cap=40.0)
    for i in range(20_000):
        b.append(
            t=i * 0.025,
            frame_time=0.05 if i % 2 else 0.01,
            download_quality=1.0,
            rewrite_quality=0.5,
            bytes_down=10 * i,
            cell=i // 100,
            pvs=30,
            budget=1000 + i,
            triangles=900,
            visible=12,
            floor_limited=i % 7 == 0,
            all_lod2=i % 3 == 0,
        )
    assert len(b) == 20_000
    log = b.build()
    assert len(log) == 20_000
    assert log.fps[0] == 40.0 and log.fps[1] == pytest.approx(20.0)
    assert log.cell.dtype == np.int64 and log.floor_limited.dtype == np.bool_
    assert log.bytes_down[-1] == 199_990
    assert int(log.floor_limited.sum()) == len(range(0, 20_000, 7))
    # Read-only columns: the log cannot be changed behind a summary's back.
    with pytest.raises(ValueError):
        log.t[0] = 5.0
    # The builder stays usable after build().
    b.append(t=500.0, frame_time=0.01, download_quality=1.0, rewrite_quality=1.0)
    assert len(b.build()) == 20_001 and len(log) == 20_000


def test_builder_defaults_and_unknown_keys() -> None:
    b = FrameLogBuilder(25.0)
    b.append(t=0.0, frame_time=0.04, download_quality=0.0, rewrite_quality=0.0)
    log = b.build()
    assert log.cell[0] == -1 and log.budget[0] == 0 and not log.all_lod2[0]
    assert log.fps[0] == 25.0 and b.build(fps_cap=10.0).fps[0] == 10.0
    with pytest.raises(TypeError):
        b.append(t=0.0, frame_time=0.04, download_quality=0.0, rewrite_quality=0.0, colour=1)  # type: ignore[call-arg]


def test_builder_takes_the_cap_at_build_time() -> None:
    b = FrameLogBuilder()
    b.append(t=0.0, frame_time=0.001, download_quality=1.0, rewrite_quality=1.0)
    with pytest.raises(InputError, match="fps_cap"):
        b.build()
    assert b.build(fps_cap=40.0).fps[0] == 40.0


def test_framelog_checks_column_lengths_and_shapes() -> None:
    good = make_log(3).columns()
    with pytest.raises(InputError, match="'pvs' has 2 rows"):
        FrameLog(**{**good, "pvs": np.zeros(2)})
    with pytest.raises(InputError, match="1-D"):
        FrameLog(**{**good, "t": np.zeros((3, 1))})
    assert len(FrameLog.empty()) == 0


# --------------------------------------------------------------------------- perfect frames


def test_perfect_ratio_counts_from_the_first_perfect_frame() -> None:
    log = make_log(
        t=[10.0, 10.5, 11.0, 11.5, 12.0, 12.5],
        download_quality=[0.0, 0.5, 1.0, 1.0, 0.9, 1.0],
        rewrite_quality=[0.0, 0.5, 1.0, 0.8, 1.0, 1.0],
    )
    assert perfect_mask(log).tolist() == [False, False, True, False, False, True]
    assert first_perfect_index(log) == 2
    s = summarise(log, fps_target=25, fps_cap=25)
    assert s["perfect_frame_ratio"] == pytest.approx(2 / 4)  # frames 2..5, two perfect
    assert s["perfect_frames"] == 2
    assert s["time_to_first_perfect_frame_s"] == pytest.approx(1.0)  # from t of frame 0
    s = summarise(log, fps_target=25, fps_cap=25, t_start=9.0)
    assert s["time_to_first_perfect_frame_s"] == pytest.approx(2.0)


def test_share_computed_as_k_over_n_counts_as_perfect() -> None:
    q = 7 / 7 * (1 - 1e-12)
    log = make_log(download_quality=[q, q], rewrite_quality=[1.0, 1.0])
    assert perfect_mask(log).all()


def test_a_frame_without_a_known_cell_is_not_perfect() -> None:
    log = make_log(cell=[-1, -1, 3])
    assert first_perfect_index(log) == 2


def test_no_perfect_frame_gives_zero_and_none() -> None:
    log = make_log(download_quality=[1.0, 1.0, 1.0], rewrite_quality=[0.0, 0.99, 0.5])
    s = summarise(log, fps_target=25, fps_cap=25)
    assert s["perfect_frame_ratio"] == 0.0
    assert s["time_to_first_perfect_frame_s"] is None
    assert s["perfect_frames"] == 0


def test_quality_means_are_percentages() -> None:
    log = make_log(download_quality=[0.0, 1.0, 0.5, 0.5], rewrite_quality=[0.0, 0.0, 0.2, 0.2])
    s = summarise(log, fps_target=25, fps_cap=25)
    assert s["download_quality_mean"] == pytest.approx(50.0)
    assert s["rewrite_quality_mean"] == pytest.approx(10.0)


# --------------------------------------------------------------------------- frame rate


def test_within_10pct_skips_first_second_and_floor_limited_and_accepts_lod2_surplus() -> None:
    target = 25.0
    # Frame times giving these displayed rates with a 100 fps tick.
    fps = np.array([5.0, 5.0, 25.0, 22.6, 22.4, 27.4, 27.6, 40.0, 40.0, 40.0, 10.0, 24.0])
    t = np.array([0.0, 0.9, 1.0, 1.1, 1.2, 1.3, 1.4, 1.5, 1.6, 1.7, 1.8, 1.9])
    lod2 = np.array([0, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0], bool)
    visible = np.array([9, 9, 9, 9, 9, 9, 9, 9, 9, 0, 9, 9])
    floor = np.array([0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1, 1], bool)
    log = make_log(
        fps_cap=100.0,
        t=t,
        frame_time=1.0 / fps,
        all_lod2=lod2,
        visible=visible,
        floor_limited=floor,
    )
    np.testing.assert_allclose(log.fps, fps)
    s = summarise(log, fps_target=target, fps_cap=100.0)
    # Counted: frames 2..9 (t >= 1 s, not floor-limited) = 8 frames.
    # ok: 25 (in), 22.6 (in), 22.4 (out), 27.4 (in), 27.6 (out: fast but not all LOD2),
    # 40 with all LOD2 (in), 40 not LOD2 (out), 40 with nothing visible (in) -> 5 of 8.
    assert s["fps_counted_frames"] == 8
    assert s["fps_within_10pct_ratio"] == pytest.approx(5 / 8)
    assert s["floor_limited_ratio"] == pytest.approx(2 / 12)
    assert s["fps_mean"] == pytest.approx(fps.mean())
    assert s["fps_target"] == 25.0 and s["fps_cap"] == 100.0


def test_within_target_mask_band_is_symmetric() -> None:
    m = within_target_mask([9.0, 11.0, 8.9, 11.1, 20.0], 10.0, nothing_to_gain=[1, 1, 1, 0, 1])
    assert m.tolist() == [True, True, False, False, True]
    with pytest.raises(InputError, match="target"):
        within_target_mask([1.0], 0.0)


def test_all_floor_limited_gives_none_not_nan() -> None:
    log = make_log(t=[0.0, 1.0, 2.0, 3.0], floor_limited=[True] * 4)
    s = summarise(log, fps_target=25, fps_cap=25)
    assert s["fps_within_10pct_ratio"] is None
    assert s["fps_counted_frames"] == 0
    assert s["floor_limited_ratio"] == 1.0
    strict_json(s)


def test_a_log_shorter_than_the_warmup_counts_nothing() -> None:
    s = summarise(make_log(10), fps_target=25, fps_cap=25)  # 0.36 s of frames
    assert s["fps_within_10pct_ratio"] is None


def test_budget_statistics() -> None:
    log = make_log(budget=[100, 300, 200, 0], triangles=[90, 280, 200, 10])
    s = summarise(log, fps_target=25, fps_cap=25)
    assert s["budget_median"] == 150.0
    assert s["budget_min"] == 0 and s["budget_max"] == 300
    assert s["triangles_mean"] == pytest.approx(145.0)
    assert isinstance(s["budget_min"], int)


# --------------------------------------------------------------------------- summary edge cases


def test_empty_log_gives_numbers_or_none() -> None:
    s = summarise(FrameLog.empty(), fps_target=25, fps_cap=25, bytes_received=0)
    assert s["frames"] == 0
    assert s["perfect_frame_ratio"] == 0.0
    for key in (
        "time_to_first_perfect_frame_s",
        "download_quality_mean",
        "rewrite_quality_mean",
        "fps_mean",
        "fps_within_10pct_ratio",
        "floor_limited_ratio",
        "budget_median",
        "budget_min",
        "budget_max",
        "triangles_mean",
        "duration_s",
    ):
        assert s[key] is None, key
    assert strict_json(s) == s


def test_nan_frame_time_never_reaches_json() -> None:
    log = make_log(frame_time=[0.04, math.nan, 0.04])
    s = summarise(log, fps_target=25, fps_cap=25)
    assert s["fps_mean"] is None
    strict_json(s)


def test_summary_values_are_python_types_and_extra_keys_merge() -> None:
    log = make_log(50)
    s = summarise(
        log,
        fps_target=25,
        fps_cap=25,
        bytes_received=np.int64(1234),  # type: ignore[arg-type]
        extra={"prefetch": True, "stream": "params", "rtt_s": 0.2},
    )
    assert s["bytes_received"] == 1234 and type(s["bytes_received"]) is int
    assert s["prefetch"] is True and s["stream"] == "params"
    assert s["duration_s"] == pytest.approx(50 * 0.04)
    for v in s.values():
        assert v is None or type(v) in (int, float, bool, str), v
    with pytest.raises(InputError, match="perfect_frame_ratio"):
        summarise(log, fps_target=25, fps_cap=25, extra={"perfect_frame_ratio": 1.0})


def test_summarise_rejects_bad_targets() -> None:
    with pytest.raises(InputError, match="target"):
        summarise(make_log(3), fps_target=-1, fps_cap=25)
    with pytest.raises(InputError, match="fps_cap"):
        summarise(make_log(3), fps_target=25, fps_cap=0)


# --------------------------------------------------------------------------- recovery


def test_recovery_counts_frames_until_back_and_staying() -> None:
    before = [25.0] * 10
    after = [5.0, 10.0, 20.0, 23.0, 25.0, 25.0, 25.0, 25.0, 25.0, 20.0, 25.0]
    rec = recovery_frames(np.array(before + after), 10, target=25.0, hold=5)
    assert rec == Recovery(3, pytest.approx(0.8), pytest.approx(0.2))


def test_recovery_needs_the_rate_to_stay_in_the_band() -> None:
    fps = [23.0, 10.0, 25.0, 25.0, 25.0, 25.0, 25.0]
    assert recovery_frames(fps, 0, target=25.0, hold=5).frames == 2
    assert recovery_frames(fps, 0, target=25.0, hold=1).frames == 0
    assert recovery_frames(fps, 0, target=25.0, hold=1).worst_slowdown_during is None


def test_recovery_that_never_happens() -> None:
    rec = recovery_frames([25.0, 5.0, 6.0, 7.0], 1, target=25.0)
    assert rec.frames is None and rec.worst_slowdown_after is None
    assert rec.worst_slowdown_during == pytest.approx(0.8)


def test_recovery_leaves_out_ignored_and_floor_limited_frames() -> None:
    fps = np.array([5.0, 25.0, 25.0, 2.0, 25.0, 25.0, 25.0])
    spike = np.array([0, 0, 0, 1, 0, 0, 0], bool)
    assert recovery_frames(fps, 0, target=25.0, hold=3).frames == 4
    assert recovery_frames(fps, 0, target=25.0, hold=3, ignore=spike).frames == 1
    log = make_log(fps_cap=100.0, frame_time=1.0 / fps, floor_limited=spike)
    rec = recovery_frames(log, 0, target=25.0, hold=3)
    assert rec.frames == 1 and rec.worst_slowdown_after == pytest.approx(0.0)


def test_recovery_rejects_bad_arguments() -> None:
    with pytest.raises(InputError, match="step"):
        recovery_frames([25.0, 25.0], 2, target=25.0)
    with pytest.raises(InputError, match="hold"):
        recovery_frames([25.0, 25.0], 0, target=25.0, hold=0)
    with pytest.raises(InputError, match="ignore"):
        recovery_frames([25.0, 25.0], 0, target=25.0, ignore=[True])


def test_summarise_adds_recovery_keys_for_a_cost_step() -> None:
    fps = np.array([25.0] * 30 + [2.5, 5.0, 12.0, 24.0] + [25.0] * 30)
    log = make_log(fps_cap=25.0, frame_time=1.0 / fps)
    s = summarise(log, fps_target=25, fps_cap=25, cost_step=30)
    assert s["cost_step_frame"] == 30
    assert s["recovery_frames"] == 3
    assert s["recovery_worst_slowdown_during"] == pytest.approx(0.9)
    assert s["recovery_worst_slowdown_after"] == pytest.approx(0.04)
    strict_json(s)
