"""Routes of a scene's impostor images: one image, or many in a batch; immutable, with ETags.

``GET /v1/scenes/{scene}/impostors/{image}``
    One image as stored (``image/webp``: :mod:`walkstream.shared.codec.image`, straight
    alpha, to be premultiplied on decoding), immutable, with an ETag and a 304 when
    ``If-None-Match`` matches.
``POST /v1/scenes/{scene}/impostors``
    Many images in one answer: body ``{"ids": [...]}`` (each once, at most
    :data:`~walkstream.shared.codec.cellbatch.CELLBATCH_MAX_CELLS`), answer the parts of
    the contents batch (:mod:`walkstream.shared.codec.cellbatch`:
    ``{cell, etag, body}``, here ``cell`` the image id and ``body`` the file), in the
    order asked, each ``etag`` the one ``GET`` sends for the image.

Which images a cell uses is in its record (``GET .../cells/{id}``: ``imp``). A scene
baked without ``--impostors`` has none: both routes answer 404 saying so.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import AsyncIterator
from typing import Annotated

from fastapi import APIRouter, Path, Request, Response
from fastapi.responses import StreamingResponse
from starlette.concurrency import run_in_threadpool

from walkstream.server.service.dependencies import SceneDep
from walkstream.server.service.http import cached, stream_response
from walkstream.server.service.models import CONTENTS_BATCH_BODY, ERRORS, error_doc
from walkstream.server.service.routers.objects import MAX_BODY_BYTES, parse_ids, read_body
from walkstream.server.service.scenes import Scene
from walkstream.shared.codec.cellbatch import CELLBATCH_MAX_CELLS, pack_contents_part
from walkstream.shared.content.impostor import IMPOSTOR_MEDIA
from walkstream.shared.errors import ApiError
from walkstream.shared.wire import MSGPACK

__all__ = ["router"]

router = APIRouter(prefix="/v1", responses=ERRORS)


def _check(scene: Scene, ids: list[int]) -> None:
    """404 for a scene without impostors or an image it lacks (a clear line, never a 500)."""
    if not scene.impostor_ids:
        raise ApiError(
            f"scene {scene.name!r} has no impostor images (baked without --impostors)",
            status=404, detail={"impostors": 0},
        )
    unknown = [i for i in ids if not scene.has_impostor(i)]
    if unknown:
        shown = ", ".join(str(i) for i in unknown[:10]) + (", ..." if len(unknown) > 10 else "")
        raise ApiError(
            f"scene {scene.name!r} has no impostor image{'s' if len(unknown) > 1 else ''} {shown}",
            status=404, detail={"ids": unknown[:100]},
        )


@router.get(
    "/scenes/{scene}/impostors/{image}",
    responses={
        200: {"description": "the image (WebP, straight alpha)", "content": {IMPOSTOR_MEDIA: {}, "image/avif": {}}},
        304: {"description": "not modified (If-None-Match matched the ETag)"},
        404: error_doc("no such image, or a scene baked without impostors"),
    },
    summary="Impostor image",
)
async def impostor(request: Request, scene: SceneDep, image: Annotated[int, Path(description="image id")]) -> Response:
    """One impostor image as stored: immutable (the same bytes whatever ``Accept`` says)."""
    _check(scene, [image])
    enc = scene.cached_impostor(image)
    if enc is None:  # a database read: in a worker thread, off the event loop
        enc = await run_in_threadpool(scene.impostor, image)
    return cached(request, enc)


@router.post(
    "/scenes/{scene}/impostors",
    responses={
        200: {
            "description": "concatenated msgpack maps {cell, etag, body} (walkstream-cellbatch/1), one per "
            "id in the order asked: cell is the image id, body the image file, etag the one GET sends",
            "content": {MSGPACK: {}},
        },
        400: error_doc("the body is not JSON / msgpack"),
        404: error_doc("an id that is no image of the scene, or a scene baked without impostors"),
        413: error_doc(f"a body over {MAX_BODY_BYTES} bytes"),
        415: error_doc("a Content-Type other than JSON or msgpack"),
        422: error_doc(f"ids not a list of at most {CELLBATCH_MAX_CELLS} integers, or an id asked twice"),
    },
    openapi_extra={"requestBody": CONTENTS_BATCH_BODY},
    summary="Impostor images in a batch",
)
async def impostors(request: Request, scene: SceneDep) -> StreamingResponse:
    """The images asked for (body ``{"ids": [...]}``), streamed in the order asked."""
    ids = parse_ids(await read_body(request), request.headers.get("content-type"))
    if len(ids) > CELLBATCH_MAX_CELLS:
        raise ApiError(
            f"{len(ids)} images asked, at most {CELLBATCH_MAX_CELLS} per batch: split the batch",
            status=422, detail={"count": len(ids), "limit": CELLBATCH_MAX_CELLS},
        )
    twice = [i for i, n in Counter(ids).items() if n > 1]
    if twice:
        raise ApiError(f"ids: image {twice[0]} asked more than once (each image once per batch)",
                       status=422, detail={"ids": twice[:100]})
    _check(scene, ids)
    headers = {"X-Scene-Version": scene.version, "X-Image-Count": str(len(ids))}
    return stream_response(request, _parts(scene, ids), MSGPACK, headers)


async def _parts(scene: Scene, ids: list[int]) -> AsyncIterator[bytes]:
    """Each image's part, read as the stream goes (off the event loop on a cache miss)."""
    for i in ids:
        enc = scene.cached_impostor(i)
        if enc is None:
            enc = await run_in_threadpool(scene.impostor, i)
        yield pack_contents_part(i, enc.etag, enc.content)
