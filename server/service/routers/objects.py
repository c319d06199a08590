"""The objects route: a scene's object parameters (or LOD2 meshes) streamed in the order asked.

The framing (plain concatenated msgpack maps, one per id in the order asked; the
``form=lod2`` mesh form) is the API's own documentation, the docstring of
:mod:`walkstream.server.service.routers`, which is also the OpenAPI description.
"""

from __future__ import annotations

import asyncio
import base64
import json
import weakref
from collections.abc import AsyncIterator, Iterable
from typing import Annotated, cast

import msgpack
from fastapi import APIRouter, Query, Request
from fastapi.responses import StreamingResponse
from starlette.concurrency import run_in_threadpool

from walkstream.server.service.dependencies import RepDep, SceneDep
from walkstream.server.service.http import dump_json, stream_response
from walkstream.server.service.models import (
    ERRORS,
    MAX_INT64,
    ObjectsIn,
    error_doc,
)
from walkstream.server.service.scenes import MAX_IDS, OBJECT_FORMS, Form, Scene
from walkstream.shared.codec import unpack_bounded
from walkstream.shared.errors import ApiError, CodecError
from walkstream.shared.wire import JSON, MSGPACK, MSGPACK_TYPES

__all__ = [
    "router", "CHUNK_BYTES", "MAX_BODY_BYTES", "MAX_RESPONSE_BYTES", "REBUILDS_AT_ONCE",
    "mesh_bytes_estimate", "read_body", "parse_ids", "json_frames", "coalesce",
]  # fmt: skip

router = APIRouter(prefix="/v1", responses=ERRORS)


CHUNK_BYTES = 16 << 10
"""Object frames are handed to the transport in chunks of about this many bytes."""

MAX_BODY_BYTES = 64 << 10
"""Largest accepted request body (1000 ids as JSON need about 20 KiB); more: 413."""

MAX_RESPONSE_BYTES = 4 << 20
"""Largest objects response (msgpack bytes; its JSON is about 4/3 of it): more is a 413
naming the limit and how many ids fit.  1000 ``params`` frames are about 200 kB; a
``lod2`` frame of the demo city about 39 kB, so about 100 meshes fit (1000 made 31.8
MB, and 20 such requests held ``/v1/health`` for 19.6 s)."""

REBUILDS_AT_ONCE = 2
"""``lod2`` requests rebuilding meshes at once per process; the others wait their turn
off the event loop's critical path (each rebuild holds the GIL in Python code, and
twenty at once starved the loop)."""

_MESH_BYTES_PER_TRIANGLE = 24  # the demo city's meshes take 30-36: a lower bound
_MESH_BYTES_PER_TRIANGLE_MAX = 48
_FRAME_BYTES = 16


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
        400: error_doc("the body is not JSON / msgpack"),
        413: error_doc(
            f"a body over {MAX_BODY_BYTES} bytes, or a response over {MAX_RESPONSE_BYTES} bytes "
            "(form=lod2: about 100 meshes; detail.ids_that_fit says how many)"
        ),
        422: error_doc(f"not an object {{\"ids\": [...]}} of at most {MAX_IDS} integers, or an unknown form"),
        415: error_doc("a Content-Type other than JSON or msgpack"),
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
            json_schema_extra={"enum": list(OBJECT_FORMS)},
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
    ids = parse_ids(await read_body(request), request.headers.get("content-type"))
    unknown = scene.unknown_ids(ids)
    if unknown:
        shown = ", ".join(str(i) for i in unknown[:10]) + (", ..." if len(unknown) > 10 else "")
        raise ApiError(
            f"scene {scene.name!r} has no object{'s' if len(unknown) > 1 else ''} {shown}",
            status=404,
            detail={"ids": unknown},
        )
    found, missing = scene.cached_frames(ids, frm)
    if frm == "lod2":
        estimate = await run_in_threadpool(mesh_bytes_estimate, scene, ids)
        _refuse_over_budget(estimate, len(ids), "estimated from the objects' triangles")
    if missing:
        # reads the database and, for meshes, rebuilds geometry: off the event loop,
        # and mesh rebuilds only a few at a time (see REBUILDS_AT_ONCE)
        if frm == "lod2":
            async with _rebuild_slots():
                found.update(await run_in_threadpool(scene.load_frames, missing, frm))
        else:
            found.update(await run_in_threadpool(scene.load_frames, missing, frm))
    frames = [found[i] for i in ids]
    _refuse_over_budget(sum(map(len, frames)), len(ids), "")
    headers = {"X-Scene-Version": scene.version, "X-Object-Count": str(len(ids))}
    if rep == "json":
        return stream_response(request, coalesce(json_frames(frames)), JSON, headers)
    return stream_response(request, coalesce(frames), MSGPACK, headers)


def mesh_bytes_estimate(scene: Scene, ids: list[int]) -> int:
    """A lower bound of the ``lod2`` frames' bytes from the stored LOD 2 triangle counts."""
    info = scene.reader.object_info(ids)
    return sum(_FRAME_BYTES + _MESH_BYTES_PER_TRIANGLE * info[i].tris[2] for i in ids if i in info)


def _refuse_over_budget(nbytes: int, count: int, how: str) -> None:
    if nbytes <= MAX_RESPONSE_BYTES:
        return
    # an estimate is a lower bound: advise from the largest bytes per triangle seen;
    # real bytes vary from frame to frame: leave a margin
    spread = _MESH_BYTES_PER_TRIANGLE_MAX / _MESH_BYTES_PER_TRIANGLE if how else 1.25
    fit = max(1, int(count * MAX_RESPONSE_BYTES / (nbytes * spread)))
    raise ApiError(
        f"{count} objects make {nbytes} bytes{f' ({how})' if how else ''}, more than the "
        f"response limit of {MAX_RESPONSE_BYTES}: ask for about {fit} at a time",
        status=413,
        detail={"limit_bytes": MAX_RESPONSE_BYTES, "bytes": nbytes, "ids_that_fit": fit},
    )


_SLOTS: weakref.WeakKeyDictionary[asyncio.AbstractEventLoop, asyncio.Semaphore] = weakref.WeakKeyDictionary()


def _rebuild_slots() -> asyncio.Semaphore:
    """This event loop's semaphore of :data:`REBUILDS_AT_ONCE` mesh rebuilds."""
    loop = asyncio.get_running_loop()
    sem = _SLOTS.get(loop)
    if sem is None:
        sem = _SLOTS[loop] = asyncio.Semaphore(REBUILDS_AT_ONCE)
    return sem


async def read_body(request: Request) -> bytes:
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


def parse_ids(body: bytes, content_type: str | None) -> list[int]:
    """Validate an ``{"ids": [...]}`` request body (objects, cells); see :func:`objects`."""
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
            status=422,
            detail={"count": len(ids), "limit": MAX_IDS},
        )
    # JSON Schema's integer includes 3.0: take an integer-valued float as its int
    ids = [int(v) if type(v) is float and v.is_integer() and 0 <= v <= MAX_INT64 else v for v in ids]
    # bool is an int subclass: true/false are not ids
    bad = [(k, v) for k, v in enumerate(ids) if type(v) is not int or not 0 <= v <= MAX_INT64]
    if bad:
        shown = ", ".join(f"ids[{k}] = {v!r:.30}" for k, v in bad[:5])
        raise ApiError(
            f"ids: expected integers from 0 to 2**63 - 1; got {shown}"
            + (f" and {len(bad) - 5} more" if len(bad) > 5 else ""),
            status=422,
            detail=[{"index": k, "got": f"{v!r:.40}"} for k, v in bad[:100]],
        )
    return ids


def json_frames(frames: Iterable[bytes]) -> Iterable[bytes]:
    """The JSON array of the frames, one element per line, as pieces."""
    yield b"["
    for k, f in enumerate(frames):
        o = msgpack.unpackb(f)
        key = "params" if "params" in o else "mesh"
        item = {"id": o["id"], "kind": o["kind"], key: base64.b64encode(o[key]).decode()}
        yield (b",\n" if k else b"\n") + dump_json(item)
    yield b"\n]\n"


async def coalesce(pieces: Iterable[bytes]) -> AsyncIterator[bytes]:
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
