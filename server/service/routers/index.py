"""Routes of a scene's cell index: outlines, height ranges and adjacency of the cells, per tile.

The manifest's ``index`` is the tile grid (origin, tile side, shape, reach); a tile's
index lists the cells whose vertex mean lies in it.  A client that holds the tiles
around it follows the viewer from cell to cell and sees the cells ahead without a
request per cell.  Immutable per scene version: ETag, 304 and a year-long
Cache-Control like every other versioned resource.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Path, Request, Response

from walkstream.server.service.dependencies import RepDep, SceneDep
from walkstream.server.service.http import cached
from walkstream.server.service.models import ERRORS, CellIndexOut, both
from walkstream.shared.errors import ApiError

__all__ = ["router"]

router = APIRouter(prefix="/v1", responses=ERRORS)


@router.get(
    "/scenes/{scene}/index",
    response_model=CellIndexOut,
    responses=both("the cell index of the whole scene"),
    summary="Cell index of the scene",
)
async def scene_index(request: Request, scene: SceneDep, rep: RepDep) -> Response:
    """Every cell's outline, height range and neighbours (``tile`` null).

    For a small scene the same as its one tile; a large scene's is large: a client
    fetches the tiles it needs instead.
    """
    return cached(request, scene.index(None, rep))


@router.get(
    "/scenes/{scene}/index/{i}/{j}",
    response_model=CellIndexOut,
    responses=both("the cell index of one tile"),
    summary="Cell index of a tile",
)
async def tile_index(
    request: Request,
    scene: SceneDep,
    rep: RepDep,
    i: Annotated[int, Path(description="tile column, 0 at the grid's west edge")],
    j: Annotated[int, Path(description="tile row, 0 at the grid's south edge")],
) -> Response:
    """The outlines, height ranges and neighbours of the cells of tile ``(i, j)``."""
    if not scene.has_tile(i, j):
        nx, ny = scene.grid.shape
        raise ApiError(
            f"scene {scene.name!r} has no tile ({i}, {j}): the grid is {nx} x {ny}",
            status=404,
            detail={"tile": [i, j], "shape": [nx, ny]},
        )
    return cached(request, scene.index((i, j), rep))
