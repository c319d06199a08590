"""Routes of an interior's textured virtual walls: the wall sides, and their textures one by one or in a batch.

``GET /v1/scenes/{scene}/walls``
    Every wall side: ``{"sides": [row, ...]}``, each row the numbers of
    :meth:`~walkstream.shared.walls.WallSide.to_row` (portal, side, ends, heights,
    floor, ``x_T``, blend, sampling depth, angle of error, zones, then one texture id
    per zone, or the first id alone when they follow one another); JSON or msgpack by
    ``Accept`` (msgpack gzip-compressed when ``Accept-Encoding`` allows), with an ETag
    and a 304.  With ``?cells=3,7,...`` (a city's rings, at most :data:`MAX_RING_CELLS`
    cells) only the walls ringing those street cells, in the same form: a walk asks for
    the rings of the cells its route comes to, as it comes to them (West Oakland's
    2,080 ring sides are 44 kB compressed, six seconds of a 56 kbit/s link).
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

import gzip
from typing import Annotated

from fastapi import APIRouter, Path, Query, Request, Response
from fastapi.responses import StreamingResponse

from walkstream.server.service.dependencies import RepDep, SceneDep
from walkstream.server.service.http import IMMUTABLE, accepts_gzip, cached, encode, etag_matches
from walkstream.server.service.imageroutes import (
    ImageSet,
    batch_responses,
    check_images,
    image_batch,
    one_image,
)
from walkstream.server.service.models import CONTENTS_BATCH_BODY, ERRORS, both, error_doc
from walkstream.server.service.scenes import Scene
from walkstream.shared.content.walltex import WALLTEX_MEDIA
from walkstream.shared.errors import ApiError
from walkstream.shared.walls import walls_wire

__all__ = ["MAX_RING_CELLS", "router"]

MAX_RING_CELLS = 256
"""Street cells one ``GET .../walls?cells=...`` may name."""

router = APIRouter(prefix="/v1", responses=ERRORS)

TEXTURES = ImageSet(
    noun="wall texture", short="texture",
    missing="virtual walls (baked without --virtual-walls)", missing_detail={"walls": 0},
    present=lambda scene: scene.has_walls, has=lambda scene, i: i in scene.wall_texture_ids,
    cached=Scene.cached_wall_texture, read=Scene.wall_texture,
)
"""The wall textures, for the shared image routes."""


@router.get(
    "/scenes/{scene}/walls",
    responses={**both("every wall side with its zones and texture ids"),
               404: error_doc("a scene baked without virtual walls")},
    summary="Virtual walls",
)
async def walls(
    request: Request, scene: SceneDep, rep: RepDep,
    cells: Annotated[str | None, Query(
        max_length=4096, pattern=r"^[0-9]+(,[0-9]+)*$",
        description="a city's ring walls: only the walls ringing these street cells "
                    "(comma-separated ids; a cell without a ring adds nothing)")] = None,
) -> Response:
    """Every wall side of the scene (``WallSide.to_row(compact=True)`` lists), or with
    ``cells`` only the rings of those street cells; gzip-compressed msgpack when the
    request accepts it."""
    check_images(TEXTURES, scene, [])
    if cells is not None:
        ids = sorted({int(c) for c in cells.split(",")})
        if len(ids) > MAX_RING_CELLS:
            raise ApiError(f"walls: at most {MAX_RING_CELLS} cells a request, got {len(ids)}", status=422,
                           detail={"cells": len(ids)})
        rows = [row for c in ids for row in scene.ring_sides.get(c, ())]
        enc = encode(walls_wire(rows), rep, scene.version, "walls-" + ",".join(map(str, ids)))
        if rep == "msgpack" and accepts_gzip(request.headers.get("accept-encoding")):
            body = gzip.compress(enc.content, 6, mtime=0)
            return Response(body, media_type=enc.media_type, headers={
                "ETag": enc.etag, "Cache-Control": IMMUTABLE, "Vary": "Accept, Accept-Encoding",
                "Content-Encoding": "gzip"})
        return cached(request, enc)
    if rep == "msgpack" and scene.walls_gzip is not None and accepts_gzip(request.headers.get("accept-encoding")):
        enc = scene.walls_gzip
        headers = {"ETag": enc.etag, "Cache-Control": IMMUTABLE, "Vary": "Accept, Accept-Encoding"}
        if etag_matches(request.headers.get("if-none-match"), enc.etag):
            return Response(status_code=304, headers=headers)
        return Response(enc.content, media_type=enc.media_type, headers={**headers, "Content-Encoding": "gzip"})
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
    return await one_image(TEXTURES, request, scene, texture)


@router.post(
    "/scenes/{scene}/walls/textures",
    responses=batch_responses("texture", "a scene baked without virtual walls"),
    openapi_extra={"requestBody": CONTENTS_BATCH_BODY},
    summary="Wall textures in a batch",
)
async def wall_textures(request: Request, scene: SceneDep) -> StreamingResponse:
    """The textures asked for (body ``{"ids": [...]}``), streamed in the order asked."""
    return await image_batch(TEXTURES, request, scene)
