"""Route of a scene's recorded paths."""


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
from walkstream.shared.wire import JSON, MSGPACK

__all__ = ["router"]

router = APIRouter(prefix="/v1", responses=ERRORS)


@router.get(
    "/scenes/{scene}/paths/{name:path}",
    responses={
        200: {
            "description": "the stored msgpack bytes as they are, or {name, data} as JSON",
            "content": {MSGPACK: {}, JSON: {}},
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
    enc = scene.cached_path(name, rep)
    if enc is None:  # read and decode in a worker thread, off the event loop
        enc = await run_in_threadpool(scene.path, name, rep)
    return cached(request, enc)
