"""Which far buildings a frame draws as impostors, how opaque, and which images fit the texture budget.

Pure numpy over the rows of the current cell's record
(:class:`~walkstream.shared.impostorwire.ImpostorRow`, with the bake's distance ``D`` and
error bound ``A`` of :class:`~walkstream.shared.impostorwire.CellImpostors`); the frame step
that calls it, wants the images and makes the quads is
:mod:`walkstream.client.walk.impostors`, the draw :mod:`walkstream.client.draw.quads`.

- **The image**: the bin of the viewer's direction from the building's centre at the
  row's level (:func:`~walkstream.shared.impostors.bin_of`); a bin the cell lists no
  image for means geometry.
- **The blend** (:func:`impostor_alpha`): the impostor's opacity is 0 (geometry only)
  at the distance ``D`` from the building's box and below, rises smoothly to 1
  (impostor only) at ``D + blend_m``, and falls back to 0 as the angular error
  (:func:`~walkstream.shared.impostors.angular_error` of the image's direction against
  the viewer's) climbs over the last quarter of ``A`` to ``A``; in between both are
  drawn, the impostor over the geometry, so nothing pops at either end.  The blend's
  length scales with ``D`` (:func:`blend_length`, :data:`BLEND_SHARE` of it): a
  building at distance ``D`` moves across the screen at a rate proportional to the
  walker's speed over ``D``, and the blend changes its pixels at the speed over the
  blend's length, so a length proportional to ``D`` keeps the blend's change the same
  share of the building's own motion whatever ``D`` (a fixed 20 m was a tenth of the
  motion's scale at ``D`` 200 m and nearly all of it at ``D`` 25 m).
- **The size** (:data:`MAX_IMAGE_DEG`): an image stands in only while its building's
  bounding sphere looks no larger than that (its angular radius), fading out over the
  last :data:`ERROR_BLEND` of it.  An image's pixels differ from the geometry's one
  sample a pixel on about a third to two thirds of the building's pixels whatever the
  image's direction, size or projection (windows a pixel wide sampled on two grids:
  docs/benchmarks.md), so a building large on the screen drawn as its image puts more
  than half a percent of the frame visibly wrong: the generated city's spire (120 m) at
  300-400 m from the drive was 1 % of the frame on one compared frame in ten.
- **The fade in time** (:func:`fade_towards`): what the blend cannot see coming --
  an image arriving while its building is already beyond ``D + blend_m``, a building
  the next cell lists or no longer lists, an image the texture budget drops -- would
  switch a building between its geometry and its image in one frame.  The opacity
  drawn therefore rises towards the blend's at most ``1 / fade_s`` a second
  (:data:`FADE_S`), and a building leaving the list fades out at that rate on the
  image it was drawn with; where the blend itself falls (the walker nearing ``D``,
  the error nearing ``A``) the opacity follows it at once, so the bounds hold.
- **The texture budget** (:func:`fit_textures`): when the images wanted do not all
  fit, the farthest buildings' images are dropped first (their buildings are drawn as
  geometry), so a budget smaller than one cell's images still draws every building.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.shared.impostors import (
    angular_error,
    bin_direction,
    bin_of,
    directions,
    image_parallax,
)
from walkstream.shared.impostorwire import ImpostorRow

__all__ = [
    "BLEND_SHARE",
    "ERROR_BLEND",
    "FADE_S",
    "MAX_IMAGE_DEG",
    "ImpostorChoice",
    "blend_length",
    "choose_impostors",
    "fade_towards",
    "fit_textures",
    "impostor_alpha",
]

BLEND_SHARE = 0.1
"""The blend's length as a share of the bake's ``D`` (25 m at the default ``D`` of 250 m)."""

FADE_S = 2.0
"""Seconds over which the opacity drawn may go from 0 to 1 at most (:func:`fade_towards`)."""

ERROR_BLEND = 0.25
"""Share of the error bound (and of :data:`MAX_IMAGE_DEG`) over which an impostor fades
out as its error (its size) nears the bound."""

MAX_IMAGE_DEG = 6.0
"""The largest angular radius, degrees, of a building's bounding sphere at which its image
stands in (``--impostor-max-size``; module docstring): a building 20 m across at the
default D of 250 m is about 2.3 degrees, the generated city's 120 m spire 9-12 degrees
at 300-400 m."""


def _smoothstep(x: NDArray[np.float64]) -> NDArray[np.float64]:
    t = np.clip(x, 0.0, 1.0)
    out: NDArray[np.float64] = t * t * (3.0 - 2.0 * t)
    return out


def blend_length(d: float, blend_m: float | None = None) -> float:
    """Metres beyond ``d`` over which an impostor fades in: ``blend_m`` when given (0: a
    hard switch), else :data:`BLEND_SHARE` of ``d`` (see the module docstring)."""
    return BLEND_SHARE * float(d) if blend_m is None else float(blend_m)


def fade_towards(shown: float, target: float, dt: float, fade_s: float = FADE_S) -> float:
    """The opacity to draw: ``shown`` (last frame's) moved towards ``target`` (the
    blend's, :func:`impostor_alpha`) by at most ``dt / fade_s`` (``dt`` seconds since
    the last frame; ``fade_s`` 0: ``target`` at once)."""
    if fade_s <= 0.0:
        return float(target)
    step = max(float(dt), 0.0) / fade_s
    return float(min(max(target, shown - step), shown + step))


def impostor_alpha(
    distance: ArrayLike, error: ArrayLike, d: float, bound: float, blend_m: float | None = None,
    size: ArrayLike = 0.0, max_size: float = math.radians(MAX_IMAGE_DEG),
) -> NDArray[np.float64]:
    """The impostor's opacity (0: geometry only, 1: impostor only) at ``distance`` from
    the building's box (metres) with angular ``error`` (radians), for the bake's ``d``
    and ``bound``; the blend over ``blend_m`` metres (None: :func:`blend_length`);
    ``size`` the building's angular radius (radians), the image fading out as it nears
    ``max_size`` (:data:`MAX_IMAGE_DEG`; ``math.inf``: no limit)."""
    near = _smoothstep((np.asarray(distance, np.float64) - d) / max(blend_length(d, blend_m), 1e-9))
    err = _smoothstep((bound - np.asarray(error, np.float64)) / (ERROR_BLEND * bound))
    out: NDArray[np.float64] = np.minimum(near, err)
    if math.isfinite(max_size):
        out = np.minimum(out, _smoothstep((max_size - np.asarray(size, np.float64)) / (ERROR_BLEND * max_size)))
    return out


@dataclass(frozen=True, slots=True)
class ImpostorChoice:
    """One listed building in one frame: the image to draw (None: geometry only), its
    opacity over the geometry, the distance to its box and the angular error."""

    object: int
    image: int | None
    alpha: float
    distance: float
    error: float


def choose_impostors(
    rows: Sequence[ImpostorRow],
    eye: ArrayLike,
    d: float,
    bound: float,
    blend_m: float | None = None,
    perspective: bool = False,
    eyes: Sequence[float] | None = None,
    max_size_deg: float = MAX_IMAGE_DEG,
) -> list[ImpostorChoice]:
    """Each listed building's image and opacity for a viewer at ``eye`` (see the module
    docstring); with ``perspective`` the error adds the image's own parallax to the
    direction's: :func:`~walkstream.shared.impostors.image_parallax` from its sampling
    eye (``eyes``, metres from the centre per row, a scene baked with perspective
    images; None: orthographic images, the eye at infinity); ``max_size_deg`` the
    largest angular radius an image stands in at (:data:`MAX_IMAGE_DEG`; ``math.inf``:
    no limit)."""
    e = np.asarray(eye, np.float64).reshape(3)
    out = []
    for k, r in enumerate(rows):
        lo, hi = np.asarray(r.box[:3]), np.asarray(r.box[3:])
        centre, radius = (lo + hi) / 2.0, float(np.linalg.norm(hi - lo)) / 2.0
        # the bake's distance: from the eye to the box's footprint
        dist = float(np.hypot(*np.maximum(np.maximum(lo[:2] - e[:2], e[:2] - hi[:2]), 0.0)))
        az, el = directions(e, centre)
        ia, ie = bin_of(r.level, az, el)
        image = r.image_for(int(ia), int(ie))
        v = e - centre
        span = float(np.linalg.norm(v))
        if image is None or span <= radius:
            out.append(ImpostorChoice(r.object, None, 0.0, dist, math.inf))
            continue
        theta = math.acos(float(np.clip(v @ bin_direction(r.level, int(ia), int(ie)) / span, -1.0, 1.0)))
        err = float(angular_error(radius, span, theta))
        if perspective:
            err += float(image_parallax(radius, span, math.inf if eyes is None else eyes[k]))
        alpha = float(impostor_alpha(dist, err, d, bound, blend_m, math.asin(min(radius / span, 1.0)),
                                     math.radians(max_size_deg)))
        out.append(ImpostorChoice(r.object, image if alpha > 0.0 else None, alpha, dist, err))
    return out


def fit_textures(choices: Sequence[ImpostorChoice], nbytes: Mapping[int, int], budget: int) -> list[ImpostorChoice]:
    """``choices`` with the images that do not fit ``budget`` bytes of textures dropped,
    farthest first: the nearest images are kept while they fit, and from the first that
    does not, every farther one is dropped (their buildings: geometry); an image two
    buildings share counts once."""
    kept: set[int] = set()
    used = 0
    for c in sorted((c for c in choices if c.image is not None), key=lambda c: c.distance):
        if c.image is None or c.image in kept:
            continue
        size = nbytes.get(c.image, 0)
        if used + size > budget:
            break  # this one and every farther one: geometry
        kept.add(c.image)
        used += size
    return [c if c.image is None or c.image in kept else ImpostorChoice(c.object, None, 0.0, c.distance, c.error)
            for c in choices]
