"""The city streamer's start: the start bundle in flight and what it brings besides cells and objects.

:class:`StartFeed` asks for the start bundle (path, first cell, index tiles,
manifest, the first cell's objects in one round trip, see
:class:`~walkstream.client.stream.bundle.StartBundle`) on behalf of a
:class:`~walkstream.client.stream.streamer.Streamer`, and keeps what the streamer's
planning and the frame loop read of it:

* :attr:`StartFeed.bundle` and :attr:`StartFeed.task` -- the bundle while it runs
  (the bytes it still brings count against the link; its task counts as a request in
  flight and is cancelled with the streamer);
* :attr:`StartFeed.first_view` -- whether the bundle was asked to bring the first
  view first (the walker then stands at its start for it);
* :attr:`StartFeed.holding` -- whether the walker standing at its start still waits
  for the bundle (on a city baked with walls, only until its first view, rings and
  first textures are in: the parts for the path's later poses come as it walks);
* :attr:`StartFeed.stand_ins` -- the boxes of the first cell's objects the first view
  does not draw: a frame does not wait for a missing object whose box its frustum
  drops.

The bundle's cells, index tiles and objects go to the streamer itself (the
:class:`~walkstream.client.stream.bundle.BundleTarget`); the feed is the bundle's
:class:`~walkstream.client.stream.bundle.StartTarget`.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from walkstream.client.stream.bundle import BundleTarget, StartBundle
from walkstream.client.stream.cellmap import CellMap
from walkstream.client.stream.startwalls import StartWalls
from walkstream.shared.codec.objectboxes import ObjectBoxes
from walkstream.shared.paths import RecordedPath
from walkstream.shared.roomview import RoomView
from walkstream.shared.wire import Manifest

__all__ = ["StartFeed"]


class StartFeed:
    """The start bundle of one city streamer, and what it brought besides cells and objects.

    Parameters
    ----------
    streamer:
        The streamer the bundle's cells, index tiles and objects go to.
    form:
        The object form it asks for (``params`` or ``lod2``).
    cellmap:
        The streamer's cell map: the start's cell becomes its current cell (:meth:`located`).
    """

    def __init__(self, streamer: BundleTarget, form: str, cellmap: CellMap) -> None:
        self.streamer = streamer
        self.form = form
        self.cellmap = cellmap
        self.bundle: StartBundle | None = None
        """The bundle while it runs (None before and after)."""
        self.task: asyncio.Task[None] | None = None
        """The bundle's task while it runs."""
        self.first_view = False
        """Whether the start bundle was asked to bring the first view first (the walker
        then stands at its start for it)."""
        self.walls: StartWalls | None = None
        """Where a city bundle's start ring and first textures go (set before the
        bundle is asked for: it then asks for them; None: not asked)."""
        self.textures_only = False
        """Whether the running bundle brings only what the path's later poses need now
        (:meth:`textures_left`): the walker no longer stands at its start for it."""
        self.stand_ins: dict[int, tuple[NDArray[np.float64], NDArray[np.float64]]] = {}
        """Objects' boxes ``(lo (3,), hi (3,))`` known before the objects (:meth:`add_boxes`)."""

    def start_bundle(
        self,
        path: str | None,
        on_path: Callable[[RecordedPath, int], None],
        on_manifest: Callable[[Manifest], None],
        on_end: Callable[[BaseException | None], None],
        view: RoomView | None = None,
    ) -> asyncio.Task[None]:
        """Ask for the start bundle at recorded path ``path``'s start; feed its parts in.

        See :class:`~walkstream.client.stream.bundle.StartBundle` for the callbacks and ``view``.
        """
        bundle = StartBundle(self.streamer, self.form, on_path, on_manifest, on_end, view=view, start=self)
        self.first_view = view is not None
        self.textures_only = False
        self.bundle = bundle
        self.task = asyncio.create_task(self._run_bundle(bundle, path))
        return self.task

    async def _run_bundle(self, bundle: StartBundle, path: str | None) -> None:
        try:
            await bundle.run(path)
        finally:
            self.bundle = None
            self.task = None
        self.streamer.replan()

    @property
    def starting(self) -> bool:
        """Whether the start bundle is still coming."""
        return self.task is not None

    @property
    def holding(self) -> bool:
        """Whether the walker standing at its start still waits for the bundle: until
        it ends or, on a city baked with walls, until its first ``walltex`` part's
        textures are in (the later poses' textures, records and objects stream while it
        walks; waiting for them held such a city's walker about 3 s)."""
        return self.task is not None and not self.textures_only

    def textures_left(self) -> None:
        """The parts the walker stands for are in; the later poses' parts follow."""
        self.textures_only = True

    def left(self) -> float:
        """Bytes the bundle is still expected to bring (0 when none runs)."""
        return self.bundle.left + self.bundle.texture_bytes if self.bundle is not None else 0.0

    def add_boxes(self, boxes: ObjectBoxes) -> None:
        """Learn objects' boxes (the start bundle's first cell's objects its first view
        does not draw): a frame does not wait for a missing one its frustum drops."""
        for oid, lo, hi in zip(boxes.ids.tolist(), boxes.lo, boxes.hi, strict=True):
            self.stand_ins[oid] = (lo, hi)

    def located(self, cid: int) -> None:
        """The server located the walk's start in cell ``cid``: it is the current cell
        unless the viewer was found in one already."""
        if self.cellmap.current is None:
            self.cellmap.current = cid
