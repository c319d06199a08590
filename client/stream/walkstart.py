"""How a walk starts: the manifest (revalidated against the disk cache) and the start bundle.

:func:`bundle_start` asks for the start bundle (path, first cells, index tiles,
manifest and objects in one round trip) through the streamer; when it fails before
the path is in, the replay falls back to fetching scene, manifest and path one by
one, :func:`manifest_task` fetching the manifest on its own.  An interior walk
starts with :func:`interior_start` instead: its bundle is the path, the topology and
the manifest (the cells' contents come by the room streamer's own requests).
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Any

from walkstream.client.clock import Clock, within
from walkstream.client.net.api import SceneClient
from walkstream.client.stream.diskcache import DiskCache
from walkstream.client.stream.streamer import Streamer
from walkstream.shared.errors import ApiError, StreamCut
from walkstream.shared.paths import RecordedPath
from walkstream.shared.roomwire import Topology
from walkstream.shared.wire import Manifest, decode_manifest

__all__ = ["fetch_manifest", "manifest_task", "bundle_start", "interior_start"]


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
    api: SceneClient, disk: DiskCache | None, arrived: Callable[[Manifest], None]
) -> asyncio.Task[Manifest]:
    """Fetch the manifest on its own; ``arrived`` is called with it when it is in."""
    task = asyncio.create_task(fetch_manifest(api, disk))
    task.add_done_callback(
        lambda t: None if t.cancelled() or t.exception() is not None else arrived(t.result())
    )
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
) -> tuple[RecordedPath, int] | None:
    """Start with the start bundle of recorded path ``path``: the path and its bytes.

    None when the bundle failed before the path arrived (the caller then starts the
    old way).  When it is cut after the path but before the manifest, a task
    (added to ``tasks``) fetches the manifest on its own.
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
            tasks.append(manifest_task(api, disk, manifest_arrived))

    streamer.start_bundle(path, on_path, on_manifest, on_end)
    try:
        got: tuple[RecordedPath, int] | None = await within(
            clock, timeout_s, path_fut
        )
    except (ApiError, StreamCut):
        return None
    return got


async def interior_start(
    path: str,
    timeout_s: float,
    clock: Clock,
    api: SceneClient,
    disk: DiskCache | None,
    manifest_arrived: Callable[[Manifest], None],
    tasks: list[asyncio.Task[Any]],
) -> tuple[tuple[RecordedPath, int] | None, Topology | None]:
    """The interior start bundle of recorded path ``path``: ``((path, its bytes), topology)``.

    ``(None, None)`` when the bundle failed (or took longer than ``timeout_s``)
    before both the path and the topology were in: the caller then starts the old
    way.  The manifest goes to ``manifest_arrived`` (and the disk cache) as it
    arrives; when the bundle is cut after the topology but before the manifest, a
    task (added to ``tasks``) fetches the manifest on its own.
    """
    got: dict[str, Any] = {}

    async def run() -> None:
        async for part, item in api.start(path=path):
            if part == "manifest":
                m = item[0]
                if disk is not None and m.etag:
                    disk.put_manifest(m.name, m.etag, m.body)
                manifest_arrived(m)
            got[part] = item

    try:
        await within(clock, timeout_s, run())
    except (ApiError, StreamCut):
        pass
    if "path" not in got or "topology" not in got:
        return None, None
    if "manifest" not in got and api.scene is not None:
        tasks.append(manifest_task(api, disk, manifest_arrived))
    return got["path"], got["topology"]

