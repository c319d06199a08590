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

from typing import Annotated

from fastapi import APIRouter, Path, Request, Response
from fastapi.responses import StreamingResponse

from walkstream.server.service.dependencies import SceneDep
from walkstream.server.service.imageroutes import ImageSet, batch_responses, image_batch, one_image
from walkstream.server.service.models import CONTENTS_BATCH_BODY, ERRORS, error_doc
from walkstream.server.service.scenes import Scene
from walkstream.shared.content.impostor import IMPOSTOR_MEDIA

__all__ = ["router"]

router = APIRouter(prefix="/v1", responses=ERRORS)

IMAGES = ImageSet(
    noun="impostor image", short="image",
    missing="impostor images (baked without --impostors)", missing_detail={"impostors": 0},
    present=lambda scene: bool(scene.impostor_ids), has=Scene.has_impostor,
    cached=Scene.cached_impostor, read=Scene.impostor,
)
"""The impostor images, for the shared image routes."""


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
    return await one_image(IMAGES, request, scene, image)


@router.post(
    "/scenes/{scene}/impostors",
    responses=batch_responses("image", "a scene baked without impostors"),
    openapi_extra={"requestBody": CONTENTS_BATCH_BODY},
    summary="Impostor images in a batch",
)
async def impostors(request: Request, scene: SceneDep) -> StreamingResponse:
    """The images asked for (body ``{"ids": [...]}``), streamed in the order asked."""
    return await image_batch(IMAGES, request, scene)
