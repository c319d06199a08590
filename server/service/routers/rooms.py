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
``GET /v1/scenes/{scene}/entrances``
    A crossing scene's entrances: per entrance its portal, the city object it stands
    for (``building``), the street cell and the doorway it joins, and the cell whose
    contents are drawn for the building (``shell``), and the ``placement`` that moves
    the interior's contents from its own frame into the scene's (absent for a crossing
    scene baked before, whose contents are stored moved); an empty list for an interior.
``GET /v1/scenes/{scene}/rooms/{cell}``
    One cell: planes, outline, portals (polygon and the other cell), neighbours and
    what its contents weigh.
``GET /v1/scenes/{scene}/rooms/{cell}/contents``
    The cell's geometry as one immutable blob (``walkstream-cellmesh/2``, media type
    ``application/vnd.walkstream.cellmesh``; decode with
    :func:`walkstream.shared.codec.decode_cell_mesh`): a cell is one request.
``POST /v1/scenes/{scene}/rooms/contents``
    Many cells' contents in one answer (``walkstream-cellbatch/1``, see
    :mod:`walkstream.shared.codec.cellbatch`): body ``{"ids": [...]}`` (JSON or msgpack,
    at most :data:`~walkstream.shared.codec.cellbatch.CELLBATCH_MAX_CELLS` ids, no
    duplicates), answer a stream of ``{cell, etag, body}`` maps in the order asked.
    gzip-compressed when the client accepts it, the blobs inflated and compressed
    together and flushed after each part: one round trip and one set of headers for
    the cells a walk needs, a fifth fewer body bytes than the blobs one by one.

Each GET has a strong ETag and a year-long immutable Cache-Control (304 on a matching
``If-None-Match``).  A city scene answers them with a 404 that says so.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import AsyncIterator
from typing import Annotated

from fastapi import APIRouter, Path, Request, Response
from fastapi.responses import StreamingResponse
from starlette.concurrency import run_in_threadpool

from walkstream.server.service.contentsform import STREAM_LEVEL, ContentsStream
from walkstream.server.service.dependencies import RepDep, SceneDep
from walkstream.server.service.http import accepts_gzip, cached, stream_response
from walkstream.server.service.interiors import InteriorState
from walkstream.server.service.models import (
    CONTENTS_BATCH_BODY,
    ERRORS,
    RoomOut,
    TopologyOut,
    both,
    error_doc,
)
from walkstream.server.service.routers.objects import MAX_BODY_BYTES, parse_ids, read_body
from walkstream.server.service.scenes import Scene
from walkstream.shared.codec.cellbatch import CELLBATCH_MAX_CELLS
from walkstream.shared.content.cellmesh import CONTENTS_MEDIA
from walkstream.shared.errors import ApiError
from walkstream.shared.roomcompact import TOPOLOGY_COMPACT_MEDIA
from walkstream.shared.roomwire import TOPOLOGY_PACKED_MEDIA
from walkstream.shared.wire import MSGPACK

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
    "/scenes/{scene}/entrances",
    responses=both("the entrances joining streets to rooms"),
    summary="Entrances of a crossing scene",
)
async def entrances(request: Request, scene: SceneDep, rep: RepDep) -> Response:
    """Portal, building, street cell, doorway and shell cell of each entrance."""
    return cached(request, _interior(scene).entrances[rep])


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


@router.post(
    "/scenes/{scene}/rooms/contents",
    responses={
        200: {
            "description": "concatenated msgpack maps {cell, etag, body} (walkstream-cellbatch/1), one per "
            "id in the order asked; body is the cell's walkstream-cellmesh blob, inflated to its N form "
            "when the answer is gzip-compressed (the stream compressed together, flushed after each part)",
            "content": {MSGPACK: {}},
        },
        400: error_doc("the body is not JSON / msgpack"),
        404: error_doc("an id that is no cell of the interior, or a scene without rooms"),
        413: error_doc(f"a body over {MAX_BODY_BYTES} bytes"),
        415: error_doc("a Content-Type other than JSON or msgpack"),
        422: error_doc(f"ids not a list of at most {CELLBATCH_MAX_CELLS} integers, or an id asked twice"),
    },
    openapi_extra={"requestBody": CONTENTS_BATCH_BODY},
    summary="Interior cells' contents in a batch",
)
async def contents_batch(request: Request, scene: SceneDep) -> StreamingResponse:
    """The contents of the cells asked for (body ``{"ids": [...]}``), streamed in the order asked.

    One request for every missing cell instead of one per cell: on a 56 kbit/s link the
    headers of 21 single answers are 4.3 kB, and 21 blobs compressed together are a fifth
    smaller than compressed one by one (the same bytes whatever ``Accept`` says).
    """
    state = _interior(scene)
    ids = parse_ids(await read_body(request), request.headers.get("content-type"))
    if len(ids) > CELLBATCH_MAX_CELLS:
        raise ApiError(
            f"{len(ids)} cells asked, at most {CELLBATCH_MAX_CELLS} per batch: split the batch",
            status=422,
            detail={"count": len(ids), "limit": CELLBATCH_MAX_CELLS},
        )
    twice = [i for i, n in Counter(ids).items() if n > 1]
    if twice:
        raise ApiError(
            f"ids: cell {twice[0]} asked more than once (each cell once per batch)",
            status=422,
            detail={"ids": twice[:100]},
        )
    unknown = [i for i in ids if not state.has(i)]
    if unknown:
        shown = ", ".join(str(i) for i in unknown[:10]) + (", ..." if len(unknown) > 10 else "")
        raise ApiError(
            f"scene {scene.name!r} has no cell{'s' if len(unknown) > 1 else ''} {shown}",
            status=404,
            detail={"ids": unknown[:100]},
        )
    inflate = accepts_gzip(request.headers.get("accept-encoding"))
    headers = {"X-Scene-Version": scene.version, "X-Cell-Count": str(len(ids))}
    # level 9: 1 % smaller than 6 on the office's start cells, and the server's cost is small
    return stream_response(request, _parts(state, ids, inflate), MSGPACK, headers, level=STREAM_LEVEL)


async def _parts(state: InteriorState, ids: list[int], inflate: bool) -> AsyncIterator[bytes]:
    """Each cell's part, read (off the event loop on a cache miss) as the stream goes, so
    the first part leaves before the last blob is read; one piece per part, so the
    gzip stream is flushed after each; in a gzip stream, each in its cheaper form there."""
    stream = ContentsStream(STREAM_LEVEL) if inflate else None
    for cid in ids:
        if state.cached_contents(cid) is None:
            await run_in_threadpool(state.contents, cid)
        yield state.contents_part(cid, inflate, stream)
