"""Typed flat areas on the ground (land use, parks, water, parking, plazas): kinds, heights, meshes.

An area is an object like a street piece (:class:`~walkstream.shared.records.AreaParams`):
it has an id, enters PVSs (the bake's id renderer draws it, so its pixels count for
ACH), is streamed as parameters and rebuilt by the client as one flat polygon, the
same at every LOD (earcut, holes kept).

How areas lie without fighting in depth: each kind has its own height just below the
ground's datum (:data:`~walkstream.shared.ground.GROUND_Z`), in the order of
:data:`AREA_KINDS` (:mod:`walkstream.shared.areakinds`) -- the broad land use lowest, water highest -- from
:data:`AREA_Z_LOWEST` up in steps of :data:`AREA_Z_STEP`.  So an area always lies
under a street (:data:`~walkstream.shared.streets.STREET_Z` above the datum) and under
a building (whose walls stand on the datum), a park drawn inside a residential area
lies above it, and every renderer -- the client's, the truth's, the bake's id
renderer -- resolves them by the depth test alone, with no polygon offset or special
draw order: what differs is the geometry.  The ground plane, drawn without depth,
lies under them all.  Two areas of the same kind that overlap lie at the same height
and tie in depth: both renderers draw in ascending id, so they resolve alike (and
they have the same colour).
"""

from __future__ import annotations

import numpy as np

from walkstream.shared.areakinds import AREA_MATERIALS, area_z
from walkstream.shared.geometry import triangulate_rings
from walkstream.shared.records import AreaParams, Mesh, StreetParams
from walkstream.shared.streets import build_street

__all__ = ["build_area", "build_flat"]


def build_area(a: AreaParams, lod: int = 0) -> Mesh:
    """The flat surface of an area, holes kept (``lod`` is accepted for symmetry: the same at every LOD)."""
    del lod
    tris = triangulate_rings(a.rings)
    xy = np.concatenate(a.rings)
    n = len(xy)
    pos = np.column_stack([xy, np.full(n, area_z(a.kind))])
    nor = np.zeros((n, 3))
    nor[:, 2] = 1.0
    return Mesh(pos, nor, tris, np.full(n, AREA_MATERIALS[a.kind], np.uint8))


def build_flat(p: StreetParams | AreaParams, lod: int = 0) -> Mesh:
    """The surface of a flat object, a street piece or an area (the same at every LOD)."""
    return build_area(p, lod) if isinstance(p, AreaParams) else build_street(p, lod)
