"""The start bundle: from nothing to the first cell's objects in one round trip.

``GET /v1/start?path=NAME`` (or ``viewpoint=NAME``, or ``x=&y=``, or nothing: the scene's
default start; ``scene=`` picks the scene, else the server's first by name; see
:func:`~walkstream.server.service.startbundle.start_position` for how they combine)
answers with a *stream* of parts, each the
msgpack map ``{part, etag, body: bin}`` where ``body`` is exactly what the part's
own endpoint sends (so a client decodes it, and may cache it under ``etag``, as if
it had asked for it):

1. ``path`` -- the recorded path, when asked by name (a replay can start walking);
2. ``cell`` -- the record of the cell holding the start (none outside every cell),
   then those of the cells straight ahead that the viewer reaches in
   :data:`~walkstream.server.service.startbundle.START_LEAD_S` seconds (``heading`` in
   radians counter-clockwise from +x and ``speed`` in m/s; a path gives its own
   start heading and speed, a viewpoint its yaw and standing still), and those of
   the cells reached in :data:`~walkstream.server.service.startbundle.START_RECORD_LEAD_S`
   more (records only); a record whose PVS the bundle's objects do not all hold comes
   as a ``record`` part instead (the same body), so that the client asks for the rest;
3. ``index`` -- after each cell, the index tile holding it (when not sent yet); outside
   every cell, the tiles that may hold cells near the start;
4. ``manifest`` -- the scene manifest (its grammar rebuilds the objects);
5. ``objects`` -- the map ``{part: "objects", etag: null, count: n}`` followed by
   ``n`` plain object frames (as the objects stream sends them, in the ``form``
   asked: ``params`` by default, ``lod2`` meshes): the first cell's PVS, highest
   ACH first, then each next cell's new objects.

On an interior the bundle is what the walk needs before its first perfect frame:
``path`` (when asked), ``topology`` (the compact ``walkstream-topology/2``, as ``GET
.../topology/compact`` sends it), then, when the client says how it views the scene
(``view=WxH`` pixels, and ``fov`` degrees, ``fog`` metres, ``depth`` portals, which
default to the replay's 60, 40 and no limit: as deep as the fog reaches), ``contents``: the map ``{part: "contents",
etag: null, cells: [ids]}`` followed by one ``{cell, etag, body}`` part per cell, as
``POST .../rooms/contents`` sends them (:mod:`walkstream.shared.codec.cellbatch`), for the
cells portal culling keeps from the path's first pose and from where it leads in a
couple of seconds (:func:`~walkstream.server.service.startbundle.start_parts`); then
``manifest``.  With ``head=SECONDS`` as well (a path and a view; compact parts), the
path's head ``pathhead`` comes in place of ``path``: its samples up to the first at or
after SECONDS (a compact path of its own, decoding exactly as the whole path's first
samples).  The walk starts on the head, the contents not queued behind the whole
path; the client fetches the whole path (``GET .../paths/{name}``) when its link is
idle, before the head ends.  With ``heads=true`` as well (a path and a view), a cell the first pose sees in
part comes first as its *head* (a part with one more field, ``missing``:
:mod:`walkstream.shared.codec.cellhead`) and whole after every other cell, so the cell
is named twice in ``cells``; the first view's parts may then come as one pack in their
place (:mod:`walkstream.shared.codec.contentspack`: the parts in one LZMA2 stream),
where that costs fewer bytes (:mod:`walkstream.server.service.firstview`).  With ``pose=true`` as
well, the ``pathhead`` before the topology is only the head's first pose (its first two
samples, ETag null: the walker stands there until its first view is in), and the head of
``head`` seconds comes as a second ``pathhead`` part among the contents' frames, right after
those that carry the first pose's view (the pack, or those cells' parts).  With ``walls=true`` (an interior baked with ``--virtual-walls``,
a path and a view) the wall sides (``walls``, as ``GET .../walls`` sends them) and the first
view's wall textures (``walltex``: ``{part, etag: null, textures: [ids]}`` then one ``{cell,
etag, body}`` part each, as ``POST .../walls/textures`` sends them) come before the
contents, and the first view's cells are those of the walk with those walls closed; on a city baked with them (with
``heads=true``) the start cell's ring (``walls``, as ``GET .../walls?cells=`` sends it) and the textures of the ring
walls the first pose sees (``walltex``) come right after the first view's objects.  A client that does not ask gets the order above; a server
that does not know ``head`` ignores it (the whole path then comes, as ``path``).  The walk's other cells come by the client's own requests.  The ``path`` part is the compact ``walkstream-path-q/1``
encoding (as ``GET .../paths/{name}`` sends it when ``Accept`` names it); with
``Accept: application/json`` each body is its JSON form.

On a 500 ms link each round trip is a visible wait: scene list, manifest, path,
locate, cell and objects asked one after the other cost six of them.  With
``Accept: application/json`` the body is a JSON array of ``{part, etag, body}``
with each body in its JSON form, the objects part's body being the array of its
frames (``{id, kind, params: base64}``).
``GET /v1/scenes/{scene}/start`` is the same for a named scene.
"""

from __future__ import annotations

import base64
from collections.abc import AsyncIterator, Iterable
from dataclasses import dataclass
from typing import Annotated, Any, cast

import msgpack
from fastapi import APIRouter, Depends, Query, Request
from fastapi.responses import StreamingResponse
from starlette.concurrency import run_in_threadpool

from walkstream.server.service.contentsform import STREAM_LEVEL
from walkstream.server.service.dependencies import RepDep, SceneDep, get_registry
from walkstream.server.service.http import (
    Rep,
    accepts_gzip,
    dump_json,
    dump_msgpack,
    stream_response,
)
from walkstream.server.service.models import ERRORS, StartPartOut, error_doc
from walkstream.server.service.registry import SceneRegistry
from walkstream.server.service.routers.objects import coalesce
from walkstream.server.service.scenes import OBJECT_FORMS, Scene
from walkstream.server.service.scenes import Form as ObjForm
from walkstream.server.service.startbundle import Frames, StartPart, start_parts, start_position
from walkstream.shared.errors import ApiError, InputError
from walkstream.shared.roomview import RoomView
from walkstream.shared.wire import JSON, MSGPACK

__all__ = ["router"]

router = APIRouter(prefix="/v1", responses=ERRORS)

_DOC: dict[int | str, dict[str, Any]] = {
    200: {
        "description": "concatenated msgpack maps {part, etag, body} (see the module docs); a "
        "JSON array with Accept: application/json",
        "content": {
            MSGPACK: {},
            JSON: {"schema": {"type": "array", "items": StartPartOut.model_json_schema()}},
        },
    },
    422: error_doc("an unknown form, or a view the interior cannot take"),
}

Coord = Annotated[
    float | None,
    Query(allow_inf_nan=False, description="scene-local metres; replaces this coordinate of the start"),
]
Heading = Annotated[
    float | None,
    Query(allow_inf_nan=False, description="radians counter-clockwise from +x (x, y starts)"),
]
Form = Annotated[
    str,
    Query(
        max_length=64,
        description="the objects' form, as in POST .../objects: params or lod2",
        json_schema_extra={"enum": list(OBJECT_FORMS)},
    ),
]
Speed = Annotated[
    float | None, Query(allow_inf_nan=False, ge=0, le=100, description="m/s (x, y starts)")
]
Name = Annotated[str | None, Query(max_length=256)]
_PIXELS = r"(1[6-9]|[2-9][0-9]|[1-9][0-9]{2}|[1-7][0-9]{3}|80[0-9]{2}|81[0-8][0-9]|819[0-2])"
"""16 to 8192, the sizes a :class:`~walkstream.shared.roomview.RoomView` takes, as a pattern."""
View = Annotated[
    str | None,
    Query(max_length=16, pattern=f"^{_PIXELS}x{_PIXELS}$",
          description="interiors: the client's viewport WIDTHxHEIGHT in pixels (asks for the first view's contents)"),
]
Fov = Annotated[float | None, Query(allow_inf_nan=False, ge=1, le=170, description="interiors: vertical field of view, degrees")]
Fog = Annotated[float | None, Query(allow_inf_nan=False, gt=0, le=10_000, description="interiors: fog distance, metres")]
Depth = Annotated[int | None, Query(ge=0, le=256, description="interiors: portals passed at most")]
Head = Annotated[
    float | None,
    Query(allow_inf_nan=False, ge=0, le=86_400,
          description="interiors, with view and path: send only the path's first SECONDS "
          "(part pathhead, in place of path)"),
]

Pose = Annotated[
    bool,
    Query(description="interiors, with head and heads: the path's first pose alone first (part pathhead, no "
          "ETag), the head of head seconds right after the first view's contents (a pathhead part among them)"),
]
Heads = Annotated[
    bool,
    Query(description="interiors, with view and path: a cell the first pose sees in part comes first as its "
          "head (the pieces drawn and the boxes of the others, part field missing), whole after the others"),
]

WallsQ = Annotated[
    bool,
    Query(description="interiors baked with --virtual-walls, with view and path: also the wall sides (part walls) "
          "and the first view's wall textures (part walltex: {part, etag: null, textures: [ids]}, then one "
          "{cell, etag, body} part each) before the contents, the first view then walked with those walls closed; "
          "a city's (with heads): the start cell's ring and the textures its first pose sees, after the first "
          "view's objects"),
]


@dataclass(frozen=True)
class StartQuery:
    """Where the bundle starts and in what form: any of path, viewpoint, x and y, each
    overriding the one before (none: the scene's default start)."""

    path: Annotated[
        str | None,
        Query(max_length=256, description="send this path; start at its start unless a viewpoint or x, y say otherwise"),
    ] = None
    viewpoint: Annotated[
        str | None, Query(max_length=256, description="start at this viewpoint unless x, y say otherwise")
    ] = None
    x: Coord = None
    y: Coord = None
    heading: Heading = None
    speed: Speed = None
    form: Form = "params"
    view: View = None
    fov: Fov = None
    fog: Fog = None
    depth: Depth = None
    head: Head = None
    heads: Heads = False
    walls: WallsQ = False
    pose: Pose = False

    def room_view(self) -> RoomView | None:
        """The client's interior view when it gave its viewport (else None)."""
        if self.view is None:
            return None
        w, h = (int(v) for v in self.view.split("x"))
        d = RoomView()
        try:
            return RoomView(
                (w, h),
                d.fov_deg if self.fov is None else self.fov,
                d.fog_m if self.fog is None else self.fog,
                d.max_depth if self.depth is None else self.depth,
            )
        except InputError as e:
            raise ApiError(str(e), status=422, detail={"view": self.view}) from e


StartDep = Annotated[StartQuery, Depends()]


@router.get("/start", responses=_DOC, summary="Start bundle (any scene)")
async def start_any(
    request: Request,
    registry: Annotated[SceneRegistry, Depends(get_registry)],
    rep: RepDep,
    q: StartDep,
    scene: Name = None,
) -> StreamingResponse:
    """The start bundle of ``scene`` (default: the first scene by name); see the module docs."""
    if scene is None:
        if not registry.scenes:
            raise ApiError("the server serves no scene", status=404)
        scene = next(iter(registry.scenes))
    return await _bundle(request, registry.get(scene), rep, q)


@router.get("/scenes/{scene}/start", responses=_DOC, summary="Start bundle")
async def start_scene(
    request: Request, scene: SceneDep, rep: RepDep, q: StartDep
) -> StreamingResponse:
    """The start bundle of a named scene; see the module docs."""
    return await _bundle(request, scene, rep, q)


async def _bundle(request: Request, scene: Scene, rep: Rep, q: StartQuery) -> StreamingResponse:
    if q.form not in OBJECT_FORMS:
        raise ApiError(
            f"unknown form {q.form!r:.80}: expected one of {', '.join(OBJECT_FORMS)}",
            status=422,
            detail={"form": q.form[:80], "known": list(OBJECT_FORMS)},
        )
    xy, h, v = await run_in_threadpool(
        lambda: start_position(scene, path=q.path, viewpoint=q.viewpoint, x=q.x, y=q.y)
    )
    h = h if q.heading is None else q.heading
    v = v if q.speed is None else q.speed
    view = q.room_view()
    inflate = accepts_gzip(request.headers.get("accept-encoding"))
    parts = await run_in_threadpool(
        lambda: start_parts(scene, xy, rep, q.path, h, v, cast(ObjForm, q.form), view=view, inflate=inflate,
                            path_head_s=q.head, heads=q.heads, walls=q.walls, pose=q.pose)
    )
    headers = {"X-Scene-Version": scene.version, "X-Scene": scene.name, "Cache-Control": "no-cache"}
    if rep == "json":
        return stream_response(request, coalesce(_json_parts(parts)), JSON, headers)
    if scene.interior is not None:
        # one piece per part, so a gzip stream is flushed after each: the walk starts
        # once the topology and the contents' list are in, and each cell is usable
        # as soon as its part is (level 9, as for a contents batch)
        # (with pose, what comes before the first pose's view is of no use without it:
        # all of it one piece, one flush, not one a part)
        pieces = _join_first_view(list(_msgpack_parts(parts)), parts)
        return stream_response(request, _each(pieces), MSGPACK, headers, level=STREAM_LEVEL)
    return stream_response(request, coalesce(_msgpack_parts(parts)), MSGPACK, headers)


async def _each(pieces: Iterable[bytes]) -> AsyncIterator[bytes]:
    for p in pieces:
        yield p


def _join_first_view(pieces: list[bytes], parts: list[StartPart]) -> list[bytes]:
    """``pieces`` (:func:`_msgpack_parts` of ``parts``) with those up to the last frame of
    the first pose's view (:attr:`Frames.view` of the ``contents`` part) joined into one,
    so the gzip stream is flushed once before that view's end rather than after each part
    (on the duplex 14 bytes sooner); as they are where no part says where that view ends."""
    n = 0
    for name, body in parts:
        if isinstance(body, Frames):
            if name == "contents" and body.view > 0:
                n += 1 + body.view
                return [b"".join(pieces[:n]), *pieces[n:]]
            n += 1 + len(body.frames)
        else:
            n += 1
    return pieces


def _msgpack_parts(parts: list[StartPart]) -> Iterable[bytes]:
    for name, body in parts:
        # a part without an ETag goes without the field (nil and missing read alike)
        if isinstance(body, Frames):
            head: dict[str, Any] = {"part": name}
            if name == "contents":
                head["cells"] = body.ids
            elif name == "walltex":
                head["textures"] = body.ids
            else:
                head["count"] = len(body.frames)
            yield dump_msgpack(head)
            yield from body.frames
        elif body.etag:
            yield dump_msgpack({"part": name, "etag": body.etag, "body": body.content})
        else:
            yield dump_msgpack({"part": name, "body": body.content})


def _json_parts(parts: list[StartPart]) -> Iterable[bytes]:
    yield b"["
    for k, (name, body) in enumerate(parts):
        if isinstance(body, Frames):
            frames = [msgpack.unpackb(f) for f in body.frames]
            content = dump_json(
                [
                    {
                        k: base64.b64encode(v).decode() if isinstance(v, bytes) else v
                        for k, v in o.items()
                    }
                    for o in frames
                ]
            )
            etag = None
        else:
            content, etag = body.content, body.etag or None
        head = dump_json({"part": name, "etag": etag})[:-1]
        yield (b",\n" if k else b"\n") + head + b',"body":' + content + b"}"
    yield b"\n]\n"
