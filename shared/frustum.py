"""The conservative frustum test of bounding boxes: what can be seen at all.

The city's frame culls its cell's PVS with it before the budget is shared
(:mod:`walkstream.client.draw.allocate`); portal culling (:mod:`.portals`) uses it
after the visible screen areas, as the paper does.  It lives in ``shared/`` because
the server runs portal culling too (the first view of an interior start bundle).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.shared.errors import InputError

__all__ = ["frustum_planes", "frustum_cull"]


# --------------------------------------------------------------------------- culling


def frustum_planes(view_proj: ArrayLike) -> NDArray[np.float64]:
    """The six clip planes of a view-projection matrix (Gribb and Hartmann).

    Parameters
    ----------
    view_proj : (4, 4) float
        ``proj @ view`` acting on column vectors, OpenGL clip conventions
        (:mod:`walkstream.shared.camera`: a point is inside when ``-w <= x, y, z <= w``).

    Returns
    -------
    (6, 4) float64
        ``(a, b, c, d)`` per plane (left, right, bottom, top, near, far), not
        normalised; a point ``p`` is on the inner side when ``a*x + b*y + c*z + d >= 0``.
    """
    m = np.asarray(view_proj, dtype=np.float64)
    if m.shape != (4, 4) or not np.all(np.isfinite(m)):
        raise InputError(f"frustum_planes: expected a finite (4, 4) matrix, got shape {m.shape}")
    r0, r1, r2, r3 = m
    return np.stack([r3 + r0, r3 - r0, r3 + r1, r3 - r1, r3 + r2, r3 - r2])


def frustum_cull(
    bbox_min: ArrayLike, bbox_max: ArrayLike, view_proj: ArrayLike
) -> NDArray[np.bool_]:
    """Conservative box-against-frustum test.

    A box is dropped only when it lies entirely outside one of the six planes; a box
    that straddles a plane is kept, and so (rarely) is a box near a frustum corner
    that is outside although no single plane shows it.  That errs on the side of
    drawing, which is what culling before LOD selection needs.

    Parameters
    ----------
    bbox_min, bbox_max : (k, 3) float
        Opposite corners of each axis-aligned box, scene-local metres.
    view_proj : (4, 4) float
        ``proj @ view`` (see :func:`frustum_planes`).

    Returns
    -------
    (k,) bool
        True for the boxes to keep.
    """
    lo = np.asarray(bbox_min, dtype=np.float64).reshape(-1, 3)
    hi = np.asarray(bbox_max, dtype=np.float64).reshape(-1, 3)
    if lo.shape != hi.shape:
        raise InputError(
            f"frustum_cull: bbox_min and bbox_max differ in shape: {lo.shape} vs {hi.shape}"
        )
    planes = frustum_planes(view_proj)
    if len(lo) == 0:
        return np.zeros(0, bool)
    normal = planes[:, :3]  # (6, 3)
    # The box corner farthest along each plane's normal ("positive vertex"): if even it
    # is outside, the whole box is.
    pos = np.where(normal[None, :, :] >= 0, hi[:, None, :], lo[:, None, :])  # (k, 6, 3)
    dist = np.einsum("kpj,pj->kp", pos, normal) + planes[:, 3]
    return np.asarray(np.all(dist >= 0, axis=1))
