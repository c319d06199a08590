"""Polygon budget control: how many triangles the next frame may draw.

Marvie et al. (section 4) compute the budget of the next frame from "an average frame
rate value estimated from the rendering time of some of the last computed frames and
the last polygon budgets used", with a history of the last four frames (section 5.3),
and treat the target as a *minimum* frame rate: asked for 25 fps they got 26.2 fps
with 56,194 polygons.  :class:`BudgetController` keeps that idea -- cost per triangle
from the last ``k`` frames, budget = what fits in the frame time -- and adds what a
bare ``cost = time / triangles`` lacks.

Definitions
-----------
``T = 1 / target_fps`` is the tick.  The frame loop ticks at the target rate and idles
when a frame finishes early, so a frame is *shown* for ``max(t, T)`` and its rate is
``1 / max(t, T)`` (:func:`~walkstream.client.report.metrics.displayed_fps`): never above the target, below it only when the
frame took longer than the tick.  The controller aims at ``T_aim = (1 - headroom) * T``
(headroom 5 %, like the paper's 26.2 fps for 25), a little under the tick, so that the
5 % frame-time jitter of a device rarely pushes a frame past ``T / 0.9`` (10 % too
slow): from the aim that takes a +3 sigma draw.

Why the fixed overhead matters
------------------------------
To first order a frame costs ``t = a + c * n``: a fixed per-frame overhead ``a``
(clear, swap, state changes, culling) plus ``c`` per triangle.  The paper's estimate
``c^ = t / n`` folds the overhead into the per-triangle cost.  Its fixed point is exact
(``t = T_aim``), but the budget approaches it geometrically with factor ``a / T_aim``
per frame: 0.59 on ``desktop2003`` at 25 fps, 0.94 at 40 fps, where 22.4 ms of the
23.75 ms aim is overhead -- after a cost change it would take tens of frames to
settle.  With an overhead estimate ``a^`` and ``c^ = (t - a^) / n`` the factor is
``(a - a^) / (T_aim - a^)``: 0 when ``a^ = a``, a smooth approach when ``a^ < a``, and
an *alternating* one (negative; unstable below -1) when ``a^ > a``.  So the controller
estimates ``a`` from below, never from above.

The algorithm, per observed frame
---------------------------------
1. **Validate.**  A frame time that is 0, negative, NaN or infinite, or a negative or
   non-finite triangle count, is ignored (counted in ``ignored``).  A frame more than
   1.5x slower than the current model predicts (and slower than the aim) is marked a
   suspected *spike* and left out of the estimates below -- unless step 2 fires.
2. **Regime change.**  When the last :data:`REGIME_FRAMES` (2) frames are both more
   than 15 % slower than ``T_aim`` -- or both under 70 % of it while drawing their
   whole budget -- the cost has changed: one spike cannot do that, two spikes in a
   row happen once in 10,000 frames and cost one cheap frame.  The history is cut to
   those two frames and the estimate follows them at once, unsmoothed.  After a
   tenfold cost step the budget is right again from the third frame on.
3. **Overhead** ``a^``.  Every :data:`FIT_EVERY` frames a Theil-Sen line
   ``t = a + c n`` (median of the pairwise slopes: robust to spikes) is fitted over
   up to the last :data:`FIT_WINDOW` (32) frames, when the triangle counts spread by
   at least 10 % (frames with no triangles are welcome: they measure ``a`` directly).
   Its intercept minus :data:`FIT_Z` (2) standard errors -- a lower confidence bound,
   with the noise scale from the residuals' MAD -- is kept when it is positive and at
   least as precise as the kept one (whose error is aged 1 % per frame, to at most
   3x, so that a newer fit can take over but a steady state without spread cannot
   replace a good fit by a vague one).  When the jitter hides the triangle cost the
   bound is low or negative, and the controller falls back towards the paper's
   estimate; the start-up ramp and every cost change give it the spread it needs.
   The overhead in use is also kept under 95 % of the fastest frame in the window.
   As a last guard, a budget that see-saws (:data:`ALTERNATION_FRAMES` steps of more
   than 15 %, alternating in sign) halves the overhead in use.
4. **Cost per triangle** from the last ``k`` frames (default 4, as in the paper): the
   *median* of the per-frame ``(t_i - a^) / n_i`` over the frames that drew
   triangles (``t_i - a^`` floored at 5 % of ``t_i``).  A median, not the paper's
   average, so that one spike moves it little.
5. **Budget** ``n = (T_aim - a^) / c^``; when settled (no regime change) the budget
   moves half the way there in log space, which filters the jitter that the
   overhead correction amplifies (by ``T_aim / (T_aim - a^)``) while the loop gain
   stays near 0.  It grows at most :data:`MAX_GROWTH` (2x) per frame -- an estimate
   from a tiny, overhead-dominated frame cannot launch it into a slow frame -- and
   may fall without limit, since slow frames are what must be avoided.  It is 0
   when the overhead alone exceeds ``T_aim`` (e.g. 1000 fps on ``desktop2003``), and
   always a finite ``int`` clamped to ``[min_budget, max_budget]``.
6. **No information.**  When none of the last ``k`` frames drew a triangle (nothing
   visible, or a budget of 0 and no LOD0 floor), the cost is unknown.  If the newest
   frame beat the aim, the budget probes upwards multiplicatively (2x, starting at
   :data:`PROBE_START` triangles) up to the budget the last cost estimate allows
   (the initial budget if there never was one); otherwise it holds.  A budget driven
   to zero climbs back, and a long look at an empty sky does not blow it up.

Noise or cost, on the fog's lever
---------------------------------
Indoors the budget sets the fog (:func:`~walkstream.client.walk.allocate.fog_for_budget`),
and a frame facing a wall draws ten triangles whatever its budget: its time above the
overhead is the device's jitter (2-15 ms on llvmpipe), and divided by ten triangles it
reads as a huge cost per triangle -- the budget, and with it the fog, collapsed to the
2 m clamp.  The city's triangle lever does not meet this, since its frames draw their
budget (ACH allocation fills it), and when one does not (everything at LOD2), the
regime test's ``n >= BUDGET_BOUND * b`` already keeps it from counting as "fast".
So a caller whose lever leaves frames under budget passes ``under_budget_is_noise``:
a frame that drew under :data:`BUDGET_BOUND` of its budget and was not more than
:data:`SLOW_RATIO` slower than the aim tells nothing about the triangles and is left
out of the cost, as a suspected spike is; with none of the last ``k`` frames telling,
the budget holds or probes upwards (step 6).  A real cost rise still shows: it makes
under-budget frames more than 15 % slow, and those count.

What remains: where the overhead is nearly the whole frame (``desktop2003`` at
40 fps: 1.35 ms of triangles under 1.2 ms of jitter), four frames cannot measure the
triangle cost well, and the budget wanders by some 15-25 % while the frame rate holds.

How well a run held its target is measured by :mod:`walkstream.client.report.metrics`
(the one definition of frame rate, "within 10 %" and recovery); the controller on its
own, on the device cost models, is benchmarked by :mod:`walkstream.benchmarks.controller`.
"""

from __future__ import annotations

import math
import statistics
from collections import deque

import numpy as np

from walkstream.shared.errors import InputError

__all__ = [
    "BudgetController",
    "FIT_WINDOW",
    "REGIME_FRAMES",
    "MAX_GROWTH",
    "PROBE_START",
]

#: Frames the overhead fit looks back over.
FIT_WINDOW = 32
#: The overhead is refitted every this many frames (the window moves slowly).
FIT_EVERY = 4
#: Fewest frames before the overhead is fitted.
FIT_MIN_FRAMES = 5
#: Triangle-count spread (max - min, relative to max) the fit needs.
FIT_SPREAD = 0.1
#: Standard errors the overhead estimate stays under the fitted intercept.
FIT_Z = 2.0
#: The standard error of the kept fit grows by this factor per frame, up to
#: ``SE_AGEING_MAX`` times its own, so that a newer, somewhat less certain fit can
#: replace an old one, but the noise of a steady state (no spread) never does.
SE_AGEING = 1.01
SE_AGEING_MAX = 3.0
#: The overhead used stays under this share of the fastest frame in the window.
MIN_TIME_TRUST = 0.95
#: Budget steps that, alternating in sign, reveal an overhead estimate that is too high.
ALTERNATION_FRAMES = 6
#: Smallest relative budget step counted as see-sawing.
ALTERNATION_STEP = 0.15
#: The per-frame time above the overhead is floored at this share of the frame time.
COST_FLOOR = 0.05
#: Consecutive frames that must agree before a regime change is believed.
REGIME_FRAMES = 2
#: A frame this much slower than the aim counts towards a regime change.
SLOW_RATIO = 1.15
#: A frame under this share of the aim, drawing its budget, counts towards one.
FAST_RATIO = 0.7
#: A frame this many times slower than the model predicts is a suspected spike.
OUTLIER_RATIO = 1.5
#: A frame that drew at least this share of its budget was budget-bound.
BUDGET_BOUND = 0.8
#: Share of the way (in log space) a settled budget moves towards the estimate per frame.
SMOOTHING = 0.5
#: Most the budget may grow from one frame to the next.
MAX_GROWTH = 2.0
#: Where an upward probe from (near) zero starts, triangles.
PROBE_START = 64



class BudgetController:
    """Triangle budget for the next frame, from the last frames' times and counts.

    See the module docstring for the algorithm and the reasoning.

    Parameters
    ----------
    target_fps : float
        The minimum frame rate to hold (> 0, finite).
    k : int
        Frames the per-triangle cost is estimated from (the paper uses 4).
    initial_budget : int
        Budget of the first frame (clamped into ``[min_budget, max_budget]``).  Low by
        default: a first frame that is too fast costs nothing, one too slow shows.
    min_budget, max_budget : int
        Bounds of the budget.  ``min_budget`` may be 0 (the allocation still draws
        every visible object's LOD0).
    headroom : float
        Aim this share under the tick: ``T_aim = (1 - headroom) / target_fps``.

    Raises
    ------
    InputError
        For a non-positive or non-finite target, ``k < 1``, bounds out of order, or a
        headroom outside ``[0, 0.5)``.
    """

    def __init__(
        self,
        target_fps: float,
        k: int = 4,
        initial_budget: int = 1_000,
        min_budget: int = 0,
        max_budget: int = 10_000_000,
        headroom: float = 0.05,
    ) -> None:
        if not (isinstance(target_fps, int | float) and math.isfinite(target_fps)):
            raise InputError(f"target fps must be a finite number, got {target_fps!r}")
        if target_fps <= 0:
            raise InputError(f"target fps must be > 0, got {target_fps}")
        if (
            isinstance(k, bool)
            or not isinstance(k, int | float)
            or not float(k).is_integer()
            or k < 1
        ):
            raise InputError(f"k (frames of history) must be an integer >= 1, got {k!r}")
        if min_budget < 0 or max_budget < min_budget:
            raise InputError(
                f"budget bounds must satisfy 0 <= min_budget <= max_budget, "
                f"got min_budget={min_budget}, max_budget={max_budget}"
            )
        if not (math.isfinite(headroom) and 0.0 <= headroom < 0.5):
            raise InputError(f"headroom must be in [0, 0.5), got {headroom}")
        self.target_fps = float(target_fps)
        self.k = int(k)
        self.min_budget = int(min_budget)
        self.max_budget = int(max_budget)
        self.headroom = float(headroom)
        #: Frame time aimed at, seconds.
        self.aim_s = (1.0 - self.headroom) / self.target_fps
        self.initial_budget = self._clamp(float(initial_budget))
        self._budget = self.initial_budget
        # (frame time s, triangles, budget the frame was given, isolated outlier?)
        self._hist: deque[tuple[float, int, int, bool]] = deque(maxlen=FIT_WINDOW)
        # The overhead fit's frames: cut only at the first regime change of a burst,
        # so that a run of changes (a slow recovery) can still be fitted.
        self._fit_hist: deque[tuple[float, int]] = deque(maxlen=FIT_WINDOW)
        self._frames = 0
        self._last_change = -(10**9)
        self._cost: float | None = None
        self._fit_overhead = 0.0
        self._fit_se = math.inf
        self._fit_se_aged = math.inf
        self._since_fit = FIT_EVERY
        self._recent_budgets: deque[int] = deque(maxlen=ALTERNATION_FRAMES + 1)
        self._overhead = 0.0
        #: Observations ignored as invalid.
        self.ignored = 0
        #: Regime changes detected (history cut to the newest frames).
        self.regime_changes = 0

    # -- public state --------------------------------------------------------------

    @property
    def budget(self) -> int:
        """Triangle budget for the next frame: a finite int in ``[min_budget, max_budget]``."""
        return self._budget

    @property
    def cost_per_triangle(self) -> float | None:
        """Current per-triangle cost estimate in seconds (None before any triangle was drawn)."""
        return self._cost

    @property
    def overhead_s(self) -> float:
        """Per-frame overhead in use, seconds (0 until the fit is trusted)."""
        return self._overhead

    def __repr__(self) -> str:
        return (
            f"BudgetController(target_fps={self.target_fps}, k={self.k}, budget={self._budget}, "
            f"overhead_s={self._overhead:.4g}, cost_per_triangle={self._cost!r})"
        )

    # -- update --------------------------------------------------------------------

    def observe(self, frame_time_s: float, triangles: int, *, under_budget_is_noise: bool = False) -> None:
        """Record one finished frame and set the budget of the next.

        Parameters
        ----------
        frame_time_s : float
            How long the frame took, seconds (> 0 and finite, else ignored).
        triangles : int
            Triangles it drew (>= 0 and finite, else ignored).  Call once per frame,
            after the frame drawn with the current :attr:`budget`.
        under_budget_is_noise : bool
            A frame under :data:`BUDGET_BOUND` of its budget and not slow tells nothing
            about the triangle cost (the fog's lever; see the module docstring).
        """
        try:
            t = float(frame_time_s)
            n_f = float(triangles)
        except (TypeError, ValueError):
            self.ignored += 1
            return
        if not (math.isfinite(t) and t > 0.0 and math.isfinite(n_f) and n_f >= 0.0):
            self.ignored += 1
            return
        n = round(n_f)
        # A frame far slower than the current model predicts is a suspected spike:
        # left out of the estimates.  Two in a row are a regime change instead.
        outlier = (
            self._cost is not None
            and t > self.aim_s
            and t > OUTLIER_RATIO * (self._overhead + self._cost * n)
        )
        noise = (under_budget_is_noise and n < BUDGET_BOUND * self._budget
                 and t <= self.aim_s * SLOW_RATIO)
        self._hist.append((t, n, self._budget, outlier or noise))
        if not outlier:
            self._fit_hist.append((t, n))
        self._frames += 1
        self._update()

    def _clamp(self, b: float) -> int:
        if not math.isfinite(b):
            b = float(self.max_budget) if b > 0 else float(self.min_budget)
        return int(min(max(math.floor(b), self.min_budget), self.max_budget))

    def _regime_change(self) -> bool:
        if len(self._hist) < REGIME_FRAMES:
            return False
        last = list(self._hist)[-REGIME_FRAMES:]
        slow = all(t > self.aim_s * SLOW_RATIO for t, _, _, _ in last)
        fast = all(
            t < self.aim_s * FAST_RATIO and n > 0 and n >= BUDGET_BOUND * b for t, n, b, _ in last
        )
        return slow or fast

    def _refit_overhead(self) -> None:
        """Fit ``t = a + c n`` and keep a lower confidence bound of ``a`` when it is useful."""
        self._fit_se_aged = min(self._fit_se_aged * SE_AGEING, SE_AGEING_MAX * self._fit_se)
        self._since_fit += 1
        if len(self._fit_hist) < FIT_MIN_FRAMES or self._since_fit < FIT_EVERY:
            return
        self._since_fit = 0
        arr = np.asarray(self._fit_hist, dtype=np.float64)
        t, n = arr[:, 0], arr[:, 1]
        n_max = float(n.max())
        if n_max <= 0 or float(n.max() - n.min()) < FIT_SPREAD * n_max:
            return
        # Theil-Sen: median of the pairwise slopes, robust to spikes.
        i, j = np.triu_indices(t.size, 1)
        dn = n[j] - n[i]
        use = dn != 0
        slopes = (t[j] - t[i])[use] / dn[use]
        slope = float(np.median(slopes))
        if not (math.isfinite(slope) and slope > 0):
            return
        resid = t - slope * n
        a_point = float(np.median(resid))
        sigma = 1.4826 * float(np.median(np.abs(resid - a_point)))
        sxx = float(np.sum((n - n.mean()) ** 2))
        se = sigma * math.sqrt(1.0 / t.size + float(n.mean()) ** 2 / sxx)
        a_low = a_point - FIT_Z * se
        if math.isfinite(a_low) and a_low > 0 and se <= self._fit_se_aged:
            self._fit_overhead = min(a_low, float(t.min()))
            self._fit_se = self._fit_se_aged = se

    def _alternating(self) -> bool:
        """Whether the budget has been see-sawing (the overhead estimate is too high)."""
        b = self._recent_budgets
        if len(b) < ALTERNATION_FRAMES + 1:
            return False
        logs = [math.log(max(x, 1)) for x in b]
        steps = [y - x for x, y in zip(logs, logs[1:], strict=False)]
        if any(abs(d) <= ALTERNATION_STEP for d in steps):
            return False
        return all(d0 * d1 < 0 for d0, d1 in zip(steps, steps[1:], strict=False))

    def _update(self) -> None:
        changed = self._regime_change()
        if changed:
            newest = list(self._hist)[-REGIME_FRAMES:]
            self._hist.clear()
            self._hist.extend(newest)
            self._since_fit = FIT_EVERY  # refit as soon as there are enough frames
            if self._frames - self._last_change > self.k + REGIME_FRAMES:
                self._fit_hist.clear()
                self._fit_hist.extend((t, n) for t, n, _, _ in newest)
            self._last_change = self._frames
            self.regime_changes += 1
        self._refit_overhead()
        hist = list(self._hist)
        t_min = min(t for t, _, _, _ in hist)
        if self._alternating():
            # An over-estimated overhead makes the loop gain negative: halve it, and
            # only a fit at least as precise as the last one may replace it.
            self._fit_overhead *= 0.5
            self._fit_se_aged = self._fit_se
            self._recent_budgets.clear()
        a = max(0.0, min(self._fit_overhead, MIN_TIME_TRUST * t_min))
        self._overhead = a
        aim = self.aim_s
        samples = []
        for t, n, _, outlier in hist[-self.k :]:
            if n <= 0 or (outlier and not changed):
                continue
            samples.append(max(t - a, COST_FLOOR * t) / n)
        current = float(self._budget)
        if samples:
            cost = float(statistics.median(samples))
            if not (math.isfinite(cost) and cost > 0):
                return  # cannot happen with t > 0 and n > 0; hold rather than guess
            self._cost = cost
            wanted = (aim - a) / cost if aim > a else 0.0
            if not changed and current >= PROBE_START and wanted > 0:
                # Settled: move part of the way (in log space).  The loop gain with a
                # good overhead estimate is ~0, so this only filters frame-time jitter.
                wanted = current * (wanted / current) ** SMOOTHING
            new = min(wanted, MAX_GROWTH * max(current, PROBE_START))
        else:
            # Nothing drawn in the last k frames: the cost per triangle is unknown.
            newest_t = hist[-1][0]
            if self._cost is not None:
                ceiling = (aim - a) / self._cost if aim > a else 0.0
            else:
                ceiling = float(self.initial_budget)
            ceiling = max(ceiling, float(PROBE_START))
            if newest_t < aim and current < ceiling:
                new = min(max(MAX_GROWTH * current, float(PROBE_START)), ceiling)
            else:
                new = current
        self._budget = self._clamp(new)
        self._recent_budgets.append(self._budget)











