"""What a frame shows below the horizon: the sky's colour, or no object at all.

A walk on the ground looks at the ground below the horizon; where a frame shows the
background colour there (:data:`~walkstream.client.draw.meshes.BACKGROUND_RGB`) the
walk seems to float in the sky.  Two shares of a frame's pixels below the horizon:

``sky``
    pixels in the background colour (within
    :data:`~walkstream.client.truth.compare.COLOUR_TOLERANCE`): what the user sees as
    sky where the ground should be.  The ground plane (:mod:`walkstream.shared.ground`)
    brings it to about zero.
``no_object``
    pixels where no object shows (id 0): the ground plane's share, and what every such
    pixel showed before there was a plane (the sky), so one run gives both the figure
    with the plane and the one without.

A pixel is below the horizon when the ray through its centre points down (world z
falls along it); the horizon is the camera's, whatever its pitch.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.client.draw.meshes import BACKGROUND_RGB
from walkstream.client.truth.compare import COLOUR_TOLERANCE

__all__ = ["HORIZON_SHARES", "below_horizon", "horizon_shares", "horizon_figures"]

#: the shares :func:`horizon_shares` gives, in order
HORIZON_SHARES: tuple[str, ...] = ("sky", "no_object")


def below_horizon(view: ArrayLike, proj: ArrayLike, size: tuple[int, int]) -> NDArray[np.bool_]:
    """``(h, w)`` which pixels' centre rays point down, row 0 at the top.

    Parameters
    ----------
    view, proj : (4, 4) float
        The camera.
    size : (int, int)
        Frame width and height in pixels.
    """
    w, h = int(size[0]), int(size[1])
    inv = np.linalg.inv(np.asarray(proj, np.float64) @ np.asarray(view, np.float64))
    x = (np.arange(w) + 0.5) / w * 2.0 - 1.0
    y = 1.0 - (np.arange(h) + 0.5) / h * 2.0  # row 0 at the top
    gx, gy = np.meshgrid(x, y)
    ends = []
    for z in (-1.0, 1.0):  # the near and the far plane
        p = np.stack([gx, gy, np.full_like(gx, z), np.ones_like(gx)], axis=-1) @ inv.T
        ends.append(p[..., 2] / p[..., 3])
    out: NDArray[np.bool_] = ends[1] < ends[0]
    return out


def horizon_shares(
    rgb: NDArray[np.uint8], ids: NDArray[np.integer[Any]], below: NDArray[np.bool_]
) -> tuple[float, float]:
    """A frame's ``sky`` and ``no_object`` shares of its pixels below the horizon (0 when none is).

    Parameters
    ----------
    rgb : (h, w, 3) uint8
        The frame's colour.
    ids : (h, w) int
        Object id + 1 per pixel, 0 where none shows.
    below : (h, w) bool
        :func:`below_horizon` of its camera.
    """
    n = int(below.sum())
    if n == 0:
        return 0.0, 0.0
    sky = np.all(np.abs(rgb.astype(np.int16) - np.array(BACKGROUND_RGB, np.int16)) <= COLOUR_TOLERANCE, axis=2)
    return float((sky & below).sum()) / n, float(((ids == 0) & below).sum()) / n


def horizon_figures(shares: Iterable[tuple[float, float]]) -> dict[str, dict[str, float | None]]:
    """``below_horizon`` of the ``truth`` figures: ``mean``, ``p95`` and ``max`` over the
    compared frames of each share (:data:`HORIZON_SHARES`)."""
    a = np.array(list(shares), np.float64).reshape(-1, len(HORIZON_SHARES))
    out: dict[str, dict[str, float | None]] = {}
    for k, name in enumerate(HORIZON_SHARES):
        v = a[:, k]
        out[name] = (
            {"mean": None, "p95": None, "max": None}
            if v.size == 0
            else {"mean": float(v.mean()), "p95": float(np.percentile(v, 95)), "max": float(v.max())}
        )
    return out
