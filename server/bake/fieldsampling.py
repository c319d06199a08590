"""Street and grid cells sampled from the dense visibility field (``--sampling field``).

The field of :mod:`.field` (a full spin at two eye heights from every free point of
a lattice, each point's visible set with its pixel counts) feeds the other cell
kinds too.  For street or grid cells the lattice is laid over the cells alone:
anchored at whole multiples of the spacing, a lattice point is a *field point of a
cell* when its square (the ``spacing`` x ``spacing`` square around it) meets the
cell in more than an edge, so

- a point inside the cell is one of its field points, and so is a point just
  outside it whose square reaches into it (the cell's *outline points*): the squares
  of a cell's field points cover every bit of its free space;
- a point exactly on the outline two cells share belongs to both (its square
  straddles the edge), the same way from either side;
- a point whose square meets the cells only inside a building (grown by the wall
  margin) is no field point: nothing is sampled inside a building, and a point that
  stands in one is rendered at a free point of its square inside the cells.

A cell's PVS is the union of its field points' visible sets, its ACH their pixel
counts summed (as a section's, :func:`~.sections.section_pvs`).  The field is
rendered once, in blocks by the one chunk runner, kept beside the database and
resumed block by block (:func:`~.field.bake_field`), whatever the cells.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import shapely

from walkstream.server.bake.field import (
    FIELD_HEIGHTS,
    FieldLattice,
    PointSets,
    built_space,
    lattice_from,
)
from walkstream.server.bake.viewcell import ViewCell
from walkstream.server.bake.visibility import VisibilityRenderer, pvs_from_counts
from walkstream.shared.arrays import F64, I64

__all__ = ["cell_field_counts", "cell_field_points", "cells_region", "field_cell_pvs", "sampling_lattice"]

def cells_region(cells: Sequence[ViewCell]) -> shapely.Geometry:
    """The union of the cells' outlines (where the field's lattice is laid)."""
    polys = shapely.make_valid(np.array([shapely.Polygon(np.asarray(c.polygon)) for c in cells], dtype=object))
    return shapely.union_all(polys)


def sampling_lattice(
    cells: Sequence[ViewCell],
    footprints: Sequence[shapely.Geometry],
    spacing: float,
    *,
    margin: float = 0.3,
    heights: tuple[float, float] = FIELD_HEIGHTS,
) -> FieldLattice:
    """The field points of ``cells`` every ``spacing`` metres (see the module docstring).

    Parameters
    ----------
    cells:
        The street or grid cells the field samples.
    footprints:
        The buildings' footprints (no point is rendered within ``margin`` of one).
    spacing, margin, heights:
        Lattice spacing (metres), wall margin, the two eye heights.
    """
    return lattice_from(built_space(footprints, margin), spacing, heights, within=cells_region(cells))


def cell_field_points(lattice: FieldLattice, polygon: F64) -> I64:
    """``(k,)`` the field points of the cell ``polygon`` ``(n, 2)``: their squares meet it.

    A point exactly on the outline belongs to the cell (and to its neighbour across
    that edge); a square that only touches the outline does not.
    """
    s, (x0, y0) = lattice.spacing, lattice.origin
    ny, nx = lattice.shape
    poly = shapely.Polygon(np.asarray(polygon, np.float64))
    bx0, by0, bx1, by1 = poly.bounds
    c0 = max(0, int(np.floor((bx0 - x0) / s - 0.5)))
    c1 = min(nx - 1, int(np.ceil((bx1 - x0) / s + 0.5)))
    r0 = max(0, int(np.floor((by0 - y0) / s - 0.5)))
    r1 = min(ny - 1, int(np.ceil((by1 - y0) / s + 0.5)))
    if c1 < c0 or r1 < r0:
        return np.zeros(0, np.int64)
    grid = lattice.grid()[r0 : r1 + 1, c0 : c1 + 1]
    rr, cc = np.nonzero(grid >= 0)
    if len(rr) == 0:
        return np.zeros(0, np.int64)
    x, y = x0 + (cc + c0) * s, y0 + (rr + r0) * s
    h = s / 2.0 - 1e-7 * s
    shapely.prepare(poly)
    hit = shapely.intersects(poly, shapely.box(x - h, y - h, x + h, y + h))
    out: I64 = np.sort(grid[rr[hit], cc[hit]]).astype(np.int64)
    return out


def field_cell_pvs(
    lattice: FieldLattice, sets: PointSets, cells: Sequence[ViewCell], *, threshold: int = 0
) -> list[tuple[int, I64, F64]]:
    """Every cell's ``(id, pvs, ach)``: the union of its field points' sets, pixels summed.

    A cell with no field point (all of it within a building's margin) gets an empty PVS.
    """
    out = []
    for c in cells:
        ids, px = sets.union(cell_field_points(lattice, np.asarray(c.polygon)))
        pvs, ach = pvs_from_counts(ids, px, threshold=threshold)
        out.append((c.id, pvs, ach))
    return out


def cell_field_counts(renderer: VisibilityRenderer, lattice: FieldLattice, polygon: F64) -> tuple[I64, I64, int]:
    """What the field gives one cell, rendered for that cell alone (``bench visibility``).

    The cell's field points (:func:`cell_field_points`) at both heights, one render.

    Returns
    -------
    ids, pixels : (k,) int64
        As :meth:`~.visibility.VisibilityRenderer.cell_counts`.
    points : int
        Field points rendered.
    """
    pts = cell_field_points(lattice, polygon)
    if len(pts) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), 0
    eyes = lattice.eyes[pts]
    xyz = np.vstack([np.column_stack([eyes, np.full(len(eyes), z)]) for z in lattice.heights])
    ids, pixels = renderer.cell_counts(xyz)
    return ids, pixels, len(pts)
