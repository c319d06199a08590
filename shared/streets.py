"""Geometry of street pieces, crossroads and squares (flat procedural ground objects).

They are objects like buildings (they enter PVSs and are streamed as parameters),
but their geometry is one flat polygon a little above the ground, the same at every
LOD: there is nothing to simplify.
"""

from __future__ import annotations

import numpy as np

from walkstream.shared.geometry import triangulate_rings
from walkstream.shared.records import Mesh, StreetParams

__all__ = ["STREET_Z", "MATERIALS", "build_street"]

#: height of the street surface above z = 0, so it never fights with a ground plane
STREET_Z = 0.02
#: palette index per street kind
MATERIALS = {"street": 5, "crossroad": 6, "square": 7}


def build_street(s: StreetParams, lod: int = 0) -> Mesh:
    """The surface of a street piece, crossroad or square (``lod`` is accepted for symmetry)."""
    del lod  # same surface at every level of detail
    tris = triangulate_rings([s.ring])
    n = len(s.ring)
    pos = np.column_stack([s.ring, np.full(n, STREET_Z)])
    nor = np.zeros((n, 3))
    nor[:, 2] = 1.0
    return Mesh(pos, nor, tris, np.full(n, MATERIALS[s.kind], np.uint8))
