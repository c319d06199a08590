"""Per-frame log of a replay and the figures computed from it.

The replay's :class:`~walkstream.client.report.framelog.FrameLog` (one row per frame,
:mod:`walkstream.client.report.framelog`) is what the figures read.  :func:`summarise`
reduces the log to the headline figures of ``report.json``;
:func:`recovery_frames` measures how the frame rate recovers after a step in the cost
of drawing.  Everything here is a pure function of its arguments.

Definitions (all documented once here, used by the report and the benchmarks)
-----------------------------------------------------------------------------
perfect frame
    A frame whose cell is known (``cell >= 0``) and whose download quality and
    rewrite quality are both 100 % (>= ``1 - 1e-9``, so that a share computed as
    ``k / n`` with ``k == n`` always counts).
``perfect_frame_ratio``
    Share of the frames from the first perfect frame (included) to the end that are
    perfect; 0 when no frame is perfect.  The frames before the first perfect one are
    the start-up, which ``time_to_first_perfect_frame_s`` measures instead.
``time_to_first_perfect_frame_s``
    ``t`` of the first perfect frame minus the replay start (``t_start``, by default
    the ``t`` of the first frame); ``None`` when no frame is perfect.
``download_quality_mean`` / ``rewrite_quality_mean``
    Mean over all frames of the per-frame quality, as a **percentage 0-100**.
displayed frame rate
    ``1 / max(frame_time, 1 / fps_cap)``: a frame cannot be shown faster than the
    replay's tick (``--fps``), however little work it took (:func:`displayed_fps`).
``fps_within_10pct_ratio``
    Among the *counted* frames -- those starting at least ``warmup_s`` (1 s) after the
    replay start and not floor-limited -- the share whose displayed frame rate is
    within ``tolerance`` (10 %) of the target, or above the target only because there
    is nothing left to spend the budget on (everything visible is already at LOD2, or
    nothing is visible).  ``None`` when no frame is counted.
``floor_limited_ratio``
    Share of all frames whose LOD0s alone exceeded the budget.
slowdown
    ``max(0, (target - fps) / target)``: the relative frame-rate deficit of a frame
    (0.2 = 20 % slower than the target).
``link_utilisation``
    Bytes received over the bytes the link could have carried in the same time:
    ``bytes / (bandwidth / 8 * seconds)`` from the replay's start to its end
    (:func:`link_utilisation`).  Bounded by what the walk needs: a slow walk leaves a
    fast link idle.
``link_utilisation_busy``
    The same over only the intervals during which the client wanted something it
    did not hold (something asked for and not received, or waiting to be asked
    for): whether the requests kept the link busy when there was work for it.
recovery (after a cost step)
    Frames from the step until the first of ``hold`` (3) frames in a row whose
    displayed rate is within ``tolerance`` of the target (fewer where the series
    ends); floor-limited frames and frames named in ``ignore`` (a simulated device's
    own spikes) are left out of both the run and the slowdowns
    (:func:`recovery_frames`).  Every report and benchmark uses this one definition.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.client.report.framelog import FrameLog, displayed_fps
from walkstream.shared.arrays import Bool
from walkstream.shared.errors import InputError

__all__ = [
    "PERFECT_EPS",
    "Recovery",
    "first_perfect_index",
    "link_utilisation",
    "perfect_mask",
    "recovery_frames",
    "summarise",
    "within_target_mask",
    "within_ratio",
]


#: A quality counts as 100 % when it is at least ``1 - PERFECT_EPS``.
PERFECT_EPS = 1e-9

# --------------------------------------------------------------------------- definitions


def link_utilisation(
    bytes_log: tuple[ArrayLike, ArrayLike],
    bandwidth_bps: float,
    intervals: ArrayLike,
) -> float | None:
    """Bytes received over the bytes the link could have carried, within ``intervals``.

    Parameters
    ----------
    bytes_log : ((k,) float, (k,) float)
        Times and cumulative bytes received after each delivery (the link's log).
    bandwidth_bps : float
        The link's bandwidth, bits per second.
    intervals : (m, 2) float
        ``(start, end)`` times to count (bytes delivered within them, over their
        total length times the bandwidth); overlapping intervals are merged.

    Returns
    -------
    float or None
        0..1 (a little above 1 only through rounding at interval edges); None when the
        intervals are empty or the bandwidth is not positive.

    >>> link_utilisation(([1.0, 2.0, 3.0], [500, 1000, 1500]), 8000.0, [[0.0, 2.0]])
    0.5
    """
    t = np.asarray(bytes_log[0], dtype=np.float64).reshape(-1)
    b = np.asarray(bytes_log[1], dtype=np.float64).reshape(-1)
    iv = np.asarray(intervals, dtype=np.float64).reshape(-1, 2)
    if not (math.isfinite(bandwidth_bps) and bandwidth_bps > 0) or len(iv) == 0:
        return None
    iv = iv[np.argsort(iv[:, 0])]
    merged: list[list[float]] = []
    for lo, hi in iv.tolist():
        if hi <= lo:
            continue
        if merged and lo <= merged[-1][1]:
            merged[-1][1] = max(merged[-1][1], hi)
        else:
            merged.append([lo, hi])
    seconds = sum(hi - lo for lo, hi in merged)
    if seconds <= 0:
        return None
    inc = np.diff(b, prepend=0.0)  # bytes of each delivery
    got = 0.0
    for lo, hi in merged:
        sel = (t > lo) & (t <= hi)
        got += float(inc[sel].sum())
    return _f(got / (bandwidth_bps / 8.0 * seconds))


def perfect_mask(log: FrameLog) -> Bool:
    """(n,) bool: the frames that are perfect (cell known, both qualities 100 %)."""
    lim = 1.0 - PERFECT_EPS
    out: Bool = (log.cell >= 0) & (log.download_quality >= lim) & (log.rewrite_quality >= lim)
    return out


def first_perfect_index(log: FrameLog) -> int | None:
    """Index of the first perfect frame, ``None`` when there is none."""
    hits = np.flatnonzero(perfect_mask(log))
    return int(hits[0]) if hits.size else None


def within_target_mask(
    fps: ArrayLike,
    target: float,
    *,
    tolerance: float = 0.1,
    nothing_to_gain: ArrayLike | None = None,
) -> Bool:
    """(n,) bool: frames whose rate is within ``tolerance`` of ``target``.

    A frame above ``target + tolerance * target`` also counts where
    ``nothing_to_gain`` is true (everything visible already at LOD2, or nothing
    visible): a budget cannot be spent there, so running fast is no fault.
    """
    _check_target(target, tolerance)
    f = np.asarray(fps, dtype=np.float64)
    ok: Bool = np.abs(f - target) <= tolerance * target
    if nothing_to_gain is not None:
        ok = ok | ((f > target) & np.asarray(nothing_to_gain, dtype=np.bool_))
    return ok


def within_ratio(
    frame_times: ArrayLike,
    target: float,
    *,
    tolerance: float = 0.1,
    skip_s: float = 1.0,
    exclude: ArrayLike | None = None,
) -> float:
    """Share of a bare series of frames whose displayed rate is within ``tolerance`` of ``target``.

    For a frame loop that ticks at ``target`` (no :class:`FrameLog`): the rates are
    :func:`displayed_fps` with the target as the cap, the test is
    :func:`within_target_mask`, and frames that *start* before ``skip_s`` seconds of
    shown time (the start-up) or that ``exclude`` marks (e.g. floor-limited ones) are
    not counted.  NaN when no frame is counted.
    """
    fps = displayed_fps(frame_times, target)
    shown = np.where(fps > 0, 1.0 / np.maximum(fps, 1e-300), np.inf)
    start = np.concatenate([[0.0], np.cumsum(shown)[:-1]]) if fps.size else fps
    counted = start >= skip_s
    if exclude is not None:
        counted &= ~np.asarray(exclude, dtype=np.bool_)
    if not counted.any():
        return math.nan
    return float(np.mean(within_target_mask(fps[counted], target, tolerance=tolerance)))


def _check_target(target: float, tolerance: float) -> None:
    if not (math.isfinite(target) and target > 0.0):
        raise InputError(f"target frame rate must be a positive finite number, got {target!r}")
    if not (math.isfinite(tolerance) and tolerance >= 0.0):
        raise InputError(f"tolerance must be a finite number >= 0, got {tolerance!r}")


def _nothing_to_gain(log: FrameLog) -> Bool:
    out: Bool = log.all_lod2 | (log.visible == 0)
    return out


def _f(x: Any) -> float | None:
    """A finite Python float, or None (so that JSON never sees NaN or infinity)."""
    if x is None:
        return None
    v = float(x)
    return v if math.isfinite(v) else None


def _mean(a: NDArray[Any]) -> float | None:
    return _f(np.mean(a)) if a.size else None


# --------------------------------------------------------------------------- recovery


@dataclass(frozen=True, slots=True)
class Recovery:
    """How the frame rate came back after a cost step (see :func:`recovery_frames`).

    Attributes
    ----------
    frames : int or None
        Frames from the step (the first frame at the new cost is frame 0) to the first
        frame of ``hold`` consecutive frames within tolerance; 0 when the step frame
        itself starts such a run; ``None`` when the frame rate never recovers.
    worst_slowdown_during : float or None
        Largest slowdown (fraction, 0.2 = 20 % slower than target) from the step up
        to the recovery (excluded); ``None`` when ``frames`` is 0.
    worst_slowdown_after : float or None
        Largest slowdown from the recovery to the end of the window; ``None`` when
        the frame rate never recovers.
    """

    frames: int | None
    worst_slowdown_during: float | None
    worst_slowdown_after: float | None


def recovery_frames(
    log: FrameLog | ArrayLike,
    step: int,
    *,
    target: float,
    tolerance: float = 0.1,
    hold: int = 3,
    end: int | None = None,
    ignore: ArrayLike | None = None,
) -> Recovery:
    """Frames until the frame rate is back within ``tolerance`` of ``target`` after a cost step.

    Parameters
    ----------
    log : FrameLog or (n,) float array
        The frames; an array is taken as the displayed frame rates (then no frame
        counts as "nothing to gain").
    step : int
        Index of the first frame drawn at the new cost.
    target : float
        Target frame rate.
    tolerance : float
        Relative band around the target (0.1 = 10 %).
    hold : int
        "Back and staying": recovery is the first frame that starts ``hold``
        consecutive frames within tolerance (fewer when the window ends first, but
        at least one).
    end : int, optional
        One past the last frame of the window (default: the end of the log).
    ignore : (n,) bool, optional
        Frames to leave out of both the band test and the slowdowns (e.g. frames
        with a deliberate spike); they neither break nor make a run.  With a
        :class:`FrameLog`, floor-limited frames are always left out.

    Returns
    -------
    Recovery

    Raises
    ------
    InputError
        ``step`` or ``end`` is outside the log, ``hold`` < 1, or the target or
        tolerance is not usable.
    """
    _check_target(target, tolerance)
    if isinstance(log, FrameLog):
        fps = log.fps
        gain = _nothing_to_gain(log)
        skip = log.floor_limited.copy()
    else:
        fps = np.asarray(log, dtype=np.float64).reshape(-1)
        gain = np.zeros(fps.shape, np.bool_)
        skip = np.zeros(fps.shape, np.bool_)
    n = fps.shape[0]
    if ignore is not None:
        ig = np.asarray(ignore, dtype=np.bool_).reshape(-1)
        if ig.shape[0] != n:
            raise InputError(f"ignore has {ig.shape[0]} entries, expected {n} (one per frame)")
        skip = skip | ig
    stop = n if end is None else int(end)
    if not 0 <= stop <= n:
        raise InputError(f"end {end} is outside the log of {n} frames")
    if not 0 <= step < stop:
        raise InputError(f"step {step} is not a frame of the window [0, {stop})")
    if hold < 1:
        raise InputError(f"hold must be at least 1 frame, got {hold}")

    # Work on the window's kept frames only; positions map back to frame indices.
    idx = np.flatnonzero(~skip[step:stop]) + step
    if idx.size == 0:
        return Recovery(None, None, None)
    f = fps[idx]
    ok = within_target_mask(f, target, tolerance=tolerance, nothing_to_gain=gain[idx])
    slow = np.maximum(0.0, (target - f) / target)
    m = idx.size
    h = min(hold, m)
    # run[i]: ok[i : i + h] all true (windows running past the end are shortened).
    bad = np.concatenate([[0], np.cumsum(~ok)])  # bad[i]: frames not ok among the first i
    pos = np.arange(m)
    run = (bad[np.minimum(pos + h, m)] - bad[pos]) == 0
    starts = np.flatnonzero(run)
    if starts.size == 0:
        return Recovery(None, _f(slow.max()), None)
    k = int(starts[0])
    frames = int(idx[k] - step)
    during = _f(slow[:k].max()) if k > 0 else None
    return Recovery(frames, during, _f(slow[k:].max()))


# --------------------------------------------------------------------------- summary


def summarise(
    log: FrameLog,
    *,
    fps_target: float,
    fps_cap: float,
    bytes_received: int | None = None,
    t_start: float | None = None,
    warmup_s: float = 1.0,
    tolerance: float = 0.1,
    cost_step: int | None = None,
    recovery_hold: int = 3,
    recovery_ignore: ArrayLike | None = None,
    extra: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """The headline figures of a replay (the body of ``report.json``).

    Parameters
    ----------
    log : FrameLog
        The frames of the replay.
    fps_target : float
        Target (minimum) frame rate of the budget controller.
    fps_cap : float
        The replay's tick rate (``--fps``); recorded as ``fps_cap``.
    bytes_received : int, optional
        Bytes received over the link (from the link, not the log); recorded as is.
    t_start : float, optional
        Replay start on the log's clock; default the ``t`` of the first frame.
    warmup_s : float
        Frames starting earlier than this after ``t_start`` are not counted by
        ``fps_within_10pct_ratio`` (the controller has no history yet).
    tolerance : float
        Relative band of ``fps_within_10pct_ratio`` (the name keeps the default's 10 %).
    cost_step : int, optional
        Index of a frame where the cost of drawing stepped; adds ``cost_step_frame``,
        ``recovery_frames``, ``recovery_worst_slowdown_during`` and
        ``recovery_worst_slowdown_after`` (:func:`recovery_frames` with ``recovery_hold``).
    recovery_ignore : (n,) bool, optional
        Frames left out of the recovery figures besides the floor-limited ones (the
        simulated device's own spikes).
    extra : mapping, optional
        More keys for the summary (``prefetch``, ``stream``, ...); a key that this
        function computes itself is an error.

    Returns
    -------
    dict
        JSON-ready (Python ints, floats, bools, None; never NaN): ``frames``,
        ``duration_s``, ``t_start_s``, ``perfect_frames``, ``perfect_frame_ratio``,
        ``time_to_first_perfect_frame_s``, ``download_quality_mean``,
        ``rewrite_quality_mean`` (percent, 0-100), ``fps_mean``, ``fps_median``,
        ``fps_target``, ``fps_cap``, ``fps_counted_frames``, ``fps_within_10pct_ratio``,
        ``floor_limited_ratio``, ``budget_median``, ``budget_min``, ``budget_max``,
        ``triangles_mean``, ``visible_mean``, ``bytes_received``, plus the recovery keys
        and ``extra``.  Statistics of an empty log are ``None`` (``frames`` is 0 and
        ``perfect_frame_ratio`` 0).

    Raises
    ------
    InputError
        A target, cap or tolerance that is not usable, or an ``extra`` key that
        collides with a computed one.
    """
    _check_target(fps_target, tolerance)
    displayed_fps(np.empty(0), fps_cap)  # validates the cap
    n = len(log)
    t0 = float(log.t[0]) if (t_start is None and n) else float(t_start or 0.0)

    perfect = perfect_mask(log)
    first = first_perfect_index(log)
    counted = ((log.t - t0) >= warmup_s) & ~log.floor_limited
    ok = within_target_mask(
        log.fps, fps_target, tolerance=tolerance, nothing_to_gain=_nothing_to_gain(log)
    )
    duration = _f(log.t[-1] - t0 + max(float(log.frame_time[-1]), 1.0 / fps_cap)) if n else None

    out: dict[str, Any] = {
        "frames": n,
        "duration_s": duration,
        "t_start_s": t0 if n or t_start is not None else None,
        "perfect_frames": int(perfect.sum()),
        "perfect_frame_ratio": _f(perfect[first:].mean()) if first is not None else 0.0,
        "time_to_first_perfect_frame_s": (_f(log.t[first] - t0) if first is not None else None),
        "download_quality_mean": _f(100.0 * log.download_quality.mean()) if n else None,
        "rewrite_quality_mean": _f(100.0 * log.rewrite_quality.mean()) if n else None,
        "fps_mean": _mean(log.fps),
        "fps_median": _f(np.median(log.fps)) if n else None,
        "fps_target": float(fps_target),
        "fps_cap": float(fps_cap),
        "fps_counted_frames": int(counted.sum()),
        "fps_within_10pct_ratio": _mean(ok[counted]),
        "floor_limited_ratio": _mean(log.floor_limited),
        "budget_median": _f(np.median(log.budget)) if n else None,
        "budget_min": int(log.budget.min()) if n else None,
        "budget_max": int(log.budget.max()) if n else None,
        "triangles_mean": _mean(log.triangles),
        "visible_mean": _mean(log.visible),
        "bytes_received": None if bytes_received is None else int(bytes_received),
    }
    if cost_step is not None:
        rec = recovery_frames(
            log,
            cost_step,
            target=fps_target,
            tolerance=tolerance,
            hold=recovery_hold,
            ignore=recovery_ignore,
        )
        out["cost_step_frame"] = int(cost_step)
        out["recovery_frames"] = rec.frames
        out["recovery_worst_slowdown_during"] = rec.worst_slowdown_during
        out["recovery_worst_slowdown_after"] = rec.worst_slowdown_after
    if extra:
        clash = sorted(set(extra) & (set(out) - {"bytes_received"}))
        if "bytes_received" in extra and bytes_received is not None:
            clash.append("bytes_received")
        if clash:
            raise InputError(f"extra keys collide with computed summary keys: {clash}")
        out.update(extra)
    return out
