"""Whole-array polygon helpers: orientation, area, triangulation."""

from __future__ import annotations

from collections.abc import Sequence

import mapbox_earcut
import numpy as np
from numpy.typing import NDArray

__all__ = ["signed_area", "orient_rings", "triangulate_rings", "ring_edges"]


def signed_area(ring: NDArray[np.float64]) -> float:
    """Shoelace area of a ring ``(n, 2)``; positive when counter-clockwise.

    The ring may repeat its first vertex at the end or not.  Coordinates are taken
    relative to the first vertex, so that rings millions of metres from the CRS
    origin do not lose their area to cancellation.

    >>> signed_area(np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [0.0, 1.0]]))
    2.0
    >>> signed_area(np.array([[6e6, 0.0], [6e6, 1.0], [6e6 + 2.0, 1.0], [6e6 + 2.0, 0.0]]))
    -2.0
    """
    x, y = (np.asarray(ring, dtype=np.float64) - ring[0]).T
    nxt = np.arange(1, len(x) + 1) % len(x)  # np.roll(-1) by index: cheaper on the small rings this sees by the thousand
    return 0.5 * float(np.dot(x, y[nxt]) - np.dot(x[nxt], y))


def orient_rings(rings: Sequence[NDArray[np.float64]]) -> list[NDArray[np.float64]]:
    """Return rings with the exterior counter-clockwise and holes clockwise."""
    out = []
    for k, r in enumerate(rings):
        a = signed_area(r)
        want_ccw = k == 0
        out.append(r[::-1].copy() if (a > 0) != want_ccw and a != 0 else np.asarray(r))
    return out


def ring_edges(rings: Sequence[NDArray[np.float64]]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Start and end points ``(E, 2)`` of every edge of every ring, rings in order."""
    p0 = np.concatenate([np.asarray(r, np.float64) for r in rings])
    p1 = np.concatenate([np.roll(np.asarray(r, np.float64), -1, axis=0) for r in rings])
    return p0, p1


def triangulate_rings(rings: Sequence[NDArray[np.float64]]) -> NDArray[np.int64]:
    """Triangulate a polygon with holes (earcut).

    Parameters
    ----------
    rings: exterior first, then holes; each ``(n, 2)``.

    Returns
    -------
    ``(t, 3) int64`` indices into the rings' concatenated vertices, every triangle
    counter-clockwise seen from above (+z).
    """
    verts = np.concatenate([np.asarray(r, np.float64) for r in rings])
    # earcut is happiest near the origin; shift to the first vertex for robustness
    local = verts - verts[0]
    ends = np.cumsum([len(r) for r in rings]).astype(np.uint32)
    idx = np.asarray(mapbox_earcut.triangulate_float64(local, ends), dtype=np.int64).reshape(-1, 3)
    if len(idx) == 0:
        return idx
    a, b, c = local[idx[:, 0]], local[idx[:, 1]], local[idx[:, 2]]
    cross = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    flip = cross < 0
    idx[flip] = idx[flip][:, ::-1]
    return idx
