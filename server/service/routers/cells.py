"""Routes of a scene's view cells: which cell holds a position, a cell's record, records in batches."""

from __future__ import annotations

from typing import Annotated

import msgpack
from fastapi import APIRouter, Path, Query, Request, Response
from fastapi.responses import StreamingResponse
from starlette.concurrency import run_in_threadpool

from walkstream.server.service.dependencies import RepDep, SceneDep
from walkstream.server.service.http import cached, dump_json, stream_response
from walkstream.server.service.models import (
    ERRORS,
    CellOut,
    CellsIn,
    LocateOut,
    both,
    error_doc,
)
from walkstream.server.service.routers.objects import MAX_BODY_BYTES, coalesce, parse_ids, read_body
from walkstream.server.service.scenes import MAX_IDS
from walkstream.shared.errors import ApiError
from walkstream.shared.wire import JSON, MSGPACK, CellRecord, cell_from_wire

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
    """The cell's own data: PVS ids (delta-coded) and ACH (units of 1/65535).

    Outlines, height ranges and neighbours are in the cell index (``.../index``).
    """
    if not scene.has_cell(cell):
        raise ApiError(
            f"scene {scene.name!r} has no cell {cell}", status=404, detail={"cell": cell}
        )
    enc = scene.cached_cell(cell, rep)
    if enc is None:  # a database read: in a worker thread, off the event loop
        enc = await run_in_threadpool(scene.cell, cell, rep)
    return cached(request, enc)


_CELLS_BODY = {
    "required": True,
    "content": {
        JSON: {"schema": CellsIn.model_json_schema()},
        MSGPACK: {"schema": CellsIn.model_json_schema()},
    },
}


@router.post(
    "/scenes/{scene}/cells",
    responses={
        200: {
            "description": "concatenated msgpack cell records (as GET .../cells/{id} sends "
            "them), one per id in the order asked; a JSON array with Accept: application/json",
            "content": {MSGPACK: {}, JSON: {}},
        },
        400: error_doc("the body is not JSON / msgpack"),
        413: error_doc(f"a body over {MAX_BODY_BYTES} bytes"),
        422: error_doc(f"not an object {{\"ids\": [...]}} of at most {MAX_IDS} integers"),
        415: error_doc("a Content-Type other than JSON or msgpack"),
    },
    openapi_extra={"requestBody": _CELLS_BODY},
    summary="Cell records in a batch",
)
async def cell_records(request: Request, scene: SceneDep, rep: RepDep) -> StreamingResponse:
    """The records of the cells asked for (body ``{"ids": [...]}``), streamed in the order asked.

    One request for the cells ahead instead of one per cell: on a 500 ms link every
    request saved is a round trip and a few hundred bytes of headers.
    """
    ids = parse_ids(await read_body(request), request.headers.get("content-type"))
    unknown = scene.unknown_cells(ids)
    if unknown:
        shown = ", ".join(str(i) for i in unknown[:10]) + (", ..." if len(unknown) > 10 else "")
        raise ApiError(
            f"scene {scene.name!r} has no cell{'s' if len(unknown) > 1 else ''} {shown}",
            status=404,
            detail={"ids": unknown},
        )
    bodies = await run_in_threadpool(scene.cells, ids)
    headers = {"X-Scene-Version": scene.version, "X-Cell-Count": str(len(ids))}
    if rep == "json":
        return stream_response(request, coalesce(_json_records(bodies)), JSON, headers)
    return stream_response(request, coalesce(bodies), MSGPACK, headers)


def _json_records(bodies: list[bytes]) -> list[bytes]:
    """The JSON array of the records (plain integer lists), one element per line."""
    out = [b"["]
    for k, b in enumerate(bodies):
        rec: CellRecord = cell_from_wire(msgpack.unpackb(b), "cell record")
        out.append((b",\n" if k else b"\n") + dump_json(rec.to_wire(compact=False)))
    out.append(b"\n]\n")
    return out
