"""The FastAPI dependencies: the app's scenes, the scene a path names, the representation asked for."""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, Request

from walkstream.server.service.http import Rep, negotiate
from walkstream.server.service.registry import SceneRegistry
from walkstream.server.service.scenes import Scene

__all__ = [
    "SceneDep",
    "RepDep",
    "get_registry",
    "get_scene",
    "get_rep",
]


# ---------------------------------------------------------------------------
# FastAPI dependencies
# ---------------------------------------------------------------------------


# The dependencies are ``async def`` although they never wait: FastAPI runs a plain
# ``def`` dependency in a worker thread, which would cost more than the request.


def _registry(request: Request) -> SceneRegistry:
    registry: SceneRegistry = request.app.state.scenes
    return registry


async def get_registry(request: Request) -> SceneRegistry:
    """The app's scenes (set by :func:`~walkstream.server.service.main.create_app`)."""
    return _registry(request)


async def get_scene(scene: str, request: Request) -> Scene:
    """The scene named by the ``{scene}`` path parameter; 404 if unknown."""
    return _registry(request).get(scene)


async def get_rep(request: Request) -> Rep:
    """The representation the request's ``Accept`` header asks for."""
    return negotiate(request.headers.get("accept"))


SceneDep = Annotated[Scene, Depends(get_scene)]
"""A route parameter: the scene named by ``{scene}``."""
RepDep = Annotated[Rep, Depends(get_rep)]
"""A route parameter: the representation the request asks for."""
