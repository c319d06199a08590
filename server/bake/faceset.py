"""The cameras one sample point renders: the six faces of a cube, or a band around the horizon.

The bake's cube faces have ``resolution`` pixels over 90 degrees (128: 1.4 pixels a
degree) where the client's frame has 10.7 (640 pixels over 60 degrees), so what a
walker sees of an object hundreds of metres off -- a sliver of a building beside a
nearer facade, a street piece at the horizon -- is often under a bake pixel.  Those far
objects stand within a few degrees of the horizon: from an eye at 1.7 m a 20 m roof
300 m off is 3.5 degrees up, a street 100 m off 1 degree down.  A *horizon band*
renders only that: the four sideways faces of the cube (90 degrees across each, the
full turn together), cut to ``half`` degrees above and below the horizon, at as many
pixels across as the client has per degree; a band of 960 x 50 pixels a face (3 degrees
either way) is twice a 128-pixel cube's pixels and 20 times fewer than a 960-pixel
cube's (:mod:`walkstream.server.bake.farband`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from walkstream.shared.arrays import F64
from walkstream.shared.camera import cube_face_views, perspective
from walkstream.shared.errors import InputError

__all__ = ["FaceSet"]


@dataclass(frozen=True, slots=True)
class FaceSet:
    """The faces a sample point renders, each a tile of ``tile`` pixels in a row of them."""

    rotations: F64
    """(k, 3, 3) each face's view rotation (world to camera)."""
    cube_faces: tuple[int, ...]
    """The cube face (order +x -x +y -y +z -z) whose frustum holds each face's (for culling)."""
    tile: tuple[int, int]
    """Width and height of each face's image, pixels."""
    fovy_deg: float
    """Vertical field of view of each face (the horizontal one is 90 degrees)."""

    def __len__(self) -> int:
        return len(self.cube_faces)

    @classmethod
    def cube(cls, resolution: int) -> FaceSet:
        """The six 90-degree faces of a cube, ``resolution`` pixels square."""
        rot = cube_face_views((0.0, 0.0, 0.0)).astype(np.float64)[:, :3, :3]
        return cls(rot, tuple(range(6)), (int(resolution), int(resolution)), 90.0)

    @classmethod
    def band(cls, width: int, half_deg: float) -> FaceSet:
        """The four sideways cube faces cut to ``half_deg`` degrees above and below the horizon.

        Parameters
        ----------
        width : int
            Pixels across each face's 90 degrees.
        half_deg : float
            Degrees above (and below) the horizon the band reaches at a face's centre
            (0 < half_deg < 45); the tile's height is rounded up to whole pixels and the
            field of view widened to match, so the pixels stay square.
        """
        if not 0.0 < float(half_deg) < 45.0 or int(width) < 1:
            raise InputError(f"FaceSet.band: expected width >= 1 and 0 < half_deg < 45, got {width}, {half_deg}")
        w = int(width)
        h = max(1, int(math.ceil(w * math.tan(math.radians(float(half_deg))) - 1e-9)))
        rot = cube_face_views((0.0, 0.0, 0.0)).astype(np.float64)[:4, :3, :3]
        return cls(rot, (0, 1, 2, 3), (w, h), 2.0 * math.degrees(math.atan(h / w)))

    def projection(self, near: float, far: float) -> F64:
        """(4, 4) the faces' projection: 90 degrees across, :attr:`fovy_deg` up, square pixels."""
        w, h = self.tile
        return perspective(self.fovy_deg, w / h, near, far).astype(np.float64)
