"""Draw order and culling of the bake's ID renderer: Hilbert-curve order, cube-face frusta, runs.

The :class:`~walkstream.server.bake.visibility.VisibilityRenderer` keeps every object
in one vertex buffer in Hilbert-curve order of their box centres (objects near each
other are contiguous, so a frustum keeps few runs of them), culls boxes against the
six cube-face frusta with one vectorised test, and turns each face's visible objects
into contiguous index ranges (runs).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from walkstream.shared.arrays import F64, I64

__all__ = ["curve_order", "frustum_planes", "runs"]


def _hilbert_key(x: I64, y: I64, bits: int = 16) -> I64:
    """Distance along a Hilbert curve of integer points ``x, y`` in ``[0, 2**bits)``."""
    x, y = x.copy(), y.copy()
    d = np.zeros(len(x), np.int64)
    s = 1 << (bits - 1)
    while s > 0:
        rx = (x & s) > 0
        ry = (y & s) > 0
        d += s * s * ((3 * rx.astype(np.int64)) ^ ry.astype(np.int64))
        # Rotate the quadrant so the sub-curve is traversed in the right orientation
        # (only the bits below ``s`` matter from here on, so ``s - 1 - x`` is enough).
        flip = ~ry & rx
        x[flip], y[flip] = s - 1 - x[flip], s - 1 - y[flip]
        swap = ~ry
        x[swap], y[swap] = y[swap], x[swap]
        s >>= 1
    return d


def curve_order(centres: F64) -> I64:
    """Indices that sort points ``(n, 2)`` along a Hilbert curve (ties by index).

    Objects next to each other on the curve are next to each other in space, so a
    frustum keeps few contiguous runs of them (a Hilbert curve gives about a quarter
    fewer runs than a Morton curve on a generated city).
    """
    if len(centres) == 0:
        return np.zeros(0, np.int64)
    lo = centres.min(axis=0)
    span = float(max((centres.max(axis=0) - lo).max(), 1e-9))
    q = np.clip((centres - lo) / span * 65535.0, 0, 65535).astype(np.int64)
    return np.argsort(_hilbert_key(q[:, 0], q[:, 1]), kind="stable").astype(np.int64)




def frustum_planes(near: float, far: float) -> tuple[F64, F64, F64]:
    """Half-space tests of the six cube-face frusta, in world axes relative to the eye.

    A box (relative to the eye) meets face ``f`` only if, for each of its six planes
    ``k``, ``max over the box of w[f, k] . x >= t[f, k]``.  For face axis ``a`` with
    sign ``s`` the planes are the four 90-degree sides ``s*x_a >= |x_b|``,
    ``s*x_a >= |x_c|``, the near plane ``s*x_a >= near`` and the far plane
    ``s*x_a <= far``.

    Returns
    -------
    w_pos, w_neg : (36, 3) float64
        Positive and negative parts of the plane normals (face-major), so that the box
        maximum is ``hi @ w_pos.T + lo @ w_neg.T``.
    t : (36,) float64
        The thresholds.
    """
    w = np.zeros((6, 6, 3))
    t = np.zeros((6, 6))
    for f in range(6):
        a, s = f // 2, (1.0 if f % 2 == 0 else -1.0)  # order +x -x +y -y +z -z
        b, c = [k for k in range(3) if k != a]
        for k, (axis, sign) in enumerate(((b, 1.0), (b, -1.0), (c, 1.0), (c, -1.0))):
            w[f, k, a] = s
            w[f, k, axis] = sign
        w[f, 4, a] = s
        t[f, 4] = near
        w[f, 5, a] = -s
        t[f, 5] = -far
    flat = w.reshape(36, 3)
    return np.maximum(flat, 0.0), np.minimum(flat, 0.0), t.reshape(36)


def runs(mask: NDArray[np.bool_]) -> tuple[I64, I64, I64]:
    """Runs of True in each row of ``mask`` ``(r, n)``: ``(row, start, stop)`` each ``(m,)``.

    Runs come row by row, left to right; ``stop`` is exclusive.
    """
    r, n = mask.shape
    padded = np.zeros((r, n + 2), np.int8)
    padded[:, 1:-1] = mask
    step = np.diff(padded, axis=1)
    rows, starts = np.nonzero(step == 1)
    _, stops = np.nonzero(step == -1)
    return rows.astype(np.int64), starts.astype(np.int64), stops.astype(np.int64)
