"""The city objects a frame may draw: the visible street cells' PVS as arrays for culling and allocation."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from walkstream.client.rewrite.geometry import ObjectGeometry
from walkstream.client.stream.cache import Cache
from walkstream.client.stream.streamer import Streamer

__all__ = ["PvsObjects"]


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

    def update(self, cells: list[int], city: Streamer, cache: Cache, skip: int, *, far: bool = False) -> None:
        """The union of ``cells``' PVS (each object at its highest ACH), ``skip`` left out;
        ``far``: with the far field their rings carry (a ring texture in view is missing,
        :attr:`~walkstream.client.walk.state.Frame.ring_far`)."""
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
            for oid, a in zip(ids.tolist(), cover.tolist(), strict=True):
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
