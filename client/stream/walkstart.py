"""How a walk starts: the manifest (revalidated against the disk cache) and the start bundle.

:func:`bundle_start` asks for the start bundle (path, first cells, index tiles,
manifest and objects in one round trip) through the streamer; when it fails before
the path is in, the replay falls back to fetching scene, manifest and path one by
one, :func:`manifest_task` fetching the manifest on its own.  An interior walk
starts with :func:`interior_start` instead: its bundle is the path (or only its first
seconds, the whole path then fetched by :func:`whole_path_when_idle`), the topology,
the contents of the cells the first view sees (:class:`StartContents`, handed to the
room streamer while they arrive) and the manifest.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass
from typing import Any

from walkstream.client.clock import Clock, within
from walkstream.client.net.api import SceneClient
from walkstream.client.stream.diskcache import DiskCache
from walkstream.client.stream.startwalls import StartWalls
from walkstream.client.stream.streamer import Streamer
from walkstream.shared.codec.cellmesh import CellMesh
from walkstream.shared.errors import ApiError, CodecError, StreamCut
from walkstream.shared.paths import RecordedPath
from walkstream.shared.roomview import RoomView
from walkstream.shared.roomwire import Topology
from walkstream.shared.wire import Manifest, decode_manifest

__all__ = [
    "fetch_manifest", "manifest_task", "bundle_start", "StartContents", "interior_start",
    "PATH_LEAD_S", "whole_path_when_idle",
]


async def fetch_manifest(api: SceneClient, disk: DiskCache | None) -> Manifest:
    """The manifest of ``api.scene``, revalidated against the disk cache's copy when there is one."""
    assert api.scene is not None
    stored = disk.get_manifest(api.scene) if disk is not None else None
    etag = stored[0] if stored is not None else None
    m = await api.manifest(etag)
    if m is None:  # 304: the stored manifest is current
        assert stored is not None
        return decode_manifest(stored[1], f"scene {api.scene!r} manifest (disk cache)", etag)
    if disk is not None and m.etag:
        disk.put_manifest(api.scene, m.etag, m.body)
    return m


def manifest_task(
    api: SceneClient,
    disk: DiskCache | None,
    arrived: Callable[[Manifest], None],
    failed: Callable[[BaseException], None] | None = None,
) -> asyncio.Task[Manifest]:
    """Fetch the manifest on its own; ``arrived`` is called with it when it is in.

    A fetch that fails (a manifest the client cannot decode: the same body refused
    twice, :meth:`~walkstream.client.net.api.SceneClient.manifest`) goes to ``failed``,
    never dropped: without the manifest the client rebuilds no building, so the replay
    ends with that one-line error.
    """
    task = asyncio.create_task(fetch_manifest(api, disk))

    def done(t: asyncio.Task[Manifest]) -> None:
        if t.cancelled():
            return
        exc = t.exception()
        if exc is None:
            arrived(t.result())
        elif failed is not None:
            failed(exc)

    task.add_done_callback(done)
    return task


async def bundle_start(
    path: str,
    timeout_s: float,
    clock: Clock,
    api: SceneClient,
    streamer: Streamer,
    disk: DiskCache | None,
    manifest_arrived: Callable[[Manifest], None],
    manifest_fut: asyncio.Future[Manifest],
    tasks: list[asyncio.Task[Any]],
    manifest_failed: Callable[[BaseException], None] | None = None,
    view: RoomView | None = None,
) -> tuple[RecordedPath, int] | None:
    """Start with the start bundle of recorded path ``path``: the path and its bytes.

    None when the bundle failed before the path arrived (the caller then starts the
    old way).  When it is cut after the path but before the manifest, a task
    (added to ``tasks``) fetches the manifest on its own.  With ``view`` (a city walk
    that stands at its start until its first view is complete), the bundle brings the
    objects that view draws first and the boxes of the first cell's others
    (:mod:`~walkstream.server.service.streetheads`).
    """
    loop = asyncio.get_running_loop()
    path_fut: asyncio.Future[tuple[RecordedPath, int]] = loop.create_future()

    def on_path(p: RecordedPath, n: int) -> None:
        if not path_fut.done():
            path_fut.set_result((p, n))

    def on_manifest(m: Manifest) -> None:
        if disk is not None and m.etag:
            disk.put_manifest(m.name, m.etag, m.body)
        manifest_arrived(m)

    def on_end(err: BaseException | None) -> None:
        if not path_fut.done():
            path_fut.set_exception(err or ApiError("start bundle: no path in it"))
        elif not manifest_fut.done() and api.scene is not None:
            # cut after the path: the manifest (the grammar) comes on its own
            tasks.append(manifest_task(api, disk, manifest_arrived, manifest_failed))

    streamer.start_feed.start_bundle(path, on_path, on_manifest, on_end, view=view)
    try:
        got: tuple[RecordedPath, int] | None = await within(
            clock, timeout_s, path_fut
        )
    except (ApiError, StreamCut):
        return None
    return got


@dataclass
class StartContents:
    """The first view's contents, still coming in the interior start bundle after the walk starts."""

    cells: list[int]
    """The cells whose contents follow, in order."""
    parts: AsyncIterator[tuple[int, CellMesh]]
    """Each cell's contents as it arrives (:class:`~walkstream.shared.errors.StreamCut`
    when the bundle ends early); the manifest after them goes to ``manifest_arrived``."""


async def interior_start(
    path: str,
    timeout_s: float,
    clock: Clock,
    api: SceneClient,
    disk: DiskCache | None,
    manifest_arrived: Callable[[Manifest], None],
    tasks: list[asyncio.Task[Any]],
    view: RoomView | None = None,
    manifest_failed: Callable[[BaseException], None] | None = None,
    path_head_s: float | None = None,
    path_arrived: Callable[[RecordedPath], None] | None = None,
    heads: bool = False,
    walls: StartWalls | None = None,
    head_arrived: Callable[[RecordedPath | None], None] | None = None,
) -> tuple[tuple[RecordedPath, int] | None, Topology | None, StartContents | None]:
    """The interior start bundle of recorded path ``path``: ``((path, its bytes), topology,
    the first view's contents)``.

    With ``view`` (how the client will view the interior) the server adds the contents
    of the cells that view sees first; this returns as soon as their list is in, so the
    walk starts while they arrive (the :class:`StartContents` carries the rest of the
    stream).  ``(None, None, None)`` when the bundle failed (or took longer than
    ``timeout_s``) before both the path and the topology were in: the caller then
    starts the old way.  The manifest goes to ``manifest_arrived`` (and the disk
    cache) as it arrives; when the bundle ends without it, a task (added to ``tasks``)
    fetches it on its own.

    With ``view``, ``path_head_s`` and ``path_arrived``, the bundle brings only the
    path's first ``path_head_s`` seconds: the path returned is then that head, and the
    caller fetches the whole path (:func:`whole_path_when_idle`).  Whenever the bundle
    brings the whole path instead (no head asked for, or a server that does not know
    ``head``), it goes to ``path_arrived`` at once: a caller that was not called walks
    a head.  With the path's head, ``heads``: a cell the first pose sees in part may
    come first as its head, then whole (``StartContents.cells`` names each cell once).
    With ``walls`` (an interior baked with ``--virtual-walls``), the wall sides and the
    first view's wall textures, before the contents: the first view is then walked with
    those walls closed.  With ``head_arrived`` as well (and a path's head, ``heads``), the
    path returned is the head's first pose alone, and the head comes once the first
    pose's view is in: to ``head_arrived``, which gets None instead when the bundle ends
    without it (the walk then goes on by the whole path alone).
    """
    got: dict[str, Any] = {}
    split = view is not None and path_head_s is not None and path_arrived is not None
    posed = split and heads and head_arrived is not None
    stream = api.start(path=path, view=view, path_head_s=path_head_s if split else None, heads=split and heads,
                       walls=walls is not None and view is not None, pose=posed)

    def on_whole(p: RecordedPath) -> None:
        if path_arrived is not None:
            path_arrived(p)

    def on_manifest(m: Manifest) -> None:
        got["manifest"] = m
        if disk is not None and m.etag:
            disk.put_manifest(m.name, m.etag, m.body)
        manifest_arrived(m)

    def without_manifest() -> None:
        if "manifest" not in got and api.scene is not None:
            tasks.append(manifest_task(api, disk, manifest_arrived, manifest_failed))

    async def head() -> None:
        async for part, item in stream:
            if part == "manifest":
                on_manifest(item[0])
            elif part == "path":
                on_whole(item[0])
            elif part == "pathhead":
                part = "path"  # walk the head while the whole path comes
            elif part == "walls" and walls is not None:
                walls.add_sides(*item)
            elif part == "texture" and walls is not None:
                walls.add_texture(*item)
            got[part] = item
            if part == "contents":
                return  # the walk can start: the contents follow as it goes

    try:
        await within(clock, timeout_s, head())
    except (ApiError, StreamCut):
        pass
    if "path" not in got or "topology" not in got:
        await stream.aclose()
        return None, None, None
    if "contents" not in got:
        await stream.aclose()
        without_manifest()
        if posed and head_arrived is not None:
            head_arrived(None)
        return got["path"], got["topology"], None
    headed: list[RecordedPath] = []

    def head_done() -> None:
        if posed and head_arrived is not None and not headed:
            head_arrived(None)

    async def rest() -> AsyncIterator[tuple[int, CellMesh]]:
        try:
            async for part, item in stream:
                if part == "room":
                    yield item
                elif part == "manifest":
                    on_manifest(item[0])
                elif part == "pathhead" and posed and head_arrived is not None and not headed:
                    headed.append(item[0])
                    head_arrived(item[0])
        except (ApiError, StreamCut):
            without_manifest()
            raise
        finally:  # ended, cut or closed without the head: the walk must not wait for it
            head_done()
        without_manifest()

    return got["path"], got["topology"], StartContents(list(dict.fromkeys(got["contents"])), rest())


PATH_LEAD_S = 4.0
"""The whole path is fetched at the latest this many seconds before the walk reaches
the end of the path's head (its transfer and a round trip at 56 kbit/s, twice over)."""
PATH_POLL_S = 0.1
"""Seconds between two looks at whether the link is idle."""
PATH_IDLE_S = 1.0
"""The link counts as idle once no contents were on it for this long (a moment between
two of the streamer's requests is not: the next is on its way)."""


async def whole_path_when_idle(
    api: SceneClient,
    clock: Clock,
    name: str,
    head: RecordedPath,
    due: float,
    busy: Callable[[], bool],
    arrived: Callable[[RecordedPath], None],
) -> None:
    """Fetch recorded path ``name`` once the link is idle, or at clock time ``due``.

    The walk runs on ``head`` (the start bundle's ``pathhead``) meanwhile; the whole
    path is needed only when the walk reaches the head's end, so it waits until
    ``busy()`` (contents on the link: the first view's, then what the walk comes to)
    has been false for :data:`PATH_IDLE_S` rather than delay them.  ``arrived`` gets
    the whole path, or ``head`` itself when the fetch fails (the walk then ends where
    the head does).
    """
    idle_since = clock.now()
    while clock.now() < due and clock.now() - idle_since < PATH_IDLE_S:
        if busy():
            idle_since = clock.now()
        await clock.sleep(PATH_POLL_S)
    try:
        whole: RecordedPath = (await api.path(name))[0]
    except (ApiError, StreamCut, CodecError):
        whole = head
    except Exception:
        arrived(head)  # whatever failed, the walk must not wait at the head's end for ever
        raise
    arrived(whole)

