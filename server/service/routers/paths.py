"""Route of a scene's recorded paths.

``GET /v1/scenes/{scene}/paths/{name}`` answers with the stored ``walkstream-path``
msgpack blob, its JSON form (``Accept: application/json``), or, when the ``Accept``
header names :data:`~walkstream.shared.pathcodec.PATH_Q_MEDIA`, the compact
``walkstream-path-q/1`` encoding (quantised differences, deflated: about a sixth of
the bytes; its own ETag).
"""


from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Path, Request, Response
from starlette.concurrency import run_in_threadpool

from walkstream.server.service.dependencies import RepDep, SceneDep
from walkstream.server.service.http import cached
from walkstream.server.service.models import (
    ERRORS,
)
from walkstream.shared.errors import ApiError
from walkstream.shared.pathcodec import PATH_Q_MEDIA
from walkstream.shared.wire import JSON, MSGPACK

__all__ = ["router"]

router = APIRouter(prefix="/v1", responses=ERRORS)


@router.get(
    "/scenes/{scene}/paths/{name:path}",
    responses={
        200: {
            "description": "the stored msgpack bytes as they are, {name, data} as JSON, or the "
            "compact encoding (walkstream-path-q/1) when Accept names its media type",
            "content": {MSGPACK: {}, JSON: {}, PATH_Q_MEDIA: {}},
        },
        304: {"description": "not modified"},
    },
    summary="Recorded path",
)
async def recorded_path(
    request: Request,
    scene: SceneDep,
    rep: RepDep,
    name: Annotated[str, Path(description="path name, as listed in the manifest")],
) -> Response:
    """A recorded walk by name (names as listed in the manifest's ``paths``)."""
    if name not in scene.path_names:
        raise ApiError(
            f"scene {scene.name!r} has no recorded path {name!r:.80}",
            status=404,
            detail={"path": name, "known": sorted(scene.path_names)},
        )
    if PATH_Q_MEDIA in request.headers.get("accept", ""):
        q1 = scene.cached_path(name, "q1")
        return cached(request, q1 if q1 is not None else await run_in_threadpool(scene.path_q, name))
    enc = scene.cached_path(name, rep)
    if enc is None:  # read and decode in a worker thread, off the event loop
        enc = await run_in_threadpool(scene.path, name, rep)
    return cached(request, enc)
