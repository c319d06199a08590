"""Routes of an interior's textured virtual walls: the wall sides, and their textures one by one or in a batch.

``GET /v1/scenes/{scene}/walls``
    Every wall side: ``{"sides": [row, ...]}``, each row the numbers of
    :meth:`~walkstream.shared.walls.WallSide.to_row` (portal, side, ends, heights,
    floor, ``x_T``, blend, sampling depth, angle of error, zones, then one texture id
    per zone); JSON or msgpack by ``Accept``, with an ETag and a 304.
``GET /v1/scenes/{scene}/walls/textures/{texture}``
    One texture as stored (``image/webp``, straight alpha, premultiplied on decoding),
    immutable, with an ETag and a 304.
``POST /v1/scenes/{scene}/walls/textures``
    Many textures in one answer: body ``{"ids": [...]}``, answer the parts of the
    contents batch (:mod:`walkstream.shared.codec.cellbatch`, ``cell`` the texture id).

A scene baked without ``--virtual-walls`` (every database from before them) has none:
each route answers 404 saying so.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import AsyncIterator
from typing import Annotated

from fastapi import APIRouter, Path, Request, Response
from fastapi.responses import StreamingResponse
from starlette.concurrency import run_in_threadpool

from walkstream.server.service.dependencies import RepDep, SceneDep
from walkstream.server.service.http import cached, stream_response
from walkstream.server.service.models import CONTENTS_BATCH_BODY, ERRORS, both, error_doc
from walkstream.server.service.routers.objects import MAX_BODY_BYTES, parse_ids, read_body
from walkstream.server.service.scenes import Scene
from walkstream.shared.codec.cellbatch import CELLBATCH_MAX_CELLS, pack_contents_part
from walkstream.shared.content.walltex import WALLTEX_MEDIA
from walkstream.shared.errors import ApiError
from walkstream.shared.wire import MSGPACK

__all__ = ["router"]

router = APIRouter(prefix="/v1", responses=ERRORS)


def _check(scene: Scene, ids: list[int]) -> None:
    """404 for a scene without walls or a texture it lacks (a clear line, never a 500)."""
    if not scene.has_walls:
        raise ApiError(
            f"scene {scene.name!r} has no virtual walls (baked without --virtual-walls)",
            status=404, detail={"walls": 0},
        )
    unknown = [i for i in ids if i not in scene.wall_texture_ids]
    if unknown:
        shown = ", ".join(str(i) for i in unknown[:10]) + (", ..." if len(unknown) > 10 else "")
        raise ApiError(
            f"scene {scene.name!r} has no wall texture{'s' if len(unknown) > 1 else ''} {shown}",
            status=404, detail={"ids": unknown[:100]},
        )


@router.get(
    "/scenes/{scene}/walls",
    responses={**both("every wall side with its zones and texture ids"),
               404: error_doc("a scene baked without virtual walls")},
    summary="Virtual walls",
)
async def walls(request: Request, scene: SceneDep, rep: RepDep) -> Response:
    """Every wall side of the scene (``WallSide.to_row`` lists)."""
    _check(scene, [])
    return cached(request, scene.walls[rep])


@router.get(
    "/scenes/{scene}/walls/textures/{texture}",
    responses={
        200: {"description": "the texture (WebP, straight alpha)", "content": {WALLTEX_MEDIA: {}}},
        304: {"description": "not modified (If-None-Match matched the ETag)"},
        404: error_doc("no such texture, or a scene baked without virtual walls"),
    },
    summary="Wall texture",
)
async def wall_texture(
    request: Request, scene: SceneDep, texture: Annotated[int, Path(description="texture id")]
) -> Response:
    """One wall texture as stored: immutable (the same bytes whatever ``Accept`` says)."""
    _check(scene, [texture])
    enc = scene.cached_wall_texture(texture)
    if enc is None:  # a database read: in a worker thread, off the event loop
        enc = await run_in_threadpool(scene.wall_texture, texture)
    return cached(request, enc)


@router.post(
    "/scenes/{scene}/walls/textures",
    responses={
        200: {
            "description": "concatenated msgpack maps {cell, etag, body} (walkstream-cellbatch/1), one per "
            "id in the order asked: cell is the texture id, body the image file, etag the one GET sends",
            "content": {MSGPACK: {}},
        },
        400: error_doc("the body is not JSON / msgpack"),
        404: error_doc("an id that is no texture of the scene, or a scene baked without virtual walls"),
        413: error_doc(f"a body over {MAX_BODY_BYTES} bytes"),
        415: error_doc("a Content-Type other than JSON or msgpack"),
        422: error_doc(f"ids not a list of at most {CELLBATCH_MAX_CELLS} integers, or an id asked twice"),
    },
    openapi_extra={"requestBody": CONTENTS_BATCH_BODY},
    summary="Wall textures in a batch",
)
async def wall_textures(request: Request, scene: SceneDep) -> StreamingResponse:
    """The textures asked for (body ``{"ids": [...]}``), streamed in the order asked."""
    ids = parse_ids(await read_body(request), request.headers.get("content-type"))
    if len(ids) > CELLBATCH_MAX_CELLS:
        raise ApiError(
            f"{len(ids)} textures asked, at most {CELLBATCH_MAX_CELLS} per batch: split the batch",
            status=422, detail={"count": len(ids), "limit": CELLBATCH_MAX_CELLS},
        )
    twice = [i for i, n in Counter(ids).items() if n > 1]
    if twice:
        raise ApiError(f"ids: texture {twice[0]} asked more than once (each texture once per batch)",
                       status=422, detail={"ids": twice[:100]})
    _check(scene, ids)
    headers = {"X-Scene-Version": scene.version, "X-Image-Count": str(len(ids))}
    return stream_response(request, _parts(scene, ids), MSGPACK, headers)


async def _parts(scene: Scene, ids: list[int]) -> AsyncIterator[bytes]:
    """Each texture's part, read as the stream goes (off the event loop on a cache miss)."""
    for i in ids:
        enc = scene.cached_wall_texture(i)
        if enc is None:
            enc = await run_in_threadpool(scene.wall_texture, i)
        yield pack_contents_part(i, enc.etag, enc.content)
