"""Impostor geometry shared by the bake and the client: the error bound, direction bins, image size.

An impostor image of an object is its orthographic projection along a direction
``u`` (from the object's centre towards the eye) onto the plane through the centre
perpendicular to ``u``, covering the object's bounding sphere (centre ``c``, radius
``R``): a square of side ``2 R``.

**The error.**  A viewer at distance ``d`` from ``c`` in direction ``v`` sees a point
of the object at distance ``r <= R`` from ``c`` where the image shows it displaced by
at most ``r sin(theta)``, ``theta`` the angle between ``u`` and ``v`` (the point's
depth along ``u`` becomes a sideways shift when the view turns by ``theta``).  Seen
from the eye that shift subtends the angle

    error(R, d, theta) = atan(R sin(theta) / d)

:func:`angular_error` -- the angle under which a point of the object moves between
the image's direction and the viewer's.  An image may stand in while this stays at
or under the bound ``A``: ``theta <= asin(min(1, d tan(A) / R))``
(:func:`allowed_angle`).

**Perspective.**  The image is orthographic while the viewer's is a perspective
view, so even from the image's own direction (``theta`` 0) a point of the object at
``x`` across and ``z`` towards the eye is seen at ``atan(x / (d - z))`` where the
image puts it at ``atan(x / d)``; over the bounding sphere that is at most
:func:`orthographic_parallax` (about ``R^2 / (2 d^2)``), which finer bins do not
reduce: 1-3 degrees for the demo's buildings at 60 m, 0.1 at 250 m.

**Perspective images** (the bake's ``--impostor-projection perspective``).  An
image of bin ``u`` at level ``l`` may instead be rendered in perspective from a
*sampling eye* ``e = c + u d_e`` (:func:`eye_distance`) onto the same plane through
``c`` across ``u``, over the square that holds the bounding sphere's silhouette from
``e`` (half side :func:`half_side`, ``R d_e / sqrt(d_e^2 - R^2)``), with the one
off-axis projection of :func:`~walkstream.shared.camera.off_axis`.  From ``e`` the
textured quad is the object, pixel for pixel.  A viewer elsewhere sees a point ``p``
displaced by the segment between ``p`` and its image on the plane (at most about
``R``) seen under the angle at ``p`` between the sampling eye and the viewer: to first
order the angle ``theta`` at the centre between ``u`` and the viewer's direction (the
bound ``A`` as before: :func:`angular_error`, :func:`level_for` and the direction
bins do not change, and the image for a viewer is still the bin of its direction
from the centre) plus the difference of the two eyes' distances, which
:func:`image_parallax` measures: about ``R^2 |1/d - 1/d_e| / (2 d)`` where the
orthographic image has ``R^2 / (2 d^2)`` (its ``d_e`` infinite).  A level serves
the distances where its bins are the coarsest within ``A`` (a factor of about two);
``d_e`` is the distance in that band that makes the largest residual over the band
the smallest, so it is a property of the image's level, and two cells that share
the image share its eye.

**Direction bins.**  Directions are binned on a fixed grid of azimuth and elevation,
one grid per *level*: level ``l`` has steps of ``BASE_STEP / 2**l`` radians.  A bin's
image is rendered from the bin's centre direction, and any direction in the bin is
within half the bin's diagonal of it (``step / sqrt(2)``, an upper bound of the
angle on the sphere), so a cell at least ``d`` from an object uses the coarsest level
whose half-diagonal is at most ``allowed_angle(R, d, A)`` (:func:`level_for`).  The
grid is the same for every cell, so cells that need the same bin of the same object
at the same level share one image.

**Size.**  An image of ``n`` texels over ``2 R`` metres keeps a texel at or under a
screen pixel of a ``height``-pixel view of vertical field ``fov`` at distance ``d``
when ``n >= 2 R height / (2 d tan(fov / 2))`` (:func:`texels_needed`).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "BASE_STEP",
    "MAX_LEVEL",
    "allowed_angle",
    "angular_error",
    "bin_direction",
    "bin_of",
    "directions",
    "eye_distance",
    "half_side",
    "image_basis",
    "image_parallax",
    "image_size",
    "level_for",
    "level_step",
    "orthographic_parallax",
    "PROJECTIONS",
    "texels_needed",
]

BASE_STEP = math.pi / 4.0
"""Bin step of level 0, radians (8 azimuth bins around an object)."""

MAX_LEVEL = 6
"""Finest level (steps of 0.70 degrees); a cell needing finer bins gets no impostor."""

PROJECTIONS: tuple[str, ...] = ("ortho", "perspective")
"""How an image is projected (module docstring): orthographic along its bin's
direction, or in perspective from its level's sampling eye."""

EYE_MIN_RADII = 1.5
"""The sampling eye is at least this many bounding radii from the centre (a level's
band may reach nearer than the object's own sphere, where no cell uses it)."""


def level_step(level: int) -> float:
    """The bin step of ``level``, radians."""
    return BASE_STEP / (1 << int(level))


def angular_error(radius: ArrayLike, distance: ArrayLike, theta: ArrayLike) -> NDArray[np.float64]:
    """The angle (radians) under which a point of an object moves when an image from a
    direction ``theta`` away from the viewer's stands in (see the module docstring)."""
    r = np.asarray(radius, np.float64)
    d = np.maximum(np.asarray(distance, np.float64), 1e-9)
    return np.arctan(r * np.sin(np.asarray(theta, np.float64)) / d)


def orthographic_parallax(radius: ArrayLike, distance: ArrayLike, samples: int = 257) -> NDArray[np.float64]:
    """The largest angle (radians) between where an orthographic image puts a point of
    an object of bounding ``radius`` and where a perspective viewer at ``distance``
    from its centre, along the image's own direction, sees it (module docstring):
    :func:`image_parallax` with the sampling eye at infinity."""
    return image_parallax(radius, distance, math.inf, samples)


def image_parallax(
    radius: ArrayLike, distance: ArrayLike, eye: ArrayLike = math.inf, samples: int = 257
) -> NDArray[np.float64]:
    """The largest angle (radians) between where an image rendered from a sampling eye
    ``eye`` metres from the centre (``inf``: orthographic) puts a point of an object of
    bounding ``radius`` and where a viewer at ``distance`` on the same axis sees it.

    A point at ``x`` across and ``z`` towards the eye (``x = R sin(phi)``,
    ``z = R cos(phi)``, over the sphere's front) lies on the image's plane at
    ``x d_e / (d_e - z)``; the viewer sees it at ``atan(x / (d - z))`` and the quad's
    texel at ``atan(x d_e / ((d_e - z) d))``; the maximum over ``samples`` angles
    ``phi``.  Zero when ``distance == eye``; ``radius``, ``distance`` and ``eye``
    broadcast; a viewer or an eye inside the sphere gets ``pi / 2``.
    """
    r = np.asarray(radius, np.float64)[..., None]
    d = np.asarray(distance, np.float64)[..., None]
    e = np.asarray(eye, np.float64)[..., None]
    phi = np.linspace(0.0, math.pi / 2.0, samples)
    x, z = r * np.sin(phi), r * np.cos(phi)
    with np.errstate(divide="ignore", invalid="ignore"):
        scale = np.where(np.isinf(e), 1.0, e / (e - z))
        diff = np.abs(np.arctan2(x, d - z) - np.arctan2(x * scale, d))
    inside = (d[..., 0] <= r[..., 0]) | (e[..., 0] <= r[..., 0])
    out: NDArray[np.float64] = np.where(inside, math.pi / 2.0, diff.max(axis=-1))
    return out


def eye_distance(radius: ArrayLike, level: ArrayLike, bound: float, far: float = 0.0) -> NDArray[np.float64]:
    """The sampling eye's distance (metres from the centre) of a perspective image of an
    object of bounding ``radius`` at ``level`` under the bound ``bound`` (radians), in a
    bake whose far objects are at least ``far`` (D) from every cell.

    Level ``l`` is the coarsest within ``bound`` for the distances ``d`` where
    :func:`allowed_angle` lies between its half diagonal and the next coarser one's:
    ``lo = R sin(h_l) / tan(A)`` to ``hi = R sin(h_{l-1}) / tan(A)`` (``hi`` infinite
    at level 0), ``lo`` at least :data:`EYE_MIN_RADII` radii.  The residual
    ``|1/d - 1/d_e| / d`` (:func:`image_parallax`'s first order) over ``1/d`` in
    ``[1/hi, 1/lo]`` is smallest at its largest for ``1/d_e = (a^2 + b^2) / (a + b)``
    (``a = 1/lo``, ``b = 1/hi``) when ``b >= (sqrt 2 - 1) a``, else ``2 (sqrt 2 - 1) a``:
    about 1.2 ``lo`` for a band of a factor of two.
    """
    r = np.maximum(np.asarray(radius, np.float64), 1e-9)
    lv = np.asarray(level, np.int64)
    t = math.tan(bound)
    h = BASE_STEP / np.exp2(lv.astype(np.float64)) / math.sqrt(2.0)
    lo = np.maximum(r * np.sin(np.minimum(h, math.pi / 2.0)) / t, EYE_MIN_RADII * r)
    coarser = np.minimum(2.0 * h, math.pi / 2.0)
    hi = np.where(lv <= 0, np.inf, r * np.sin(coarser) / t)
    lo = np.where(far < hi, np.maximum(lo, far), lo)
    a = 1.0 / lo
    b = np.where(hi > lo, 1.0 / np.maximum(hi, lo), a)
    x = np.where(b >= (math.sqrt(2.0) - 1.0) * a, (a * a + b * b) / (a + b), 2.0 * (math.sqrt(2.0) - 1.0) * a)
    out: NDArray[np.float64] = 1.0 / x
    return out


def half_side(radius: ArrayLike, eye: ArrayLike = math.inf) -> NDArray[np.float64]:
    """Half the side of an image's square on the plane through the centre: ``radius``
    for an orthographic image (``eye`` infinite), the bounding sphere's silhouette from
    a sampling eye ``eye`` metres away, ``R d_e / sqrt(d_e^2 - R^2)``, for a perspective one."""
    r = np.asarray(radius, np.float64)
    e = np.asarray(eye, np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        out: NDArray[np.float64] = np.where(np.isinf(e), r, r * e / np.sqrt(np.maximum(e * e - r * r, 1e-18)))
    return out


def allowed_angle(radius: ArrayLike, distance: ArrayLike, bound: float) -> NDArray[np.float64]:
    """The largest angle between an image's direction and the viewer's that keeps the
    error at or under ``bound`` (radians), for objects of ``radius`` at ``distance``."""
    r = np.maximum(np.asarray(radius, np.float64), 1e-9)
    ratio = np.asarray(distance, np.float64) * math.tan(bound) / r
    return np.arcsin(np.clip(ratio, 0.0, 1.0))


def level_for(radius: ArrayLike, distance: ArrayLike, bound: float) -> NDArray[np.int64]:
    """The coarsest level whose bins keep the error bound at ``distance`` (-1: none does)."""
    theta = allowed_angle(radius, distance, bound)
    # half-diagonal step/sqrt(2) <= theta  <=>  l >= log2(BASE_STEP / (sqrt(2) theta))
    with np.errstate(divide="ignore"):
        need = np.log2(BASE_STEP / (math.sqrt(2.0) * np.maximum(theta, 1e-12)))
    level = np.maximum(np.ceil(need - 1e-9), 0).astype(np.int64)
    return np.where(level > MAX_LEVEL, -1, level)


def directions(points: ArrayLike, centre: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Azimuth and elevation (radians) of ``points - centre`` (the direction to the eye)."""
    d = np.asarray(points, np.float64) - np.asarray(centre, np.float64)
    az = np.arctan2(d[..., 1], d[..., 0])
    el = np.arctan2(d[..., 2], np.hypot(d[..., 0], d[..., 1]))
    return az, el


def bin_of(level: int, az: ArrayLike, el: ArrayLike) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """The azimuth and elevation bin indices of directions at ``level``."""
    step = level_step(level)
    n_az = int(round(2.0 * math.pi / step))
    ia = np.floor((np.asarray(az, np.float64) + math.pi) / step).astype(np.int64) % n_az
    ie = np.floor((np.asarray(el, np.float64) + math.pi / 2.0) / step).astype(np.int64)
    return ia, np.clip(ie, 0, int(round(math.pi / step)) - 1)


def bin_direction(level: int, ia: int, ie: int) -> NDArray[np.float64]:
    """The unit direction (object towards eye) an image of bin ``(ia, ie)`` at ``level`` is rendered from."""
    step = level_step(level)
    az = -math.pi + (ia + 0.5) * step
    el = -math.pi / 2.0 + (ie + 0.5) * step
    return np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])


def texels_needed(radius: ArrayLike, distance: ArrayLike, height_px: int, fov_deg: float) -> NDArray[np.float64]:
    """Texels across an image so that one is at most a screen pixel at ``distance``."""
    d = np.maximum(np.asarray(distance, np.float64), 1e-9)
    per_m = height_px / (2.0 * d * math.tan(math.radians(fov_deg) / 2.0))
    return 2.0 * np.asarray(radius, np.float64) * per_m


def image_size(texels: ArrayLike, cap: int, floor: int = 8) -> NDArray[np.int64]:
    """The power of two at or above ``texels``, between ``floor`` and ``cap``."""
    t = np.maximum(np.asarray(texels, np.float64), 1.0)
    p = np.exp2(np.ceil(np.log2(t))).astype(np.int64)
    return np.clip(p, floor, cap)


def image_basis(direction: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The image's right and up vectors (world, unit) for a direction ``u`` (object towards eye).

    The image looks along ``-u`` with the world's z as its screen-up, as
    :func:`~walkstream.shared.camera.look_at` does; texel column ``j`` of ``n`` (row
    ``i`` from the top) shows ``c + R (2 (j + 0.5) / n - 1) right + R (1 - 2 (i + 0.5) / n) up``.
    """
    x, y, z = (float(v) for v in np.asarray(direction, np.float64).reshape(3))
    n = math.sqrt(x * x + y * y + z * z)
    x, y, z = x / n, y / n, z / n
    h = math.hypot(x, y)
    # right = -u x z_up, normalised; up = right x -u (plain arithmetic: this runs per image)
    right = np.array([1.0, 0.0, 0.0]) if h < 1e-9 else np.array([-y / h, x / h, 0.0])
    up = np.array([-right[1] * z, right[0] * z, -(right[0] * y - right[1] * x)])
    return right, up / np.linalg.norm(up)
