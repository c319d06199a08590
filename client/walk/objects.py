"""The city objects a frame may draw: the visible street cells' PVS as arrays for culling and allocation."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from walkstream.client.rewrite.geometry import ObjectGeometry
from walkstream.client.stream.cache import Cache
from walkstream.client.stream.streamer import Streamer

__all__ = ["PvsObjects", "behind_walls", "through_walls"]


class PvsObjects:
    """The visible PVS (one object left out: an entrance's building, drawn as its shell)
    and the built geometry of its objects, rebuilt only when something changed."""

    def __init__(self) -> None:
        self.key: tuple[Any, ...] | None = None
        self.pvs: list[int] = []
        """Object ids of the visible PVS (built or not)."""
        self.geoms: list[ObjectGeometry] = []
        """The built ones, in PVS order."""
        self.ach = np.zeros(0)
        self.tri: NDArray[np.int64] = np.zeros((0, 3), np.int64)
        self.avail: NDArray[np.bool_] = np.zeros((0, 3), bool)
        self.lo: NDArray[np.float64] = np.zeros((0, 3))
        self.hi: NDArray[np.float64] = np.zeros((0, 3))

    def update(self, cells: list[int], city: Streamer, cache: Cache, skip: int, *,
               far: tuple[tuple[float, float, float, float], ...] = (),
               eye: NDArray[np.float64] | None = None, far_all: bool = False) -> None:
        """The union of ``cells``' PVS (each object at its highest ACH), ``skip`` left out;
        ``far``: the ring walls in view without their texture (their ends, the hidden
        space to the left, :attr:`~walkstream.client.walk.state.Frame.far_walls`): the
        objects of the far field their ring carries that stand behind one of them join
        (:func:`behind_walls`; one not built yet joins too: it must arrive); with ``eye``
        ``(3,)`` only those seen through one of those walls from it; ``far_all``: the
        whole far field joins (the cell's ring has not arrived)."""
        # the eye moves the far field's angles: in the key only while a far field is drawn
        at = tuple(np.round(np.asarray(eye, np.float64).reshape(-1)[:2], 2).tolist()) if far and eye is not None else ()
        key = (tuple((c, c in city.cells) for c in cells), city.geometry_version, sum(cache.evictions.values()), far, at,
               far_all)
        if key == self.key:
            return
        self.key = key
        ach: dict[int, float] = {}
        for c in cells:
            rec = city.cells.get(c)
            if rec is None:
                continue
            ids, cover = rec.streamed() if far or far_all else (rec.pvs, rec.ach)
            keep = np.ones(len(ids), bool)
            if far and not far_all:
                keep[len(rec.pvs):] = behind_walls([cache.peek("geom", int(i)) for i in ids[len(rec.pvs):]], far, eye)
            for oid, a in zip(ids[keep].tolist(), cover[keep].tolist(), strict=True):
                if oid != skip:
                    ach[oid] = max(a, ach.get(oid, 0.0))
        self.pvs = list(ach)
        self.geoms = [g for oid in self.pvs if (g := cache.peek("geom", oid)) is not None]
        self.ach = np.array([ach[g.id] for g in self.geoms])
        if self.geoms:
            self.tri = np.stack([g.triangles for g in self.geoms])
            self.avail = np.stack([g.available for g in self.geoms])
            self.lo = np.stack([g.bbox_min for g in self.geoms])
            self.hi = np.stack([g.bbox_max for g in self.geoms])
        else:
            self.tri = np.zeros((0, 3), np.int64)
            self.avail = np.zeros((0, 3), bool)
            self.lo = self.hi = np.zeros((0, 3))


def behind_walls(geoms: list[ObjectGeometry | None], walls: tuple[tuple[float, float, float, float], ...],
                 eye: NDArray[np.float64] | None = None) -> NDArray[np.bool_]:
    """``(n,)`` which of ``geoms`` (None: not built yet, kept) have a corner of their box
    behind one of ``walls`` (ends ``(x0, y0, x1, y1)``, the hidden space to the left of
    ``p0 -> p1`` seen from above): the far field a missing texture of those walls leaves
    to geometry.

    With ``eye`` ``(2,)`` or ``(3,)`` as well, only the boxes seen *through* one of those
    walls: behind its line and within the angle it spans from the eye
    (:func:`through_walls`).  A far object behind a missing wall's line but seen only
    through a neighbour wall whose texture is held is on that texture: drawing it as
    geometry too only cost culling (the ring's four walls meet at its corners, so most of
    a wall's half-plane is seen through its neighbours)."""
    out = np.ones(len(geoms), bool)
    built = [k for k, g in enumerate(geoms) if g is not None]
    if not built or not walls:
        return out
    lo = np.stack([np.asarray(geoms[k].bbox_min, np.float64)[:2] for k in built])  # type: ignore[union-attr]
    hi = np.stack([np.asarray(geoms[k].bbox_max, np.float64)[:2] for k in built])  # type: ignore[union-attr]
    corners = np.stack([lo, np.stack([hi[:, 0], lo[:, 1]], 1), hi, np.stack([lo[:, 0], hi[:, 1]], 1)], 1)  # (m, 4, 2)
    w = np.asarray(walls, np.float64).reshape(-1, 4)
    d = w[:, 2:] - w[:, :2]  # (k, 2)
    rel = corners[:, :, None, :] - w[None, None, :, :2]  # (m, 4, k, 2)
    left = (d[None, None, :, 0] * rel[..., 1] - d[None, None, :, 1] * rel[..., 0] > 0.0).any(axis=1)  # (m, k)
    if eye is not None:
        left &= through_walls(corners, w, np.asarray(eye, np.float64).reshape(-1)[:2])
    out[built] = np.any(left, axis=1)
    return out


def through_walls(corners: NDArray[np.float64], walls: NDArray[np.float64], eye: NDArray[np.float64]) -> NDArray[np.bool_]:
    """``(m, k)`` whether box ``i`` (its four corners ``(m, 4, 2)``, seen from above)
    overlaps the angle wall ``j`` (ends ``(k, 4)`` as ``(x0, y0, x1, y1)``) spans from
    ``eye`` ``(2,)``: every angle is taken from the direction to the wall's middle, so
    neither interval wraps; a box spanning half a turn or more (the eye inside it, or
    beside it) always overlaps.  Conservative: a box outside the angle cannot be seen
    through the wall."""
    mid = (walls[:, :2] + walls[:, 2:]) / 2.0 - eye  # (k, 2)

    def angle(v: NDArray[np.float64]) -> NDArray[np.float64]:  # v (..., k, 2) from the eye
        return np.arctan2(mid[:, 0] * v[..., 1] - mid[:, 1] * v[..., 0], mid[:, 0] * v[..., 0] + mid[:, 1] * v[..., 1])

    ends = np.stack([angle(walls[:, :2] - eye), angle(walls[:, 2:] - eye)])  # (2, k)
    a_lo, a_hi = ends.min(axis=0), ends.max(axis=0)
    seen = angle(corners[:, :, None, :] - eye)  # (m, 4, k)
    b_lo, b_hi = seen.min(axis=1), seen.max(axis=1)  # (m, k)
    wide = b_hi - b_lo >= np.pi
    return wide | ((b_hi >= a_lo[None, :]) & (b_lo <= a_hi[None, :]))
