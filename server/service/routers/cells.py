"""Routes of a scene's view cells: which cell holds a position, and a cell's record."""


from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Path, Query, Request, Response
from starlette.concurrency import run_in_threadpool

from walkstream.server.service.dependencies import RepDep, SceneDep
from walkstream.server.service.http import cached
from walkstream.server.service.models import (
    ERRORS,
    CellOut,
    LocateOut,
    both,
)
from walkstream.shared.errors import ApiError

__all__ = ["router"]

router = APIRouter(prefix="/v1", responses=ERRORS)


@router.get(
    "/scenes/{scene}/locate",
    response_model=LocateOut,
    responses=both("the cell containing the position, or cell null and the reason"),
    summary="Locate a position",
)
async def locate(
    request: Request,
    scene: SceneDep,
    rep: RepDep,
    x: Annotated[float, Query(allow_inf_nan=False, description="scene-local metres")],
    y: Annotated[float, Query(allow_inf_nan=False, description="scene-local metres")],
    z: Annotated[
        float | None,
        Query(allow_inf_nan=False, description="height (eye), metres: in an interior it picks the storey"),
    ] = None,
) -> Response:
    """The id of the cell that contains ``(x, y)`` (in an interior, at height ``z``).

    A position outside every cell is a normal answer (200, ``cell: null``), not an
    error: a walker may step off the navigation space.
    """
    return cached(request, scene.locate(x, y, rep, z))


@router.get(
    "/scenes/{scene}/cells/{cell}",
    response_model=CellOut,
    responses=both("the cell record"),
    summary="Cell record",
)
async def cell_record(
    request: Request,
    scene: SceneDep,
    rep: RepDep,
    cell: Annotated[int, Path(description="cell id")],
) -> Response:
    """Boundary, height range, neighbours with their boundaries, PVS ids and ACH."""
    if not scene.has_cell(cell):
        raise ApiError(f"scene {scene.name!r} has no cell {cell}", status=404, detail={"cell": cell})
    enc = scene.cached_cell(cell, rep)
    if enc is None:  # a database read: in a worker thread, off the event loop
        enc = await run_in_threadpool(scene.cell, cell, rep)
    return cached(request, enc)
