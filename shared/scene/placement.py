"""Contents kept in an interior's own frame, and the rigid move that places them in the scene.

A crossing scene holds a city and an interior placed in one of its buildings, turned
to the facade.  The interior's topology (cell planes, outlines, portals, stairs) is
stored and sent in the city's frame, since locating the eye and the portal walk need
it there; its room **contents** are stored and sent in the interior's own frame
(generated offices run along the axes there, which ``walkstream-cellmesh/3``'s boxes
and axis rectangles need), with one :class:`ContentsPlacement` per interior: a turn
about the vertical, a shift and a lift, and the range of cells it applies to.  The
client places each cell's contents once, where it stores them after decoding
(:meth:`ContentsPlacement.place`), so everything after sees placed meshes.

A scene without a placement (an interior alone, or a crossing scene baked before the
placement was stored) keeps its contents in the scene's frame: the identity.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.shared.codec.cellmesh import CellMesh, CellPart
from walkstream.shared.errors import CodecError

__all__ = ["ContentsPlacement", "placement_for"]


@dataclass(frozen=True)
class ContentsPlacement:
    """The move from an interior's own frame into the scene's, for the contents of cells
    ``cells[0]`` to ``cells[1]`` (inclusive): point ``(x, y, z)`` goes to
    ``(c x - s y + shift[0], s x + c y + shift[1], z + dz)`` with ``c, s`` the cosine and
    sine of ``angle`` (radians, counter-clockwise seen from above)."""

    angle: float
    shift: tuple[float, float]
    dz: float
    cells: tuple[int, int]

    def holds(self, cid: int) -> bool:
        """Whether cell ``cid``'s contents are in this placement's frame."""
        return self.cells[0] <= cid <= self.cells[1]

    def xyz(self, pts: ArrayLike) -> NDArray[np.float64]:
        """``(n, 3)`` points moved into the scene's frame (float64)."""
        p = np.asarray(pts, np.float64).reshape(-1, 3)
        c, s = math.cos(self.angle), math.sin(self.angle)
        return np.column_stack([c * p[:, 0] - s * p[:, 1] + self.shift[0], s * p[:, 0] + c * p[:, 1] + self.shift[1],
                                p[:, 2] + self.dz])

    def matrix(self) -> NDArray[np.float64]:
        """The ``(4, 4)`` model matrix of the move (column vectors)."""
        c, s = math.cos(self.angle), math.sin(self.angle)
        return np.array([[c, -s, 0.0, self.shift[0]], [s, c, 0.0, self.shift[1]], [0.0, 0.0, 1.0, self.dz],
                         [0.0, 0.0, 0.0, 1.0]])

    def place(self, mesh: CellMesh) -> CellMesh:
        """``mesh`` (a cell's contents as decoded, in the interior's frame) in the scene's
        frame: every part's positions moved (in float64, then float32 as decoded), the
        triangles as they were (a turn keeps their winding); ``lo`` and ``extent`` the box
        of the moved quantisation box, ``nbytes`` and ``grid`` as they were."""
        parts = tuple(CellPart(p.element, p.material, self.xyz(p.positions), p.indices) for p in mesh.parts)
        lo, ext = np.asarray(mesh.lo, np.float64), np.asarray(mesh.extent, np.float64)
        corners = lo + ext * np.array([[i & 1, (i >> 1) & 1, (i >> 2) & 1] for i in range(8)], np.float64)
        moved = self.xyz(corners)
        lo2 = moved.min(axis=0)
        ext2 = moved.max(axis=0) - lo2
        return replace(mesh, parts=parts, lo=(float(lo2[0]), float(lo2[1]), float(lo2[2])),
                       extent=(float(ext2[0]), float(ext2[1]), float(ext2[2])), _cache={})

    def to_wire(self) -> dict[str, Any]:
        """The placement as sent (``GET .../entrances``: an entrance's ``placement``)."""
        return {"angle": float(self.angle), "shift": [float(self.shift[0]), float(self.shift[1])],
                "dz": float(self.dz), "cells": [int(self.cells[0]), int(self.cells[1])]}

    @classmethod
    def from_wire(cls, obj: Any, what: str) -> ContentsPlacement:
        """A placement as sent, checked (finite numbers, an ordered range of cell ids).

        Raises
        ------
        CodecError
            A missing field, a number that is not finite, a bad range.
        """
        if not isinstance(obj, dict):
            raise CodecError(f"{what}: expected a map")
        try:
            angle, shift, dz, cells = obj["angle"], obj["shift"], obj["dz"], obj["cells"]
        except KeyError as exc:
            raise CodecError(f"{what}: has no {exc.args[0]!r}") from None
        nums = [angle, dz, *(shift if isinstance(shift, list | tuple) else ())]
        if (not isinstance(shift, list | tuple) or len(shift) != 2
                or not all(isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in nums)):
            raise CodecError(f"{what}: angle, shift [x, y] and dz must be finite numbers")
        if (not isinstance(cells, list | tuple) or len(cells) != 2
                or not all(type(v) is int and v >= 0 for v in cells) or cells[0] > cells[1]):
            raise CodecError(f"{what}: cells must be [first, last] cell ids, first <= last")
        return cls(float(angle), (float(shift[0]), float(shift[1])), float(dz), (int(cells[0]), int(cells[1])))


def placement_for(placements: Iterable[ContentsPlacement | None], cid: int) -> ContentsPlacement | None:
    """The placement whose cells hold ``cid`` (None: its contents are in the scene's frame)."""
    return next((p for p in placements if p is not None and p.holds(cid)), None)
