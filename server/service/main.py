"""The FastAPI application: :func:`create_app` over one or more scene databases.

The routes are in :mod:`walkstream.server.service.routers`, the per-scene state and dependencies in
:mod:`walkstream.server.service.scenes`.  This module adds what wraps every request:

* :class:`MetricsMiddleware`, a plain ASGI middleware (no per-request task or
  thread, unlike Starlette's ``BaseHTTPMiddleware``) that counts requests by route
  and status, response bytes and latency into :class:`Metrics`, and adds
  ``Vary: Accept`` to every response;
* exception handlers that turn every error into JSON ``{"error": message,
  "detail": ...}`` with a 4xx status: unknown things 404, malformed input
  400/413/415/422, a damaged database 503 with ``Retry-After`` (the server's
  fault), a client that hangs up mid-body a closed request (499 in the metrics,
  one log line: starlette's ``ClientDisconnect``).  Bad input never reaches the
  500 handler, which exists so that even a bug answers in the same format;
* ``OPTIONS`` on any path: ``Allow`` with the methods of the route the path is."""

from __future__ import annotations

import logging
import os
import re
from collections.abc import Sequence
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse, Response
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.requests import ClientDisconnect

from walkstream.server.service import routers
from walkstream.server.service.metrics import Metrics, MetricsMiddleware
from walkstream.server.service.registry import SceneRegistry
from walkstream.shared.cullkernels import warm_up as warm_up_culling
from walkstream.shared.errors import (
    ApiError,
    CodecError,
    DatabaseDamagedError,
    NotFoundError,
    StoreError,
    WalkstreamError,
)

__all__ = ["log", "create_app", "OptionsMiddleware", "RETRY_AFTER_S"]

log = logging.getLogger(__name__)


# ---------------------------------------------------------------------------
# errors
# ---------------------------------------------------------------------------


def _error(status: int, message: str, detail: Any = None) -> JSONResponse:
    return JSONResponse({"error": message, "detail": detail}, status_code=status)


async def _api_error(request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, ApiError)
    return _error(exc.status or 400, exc.message, exc.detail)


async def _validation_error(request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, RequestValidationError)
    # keep only JSON-safe parts: pydantic's "ctx"/"input" may hold exceptions or NaN
    errors = [
        {
            "loc": [str(p) for p in e.get("loc", ())],
            "msg": str(e.get("msg", "")),
            "type": e.get("type"),
        }
        for e in exc.errors()
    ]
    message = "; ".join(f"{'.'.join(e['loc'])}: {e['msg']}" for e in errors[:5])
    return _error(422, message or "invalid request", errors)


async def _http_error(request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, StarletteHTTPException)
    message = exc.detail if isinstance(exc.detail, str) else "HTTP error"
    if exc.status_code == 404:
        message = f"no such endpoint: {request.url.path[:200]}"
    response = _error(exc.status_code, message, {"path": request.url.path[:200]})
    for k, v in (exc.headers or {}).items():
        response.headers[k] = v
    return response


async def _walkstream_error(request: Request, exc: Exception) -> JSONResponse:
    # NotFoundError: the store was asked for something absent; anything else the
    # project raises on purpose is about the input
    status = 404 if isinstance(exc, NotFoundError) else 400
    return _error(status, str(exc))


#: Seconds a client is asked to wait (``Retry-After``) when a database is damaged: the
#: registry looks for a replacement file once a second.
RETRY_AFTER_S = 5


async def _damaged(request: Request, exc: Exception) -> JSONResponse:
    # the stored file, not the request, is at fault, and a replaced file is served
    # within a second: 503 and come back, not the client's 400
    log.warning("%s", exc)
    response = _error(503, str(exc), {"retry_after_s": RETRY_AFTER_S})
    response.headers["Retry-After"] = str(RETRY_AFTER_S)
    return response


async def _disconnected(request: Request, exc: Exception) -> Response:
    # the client hung up before its body arrived: nobody reads an answer, so the
    # request is closed with one log line (nginx's 499 in the metrics), no traceback
    log.info("client %s hung up during %s %s", request.client.host if request.client else "?",
             request.method, request.url.path[:200])
    return Response(status_code=499)


def _route_table(app: FastAPI) -> list[tuple[re.Pattern[str], int, frozenset[str]]]:
    """``(pattern, literal characters, methods)`` of every path in the app's OpenAPI."""
    table = getattr(app.state, "options_table", None)
    if table is None:
        table = []
        for path, ops in app.openapi().get("paths", {}).items():
            pattern = re.compile("^" + re.sub(r"\\{[^}]*\\}", "[^/]+", re.escape(path)) + "$")
            literal = len(re.sub(r"{[^}]*}", "", path))
            table.append((pattern, literal, frozenset(m.upper() for m in ops)))
        app.state.options_table = table
    return table


class OptionsMiddleware:
    """``OPTIONS`` on any path: 204 with ``Allow`` naming the methods of the route the
    path really is (the most literal OpenAPI path matching it), 404 when none does.

    Without it Starlette answered with the first route whose pattern matched, so
    ``OPTIONS .../rooms/contents`` (a POST route) said ``Allow: GET`` from
    ``.../rooms/{id}``.  A plain ASGI middleware: a catch-all route would turn every
    unknown path's 404 into a 405.
    """

    def __init__(self, app: Any, fastapi: FastAPI) -> None:
        self.app = app
        self.fastapi = fastapi

    async def __call__(self, scope: Any, receive: Any, send: Any) -> None:
        if scope["type"] != "http" or scope["method"] != "OPTIONS":
            await self.app(scope, receive, send)
            return
        path = scope["path"]
        matching = [(lit, methods) for pattern, lit, methods in _route_table(self.fastapi) if pattern.match(path)]
        if not matching:
            response: Response = _error(404, f"no such endpoint: {path[:200]}", {"path": path[:200]})
        else:
            best = max(lit for lit, _ in matching)
            allowed = sorted({m for lit, methods in matching if lit == best for m in methods} | {"OPTIONS"})
            response = Response(status_code=204, headers={"Allow": ", ".join(allowed)})
        await response(scope, receive, send)


async def _unexpected(request: Request, exc: Exception) -> JSONResponse:
    log.exception("unexpected error answering %s %s", request.method, request.url.path)
    return _error(500, "internal server error")


# ---------------------------------------------------------------------------
# the app
# ---------------------------------------------------------------------------


def create_app(paths: Sequence[str | os.PathLike[str]]) -> FastAPI:
    """The service over the given scene databases, each served under its scene name.

    Every database is opened read-only and validated now (see
    :meth:`~walkstream.server.service.scenes.Scene.load`), so a bad one stops the start.  The databases
    stay open for the life of the app; :func:`~walkstream.server.service.run.serve` closes them
    (``app.state.scenes.close()``) when the server stops.

    Parameters
    ----------
    paths:
        Scene database files, at least one; scene names must differ.

    Returns
    -------
    FastAPI
        The app: API under ``/v1``, OpenAPI at ``/openapi.json`` and ``/docs``,
        Prometheus text at ``/metrics``.

    Raises
    ------
    StoreError
        No path, a missing, corrupt, unfinished or wrong-version database, or two
        databases with the same scene name.  The message names the file.
    """
    registry = SceneRegistry.open(list(paths))
    if any(scene.interior is not None for scene in registry.scenes.values()):
        # an interior's first view is culled on the server (its start bundle): the compiled
        # culling made (a cold cache: seconds) or loaded now, not in the first walker's request
        warm_up_culling()
    app = FastAPI(
        title="walkstream",
        version="1",
        summary="Streams baked city scenes: view cells, PVS/ACH, compact building parameters.",
        description=(routers.__doc__ or "").split("\n\n", 1)[-1],
        docs_url="/docs",
        redoc_url=None,
    )
    app.state.scenes = registry
    app.state.metrics = Metrics()
    for router in routers.ROUTERS:
        app.include_router(router)
    app.add_middleware(OptionsMiddleware, fastapi=app)
    app.add_middleware(MetricsMiddleware, metrics=app.state.metrics)
    app.add_exception_handler(ApiError, _api_error)
    app.add_exception_handler(RequestValidationError, _validation_error)
    app.add_exception_handler(StarletteHTTPException, _http_error)
    for exc_type in (StoreError, CodecError, WalkstreamError):
        app.add_exception_handler(exc_type, _walkstream_error)
    app.add_exception_handler(DatabaseDamagedError, _damaged)
    app.add_exception_handler(ClientDisconnect, _disconnected)
    app.add_exception_handler(Exception, _unexpected)
    return app
