"""The start bundle: where a walk starts and what it needs before its first frame.

``GET /v1/start`` (:mod:`walkstream.server.service.routers.start`) answers with the parts
:func:`start_parts` lists, at the position :func:`start_position` picks.  A city's bundle
is the path, the records of the cells the viewer reaches in the first seconds going
straight on (with their index tiles), the manifest, then the objects of the first
cells' PVS; an interior's is the path (or its head), the topology, the contents of the
cells the client's view sees from the path's first poses, then the manifest.  Every
body is one the scene's own endpoints send (:class:`~walkstream.server.service.scenes.Scene`
encodes and caches them), so a client decodes and caches each part as if it had asked
for it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from walkstream.server.service.firstrings import first_rings
from walkstream.server.service.firstview import first_view_contents
from walkstream.server.service.firstwalls import (
    first_wall_textures,
    scene_walls,
)
from walkstream.server.service.http import Encoded, Rep, dump_msgpack
from walkstream.server.service.scenes import Form, Scene
from walkstream.server.service.streetheads import POSE_STEP_S, first_view_plan, object_boxes_body
from walkstream.shared.codec.cellbatch import pack_contents_part
from walkstream.shared.errors import ApiError
from walkstream.shared.pathcodec import decode_path_q
from walkstream.shared.paths import RecordedPath
from walkstream.shared.roomview import RoomView, cells_seen

__all__ = [
    "START_LEAD_S",
    "START_MAX_AHEAD_M",
    "START_RECORD_LEAD_S",
    "START_RECORD_AHEAD_M",
    "START_ROOM_LEAD_S",
    "START_ROOM_BYTES",
    "Frames",
    "StartPart",
    "start_position",
    "default_start",
    "path_start",
    "start_cells",
    "start_parts",
    "room_lead",
]


START_LEAD_S = 3.0
"""A start bundle holds the cells the viewer reaches in this many seconds, going straight on."""

START_MAX_AHEAD_M = 200.0
"""A start bundle looks at most this far ahead."""

START_RECORD_LEAD_S = 2.0
"""A start bundle also holds the records (and index tiles) of the cells reached in this
many seconds more, without their objects: a record is small, and a viewer who enters a
cell whose record has not come cannot even count what it misses; the client's own
requests queue behind the bundle."""

START_RECORD_AHEAD_M = 20.0
"""... and at least this many metres more (a walker's next junction)."""

START_ROOM_LEAD_S: tuple[float, ...] = tuple(0.25 * k for k in range(1, 9))
"""An interior start bundle holds the contents of the cells seen from the path's first
pose and from its poses after these many seconds (every quarter second of the first
two: a walk swerving round a stair or a door leaf glimpses a cell for half a second)."""

START_ROOM_BYTES = 32_000
"""An interior start bundle holds at most this many bytes of stored contents (the
first cell's always)."""


@dataclass(frozen=True)
class Frames:
    """The frames that follow a start bundle part's header: ``ids`` in order, each packed;
    ``view``: how many of the first frames carry the first pose's view (an interior's
    ``contents`` with ``pose``; else 0)."""

    ids: list[int]
    frames: list[bytes]
    view: int = 0


StartPart = tuple[str, "Encoded | Frames"]
"""One part of a start bundle: its name (:data:`~walkstream.shared.startwire.START_PARTS`) and
its encoded body, or for ``objects`` and ``contents`` the frames that follow its header."""


def start_position(
    scene: Scene,
    *,
    path: str | None = None,
    viewpoint: str | None = None,
    x: float | None = None,
    y: float | None = None,
) -> tuple[tuple[float, float], float | None, float]:
    """Where a start bundle starts: ``((x, y), heading or None, speed in m/s)``.

    Every combination of the parameters is an answer, each one overriding the one
    before: the scene's default start (its first viewpoint, else the start of its
    first path by name, else the middle of its bounds); a named ``path``'s first
    point, heading and speed over its first second; a named ``viewpoint``'s position
    and yaw (standing still); then ``x`` and ``y``, each replacing its coordinate (a
    start moved this way has no heading and stands still).  So ``path=P&x=..&y=..``
    sends path ``P`` and starts at the point given.

    Raises
    ------
    ApiError
        404 for an unknown path or viewpoint.
    """
    if path is not None and path not in scene.path_names:
        raise ApiError(
            f"scene {scene.name!r} has no path {path!r:.80}", status=404, detail={"path": path}
        )
    heading: float | None
    if viewpoint is not None:
        vp = next((v for v in scene.manifest_viewpoints if v.name == viewpoint), None)
        if vp is None:
            raise ApiError(
                f"scene {scene.name!r} has no viewpoint {viewpoint!r:.80}",
                status=404,
                detail={"viewpoint": viewpoint},
            )
        xy, heading, speed = (vp.x, vp.y), vp.yaw, 0.0
    elif path is not None:
        xy, heading, speed = path_start(scene, path)
    else:
        xy, heading, speed = default_start(scene)
    if x is None and y is None:
        return (float(xy[0]), float(xy[1])), heading, speed
    return (float(xy[0] if x is None else x), float(xy[1] if y is None else y)), None, 0.0


def default_start(scene: Scene) -> tuple[tuple[float, float], float | None, float]:
    """The start of a bundle that names none: the first viewpoint, else the first
    path's start (by name), else the middle of the scene's bounds (no heading)."""
    if scene.manifest_viewpoints:
        v = scene.manifest_viewpoints[0]
        return (v.x, v.y), v.yaw, 0.0
    if scene.path_names:
        return path_start(scene, min(scene.path_names))
    b = scene.reader.bounds()
    return ((b[0] + b[3]) / 2.0, (b[1] + b[4]) / 2.0), None, 0.0


def path_start(scene: Scene, path: str) -> tuple[tuple[float, float], float, float]:
    """A recorded path's first point, heading, and speed over its first second."""
    p = RecordedPath.from_msgpack(scene.path(path, "msgpack").content, f"path {path!r}")
    xyz, yaw, _pitch = p.at(0.0)
    dt = min(1.0, p.duration) or 1.0
    later, _, _ = p.at(dt)
    speed = float(np.hypot(*(np.asarray(later[:2]) - np.asarray(xyz[:2])))) / dt
    return (float(xyz[0]), float(xyz[1])), float(yaw), speed


def start_cells(
    scene: Scene, xy: tuple[float, float], heading: float | None, ahead_m: float
) -> list[int]:
    """The cell holding ``xy`` and those a straight line ``ahead_m`` long along
    ``heading`` enters, in the order entered (empty outside every cell)."""
    first = scene.locator.locate(*xy)
    if first is None:
        return []
    out = [first]
    if heading is not None and ahead_m > 0:
        d = np.arange(1.0, ahead_m + 1e-9, 1.0)
        pts = np.asarray(xy)[None, :] + d[:, None] * np.array([math.cos(heading), math.sin(heading)])
        for c in scene.locator.locate_many(pts).tolist():
            if c < 0:
                break  # the line left the cells: what lies beyond is not straight on
            if c not in out:
                out.append(int(c))
    return out


def start_parts(
    scene: Scene,
    xy: tuple[float, float],
    rep: Rep,
    path: str | None = None,
    heading: float | None = None,
    speed: float = 0.0,
    form: Form = "params",
    view: RoomView | None = None,
    inflate: bool = False,
    path_head_s: float | None = None,
    heads: bool = False,
    walls: bool = False,
    pose: bool = False,
) -> list[StartPart]:
    """The parts of a start bundle at ``xy``, in the order sent.

    The path (when asked by name; the walk can start once it is in), the
    records of the cell holding ``xy`` and of the cells straight ahead that the
    viewer reaches within :data:`START_LEAD_S` at ``speed`` and
    :data:`START_RECORD_LEAD_S` more (none outside every cell), each followed by
    the index tile holding it when not sent yet (the client tracks the viewer
    with them; outside every cell, the tiles that may hold cells near ``xy``),
    the manifest, then the objects of the PVS of the cells of the first
    :data:`START_LEAD_S`: the first cell's by ACH (highest first), then each
    next cell's new ones.  A record whose PVS those objects do not all hold comes as
    a ``record`` part (:func:`_record_part`), the others as ``cell`` parts.  Reads the database on cache misses: call it
    from a worker thread.

    An interior's bundle is the path, the topology, then (for a path and a client
    ``view``) the contents of the cells that view sees from the path's first pose
    and from where the path leads in :data:`START_ROOM_LEAD_S` (up to
    :data:`START_ROOM_BYTES`; ``inflate``: for a gzip-compressed answer, each blob
    inflated or as stored, whichever costs fewer bytes in the answer's stream,
    :mod:`~walkstream.server.service.contentsform`), then the manifest.  With ``path_head_s`` as well (compact parts only),
    only the path's first ``path_head_s`` seconds come, as ``pathhead`` (the walk
    starts on the head; the client fetches the whole path when its link is idle: on
    a long tour it is a third of the bytes before the contents otherwise).  With
    ``heads`` as well, a cell the path's first pose sees in part goes first as its head
    (:mod:`~walkstream.server.service.firstheads`) and whole after every other cell: the
    contents' list then names it twice.

    With ``pose`` as well (with ``path_head_s`` and ``heads``), the head's first pose
    comes first (``pathhead``, the path's first two samples, no ETag: the walker stands
    there until its first view is in) and the head of ``path_head_s`` among the
    contents' frames, right after those that carry the first pose's view (the pack,
    or those cells part by part): the first view arrives that much sooner.  The
    ``contents`` part's :attr:`Frames.view` then counts those frames: the service sends
    everything up to them as one piece of its gzip stream (the walker needs all of it
    before its first frame; one flush, not one a part, saves the flushes' bytes).

    With ``walls``, on an interior baked with ``--virtual-walls``, the bundle also brings
    the wall sides (``walls``) and the textures of the walls the first view sees
    (``walltex``, :mod:`~walkstream.server.service.firstwalls`) before its contents,
    whose first view is then the walk with those walls closed (a city's bundle is
    unchanged).
    """
    parts: list[StartPart] = []
    split = path is not None and scene.interior is not None and view is not None and rep == "msgpack"
    head = scene.path_head_q(path, path_head_s) if split and path and path_head_s is not None else None
    first_pose = scene.path_head_q(path, 0.0) if head is not None and path and pose and heads else None
    if path is not None:
        whole = scene.path_q(path) if rep == "msgpack" else scene.path(path, rep)
        if first_pose is not None:  # the head's first pose alone: no cache keeps it
            parts.append(("pathhead", Encoded(first_pose.content, first_pose.media_type, "")))
        else:
            parts.append(("path", whole) if head is None else ("pathhead", head))
    if scene.interior is not None:
        # an interior walk needs its topology before its first frame, then the first
        # view's contents; the manifest (not needed to walk) goes last
        topology = scene.interior.topology_compact if rep == "msgpack" else scene.interior.topology[rep]
        parts.append(("topology", topology))
        if path is not None and view is not None:
            interior = scene.interior
            lead = room_lead(scene, path)
            closed: frozenset[int] = frozenset()
            if walls and scene.has_walls:  # the first view's wall textures first: their walls closed
                wall_parts, closed = _first_walls(scene, lead[0], view, rep)
                parts += wall_parts
            cells, first = interior.first_view(lead, view, START_ROOM_BYTES, closed)
            ids, frames, seen = first_view_contents(interior, cells, lead[0], view, heads=heads, inflate=inflate,
                                                    pack=heads and rep == "msgpack", first=first, lead=lead[1:])
            if first_pose is not None and head is not None:  # the rest of the head once the first view is in
                frames.insert(seen, dump_msgpack({"part": "pathhead", "etag": head.etag or None, "body": head.content}))
            parts.append(("contents", Frames(ids, frames, seen if first_pose is not None else 0)))
        return [*parts, ("manifest", scene.manifest[rep])]
    ahead = min(START_MAX_AHEAD_M, max(0.0, speed) * START_LEAD_S)
    more = max(START_RECORD_AHEAD_M, max(0.0, speed) * START_RECORD_LEAD_S) if speed > 0 else 0.0
    cells = start_cells(scene, xy, heading, min(START_MAX_AHEAD_M, ahead + more))
    with_objects = start_cells(scene, xy, heading, ahead)
    if heads and path is not None and view is not None and rep == "msgpack" and cells:
        return parts + _first_view_parts(scene, path, view, cells, with_objects, form, walls)
    # the records first, each with the index tile that holds its cell (the client
    # follows the viewer into it by its outline; other tiles around the start it
    # asks for when it needs them), then the manifest (its grammar rebuilds the
    # objects), then the objects of the cells reached within START_LEAD_S
    sent: set[tuple[int, int]] = set()
    order = _objects_of(scene, with_objects)
    brought = set(order)
    for cid in cells:
        parts.append((_record_part(scene, cid, brought), scene.cell(cid, rep)))
        tile = scene.cell_tile[cid]
        if tile not in sent:
            sent.add(tile)
            parts.append(("index", scene.index(tile, rep)))
    if not cells:  # outside every cell: the tiles that may hold cells near the start
        parts += [("index", scene.index(t, rep)) for _d, t in scene.grid.tiles_near(xy)]
    parts.append(("manifest", scene.manifest[rep]))
    if order:
        parts.append(_objects_part(scene, order, form))
    return parts


def _record_part(scene: Scene, cid: int, brought: set[int]) -> str:
    """The part name of cell ``cid``'s record in a bundle that brings the objects
    ``brought``: ``cell`` when they hold its whole PVS, else ``record`` (the client
    then does not wait for the bundle to bring its objects: the records of the cells
    beyond :data:`START_LEAD_S` come without them, and on a slow link the bundle can
    take seconds longer than the walk takes to reach them)."""
    pvs = scene.reader.cell(cid).pvs.tolist()
    return "cell" if brought.issuperset(int(i) for i in pvs) else "record"


def _objects_of(scene: Scene, cells: list[int], seen: set[int] | None = None) -> list[int]:
    """The objects of ``cells``' PVS not in ``seen``: the first cell's by ACH (highest
    first), then each next cell's new ones."""
    seen = set() if seen is None else set(seen)
    order: list[int] = []
    for cid in cells:
        c = scene.reader.cell(cid)
        for oid in c.pvs[np.argsort(-c.ach, kind="stable")].tolist():
            if oid not in seen:
                seen.add(oid)
                order.append(int(oid))
    return order


def _objects_part(scene: Scene, ids: list[int], form: Form) -> StartPart:
    found, missing = scene.cached_frames(ids, form)
    if missing:
        found.update(scene.load_frames(missing, form))
    return "objects", Frames(ids, [found[oid] for oid in ids])


def _first_view_parts(scene: Scene, path: str, view: RoomView, cells: list[int], with_objects: list[int],
                      form: Form, walls: bool = False) -> list[StartPart]:
    """A city bundle's parts after the path when the client holds its start for its first
    view, in the order :func:`~walkstream.server.service.streetheads.first_view_plan` gives.

    With ``walls`` on a city baked with them (:mod:`~.firstrings`): after the first
    pose's parts the rings of the cells its first seconds pass and the textures its
    first :data:`~.firstrings.HOLD_TEXTURES_S` see, in a ``walltex`` part sent even when
    empty: the client's walker stands at its start until that part's textures are in,
    not for the rest of the bundle.  The later poses' parts and textures follow in the
    order the walk needs them (each a pose's step before the pose that first needs it:
    the walk crosses into a cell or a zone anywhere between two poses), so the textures
    of the walls the walk turns to come before the records of the cells it reaches later (the
    walker does not wait for them: on West Oakland's walk it crossed into the next zone
    of a wall 0.08 s after it started walking, and a missing texture leaves its far
    field, tens of objects, to geometry)."""
    ring = None
    if walls and scene.has_walls:
        ring = first_rings(scene, RecordedPath.from_msgpack(scene.path(path, "msgpack").content, f"path {path!r}"),
                           view, START_LEAD_S)
    plan = first_view_plan(scene, path, view, START_LEAD_S, cells, with_objects)
    brought = {int(i) for name, what, _t in plan if name == "objects" for i in what}

    def part(name: str, what: Any) -> StartPart:
        if name == "cell":
            return _record_part(scene, what, brought), scene.cell(what, "msgpack")
        if name == "index":
            return "index", scene.index(what, "msgpack")
        if name == "manifest":
            return "manifest", scene.manifest["msgpack"]
        if name == "objects":
            return _objects_part(scene, what, form)
        return "boxes", Encoded(object_boxes_body(scene, what), scene.manifest["msgpack"].media_type, "")

    if ring is None:
        return [part(name, what) for name, what, _t in plan]
    first = [part(name, what) for name, what, t in plan if t <= 0.0]
    first += [("walls", ring[0]), ("walltex", _textures(scene, ring[1]))]  # the walker's wait ends here
    # the rest by the time the walk needs it: a pose's step before the pose that first needs
    # it (the walk may cross into a cell or a zone anywhere between two poses), a cell's
    # record before the textures of the same pose (without it the frame knows no cell)
    later: list[tuple[float, int, str, Any]] = [(t - POSE_STEP_S, 0, name, what) for name, what, t in plan if t > 0.0]
    later += [(t - POSE_STEP_S, 1, "walltex", tid) for tid, t in ring[2]]
    later.sort(key=lambda x: (x[0], x[1]))  # stable: the plan's order kept at equal times
    groups: list[tuple[str, Any]] = []
    for _t, _k, name, what in later:
        if name == "walltex" and groups and groups[-1][0] == "walltex":
            groups[-1][1].append(what)  # textures in a row: one part
        else:
            groups.append((name, [what] if name == "walltex" else what))
    rest = [("walltex", _textures(scene, what)) if name == "walltex" else part(name, what) for name, what in groups]
    return first + rest


def _first_walls(scene: Scene, pose: tuple[NDArray[np.float64], float, float], view: RoomView,
                 rep: Rep) -> tuple[list[StartPart], frozenset[int]]:
    """An interior's wall parts (every side, then the textures of the walls ``pose``
    sees at full weight on the cells its walk reaches with them closed) and those walls."""
    interior = scene.interior
    assert interior is not None
    graph, locator = interior.view_model
    ids, closed = first_wall_textures(
        scene_walls(scene, interior.topology_compact.content), pose, view,
        reached=lambda shut: cells_seen(graph, locator, [pose], view, shut)[0])
    return [("walls", scene.walls[rep]), ("walltex", _textures(scene, ids))], closed


def _textures(scene: Scene, ids: list[int]) -> Frames:
    """Wall textures ``ids`` as the textures' batch sends them, one part each."""
    encs = [scene.wall_texture(t) for t in ids]
    return Frames(ids, [pack_contents_part(t, e.etag, e.content) for t, e in zip(ids, encs, strict=True)])


def room_lead(scene: Scene, path: str) -> list[tuple[NDArray[np.float64], float, float]]:
    """The poses of an interior start: the path's first (as the client decodes the
    compact path) and the path's own poses after :data:`START_ROOM_LEAD_S` (past its end,
    its last).  The walk follows the path, so the bundle follows it too: a walk that
    bends in its first seconds (round a stair or a door leaf, keeping its clearance)
    sees cells that going straight on never would, and the client's own requests for
    them queue behind the bundle."""
    p = decode_path_q(scene.path_q(path).content, f"path {path!r}")
    out: list[tuple[NDArray[np.float64], float, float]] = []
    for h in (0.0, *START_ROOM_LEAD_S):
        xyz, yaw, pitch = p.at(min(h, p.duration))
        out.append((np.asarray(xyz, dtype=np.float64), float(yaw), float(pitch)))
    return out
