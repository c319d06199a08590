"""What every route serving a scene's immutable stored images does: one image, or many in a batch.

Impostor images and wall textures are the same kind of resource: files stored once at
bake time, each with an id, served as stored (the same bytes whatever ``Accept`` says)
with an ETag, and in batches as the parts of the contents batch
(:mod:`walkstream.shared.codec.cellbatch`, ``cell`` the image id).  An :class:`ImageSet`
names one such set (its words for the error lines and how a :class:`Scene` holds it);
the routers keep their own paths, summaries and documented answers.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass
from typing import Any

from fastapi import Request, Response
from fastapi.responses import StreamingResponse
from starlette.concurrency import run_in_threadpool

from walkstream.server.service.http import Encoded, cached, stream_response
from walkstream.server.service.models import error_doc
from walkstream.server.service.routers.objects import MAX_BODY_BYTES, parse_ids, read_body
from walkstream.server.service.scenes import Scene
from walkstream.shared.codec.cellbatch import CELLBATCH_MAX_CELLS, pack_contents_part
from walkstream.shared.errors import ApiError
from walkstream.shared.wire import MSGPACK

__all__ = ["ImageSet", "batch_responses", "check_images", "image_batch", "one_image"]


@dataclass(frozen=True)
class ImageSet:
    """One set of a scene's stored images, as the routes serving it need it.

    Parameters
    ----------
    noun:
        One image in an error line (``"impostor image"``, ``"wall texture"``).
    short:
        One image in a batch's error lines (``"image"``, ``"texture"``).
    missing:
        What a scene without the set has not, with the bake flag
        (``"impostor images (baked without --impostors)"``).
    missing_detail:
        The ``detail`` of that 404 (``{"impostors": 0}``).
    present:
        Whether a scene has the set at all.
    has:
        Whether a scene has one image of it.
    cached:
        The image if the scene has it cached (no database access), else ``None``.
    read:
        The image (a known one) read from the database.
    """

    noun: str
    short: str
    missing: str
    missing_detail: dict[str, int]
    present: Callable[[Scene], bool]
    has: Callable[[Scene, int], bool]
    cached: Callable[[Scene, int], Encoded | None]
    read: Callable[[Scene, int], Encoded]


def check_images(images: ImageSet, scene: Scene, ids: list[int]) -> None:
    """404 for a scene without the set or an image it lacks (a clear line, never a 500).

    Parameters
    ----------
    images:
        The image set.
    scene:
        The scene asked.
    ids:
        The image ids asked (may be empty: then only whether the scene has the set).
    """
    if not images.present(scene):
        raise ApiError(f"scene {scene.name!r} has no {images.missing}", status=404, detail=dict(images.missing_detail))
    unknown = [i for i in ids if not images.has(scene, i)]
    if unknown:
        shown = ", ".join(str(i) for i in unknown[:10]) + (", ..." if len(unknown) > 10 else "")
        raise ApiError(
            f"scene {scene.name!r} has no {images.noun}{'s' if len(unknown) > 1 else ''} {shown}",
            status=404, detail={"ids": unknown[:100]},
        )


async def one_image(images: ImageSet, request: Request, scene: Scene, image: int) -> Response:
    """One image as stored: immutable, with its ETag and a 304 when ``If-None-Match`` matches."""
    check_images(images, scene, [image])
    enc = images.cached(scene, image)
    if enc is None:  # a database read: in a worker thread, off the event loop
        enc = await run_in_threadpool(images.read, scene, image)
    return cached(request, enc)


async def image_batch(images: ImageSet, request: Request, scene: Scene) -> StreamingResponse:
    """The images the body asks for (``{"ids": [...]}``, each once), streamed in the order asked.

    Too many ids or one asked twice is a 422, an unknown one a 404, all before the stream starts.
    """
    ids = parse_ids(await read_body(request), request.headers.get("content-type"))
    if len(ids) > CELLBATCH_MAX_CELLS:
        raise ApiError(
            f"{len(ids)} {images.short}s asked, at most {CELLBATCH_MAX_CELLS} per batch: split the batch",
            status=422, detail={"count": len(ids), "limit": CELLBATCH_MAX_CELLS},
        )
    twice = [i for i, n in Counter(ids).items() if n > 1]
    if twice:
        raise ApiError(
            f"ids: {images.short} {twice[0]} asked more than once (each {images.short} once per batch)",
            status=422, detail={"ids": twice[:100]},
        )
    check_images(images, scene, ids)
    headers = {"X-Scene-Version": scene.version, "X-Image-Count": str(len(ids))}
    return stream_response(request, _parts(images, scene, ids), MSGPACK, headers)


async def _parts(images: ImageSet, scene: Scene, ids: list[int]) -> AsyncIterator[bytes]:
    """Each image's part, read as the stream goes (off the event loop on a cache miss)."""
    for i in ids:
        enc = images.cached(scene, i)
        if enc is None:
            enc = await run_in_threadpool(images.read, scene, i)
        yield pack_contents_part(i, enc.etag, enc.content)


def batch_responses(short: str, missing: str) -> dict[int | str, dict[str, Any]]:
    """The documented answers of a batch route (OpenAPI ``responses``).

    Parameters
    ----------
    short:
        One image in the descriptions (``"image"``, ``"texture"``).
    missing:
        What a scene without the set lacks, for the 404 (``"a scene baked without impostors"``).
    """
    return {
        200: {
            "description": "concatenated msgpack maps {cell, etag, body} (walkstream-cellbatch/1), one per "
            f"id in the order asked: cell is the {short} id, body the image file, etag the one GET sends",
            "content": {MSGPACK: {}},
        },
        400: error_doc("the body is not JSON / msgpack"),
        404: error_doc(f"an id that is no {short} of the scene, or {missing}"),
        413: error_doc(f"a body over {MAX_BODY_BYTES} bytes"),
        415: error_doc("a Content-Type other than JSON or msgpack"),
        422: error_doc(f"ids not a list of at most {CELLBATCH_MAX_CELLS} integers, or an id asked twice"),
    }
