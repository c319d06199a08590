"""The HTTP API: scene list, manifest, recorded paths, locate, cells, objects, health, metrics.

Every route under ``/v1`` answers in msgpack (``application/msgpack``) unless the
request's ``Accept`` prefers ``application/json``; every response carries
``Vary: Accept``.  Whatever is keyed by a scene version (manifest, path, locate,
cell) has a strong ``ETag`` naming version, resource and representation, and
``Cache-Control: public, max-age=31536000, immutable``; a matching
``If-None-Match`` gets ``304``.  Errors are always JSON ``{"error": message,
"detail": ...}``.

Object stream framing
---------------------
``POST /v1/scenes/{scene}/objects`` with body ``{"ids": [int, ...]}`` (msgpack when
the ``Content-Type`` is ``application/msgpack``, JSON otherwise; at most
:data:`server.deps.MAX_IDS` = 1000 ids, else 413) answers with a *streamed* body
made of **plain concatenated msgpack objects, one per id in the order asked**
(repeats included), with no length prefix or separator: msgpack is
self-delimiting, so a client feeds the bytes to ``msgpack.Unpacker`` as they
arrive and gets each object as soon as its last byte is in.  Each object is the map
``{"id": int, "kind": str, "params": bin}`` where ``params`` is the stored record
(:func:`shared.codec.decode_building` / :func:`shared.codec.decode_street`, or
:func:`shared.codec.decode_object` for either).  The server hands the frames to the
transport in chunks of about :data:`CHUNK_BYTES`, never splitting the order.  The
headers ``X-Scene-Version`` and ``X-Object-Count`` come first.  With
``Accept: application/json`` the body is instead a JSON array, streamed one element
per line, of ``{"id", "kind", "params": base64}``.

All ids are checked before the first byte is sent: an unknown id gives a 404 that
lists the unknown ids, never a truncated stream.

Mesh form (for comparison only)
-------------------------------
``POST /v1/scenes/{scene}/objects?form=lod2`` answers with the same framing, but
each map is ``{"id": int, "kind": str, "mesh": bin}`` where ``mesh`` is the object's
LOD2 mesh, rebuilt on the server (buildings with the scene's grammar, street pieces
as their flat surface) and encoded by :func:`shared.codec.encode_mesh` (decode with
:func:`shared.codec.decode_mesh`); with ``Accept: application/json`` the elements
are ``{"id", "kind", "mesh": base64}``.  It exists so that a client's
``--stream meshes`` mode can measure what sending geometry instead of parameters
costs in bytes and quality, which is the paper's central claim; meshes are about a
thousand times larger than parameters.  ``form=params`` is the default and the
format described above; any other form is a 422 naming it.
"""

from __future__ import annotations

import base64
import json
from collections.abc import AsyncIterator, Iterable
from typing import TYPE_CHECKING, Annotated, Any, cast

import msgpack
from fastapi import APIRouter, Depends, Path, Query, Request, Response
from fastapi.responses import StreamingResponse
from pydantic import BaseModel, Field
from starlette.concurrency import run_in_threadpool

from walkstream.server.deps import (
    IMMUTABLE,
    MAX_IDS,
    OBJECT_FORMS,
    Encoded,
    Form,
    Rep,
    Scene,
    SceneRegistry,
    dump_json,
    etag_matches,
    get_registry,
    get_rep,
    get_scene,
)
from walkstream.shared.codec import unpack_bounded
from walkstream.shared.errors import ApiError, CodecError
from walkstream.shared.wire import JSON, MSGPACK, MSGPACK_TYPES

if TYPE_CHECKING:
    from walkstream.server.app import Metrics

__all__ = ["router", "ops_router", "CHUNK_BYTES", "MAX_BODY_BYTES"]

CHUNK_BYTES = 16 << 10
"""Object frames are handed to the transport in chunks of about this many bytes."""

MAX_BODY_BYTES = 64 << 10
"""Largest accepted request body (1000 ids as JSON need about 20 KiB); more: 413."""

_MAX_INT64 = 2**63 - 1


# ---------------------------------------------------------------------------
# documented shapes (the handlers send pre-encoded bytes; these are for /docs)
# ---------------------------------------------------------------------------


class ErrorOut(BaseModel):
    """Every error: a message and a machine-readable detail."""

    error: str
    detail: Any = None


class HealthOut(BaseModel):
    """Health: ``ok`` and the number of scenes served."""

    status: str
    scenes: int


class SceneRef(BaseModel):
    """A served scene: its name (used in URLs) and version (content hash)."""

    name: str
    version: str


class GrammarOut(BaseModel):
    """The building grammar the scene's objects are meant for."""

    id: str
    text: str


class ViewpointOut(BaseModel):
    """A named start position in scene-local metres; ``yaw`` in radians."""

    name: str
    x: float
    y: float
    z: float
    yaw: float
    cell: int | None


class LimitsOut(BaseModel):
    """Request limits a client must respect."""

    objects_per_request: int


class Manifest(BaseModel):
    """What a client needs to start walking a scene."""

    name: str
    version: str
    schema_version: int
    crs: str
    origin: list[float] = Field(description="CRS position of local (0, 0)")
    bounds: list[float] = Field(description="minx, miny, minz, maxx, maxy, maxz in local metres")
    features: list[str]
    grammar: GrammarOut
    viewpoints: list[ViewpointOut]
    paths: list[str] = Field(description="names of the recorded paths")
    objects: int
    cells: int
    limits: LimitsOut


class LocateOut(BaseModel):
    """The cell containing a position, or ``cell: null`` with the reason."""

    cell: int | None
    reason: str | None = None


class NeighbourOut(BaseModel):
    """An adjacent cell and its boundary."""

    id: int
    boundary: list[list[float]]


class CellOut(BaseModel):
    """A view cell: convex boundary, eye-height range, neighbours, PVS and ACH."""

    id: int
    kind: str
    boundary: list[list[float]] = Field(description="(n, 2) convex outline, local metres")
    zmin: float
    zmax: float
    neighbours: list[NeighbourOut]
    pvs: list[int] = Field(description="ids of the potentially visible objects, ascending")
    ach: list[float] = Field(description="average coverage of each PVS object; sums to 1")


class ObjectsIn(BaseModel):
    """The objects to send, in the order to send them."""

    ids: list[Annotated[int, Field(ge=0, le=_MAX_INT64)]] = Field(max_length=MAX_IDS)


def _err(description: str) -> dict[str, Any]:
    return {"model": ErrorOut, "description": description}


_ERRORS: dict[int | str, dict[str, Any]] = {
    404: _err("unknown scene, cell, path or object (named in the error)"),
    422: _err("a malformed parameter"),
}


def _both(description: str) -> dict[int | str, dict[str, Any]]:
    # the JSON schema comes from response_model; msgpack carries the same structure
    return {
        200: {"description": description, "content": {MSGPACK: {}}},
        304: {"description": "not modified (If-None-Match matched the ETag)"},
    }


router = APIRouter(prefix="/v1", responses=_ERRORS)
"""The versioned API."""

ops_router = APIRouter()
"""Operational endpoints outside the versioned API (``/metrics``)."""

SceneDep = Annotated[Scene, Depends(get_scene)]
RepDep = Annotated[Rep, Depends(get_rep)]


def cached(request: Request, enc: Encoded, cache_control: str = IMMUTABLE) -> Response:
    """A response for a pre-encoded body, or 304 when ``If-None-Match`` matches its ETag."""
    headers = {"ETag": enc.etag, "Cache-Control": cache_control, "Vary": "Accept"}
    if etag_matches(request.headers.get("if-none-match"), enc.etag):
        return Response(status_code=304, headers=headers)
    return Response(enc.content, media_type=enc.media_type, headers=headers)


# ---------------------------------------------------------------------------
# routes
# ---------------------------------------------------------------------------


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
    responses=_both("the served scenes, by name"),
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
    responses=_both("the scene manifest"),
    summary="Scene manifest",
)
async def manifest(request: Request, scene: SceneDep, rep: RepDep) -> Response:
    """Version, origin and CRS, bounds, features, grammar, viewpoints, path names, counts."""
    return cached(request, scene.manifest[rep])


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


@router.get(
    "/scenes/{scene}/locate",
    response_model=LocateOut,
    responses=_both("the cell containing the position, or cell null and the reason"),
    summary="Locate a position",
)
async def locate(
    request: Request,
    scene: SceneDep,
    rep: RepDep,
    x: Annotated[float, Query(allow_inf_nan=False, description="scene-local metres")],
    y: Annotated[float, Query(allow_inf_nan=False, description="scene-local metres")],
) -> Response:
    """The id of the cell that contains ``(x, y)``.

    A position outside every cell is a normal answer (200, ``cell: null``), not an
    error: a walker may step off the navigation space.
    """
    return cached(request, scene.locate(x, y, rep))


@router.get(
    "/scenes/{scene}/cells/{cell}",
    response_model=CellOut,
    responses=_both("the cell record"),
    summary="Cell record",
)
async def cell_record(
    request: Request,
    scene: SceneDep,
    rep: RepDep,
    cell: Annotated[int, Path(description="cell id")],
) -> Response:
    """Boundary, height range, neighbours with their boundaries, PVS ids and ACH."""
    if not scene.has_cell(cell):
        raise ApiError(f"scene {scene.name!r} has no cell {cell}", status=404, detail={"cell": cell})
    enc = scene.cached_cell(cell, rep)
    if enc is None:  # a database read: in a worker thread, off the event loop
        enc = await run_in_threadpool(scene.cell, cell, rep)
    return cached(request, enc)


_OBJECTS_BODY = {
    "required": True,
    "content": {
        JSON: {"schema": ObjectsIn.model_json_schema()},
        MSGPACK: {"schema": ObjectsIn.model_json_schema()},
    },
}


@router.post(
    "/scenes/{scene}/objects",
    responses={
        200: {
            "description": "concatenated msgpack maps {id, kind, params} (or {id, kind, mesh} "
            "with form=lod2), one per id in the order asked (see the module docs); a JSON "
            "array with Accept: application/json",
            "content": {MSGPACK: {}, JSON: {}},
        },
        400: _err("the body is not JSON / msgpack"),
        413: _err(f"more than {MAX_IDS} ids, or a body over {MAX_BODY_BYTES} bytes"),
        415: _err("a Content-Type other than JSON or msgpack"),
    },
    openapi_extra={"requestBody": _OBJECTS_BODY},
    summary="Stream object parameters",
)
async def objects(
    request: Request,
    scene: SceneDep,
    rep: RepDep,
    form: Annotated[
        str,
        Query(
            description="what each frame carries: `params` (the default), the compact "
            "procedural parameters, or `lod2`, the LOD2 mesh rebuilt on the server "
            "(shared.codec.encode_mesh), offered only to compare streaming geometry "
            "against streaming parameters",
            examples=list(OBJECT_FORMS),
            max_length=64,
        ),
    ] = "params",
) -> StreamingResponse:
    """Stream the parameters (or, with ``form=lod2``, the LOD2 meshes) of the objects asked for.

    The frames come in the order asked; see the module docs for the framing.
    """
    if form not in OBJECT_FORMS:
        raise ApiError(
            f"unknown form {form!r:.80}: expected one of {', '.join(OBJECT_FORMS)}",
            status=422,
            detail={"form": form[:80], "known": list(OBJECT_FORMS)},
        )
    frm = cast(Form, form)
    ids = _parse_ids(await _read_body(request), request.headers.get("content-type"))
    unknown = scene.unknown_ids(ids)
    if unknown:
        shown = ", ".join(str(i) for i in unknown[:10]) + (", ..." if len(unknown) > 10 else "")
        raise ApiError(
            f"scene {scene.name!r} has no object{'s' if len(unknown) > 1 else ''} {shown}",
            status=404,
            detail={"ids": unknown},
        )
    found, missing = scene.cached_frames(ids, frm)
    if missing:
        # reads the database and, for meshes, rebuilds geometry: off the event loop
        found.update(await run_in_threadpool(scene.load_frames, missing, frm))
    frames = [found[i] for i in ids]
    headers = {"X-Scene-Version": scene.version, "X-Object-Count": str(len(ids))}
    if rep == "json":
        return StreamingResponse(_coalesce(_json_items(frames)), media_type=JSON, headers=headers)
    return StreamingResponse(_coalesce(frames), media_type=MSGPACK, headers=headers)


async def _read_body(request: Request) -> bytes:
    """The request body, refusing (413) more than :data:`MAX_BODY_BYTES` before reading it all."""
    declared = request.headers.get("content-length")
    if declared is not None and declared.isdigit() and int(declared) > MAX_BODY_BYTES:
        raise ApiError(
            f"request body of {int(declared)} bytes, more than the limit of {MAX_BODY_BYTES}",
            status=413,
            detail={"limit_bytes": MAX_BODY_BYTES},
        )
    chunks: list[bytes] = []
    n = 0
    async for chunk in request.stream():
        n += len(chunk)
        if n > MAX_BODY_BYTES:
            raise ApiError(
                f"request body over the limit of {MAX_BODY_BYTES} bytes",
                status=413,
                detail={"limit_bytes": MAX_BODY_BYTES},
            )
        chunks.append(chunk)
    return b"".join(chunks)


def _parse_ids(body: bytes, content_type: str | None) -> list[int]:
    """Validate an objects request body; see :func:`objects` for the answers."""
    media = (content_type or "").split(";")[0].strip().lower()
    if media in MSGPACK_TYPES:
        try:
            obj = unpack_bounded(
                body,
                "request body",
                max_bytes=MAX_BODY_BYTES,
                max_array_len=MAX_BODY_BYTES,
                max_map_len=64,
                max_str_len=1024,
                max_bin_len=0,
            )
        except CodecError as exc:
            raise ApiError(str(exc), status=400) from exc
    elif media in ("", JSON) or media.endswith("+json"):
        if not body.strip():
            raise ApiError('request body is empty; send {"ids": [int, ...]}', status=400)
        try:
            obj = json.loads(body)
        except (ValueError, RecursionError) as exc:
            raise ApiError(f"request body is not valid JSON ({exc})", status=400) from exc
    else:
        raise ApiError(
            f"request body of type {media!r:.80}: send {JSON} or {MSGPACK}",
            status=415,
            detail={"content_type": media},
        )
    if not isinstance(obj, dict) or "ids" not in obj:
        raise ApiError(
            'request body: expected an object {"ids": [int, ...]}',
            status=422,
            detail={"got": type(obj).__name__},
        )
    ids = obj["ids"]
    if not isinstance(ids, list):
        raise ApiError(
            f"ids: expected an array of integers, got {type(ids).__name__}",
            status=422,
            detail={"field": "ids"},
        )
    if len(ids) > MAX_IDS:
        raise ApiError(
            f"{len(ids)} ids asked, at most {MAX_IDS} per request: split the batch",
            status=413,
            detail={"count": len(ids), "limit": MAX_IDS},
        )
    # bool is an int subclass: true/false are not ids
    bad = [(k, v) for k, v in enumerate(ids) if type(v) is not int or not 0 <= v <= _MAX_INT64]
    if bad:
        shown = ", ".join(f"ids[{k}] = {v!r:.30}" for k, v in bad[:5])
        raise ApiError(
            f"ids: expected integers from 0 to 2**63 - 1; got {shown}"
            + (f" and {len(bad) - 5} more" if len(bad) > 5 else ""),
            status=422,
            detail=[{"index": k, "got": f"{v!r:.40}"} for k, v in bad[:100]],
        )
    return ids


def _json_items(frames: Iterable[bytes]) -> Iterable[bytes]:
    """The JSON array of the frames, one element per line, as pieces."""
    yield b"["
    for k, f in enumerate(frames):
        o = msgpack.unpackb(f)
        key = "params" if "params" in o else "mesh"
        item = {"id": o["id"], "kind": o["kind"], key: base64.b64encode(o[key]).decode()}
        yield (b",\n" if k else b"\n") + dump_json(item)
    yield b"\n]\n"


async def _coalesce(pieces: Iterable[bytes]) -> AsyncIterator[bytes]:
    """Join small pieces into chunks of about :data:`CHUNK_BYTES`, keeping their order.

    An async generator, so Starlette iterates it on the event loop instead of
    hopping to a worker thread for every chunk; the frames are already in memory.
    """
    buf: list[bytes] = []
    n = 0
    for p in pieces:
        buf.append(p)
        n += len(p)
        if n >= CHUNK_BYTES:
            yield b"".join(buf)
            buf, n = [], 0
    if buf:
        yield b"".join(buf)


@ops_router.get(
    "/metrics",
    response_class=Response,
    responses={200: {"content": {"text/plain": {}}, "description": "Prometheus text format"}},
    summary="Prometheus metrics",
)
async def metrics(request: Request) -> Response:
    """Requests by route and status, response bytes, latency histogram (this process)."""
    m: Metrics = request.app.state.metrics
    return Response(
        m.render(request.app.state.scenes),
        media_type="text/plain; version=0.0.4; charset=utf-8",
        headers={"Cache-Control": "no-store"},
    )
