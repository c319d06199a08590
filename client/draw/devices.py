"""Device cost models: how long a frame takes on a device we do not have.

A *device* answers one question for the replay: how many seconds did the frame that
drew ``triangles`` triangles (in ``objects`` draw calls) take?  ``gl`` really draws and
the renderer times it; the other two are cost models fitted to the papers behind
issue 6, so the whole client (streaming, allocation, budget control, reports) can run
on a machine without a GPU and still see a plausible, reproducible frame-time series.

``pda``
    Mulloni et al., Table 1 ("without fog" column): a PDA drawing 1 to 4 visible
    cells of a university building.  Frame time ``1 / fps`` is interpolated piecewise
    linearly over the triangle count through the four rows

    ======  =========  ========  ==============
    cells   triangles  fps       frame time ms
    ======  =========  ========  ==============
    1       188        56.4      17.73
    2       532        35.8      27.93
    3       766        22.6      44.25
    4       1156       19.4      51.55
    ======  =========  ========  ==============

    and extrapolated linearly beyond them with the slope of the nearest segment:
    below 188 triangles with the first segment's slope (0 triangles -> 12.15 ms,
    the zero-triangle *overhead* of this model), above 1,156 with the last one's
    (0.0187 ms per triangle, so 10 fps is reached at about 3,740 triangles).  The
    result is kept at or above :data:`MIN_FRAME_TIME_S` so it never reaches zero.

``desktop2003``
    Marvie et al., Figure 4: a 2003 desktop (Pentium XEON 1.7 GHz, Quadro2 Pro) drew
    56,194 polygons at 26.2 fps and 5,703 polygons at 41.7 fps.  The affine frame time
    ``a + b * triangles`` through those two points has ``a = 22.38 ms`` of fixed
    per-frame overhead and ``b = 2.81e-7 s`` (0.281 microseconds) per triangle.  The
    overhead dominates: at 40 fps only about 1.4 ms of the 25 ms frame is triangles.

Both simulated devices multiply the model time by noise drawn from a seeded
:class:`numpy.random.Generator` (same seed, same series):

- lognormal jitter ``exp(N(0, 0.05))`` -- 5 % of the log, mean log 0, and
- a *spike*: with probability :data:`SPIKE_PROBABILITY` (1 %) a frame takes
  :data:`SPIKE_FACTOR` (2x) as long, like a garbage collection or a driver stall.
  Spikes are independent per frame, so two in a row happen about once in 10,000
  frames.  ``last_spike`` tells whether the latest frame was one (simulations use it
  to leave the device's own stalls out of controller figures).

``cost_scale`` (default 1.0, settable) multiplies the **triangle-dependent part** of
the frame time and nothing else: ``t(n) = t(0) + cost_scale * (t_model(n) - t(0))``,
where ``t(0)`` is the model's zero-triangle overhead (12.15 ms for ``pda``, 22.38 ms
for ``desktop2003``).  Setting it to 10 is the issue's "tenfold cost step": every
triangle suddenly costs ten times as much while the fixed overhead stays.  The
per-object cost ``object_cost_s`` (default 0: neither paper gives one) is added per
drawn object and is not scaled.
"""

from __future__ import annotations

import math
from typing import Protocol, runtime_checkable

import numpy as np

from walkstream.shared.errors import InputError

__all__ = [
    "DEVICES",
    "Device",
    "GlDevice",
    "CostModelDevice",
    "make_device",
    "PDA_TABLE",
    "DESKTOP2003_POINTS",
    "NOISE_SIGMA",
    "SPIKE_PROBABILITY",
    "SPIKE_FACTOR",
    "MIN_FRAME_TIME_S",
]

#: The device names ``make_device`` knows, the real one first.
DEVICES: tuple[str, ...] = ("gl", "desktop2003", "pda")

#: Mulloni et al. Table 1, without fog: (triangles, frames per second).
PDA_TABLE: tuple[tuple[int, float], ...] = ((188, 56.4), (532, 35.8), (766, 22.6), (1156, 19.4))

#: Marvie et al. Figure 4: (polygons, frames per second) at targets 25 and 40 fps.
DESKTOP2003_POINTS: tuple[tuple[int, float], ...] = ((56_194, 26.2), (5_703, 41.7))

#: Standard deviation of the log of the multiplicative frame-time jitter.
NOISE_SIGMA = 0.05
#: Chance that a frame is a spike.
SPIKE_PROBABILITY = 0.01
#: How much longer a spike frame takes.
SPIKE_FACTOR = 2.0
#: No modelled frame is faster than this (1 microsecond): keeps 1/t finite.
MIN_FRAME_TIME_S = 1e-6


@runtime_checkable
class Device(Protocol):
    """What the replay needs from a device.

    Attributes
    ----------
    name : str
        One of :data:`DEVICES`.
    simulated : bool
        True when :meth:`frame_time` gives the frame time; False for ``gl``, whose
        frames are drawn and timed by the renderer.
    cost_scale : float
        Multiplies the per-triangle part of the frame time (see the module docstring).
    last_spike : bool
        Whether the latest simulated frame was a 2x spike (always False for ``gl``).
    """

    name: str
    simulated: bool
    cost_scale: float
    last_spike: bool

    def frame_time(self, triangles: int, objects: int = 0) -> float:
        """Seconds the frame takes to draw ``triangles`` triangles in ``objects`` draws."""
        ...


class GlDevice:
    """Marker for the real renderer: frame times are measured, not modelled.

    ``frame_time`` raises, because asking a cost model for a real GPU's time is a bug
    in the caller (check ``simulated`` first).
    """

    def __init__(self) -> None:
        self.name = "gl"
        self.simulated = False
        self.cost_scale = 1.0
        self.last_spike = False

    def frame_time(self, triangles: int, objects: int = 0) -> float:
        """Always raises: the ``gl`` device's frame times come from the renderer."""
        raise NotImplementedError(
            "device 'gl' has no cost model: its frame times are measured by the renderer"
        )

    def __repr__(self) -> str:
        return "GlDevice()"


class CostModelDevice:
    """A simulated device: model frame time times seeded noise.

    Parameters
    ----------
    name : str
        Reported name.
    knots_n, knots_t : sequence of float
        Triangle counts (strictly increasing, at least two) and frame times in seconds
        of a piecewise-linear model; extrapolated linearly with the end segments.
        Two knots make an affine model.
    seed : int
        Seed of the noise generator.
    noise : bool
        False turns jitter and spikes off (the model exactly).
    """

    def __init__(
        self,
        name: str,
        knots_n: list[float] | tuple[float, ...],
        knots_t: list[float] | tuple[float, ...],
        seed: int = 0,
        noise: bool = True,
    ) -> None:
        n = np.asarray(knots_n, dtype=np.float64)
        t = np.asarray(knots_t, dtype=np.float64)
        if n.ndim != 1 or n.shape != t.shape or n.size < 2 or np.any(np.diff(n) <= 0):
            raise InputError(
                f"device {name!r}: knots need >= 2 strictly increasing triangle counts "
                f"with one frame time each, got {n.tolist()} / {t.tolist()}"
            )
        if not np.all(np.isfinite(t)) or np.any(t <= 0):
            raise InputError(f"device {name!r}: knot frame times must be > 0, got {t.tolist()}")
        self.name = name
        self.simulated = True
        self.cost_scale = 1.0
        self.object_cost_s = 0.0
        self.noise = bool(noise)
        self.last_spike = False
        self._n = n
        self._t = t
        self._rng = np.random.default_rng(seed)
        # Zero-triangle overhead: the first segment extrapolated to 0 triangles.
        self.overhead_s = max(self._model(0.0), MIN_FRAME_TIME_S)

    def _model(self, n: float) -> float:
        """Noise-free model time at ``n`` triangles (no cost_scale, no floor)."""
        kn, kt = self._n, self._t
        if n <= kn[0]:
            i = 0
        elif n >= kn[-1]:
            i = kn.size - 2
        else:
            i = int(np.searchsorted(kn, n, side="right")) - 1
        slope = (kt[i + 1] - kt[i]) / (kn[i + 1] - kn[i])
        return float(kt[i] + slope * (n - kn[i]))

    def model_time(self, triangles: float, objects: int = 0) -> float:
        """Noise-free frame time in seconds, with ``cost_scale`` and the per-object cost.

        Parameters
        ----------
        triangles : float
            Triangles drawn (negative counts as 0).
        objects : int
            Draw calls (objects) in the frame.

        Returns
        -------
        float
            Seconds, at least :data:`MIN_FRAME_TIME_S`.
        """
        n = max(float(triangles), 0.0) if math.isfinite(triangles) else 0.0
        base = self.overhead_s + self.cost_scale * (self._model(n) - self.overhead_s)
        base += self.object_cost_s * max(int(objects), 0)
        return max(base, MIN_FRAME_TIME_S)

    def frame_time(self, triangles: int, objects: int = 0) -> float:
        """One frame's time in seconds: model time times jitter, sometimes a 2x spike.

        Parameters
        ----------
        triangles : int
            Triangles drawn.
        objects : int
            Objects (draw calls) drawn; costs ``object_cost_s`` each (0 by default).

        Returns
        -------
        float
            Seconds (> 0, finite).  Draws two numbers from the generator per call when
            noise is on, so a series is reproducible from the seed.
        """
        t = self.model_time(triangles, objects)
        if not self.noise:
            self.last_spike = False
            return t
        jitter = float(np.exp(self._rng.normal(0.0, NOISE_SIGMA)))
        self.last_spike = bool(self._rng.random() < SPIKE_PROBABILITY)
        return t * jitter * (SPIKE_FACTOR if self.last_spike else 1.0)

    def __repr__(self) -> str:
        return f"CostModelDevice({self.name!r}, noise={self.noise}, cost_scale={self.cost_scale})"


def make_device(name: str, seed: int = 0, noise: bool = True) -> Device:
    """The device called ``name``.

    Parameters
    ----------
    name : str
        One of :data:`DEVICES`: ``"gl"`` (real, measured), ``"desktop2003"``, ``"pda"``.
    seed : int
        Noise seed of a simulated device (ignored for ``gl``).
    noise : bool
        False: a simulated device returns its model time exactly.

    Returns
    -------
    Device

    Raises
    ------
    InputError
        For an unknown name; the message lists the known ones.
    """
    if name == "gl":
        return GlDevice()
    if name == "pda":
        return CostModelDevice(
            "pda", [n for n, _ in PDA_TABLE], [1.0 / f for _, f in PDA_TABLE], seed, noise
        )
    if name == "desktop2003":
        pts = sorted(DESKTOP2003_POINTS)
        return CostModelDevice(
            "desktop2003", [n for n, _ in pts], [1.0 / f for _, f in pts], seed, noise
        )
    raise InputError(f"unknown device {name!r}; known devices: {', '.join(DEVICES)}")
