"""Routes of an interior: its topology, a cell's record, and a cell's contents.

``GET /v1/scenes/{scene}/topology``
    The topological file of Mulloni et al.: storeys, every cell (plane set, outline,
    height range, triangles and contents bytes), every portal (polygon and its two
    cells), every stair.  One request gives a client the whole visibility graph.
``GET /v1/scenes/{scene}/topology/packed``
    The same topology's msgpack body gzip-compressed (``walkstream-topology/1+gzip``,
    media type ``application/vnd.walkstream.topology+gzip``; decode with
    :func:`walkstream.shared.roomwire.decode_topology_packed`): about a seventh of the
    bytes, what a client on a slow link asks for first.
``GET /v1/scenes/{scene}/topology/compact``
    The same topology in millimetres with the planes rebuilt from the outlines
    (``walkstream-topology/2``, media type ``application/vnd.walkstream.topology-c2``;
    decode with :func:`walkstream.shared.roomcompact.decode_topology_compact`): half
    the packed one's bytes.
``GET /v1/scenes/{scene}/rooms/{cell}``
    One cell: planes, outline, portals (polygon and the other cell), neighbours and
    what its contents weigh.
``GET /v1/scenes/{scene}/rooms/{cell}/contents``
    The cell's geometry as one immutable blob (``walkstream-cellmesh/2``, media type
    ``application/vnd.walkstream.cellmesh``; decode with
    :func:`walkstream.shared.codec.decode_cell_mesh`): a cell is one request.

Each has a strong ETag and a year-long immutable Cache-Control (304 on a matching
``If-None-Match``).  A city scene answers them with a 404 that says so.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Path, Request, Response
from starlette.concurrency import run_in_threadpool

from walkstream.server.service.dependencies import RepDep, SceneDep
from walkstream.server.service.http import cached
from walkstream.server.service.interiors import CONTENTS_MEDIA, InteriorState
from walkstream.server.service.models import ERRORS, RoomOut, TopologyOut, both
from walkstream.server.service.scenes import Scene
from walkstream.shared.errors import ApiError
from walkstream.shared.roomcompact import TOPOLOGY_COMPACT_MEDIA
from walkstream.shared.roomwire import TOPOLOGY_PACKED_MEDIA

__all__ = ["router"]

router = APIRouter(prefix="/v1", responses=ERRORS)


def _interior(scene: Scene) -> InteriorState:
    if scene.interior is None:
        raise ApiError(
            f"scene {scene.name!r} is a {scene.kind}: it has no rooms (see its manifest's kind)",
            status=404,
            detail={"scene": scene.name, "kind": scene.kind},
        )
    return scene.interior


@router.get(
    "/scenes/{scene}/topology",
    response_model=TopologyOut,
    responses=both("the interior's storeys, cells, portals and stairs"),
    summary="Interior topology",
)
async def topology(request: Request, scene: SceneDep, rep: RepDep) -> Response:
    """Every cell as a plane set with its outline, every portal with its two cells."""
    return cached(request, _interior(scene).topology[rep])


@router.get(
    "/scenes/{scene}/topology/packed",
    responses={
        200: {"description": "the topology, gzip-compressed msgpack (walkstream-topology/1+gzip)",
              "content": {TOPOLOGY_PACKED_MEDIA: {}}},
        304: {"description": "not modified (If-None-Match matched the ETag)"},
    },
    summary="Interior topology, packed",
)
async def topology_packed(request: Request, scene: SceneDep) -> Response:
    """The topology's msgpack body gzip-compressed (the same bytes whatever ``Accept`` says)."""
    return cached(request, _interior(scene).topology_packed)


@router.get(
    "/scenes/{scene}/topology/compact",
    responses={
        200: {"description": "the topology in millimetres (walkstream-topology/2)",
              "content": {TOPOLOGY_COMPACT_MEDIA: {}}},
        304: {"description": "not modified (If-None-Match matched the ETag)"},
    },
    summary="Interior topology, compact",
)
async def topology_compact(request: Request, scene: SceneDep) -> Response:
    """The topology in millimetres (the same bytes whatever ``Accept`` says)."""
    return cached(request, _interior(scene).topology_compact)


@router.get(
    "/scenes/{scene}/rooms/{cell}",
    response_model=RoomOut,
    responses=both("the interior cell record"),
    summary="Interior cell record",
)
async def room(
    request: Request, scene: SceneDep, rep: RepDep, cell: Annotated[int, Path(description="cell id")]
) -> Response:
    """Planes, outline, portals (polygon and the other cell), neighbours, contents sizes."""
    state = _interior(scene)
    enc = state.cached_room(cell, rep)
    if enc is None:
        enc = state.room(cell, rep)
    return cached(request, enc)


@router.get(
    "/scenes/{scene}/rooms/{cell}/contents",
    responses={
        200: {"description": "the cell's geometry (walkstream-cellmesh/2; /1 from older bakes)", "content": {CONTENTS_MEDIA: {}}},
        304: {"description": "not modified (If-None-Match matched the ETag)"},
    },
    summary="Interior cell contents",
)
async def contents(request: Request, scene: SceneDep, cell: Annotated[int, Path(description="cell id")]) -> Response:
    """The cell's geometry as one immutable blob (the same bytes whatever ``Accept`` says)."""
    state = _interior(scene)
    enc = state.cached_contents(cell)
    if enc is None:  # a database read: in a worker thread, off the event loop
        enc = await run_in_threadpool(state.contents, cell)
    return cached(request, enc)
