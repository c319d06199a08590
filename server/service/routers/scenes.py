"""Routes of the service itself and its scenes: health, the scene list, a scene's manifest."""


from __future__ import annotations

from typing import Annotated

import msgpack
from fastapi import APIRouter, Depends, Request, Response

from walkstream.server.service.dependencies import RepDep, SceneDep, get_registry
from walkstream.server.service.http import cached, dump_json
from walkstream.server.service.models import (
    ERRORS,
    HealthOut,
    Manifest,
    SceneRef,
    both,
)
from walkstream.server.service.registry import SceneRegistry
from walkstream.shared.wire import JSON, MSGPACK

__all__ = ["router"]

router = APIRouter(prefix="/v1", responses=ERRORS)


@router.get(
    "/health",
    response_model=HealthOut,
    responses={200: {"content": {MSGPACK: {}}}},
    summary="Health",
)
async def health(
    registry: Annotated[SceneRegistry, Depends(get_registry)], rep: RepDep
) -> Response:
    """``{"status": "ok", "scenes": n}`` while the service can answer."""
    body = {"status": "ok", "scenes": len(registry.scenes)}
    content = dump_json(body) if rep == "json" else msgpack.packb(body)
    return Response(
        content,
        media_type=JSON if rep == "json" else MSGPACK,
        headers={"Cache-Control": "no-store", "Vary": "Accept"},
    )


@router.get(
    "/scenes",
    response_model=list[SceneRef],
    responses=both("the served scenes, by name"),
    summary="List scenes",
)
async def list_scenes(
    request: Request, registry: Annotated[SceneRegistry, Depends(get_registry)], rep: RepDep
) -> Response:
    """Name and version of every served scene.

    Not keyed by one scene version, so it is revalidated (``no-cache``) rather than
    cached for a year; the ETag still gives 304s.
    """
    return cached(request, registry.listing[rep], "no-cache")


@router.get(
    "/scenes/{scene}",
    response_model=Manifest,
    responses=both("the scene manifest"),
    summary="Scene manifest",
)
async def manifest(request: Request, scene: SceneDep, rep: RepDep) -> Response:
    """Version, origin and CRS, bounds, features, grammar, viewpoints, path names, counts."""
    return cached(request, scene.manifest[rep])
