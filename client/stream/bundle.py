"""The start bundle on the client's side: from nothing to the first cell's objects in one round trip.

:class:`StartBundle` asks for the bundle (``GET /v1/start``, see
:mod:`walkstream.server.service.routers.start`) and feeds its parts to a
:class:`BundleTarget` (the :class:`~walkstream.client.stream.streamer.Streamer`) and a
:class:`StartTarget` (its :class:`~walkstream.client.stream.startfeed.StartFeed`) as
they arrive: the path to
the replay (the walk starts), the cell records and index tiles to the streamer
(the viewer is tracked from the first frame), the manifest to the replay (the
grammar lets rewriting start), the objects to the cache.  While it runs, the
objects of the cells it brought as ``cell`` parts count as in flight, so nobody asks
for them twice (a ``record`` part's cell -- one beyond the bundle's first seconds --
does not: the bundle does not bring all its objects, and on a slow link it ends seconds
after the walk reached that cell, so the streamer asks for them by their need time);
and the bytes it is still expected to bring count against the link, so that other
requests queue behind it instead of slowing it down.  When the manifest says the
disk cache holds this scene version and it holds the objects still to come, the
bundle is stopped there and the link is free.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

from walkstream.client.net.api import SceneClient
from walkstream.client.stream.startwalls import StartWalls
from walkstream.client.stream.stats import StreamStats
from walkstream.shared.codec.objectboxes import ObjectBoxes
from walkstream.shared.errors import ApiError, StreamCut
from walkstream.shared.paths import RecordedPath
from walkstream.shared.roomview import RoomView
from walkstream.shared.wire import CellIndex, CellRecord, Manifest, ObjectFrame

__all__ = ["TEXTURE_BYTES", "BundleTarget", "StartTarget", "StartBundle"]

TEXTURE_BYTES = 900.0
"""A ring wall texture's bytes on the wire before it arrives (about 0.9 kB: lossy WebP)."""


class BundleTarget(Protocol):
    """What a start bundle feeds its parts to: the streamer's side of the bundle.

    The target owns what it learns (cells, index tiles, objects, the current cell); the
    bundle owns what it still expects to bring (:attr:`StartBundle.ids`,
    :attr:`StartBundle.left`), which the target reads to count the link's load.
    """

    api: SceneClient
    stats: StreamStats

    @property
    def frame_bytes(self) -> float:
        """The mean bytes of an object frame on the wire."""
        ...

    def add_index(self, idx: CellIndex) -> None:
        """Learn an index tile."""
        ...

    def add_cell(self, rec: CellRecord) -> None:
        """Learn a cell record."""
        ...

    def add_object(self, frame: ObjectFrame) -> None:
        """Learn an object."""
        ...

    def has_object(self, oid: int) -> bool:
        """Whether ``oid`` is held."""
        ...

    def expect(self, ids: set[int], coming: bool = True) -> None:
        """Mark objects as on their way (``coming``) or no longer so."""
        ...

    def objects_from_disk(self, ids: list[int]) -> set[int]:
        """Take what the disk cache holds of ``ids``; the ids taken."""
        ...

    def store_objects(self, frames: list[ObjectFrame]) -> None:
        """Keep arrived objects in the disk cache."""
        ...

    def replan(self) -> None:
        """Plan and dispatch again (a part arrived)."""
        ...


class StartTarget(Protocol):
    """Where a start bundle's start-only parts go: where the walk starts and the stand-ins'
    boxes (:class:`~walkstream.client.stream.startfeed.StartFeed`)."""

    def located(self, cid: int) -> None:
        """The server located the walk's start in cell ``cid``."""
        ...

    def add_boxes(self, boxes: ObjectBoxes) -> None:
        """Learn objects' boxes (stand-ins for objects not in yet)."""
        ...

    @property
    def walls(self) -> StartWalls | None:
        """Where a city's start ring and first wall textures go (None: not asked for)."""
        ...

    def textures_left(self) -> None:
        """The bundle's parts the walker stands at its start for are in (a city's first
        view, its rings and the textures its first moments see): what still comes is
        for the walk's later poses, and the walker walks as it comes."""
        ...


class StartBundle:
    """One start bundle in flight for a streamer.

    Parameters
    ----------
    streamer:
        Where the cells, index tiles and objects go.
    form:
        The object form asked for (``params`` or ``lod2``).
    on_path, on_manifest:
        Called as those parts arrive (the path with its bytes on the wire).
    view:
        How the walk views the city, when it stands at its start until its first view
        is complete: the bundle then brings that view's objects first and the boxes of
        the first cell's other objects (part ``boxes``).
    on_end:
        Called when the bundle ends, with the error that ended it (None when it
        ended well), e.g. an :class:`ApiError` 404 from a server without bundles.
    start:
        Where the start cell's id and the stand-ins' boxes go.

    Attributes
    ----------
    ids:
        Objects the bundle is still expected to bring.
    left:
        Bytes it is still expected to bring (an estimate).
    """

    def __init__(
        self,
        streamer: BundleTarget,
        form: str,
        on_path: Callable[[RecordedPath, int], None],
        on_manifest: Callable[[Manifest], None],
        on_end: Callable[[BaseException | None], None],
        view: RoomView | None = None,
        *,
        start: StartTarget,
    ) -> None:
        self.streamer = streamer
        self.start = start
        self.view = view
        self.form = form
        self.on_path = on_path
        self.on_manifest = on_manifest
        self.on_end = on_end
        self.ids: set[int] = set()
        self.left = 2000.0  # the manifest, at least
        self.texture_bytes = 0.0
        """Bytes of the wall textures announced and not yet in (an estimate): they count
        against the link as :attr:`left` does."""
        self._first_textures: set[int] | None = None  # the first walltex part's, not yet in

    async def run(self, path: str | None) -> None:
        """Stream the bundle for recorded path ``path``'s start; never raises for the network."""
        st = self.streamer
        error: BaseException | None = None
        frames: list[ObjectFrame] = []
        walls = self.start.walls if self.view is not None else None
        try:
            async for part, item in st.api.start(path=path, form=self.form, view=self.view,
                                                  heads=self.view is not None, walls=walls is not None):
                if part == "path":
                    p, n = item
                    st.stats.bundle_bytes += n
                    self.on_path(p, n)
                elif part == "manifest":
                    m, n = item
                    st.stats.bundle_bytes += n
                    self.left = max(0.0, self.left - n)
                    self.on_manifest(m)  # binds the disk cache of this scene version, if any
                    found = st.objects_from_disk(sorted(self.ids))
                    self._arrived(found)
                    if found and not self.ids:
                        break  # the rest of the bundle is on disk: stop it, the link is free
                elif part == "topology":  # an interior's: the replay fetches it for its walk
                    st.stats.bundle_bytes += item.nbytes
                elif part == "boxes":
                    st.stats.bundle_bytes += item.nbytes
                    self.start.add_boxes(item)
                elif part == "index":
                    st.stats.bundle_bytes += item.nbytes
                    st.add_index(item)
                elif part in ("cell", "record"):
                    st.stats.bundle_bytes += item.nbytes
                    self.start.located(item.id)
                    st.add_cell(item)
                    if part == "record":
                        st.replan()
                        continue  # its objects do not all come in the bundle: the streamer asks for them
                    ids = {i for i in item.pvs.tolist() if not st.has_object(i)} - self.ids
                    self.ids |= ids
                    st.expect(ids)
                    self.left += len(ids) * st.frame_bytes
                elif part == "objects":
                    self.left = item * st.frame_bytes
                elif part == "walls":  # a city's start ring (walls asked for)
                    if walls is not None:
                        walls.add_sides(*item)
                    st.stats.bundle_bytes += item[1]
                elif part == "walltex":  # the ids of the textures that follow
                    self.texture_bytes += len(item) * TEXTURE_BYTES
                    if walls is not None:
                        walls.expect(item)
                    if self._first_textures is None:  # the first: what the walker stands for ends with it
                        self._first_textures = set(item)
                        self._walk_on()
                elif part == "texture":
                    if walls is not None:
                        walls.add_texture(*item)
                    st.stats.bundle_bytes += item[2]
                    self.texture_bytes = max(0.0, self.texture_bytes - TEXTURE_BYTES)
                    if self._first_textures:
                        self._first_textures.discard(item[0])
                        self._walk_on()
                else:
                    st.stats.bundle_bytes += item.nbytes
                    self._arrived({item.id})
                    self.left = max(0.0, self.left - st.frame_bytes)
                    frames.append(item)
                    st.add_object(item)
                st.replan()
        except (ApiError, StreamCut) as exc:
            error = exc
        finally:
            self._arrived(set(self.ids))
            self.left = self.texture_bytes = 0.0
            if walls is not None:
                walls.ended()
            st.store_objects(frames)
            self.on_end(error)

    def _walk_on(self) -> None:
        """Tell the start target once the first ``walltex`` part's textures are all in."""
        if self._first_textures is not None and not self._first_textures:
            self.start.textures_left()

    def _arrived(self, ids: set[int]) -> None:
        self.ids -= ids
        self.streamer.expect(ids, False)
