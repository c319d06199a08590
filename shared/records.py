"""Scene records shared by server and client.

Records are frozen, slotted dataclasses.  Geometry is numpy arrays in scene-local
metres (float64 for footprints; the server keeps the CRS origin separately) and the
arrays are made read-only so caches can hand them out safely.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from walkstream.shared.areakinds import AREA_KINDS
from walkstream.shared.arrays import F64
from walkstream.shared.errors import InputError
from walkstream.shared.landmarks import crown_top, shortest_edge

__all__ = ["AreaParams", "BuildingParams", "StreetParams", "Mesh", "Viewpoint", "readonly"]



def readonly(a: NDArray[Any]) -> NDArray[Any]:
    """Return ``a`` (contiguous) with its write flag cleared."""
    a = np.ascontiguousarray(a)
    a.flags.writeable = False
    return a


def _oriented(
    rings: tuple[F64, ...], heights: tuple[F64, ...]
) -> tuple[tuple[F64, ...], tuple[F64, ...]]:
    """Exterior counter-clockwise, holes clockwise; per-edge values follow their edges."""
    out_r, out_h = [], []
    for k, (r, h) in enumerate(zip(rings, heights, strict=True)):
        x, y = r[:, 0] - r[0, 0], r[:, 1] - r[0, 1]
        nxt = np.arange(1, len(x) + 1) % len(x)  # np.roll(-1) by index (cheaper on small rings)
        area2 = float(np.dot(x, y[nxt]) - np.dot(x[nxt], y))
        if area2 != 0 and (area2 > 0) != (k == 0):
            # reversing a ring turns edge i (v_i -> v_i+1) into edge n-2-i
            r = readonly(r[::-1])
            h = readonly(np.roll(h[::-1], -1))
        out_r.append(r)
        out_h.append(h)
    return tuple(out_r), tuple(out_h)


@dataclass(frozen=True, slots=True)
class BuildingParams:
    """The compact procedural description of one building.

    Attributes
    ----------
    id:
        Object id, unique in a scene (non-negative int).
    rings:
        Footprint rings, each ``(n, 2) float64`` in scene-local metres, without a
        repeated closing vertex.  ``rings[0]`` is the exterior, counter-clockwise;
        the others are holes (courtyards), clockwise.  Edge ``i`` of a ring runs from
        vertex ``i`` to vertex ``(i + 1) % n``; its outward normal is to its right.
    neighbour_heights:
        One ``(n,) float64`` array per ring: the height in metres of the neighbour
        building behind each edge (0 where the edge is a free frontage).
    floors:
        Number of floors, at least 1.
    floor_height:
        Height of one floor in metres (> 0).
    style:
        Style seed; the grammar may vary the facade with it.
    kind:
        0 for an ordinary building, else a landmark kind
        (:mod:`walkstream.shared.landmarks`: 1 tower, 2 spire) whose crown the grammar
        builds above the eaves.
    source_id:
        The id of the feature the building came from (for error reports).
    """

    id: int
    rings: tuple[F64, ...]
    neighbour_heights: tuple[F64, ...]
    floors: int
    floor_height: float
    style: int = 0
    source_id: str = ""
    kind: int = 0

    def __post_init__(self) -> None:
        if len(self.rings) == 0:
            raise InputError("BuildingParams.rings: expected at least one ring, got none")
        if len(self.neighbour_heights) != len(self.rings):
            raise InputError(
                f"BuildingParams.neighbour_heights: expected {len(self.rings)} arrays "
                f"(one per ring), got {len(self.neighbour_heights)}"
            )
        rings = tuple(readonly(np.asarray(r, dtype=np.float64).reshape(-1, 2)) for r in self.rings)
        nbs = tuple(readonly(np.asarray(h, dtype=np.float64).reshape(-1)) for h in self.neighbour_heights)
        for k, (r, h) in enumerate(zip(rings, nbs, strict=True)):
            if len(r) < 3:
                raise InputError(f"BuildingParams.rings[{k}]: expected >= 3 vertices, got {len(r)}")
            if len(h) != len(r):
                raise InputError(
                    f"BuildingParams.neighbour_heights[{k}]: expected {len(r)} values, got {len(h)}"
                )
        rings, nbs = _oriented(rings, nbs)
        if int(self.floors) < 1:
            raise InputError(f"BuildingParams.floors: expected >= 1, got {self.floors}")
        if not float(self.floor_height) > 0:
            raise InputError(f"BuildingParams.floor_height: expected > 0, got {self.floor_height}")
        object.__setattr__(self, "rings", rings)
        object.__setattr__(self, "neighbour_heights", nbs)
        object.__setattr__(self, "floors", int(self.floors))
        object.__setattr__(self, "floor_height", float(self.floor_height))
        object.__setattr__(self, "style", int(self.style))
        object.__setattr__(self, "kind", int(self.kind))
        crown_top(self.kind, 0.0, 0.0)  # names a bad kind

    @property
    def height(self) -> float:
        """Total height in metres (floors times floor height)."""
        return self.floors * self.floor_height

    @property
    def top(self) -> float:
        """Height in metres of the highest point the grammar builds: the eaves, or a landmark's crown."""
        if self.kind == 0:
            return self.height
        return crown_top(self.kind, self.height, shortest_edge(self.rings[0]))


@dataclass(frozen=True, slots=True)
class StreetParams:
    """A street piece, crossroad or square: a flat procedural ground object.

    ``kind`` is ``"street"``, ``"crossroad"`` or ``"square"``; ``ring`` is its outline,
    ``(n, 2) float64``, counter-clockwise, scene-local metres; ``width`` is the street
    width in metres (for a crossroad, the widest street meeting there).
    """

    id: int
    kind: str
    ring: F64
    width: float
    source_id: str = ""

    def __post_init__(self) -> None:
        if self.kind not in ("street", "crossroad", "square"):
            raise InputError(f"StreetParams.kind: expected street|crossroad|square, got {self.kind!r}")
        object.__setattr__(self, "ring", readonly(np.asarray(self.ring, dtype=np.float64).reshape(-1, 2)))
        object.__setattr__(self, "width", float(self.width))


@dataclass(frozen=True, slots=True)
class AreaParams:
    """A typed flat area on the ground: grass, water, parking, ... (:mod:`walkstream.shared.areas`).

    ``kind`` is one of :data:`~walkstream.shared.areas.AREA_KINDS`; ``rings`` its
    polygon, each ``(n, 2) float64`` scene-local metres without a repeated closing
    vertex, the exterior first (counter-clockwise), then the holes (clockwise): an
    island in a lake is a hole of the lake.
    """

    id: int
    kind: str
    rings: tuple[F64, ...]
    source_id: str = ""

    def __post_init__(self) -> None:
        if self.kind not in AREA_KINDS:
            raise InputError(f"AreaParams.kind: expected one of {', '.join(AREA_KINDS)}, got {self.kind!r}")
        rings = tuple(readonly(np.asarray(r, dtype=np.float64).reshape(-1, 2)) for r in self.rings)
        if not rings:
            raise InputError("AreaParams.rings: expected at least one ring, got none")
        for k, r in enumerate(rings):
            if len(r) < 3:
                raise InputError(f"AreaParams.rings[{k}]: expected >= 3 vertices, got {len(r)}")
        out = []
        for k, r in enumerate(rings):  # exterior counter-clockwise, holes clockwise
            x, y = r[:, 0], r[:, 1]
            ccw = float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y)) > 0
            out.append(r if ccw == (k == 0) else readonly(r[::-1]))
        object.__setattr__(self, "rings", tuple(out))


@dataclass(frozen=True, slots=True)
class Mesh:
    """A GPU-ready triangle mesh with flat-shaded faces.

    Attributes
    ----------
    positions: ``(n, 3) float32`` vertex positions (x east, y north, z up), scene-local metres.
    normals: ``(n, 3) float32`` unit vertex normals.
    indices: ``(m, 3) uint32`` triangles, counter-clockwise seen from outside.
    materials: ``(n,) uint8`` material id per vertex (wall, window, door, roof, ...),
        used for colouring; not counted as GPU bytes.
    """

    # typed loosely: any numeric array is accepted and converted in __post_init__
    positions: NDArray[Any]
    normals: NDArray[Any]
    indices: NDArray[Any]
    materials: NDArray[Any] = field(default_factory=lambda: np.zeros(0, np.uint8))

    def __post_init__(self) -> None:
        p = readonly(np.asarray(self.positions, dtype=np.float32).reshape(-1, 3))
        n = readonly(np.asarray(self.normals, dtype=np.float32).reshape(-1, 3))
        i = readonly(np.asarray(self.indices, dtype=np.uint32).reshape(-1, 3))
        m = np.asarray(self.materials, dtype=np.uint8).reshape(-1)
        if len(m) == 0:
            m = np.zeros(len(p), np.uint8)
        m = readonly(m)
        if len(n) != len(p) or len(m) != len(p):
            raise InputError(
                f"Mesh: positions, normals and materials must have the same length, got "
                f"{len(p)}, {len(n)}, {len(m)}"
            )
        object.__setattr__(self, "positions", p)
        object.__setattr__(self, "normals", n)
        object.__setattr__(self, "indices", i)
        object.__setattr__(self, "materials", m)

    @property
    def triangles(self) -> int:
        """Number of triangles."""
        return int(len(self.indices))

    @property
    def gpu_bytes(self) -> int:
        """Bytes of float32 positions and normals plus uint32 indices."""
        return int(self.positions.nbytes + self.normals.nbytes + self.indices.nbytes)

    @staticmethod
    def concat(meshes: list[Mesh]) -> Mesh:
        """Join meshes into one (indices re-based)."""
        if not meshes:
            return Mesh(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)))
        offsets = np.cumsum([0] + [len(m.positions) for m in meshes[:-1]])
        return Mesh(
            np.concatenate([m.positions for m in meshes]),
            np.concatenate([m.normals for m in meshes]),
            np.concatenate([m.indices + np.uint32(o) for m, o in zip(meshes, offsets, strict=True)]),
            np.concatenate([m.materials for m in meshes]),
        )


@dataclass(frozen=True, slots=True)
class Viewpoint:
    """A named start position for a walkthrough.

    ``x, y, z`` in scene-local metres (``z`` = eye height above the ground); ``yaw`` in
    radians, 0 looking east (+x), counter-clockwise; ``cell`` is the id of the cell the
    position lies in (``None``: outside every cell).
    """

    name: str
    x: float
    y: float
    z: float
    yaw: float
    cell: int | None
