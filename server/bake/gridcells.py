"""Grid cells (m-LOMA): the free space covered by a regular grid of squares.

Without street data the free space is covered by a regular grid of squares; a
square is kept when at least ``min_free`` of it is not covered by building
footprints.  Neighbours are the 4-connected kept squares.
"""

from __future__ import annotations

import math

import numpy as np
import shapely
from numpy.typing import NDArray

from walkstream.server.bake.viewcell import (
    ViewCell,
    check_height_range,
    footprint_polygons,
    positive_metres,
)
from walkstream.server.sources.scene import SourceScene
from walkstream.shared.arrays import F64
from walkstream.shared.errors import InputError

__all__ = ["grid_cells", "free_share"]


def grid_cells(
    scene: SourceScene,
    *,
    cell_size: float = 40.0,
    height_range: tuple[float, float] = (1.5, 2.0),
    min_free: float = 0.15,
    bbox: tuple[float, float, float, float] | None = None,
) -> list[ViewCell]:
    """Cover the free space with a regular grid of square cells (m-LOMA).

    The grid starts at the bbox's lower-left corner and has ``ceil(width / cell_size)``
    by ``ceil(height / cell_size)`` squares (the last row and column may reach past
    the bbox).  A square is kept when the part of it not covered by building
    footprints is at least ``min_free`` of its area (footprint overlaps, which real
    data has a few of, are counted twice: negligible, and it keeps this vectorised).

    Parameters
    ----------
    scene:
        The scene; its buildings are the obstacles.
    cell_size:
        Side of a grid square in metres.
    height_range:
        ``(zmin, zmax)`` eye heights the cells' PVSs are baked for.
    min_free:
        Smallest free share of a kept square, in ``[0, 1]``.
    bbox:
        ``(xmin, ymin, xmax, ymax)`` in scene-local metres; default the bounding box
        of the building footprints and the street pieces.

    Returns
    -------
    list[ViewCell]
        Kind ``"grid"`` cells ordered by row (south to north) then column (west to
        east); neighbours are the kept squares sharing an edge.

    Raises
    ------
    InputError
        If a parameter is out of range, or the scene is empty and no bbox is given.
    """
    cell_size = positive_metres("cell_size", cell_size)
    zmin, zmax = check_height_range(height_range)
    if not 0.0 <= float(min_free) <= 1.0:
        raise InputError(f"min_free must lie in [0, 1], got {min_free}")
    x0, y0, x1, y1 = _grid_bbox(scene, bbox)
    nx = max(1, math.ceil((x1 - x0) / cell_size - 1e-9))
    ny = max(1, math.ceil((y1 - y0) / cell_size - 1e-9))
    if nx * ny > 4_000_000:
        raise InputError(
            f"grid of {nx} x {ny} cells is too large; use a larger cell_size or a smaller bbox"
        )
    col_grid, row_grid = np.meshgrid(np.arange(nx), np.arange(ny))  # row-major: y then x
    cols, rows = col_grid.ravel(), row_grid.ravel()
    bx0 = x0 + cols * cell_size
    by0 = y0 + rows * cell_size
    boxes = shapely.box(bx0, by0, bx0 + cell_size, by0 + cell_size)
    free = free_share(boxes, footprint_polygons(scene))
    keep = free >= float(min_free) - 1e-12

    # id of each kept square by (row, col); -1 where dropped
    ids = np.full((ny + 2, nx + 2), -1, np.int64)  # padded so neighbours never wrap
    ids[rows[keep] + 1, cols[keep] + 1] = np.arange(int(keep.sum()))
    cells = []
    for cid, (r, c, xa, ya) in enumerate(
        zip(rows[keep], cols[keep], bx0[keep], by0[keep], strict=True)
    ):
        nb = ids[[r, r + 1, r + 1, r + 2], [c + 1, c, c + 2, c + 1]]
        xb, yb = xa + cell_size, ya + cell_size
        cells.append(
            ViewCell(
                id=cid,
                kind="grid",
                polygon=np.array([[xa, ya], [xb, ya], [xb, yb], [xa, yb]]),
                zmin=zmin,
                zmax=zmax,
                neighbours=tuple(int(n) for n in nb[nb >= 0]),
            )
        )
    return cells


def _grid_bbox(
    scene: SourceScene, bbox: tuple[float, float, float, float] | None
) -> tuple[float, float, float, float]:
    if bbox is not None:
        try:
            x0, y0, x1, y1 = (float(v) for v in bbox)
        except (TypeError, ValueError) as exc:
            raise InputError(f"bbox must be (xmin, ymin, xmax, ymax), got {bbox!r}") from exc
        if not all(map(math.isfinite, (x0, y0, x1, y1))) or not (x0 < x1 and y0 < y1):
            raise InputError(f"bbox must be finite with xmin < xmax and ymin < ymax, got {bbox!r}")
        return x0, y0, x1, y1
    # streets too: a walk along a street beyond the last building stays in the grid
    rings = [b.rings[0] for b in scene.buildings] + [s.ring for s in scene.streets]
    if not rings:
        raise InputError(f"scene {scene.name!r} has no buildings or streets: give a bbox")
    pts = np.concatenate(rings)
    (x0, y0), (x1, y1) = pts.min(axis=0), pts.max(axis=0)
    if not (x0 < x1 and y0 < y1):
        raise InputError(f"scene {scene.name!r} has a degenerate bounding box: give a bbox")
    return float(x0), float(y0), float(x1), float(y1)


def free_share(boxes: NDArray[np.object_], footprints: NDArray[np.object_]) -> F64:
    """``(n,)`` share of each polygon's area not covered by footprints."""
    area = shapely.area(boxes)
    built = np.zeros(len(boxes))
    if len(footprints) and len(boxes):
        b, f = shapely.STRtree(footprints).query(boxes, predicate="intersects")
        inter = shapely.area(shapely.intersection(boxes[b], footprints[f]))
        built = np.bincount(b, weights=inter, minlength=len(boxes)).astype(np.float64)
    return np.clip(1.0 - built / np.maximum(area, 1e-300), 0.0, 1.0)
