"""The city objects a frame may draw: the visible street cells' PVS as arrays for culling and allocation."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from walkstream.client.rewrite.geometry import ObjectGeometry
from walkstream.client.stream.cache import Cache
from walkstream.client.stream.streamer import Streamer

__all__ = ["PvsObjects", "behind_walls"]


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
               far: tuple[tuple[float, float, float, float], ...] = ()) -> None:
        """The union of ``cells``' PVS (each object at its highest ACH), ``skip`` left out;
        ``far``: the ring walls in view without their texture (their ends, the hidden
        space to the left, :attr:`~walkstream.client.walk.state.Frame.far_walls`): the
        objects of the far field their ring carries that stand behind one of them join
        (:func:`behind_walls`; one not built yet joins too: it must arrive)."""
        key = (tuple((c, c in city.cells) for c in cells), city.geometry_version, sum(cache.evictions.values()), far)
        if key == self.key:
            return
        self.key = key
        ach: dict[int, float] = {}
        for c in cells:
            rec = city.cells.get(c)
            if rec is None:
                continue
            ids, cover = rec.streamed() if far else (rec.pvs, rec.ach)
            keep = np.ones(len(ids), bool)
            if far:
                keep[len(rec.pvs):] = behind_walls([cache.peek("geom", int(i)) for i in ids[len(rec.pvs):]], far)
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


def behind_walls(geoms: list[ObjectGeometry | None], walls: tuple[tuple[float, float, float, float], ...]) -> NDArray[np.bool_]:
    """``(n,)`` which of ``geoms`` (None: not built yet, kept) have a corner of their box
    behind one of ``walls`` (ends ``(x0, y0, x1, y1)``, the hidden space to the left of
    ``p0 -> p1`` seen from above): the far field a missing texture of those walls leaves
    to geometry."""
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
    left = d[None, None, :, 0] * rel[..., 1] - d[None, None, :, 1] * rel[..., 0] > 0.0
    out[built] = left.any(axis=(1, 2))
    return out

