"""The view cell record of the bake, and what every cell kind shares: ids, neighbours, checks.

Every cell is a convex, counter-clockwise polygon in scene-local metres with a height
range (eye heights above the flat ground).  Cell ids are the cells' positions in the
list a partition returns; they are deterministic: cells are ordered by kind (in the
order of :data:`~walkstream.shared.cells.CELL_KINDS`) and then by centroid (y, then x,
rounded to a millimetre).  Neighbours share more than :data:`MIN_SHARED_EDGE` of
boundary.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import shapely
from numpy.typing import NDArray

from walkstream.server.sources.scene import SourceScene
from walkstream.shared.arrays import F64
from walkstream.shared.cells import CellLocator, outline_polygons
from walkstream.shared.errors import InputError
from walkstream.shared.geometry import signed_area
from walkstream.shared.records import readonly
from walkstream.shared.scene.cellkinds import CELL_KINDS

__all__ = [
    "MIN_SHARED_EDGE",
    "ViewCell",
    "cell_polygons",
    "cell_locator",
    "positive_metres",
    "check_height_range",
    "finish_cells",
    "footprint_polygons",
]


#: Cell kinds in id order.
#: Two cells are neighbours when their boundaries share more than this many metres.
MIN_SHARED_EDGE = 0.5


# --------------------------------------------------------------------------- records


@dataclass(frozen=True, slots=True)
class ViewCell:
    """One view cell.

    Attributes
    ----------
    id:
        Cell id, its index in the list the cell came in (non-negative).
    kind:
        ``"street"``, ``"crossroad"``, ``"square"`` or ``"grid"``.
    polygon:
        ``(n, 2) float64`` convex outline, counter-clockwise, scene-local metres, no
        repeated closing vertex; read-only.
    zmin, zmax:
        Range of eye heights (metres above the ground) the cell's PVS is valid for.
    neighbours:
        Ids of the adjacent cells, ascending.
    """

    id: int
    kind: str
    polygon: F64
    zmin: float
    zmax: float
    neighbours: tuple[int, ...]

    def __post_init__(self) -> None:
        if self.kind not in CELL_KINDS:
            raise InputError(f"ViewCell.kind: expected one of {CELL_KINDS}, got {self.kind!r}")
        poly = np.asarray(self.polygon, dtype=np.float64).reshape(-1, 2)
        if len(poly) < 3:
            raise InputError(f"ViewCell.polygon: expected >= 3 vertices, got {len(poly)}")
        if not float(self.zmin) <= float(self.zmax):
            raise InputError(f"ViewCell: zmin {self.zmin} > zmax {self.zmax}")
        object.__setattr__(self, "id", int(self.id))
        object.__setattr__(self, "polygon", readonly(poly))
        object.__setattr__(self, "zmin", float(self.zmin))
        object.__setattr__(self, "zmax", float(self.zmax))
        object.__setattr__(self, "neighbours", tuple(sorted(int(n) for n in self.neighbours)))

    @property
    def centroid(self) -> tuple[float, float]:
        """Area centroid ``(x, y)`` of the polygon (inside it: the cell is convex)."""
        return _centroid(self.polygon)

    @property
    def area(self) -> float:
        """Area in square metres."""
        return signed_area(self.polygon)


def cell_polygons(cells: Sequence[ViewCell]) -> NDArray[np.object_]:
    """The cells' outlines as a ``(n,)`` array of shapely Polygons (index = position)."""
    return outline_polygons([c.polygon for c in cells])


def cell_locator(cells: Sequence[ViewCell]) -> CellLocator:
    """A :class:`~walkstream.shared.cells.CellLocator` over the cells (ids as given)."""
    return CellLocator([c.id for c in cells], [c.polygon for c in cells])


# --------------------------------------------------------------------------- helpers


def positive_metres(name: str, value: float) -> float:
    """``value`` as a float, or an :class:`InputError` naming ``name`` when it is not positive and finite."""
    v = float(value)
    if not (math.isfinite(v) and v > 0):
        raise InputError(f"{name} must be a positive number of metres, got {value}")
    return v


def check_height_range(height_range: tuple[float, float]) -> tuple[float, float]:
    """``(zmin, zmax)`` as floats, checked: finite and ``0 <= zmin <= zmax``."""
    try:
        zmin, zmax = (float(z) for z in height_range)
    except (TypeError, ValueError) as exc:
        raise InputError(f"height_range must be (zmin, zmax), got {height_range!r}") from exc
    if not (math.isfinite(zmin) and math.isfinite(zmax) and 0 <= zmin <= zmax):
        raise InputError(f"height_range must satisfy 0 <= zmin <= zmax, got {height_range!r}")
    return zmin, zmax




def _centroid(ring: F64) -> tuple[float, float]:
    # relative to the first vertex: keeps precision far from the origin
    o = ring[0]
    p = ring - o
    q = np.roll(p, -1, axis=0)
    cr = p[:, 0] * q[:, 1] - q[:, 0] * p[:, 1]
    a = cr.sum()
    if abs(a) < 1e-15:
        c = p.mean(axis=0)
    else:
        c = ((p + q) * cr[:, None]).sum(axis=0) / (3.0 * a)
    return float(c[0] + o[0]), float(c[1] + o[1])


def finish_cells(parts: list[tuple[str, F64]], zmin: float, zmax: float) -> list[ViewCell]:
    """Order parts deterministically, find neighbours and build the cells."""
    order = sorted(
        range(len(parts)),
        key=lambda k: (
            CELL_KINDS.index(parts[k][0]),
            *(round(v, 3) for v in reversed(_centroid(parts[k][1]))),
            round(signed_area(parts[k][1]), 3),
        ),
    )
    parts = [parts[k] for k in order]
    # outlines of any vertex counts (shapely.polygons wants one (n, m, 2) array)
    polys = outline_polygons([p for _, p in parts])
    nbrs = _neighbours(polys)
    return [
        ViewCell(id=k, kind=kind, polygon=ring, zmin=zmin, zmax=zmax, neighbours=tuple(nbrs[k]))
        for k, (kind, ring) in enumerate(parts)
    ]


def _neighbours(polys: NDArray[np.object_]) -> list[list[int]]:
    """Pairs of polygons whose boundaries share more than MIN_SHARED_EDGE metres.

    Exact boundary intersection misses collinear edges whose vertices differ by
    rounding (a cut point lies on its square's edge only up to an ulp), so the shared
    length is measured as the length of one boundary inside the other polygon grown
    by a micrometre.
    """
    out: list[list[int]] = [[] for _ in range(len(polys))]
    if len(polys) < 2:
        return out
    grown = shapely.buffer(polys, 1e-6, quad_segs=1, join_style="mitre")
    i, j = shapely.STRtree(polys).query(grown, predicate="intersects")
    keep = i < j
    i, j = i[keep], j[keep]
    shared = shapely.length(shapely.intersection(shapely.boundary(polys[i]), grown[j]))
    for a, b in zip(i[shared > MIN_SHARED_EDGE], j[shared > MIN_SHARED_EDGE], strict=True):
        out[int(a)].append(int(b))
        out[int(b)].append(int(a))
    return [sorted(n) for n in out]


def footprint_polygons(scene: SourceScene) -> NDArray[np.object_]:
    """Building footprints as a ``(b,)`` array of shapely Polygons (holes kept)."""
    polys = [shapely.Polygon(b.rings[0], b.rings[1:]) for b in scene.buildings]
    return np.array(polys, dtype=object) if polys else np.empty(0, object)
