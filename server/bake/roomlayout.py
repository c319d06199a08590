"""An interior's layout as the bake hands it on: room cells, portals, stairs.

:func:`~walkstream.server.bake.rooms.room_layout` builds a :class:`RoomLayout`; the
interior's plan, its walks, its navigation graph, its virtual walls and the placement of
an interior into a city read it.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import shapely
from numpy.typing import NDArray

from walkstream.shared.arrays import F64

__all__ = [
    "PORTAL_KINDS",
    "WALKABLE",
    "RoomCell",
    "Portal",
    "StairLink",
    "RoomLayout",
    "portal_counts",
]

PORTAL_KINDS = ("door", "window", "opening", "virtual", "split", "void", "stair", "wall")
"""Kinds of portals: door, window, opening (an empty hole or an open stretch of a
room's edge), virtual (an open boundary of the source), split (between convex parts
of one room), void (a hole in a floor), stair (a hole a stair climbs through) and
wall (a textured virtual wall across an open room, baked with ``--virtual-walls``)."""

WALKABLE = frozenset({"door", "opening", "virtual", "split", "stair", "wall"})
"""Portals a walker may pass (a stair portal only along its stair)."""


@dataclass(frozen=True)
class RoomCell:
    """A convex cell: ``outline`` ``(n, 2)`` CCW, volume ``zmin``..``zmax``, ``planes``
    ``(k, 4)`` (:func:`~.roomgeom.cell_planes`; empty for the outside cell)."""

    id: int
    kind: str
    name: str
    room: str | None
    storey: int
    outline: F64
    zmin: float
    zmax: float
    planes: F64

    @cached_property
    def polygon(self) -> shapely.Polygon:
        """The outline as a shapely polygon (made once)."""
        return shapely.Polygon(self.outline)

    def holds(self, xy: F64, z: float, tol: float = 1e-6) -> bool:
        """Whether ``(x, y, z)`` is in the cell (its side planes and height range)."""
        if not self.zmin - tol <= z < self.zmax or len(self.planes) < 3:
            return False
        side = self.planes[:-2]
        return bool(np.all(side[:, 0] * xy[0] + side[:, 1] * xy[1] + side[:, 3] <= tol))


@dataclass(frozen=True)
class Portal:
    """A portal: ``polygon`` ``(k, 3)`` between cells ``a`` and ``b``."""

    id: int
    kind: str
    a: int
    b: int
    polygon: F64
    source: str
    name: str = ""

    @property
    def walkable(self) -> bool:
        """Whether a walker may pass it."""
        return self.kind in WALKABLE


@dataclass(frozen=True)
class StairLink:
    """A stair: the portal it climbs through, its lower and upper cell, and its
    walking line ``(k, 3)`` (floor points, bottom to top)."""

    portal: int
    lower: int
    upper: int
    path: F64
    name: str = ""


@dataclass
class RoomLayout:
    """Cells, portals and stairs of an interior, plus what the bake should report."""

    cells: list[RoomCell]
    portals: list[Portal]
    stairs: list[StairLink]
    ranges: F64
    """``(storeys, 2)`` the height range of each storey's cells."""
    notes: list[str] = field(default_factory=list)
    sources: Counter[str] = field(default_factory=Counter)
    """Portals by where their two sides came from (boundary, geometry, file, split, ...)."""

    @property
    def outside(self) -> int:
        """Id of the outside cell."""
        return self.cells[-1].id


def portal_counts(layout: RoomLayout) -> NDArray[np.int64]:
    """Portals per cell, ``(cells,)``."""
    n = np.zeros(len(layout.cells), np.int64)
    for p in layout.portals:
        n[p.a] += 1
        n[p.b] += 1
    return n
