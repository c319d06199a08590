"""Poses in solid geometry: how near the eye comes to a room surface.

An eye in a wall's face, or so near a wall that the near plane cuts it, looks through
the cut into what lies behind -- the rooms on the other side, the wall's far face --
which no walker sees.  The truth refuses such a pose instead of counting what it
shows as culled (:func:`~walkstream.client.truth.culled.culled_figures`).  The test
is geometric, not by the picture: a wall faced squarely closer than the near plane
vanishes altogether, and one walked along in its own plane is edge-on, so neither
leaves a near pixel to find.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
import trimesh
from numpy.typing import ArrayLike, NDArray

from walkstream.shared.codec.cellmesh import CellMesh

__all__ = ["SolidProbe"]


class SolidProbe:
    """The room surfaces of a truth, asked how near an eye comes to them.

    Parameters
    ----------
    rooms : {cell: CellMesh}
        The room cells' contents, as the truth draws them.
    """

    def __init__(self, rooms: Mapping[int, CellMesh]) -> None:
        tris: list[NDArray[np.float64]] = []
        for cid in sorted(rooms):
            for part in rooms[cid].parts:
                if part.triangles:
                    p = np.asarray(part.positions, np.float64)
                    tris.append(p[np.asarray(part.indices, np.int64)])
        self.triangles = np.concatenate(tris) if tris else np.zeros((0, 3, 3))
        """``(n, 3, 3)`` every room triangle."""
        self._lo = self.triangles.min(axis=1) if len(self.triangles) else np.zeros((0, 3))
        self._hi = self.triangles.max(axis=1) if len(self.triangles) else np.zeros((0, 3))

    def nearest(self, eye: ArrayLike, within: float) -> float:
        """The distance from ``eye`` to the nearest room surface, when it is below
        ``within`` metres (``inf`` otherwise: only triangles whose box comes that near are measured)."""
        e = np.asarray(eye, np.float64).reshape(3)
        near = np.all((self._lo <= e + within) & (self._hi >= e - within), axis=1)
        if not near.any():
            return math.inf
        t = self.triangles[near]
        closest = trimesh.triangles.closest_point(t, np.broadcast_to(e, (len(t), 3)))
        d = float(np.linalg.norm(closest - e, axis=1).min())
        return d if d < within else math.inf
