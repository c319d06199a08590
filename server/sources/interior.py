"""What an interior source (an IFC model or a generated interior) hands to the bake.

A city source gives footprints to rebuild with a grammar (:class:`~.scene.SourceScene`);
an interior gives a building's *inside*: storeys, rooms (the candidate cells), the
openings between them (the candidate portals) and every building element as a
triangle mesh.  Everything is plain numbers and numpy arrays in scene-local metres
(float64; the CRS position of local (0, 0, 0) is :attr:`InteriorScene.origin`), so
the record pickles cheaply to the bake's worker processes and Dask, and nothing of
the IFC library travels with it.

Readers: :func:`~walkstream.server.sources.ifc.load_ifc` (IFC2X3 / IFC4) and
:func:`~walkstream.server.sources.interiorfile.load_interior` (the documented
``walkstream-interior`` format that ``walkstream generate interior`` writes).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import shapely
from numpy.typing import ArrayLike, NDArray

from walkstream.server.sources.scene import FeatureIssue
from walkstream.shared.arrays import F64
from walkstream.shared.errors import SourceError
from walkstream.shared.records import readonly

__all__ = [
    "ELEMENT_KINDS",
    "OPENING_KINDS",
    "Storey",
    "Room",
    "Opening",
    "Stair",
    "Element",
    "InteriorScene",
    "mesh_footprint",
]

ELEMENT_KINDS = (
    "wall",
    "slab",
    "roof",
    "door",
    "window",
    "stair",
    "railing",
    "furniture",
    "covering",
    "beam",
    "column",
    "other",
)
"""Kinds of building elements (what decides their colour and whether they block a view)."""

OPENING_KINDS = ("door", "window", "opening", "virtual")
"""Kinds of openings: a filled or empty hole through a wall, or a virtual (open) boundary."""


@dataclass(frozen=True, slots=True)
class Storey:
    """A building storey: its name and floor elevation (scene-local metres)."""

    name: str
    elevation: float


@dataclass(frozen=True, slots=True)
class Room:
    """A room (an IFC space): its footprint on its storey and the height of its solid.

    ``outline`` is ``(n, 2) float64``, one simple ring (any orientation, maybe not
    convex: the bake cuts it into convex cells); ``zmin``/``zmax`` are the extent of
    the space's solid, which may reach into the storey above (a stair space).
    """

    key: str
    name: str
    storey: int
    outline: F64
    zmin: float
    zmax: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "outline", readonly(np.asarray(self.outline, np.float64).reshape(-1, 2)))


@dataclass(frozen=True, slots=True)
class Opening:
    """A door, window or empty opening through a wall, or a virtual boundary.

    A hole through a wall is a box: ``centre`` ``(3,)`` (the middle of the wall
    thickness, halfway up), ``normal`` ``(2,)`` (horizontal, across the wall),
    ``width`` along the wall, ``depth`` across it (the wall thickness; the two rooms
    of a door lie about that far apart) and ``zmin``..``zmax`` (sill to head).  A
    virtual boundary has ``depth`` 0 and its polygon in ``polygon`` (``(k, 3)``).
    ``rooms`` are the keys of the rooms the source itself says it bounds (IFC space
    boundaries), empty when the source does not say: the bake then finds them from
    the geometry.  ``source`` says where the record came from (``boundary``,
    ``geometry`` or ``file``).
    """

    key: str
    kind: str
    name: str
    storey: int
    centre: F64
    normal: F64
    width: float
    depth: float
    zmin: float
    zmax: float
    rooms: tuple[str, ...] = ()
    polygon: F64 | None = None
    source: str = "geometry"

    def __post_init__(self) -> None:
        if self.kind not in OPENING_KINDS:
            raise SourceError(f"opening {self.key}: kind must be one of {OPENING_KINDS}, got {self.kind!r}")
        c = np.asarray(self.centre, np.float64).reshape(3)
        n = np.asarray(self.normal, np.float64).reshape(2)
        length = float(np.hypot(*n))
        if not (np.all(np.isfinite(c)) and length > 0):
            raise SourceError(f"opening {self.key}: centre and normal must be finite, normal non-zero")
        object.__setattr__(self, "centre", readonly(c))
        object.__setattr__(self, "normal", readonly(n / length))
        if self.polygon is not None:
            object.__setattr__(
                self, "polygon", readonly(np.asarray(self.polygon, np.float64).reshape(-1, 3))
            )

    @property
    def along(self) -> F64:
        """``(2,)`` unit vector along the wall (the normal turned left)."""
        return np.array([-self.normal[1], self.normal[0]])


@dataclass(frozen=True, slots=True)
class Stair:
    """A stair flight: the line a walker follows, ``(k, 3)`` floor points, bottom to top."""

    key: str
    name: str
    storey: int
    path: F64

    def __post_init__(self) -> None:
        p = readonly(np.asarray(self.path, np.float64).reshape(-1, 3))
        if len(p) < 2 or p[-1, 2] <= p[0, 2]:
            raise SourceError(f"stair {self.key}: its path must have >= 2 points and climb")
        object.__setattr__(self, "path", p)


@dataclass(frozen=True, slots=True)
class Element:
    """A building element tessellated: ``vertices`` ``(n, 3) float64`` scene-local
    metres, ``triangles`` ``(m, 3) int32`` counter-clockwise from outside, and
    ``materials`` ``(m,) uint8`` per triangle."""

    id: int
    key: str
    kind: str
    name: str
    # typed loosely: any numeric array is accepted and converted in __post_init__
    vertices: NDArray[Any]
    triangles: NDArray[Any]
    materials: NDArray[Any]

    def __post_init__(self) -> None:
        v = np.asarray(self.vertices, np.float64).reshape(-1, 3)
        t = np.asarray(self.triangles, np.int32).reshape(-1, 3)
        m = np.asarray(self.materials, np.uint8).reshape(-1)
        if len(m) == 1 and len(t) != 1:
            m = np.full(len(t), m[0], np.uint8)
        if len(m) != len(t):
            raise SourceError(f"element {self.key}: {len(t)} triangles but {len(m)} materials")
        if len(t) and (t.min() < 0 or t.max() >= len(v)):
            raise SourceError(f"element {self.key}: triangle index out of range")
        object.__setattr__(self, "vertices", readonly(v))
        object.__setattr__(self, "triangles", readonly(t))
        object.__setattr__(self, "materials", readonly(m))

    @property
    def soup(self) -> F64:
        """``(m, 3, 3)`` the triangles' corner positions."""
        return np.asarray(self.vertices[self.triangles], np.float64)


@dataclass(frozen=True)
class InteriorScene:
    """A building interior in scene-local metres.

    ``origin`` is the position of local (0, 0, 0) in ``crs`` (or in the model's own
    frame when it has no CRS, ``crs`` then ``"local"``); local = source - origin.
    ``notes`` are one-line remarks for the bake summary (e.g. that the file's space
    boundaries could not be used and portals were found from the geometry).
    """

    name: str
    crs: str
    origin: tuple[float, float, float]
    storeys: tuple[Storey, ...]
    rooms: tuple[Room, ...]
    openings: tuple[Opening, ...]
    stairs: tuple[Stair, ...]
    elements: tuple[Element, ...]
    source_format: str = ""
    issues: tuple[FeatureIssue, ...] = ()
    notes: tuple[str, ...] = field(default_factory=tuple)

    @property
    def triangles(self) -> int:
        """Triangles over every element."""
        return sum(len(e.triangles) for e in self.elements)


def mesh_footprint(vertices: ArrayLike, triangles: ArrayLike, *, min_area: float = 1e-6) -> shapely.Geometry:
    """The union of a mesh's triangles projected on the ground plane.

    Parameters
    ----------
    vertices : (n, 3) float
    triangles : (m, 3) int

    Returns
    -------
    shapely geometry
        A (Multi)Polygon; empty when every triangle is vertical.

    >>> v = [[0, 0, 0], [2, 0, 0], [2, 1, 0], [0, 1, 0], [0, 0, 1]]
    >>> round(mesh_footprint(v, [[0, 1, 2], [0, 2, 3], [0, 1, 4]]).area, 6)
    2.0
    """
    v = np.asarray(vertices, np.float64).reshape(-1, 3)
    t = np.asarray(triangles, np.int64).reshape(-1, 3)
    if len(t) == 0:
        return shapely.Polygon()
    tri = v[t][:, :, :2]
    polys = shapely.polygons(np.concatenate([tri, tri[:, :1]], axis=1))
    polys = polys[shapely.area(polys) > min_area]
    if len(polys) == 0:
        return shapely.Polygon()
    return shapely.make_valid(shapely.union_all(shapely.make_valid(polys)))
