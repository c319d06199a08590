"""Interior streaming: which cell the viewer is in, which cells it may see, their contents fetched.

An interior is walked like this (Mulloni et al.'s cell manager):

* the **viewer's cell** is the cell whose plane set holds the eye (a linear check of
  the current cell, its neighbours, then all cells; the eye on a shared plane stays
  in the cell it was in; outside every cell it keeps the last one);
* the **visible cells** are found by portal culling with visible screen areas
  (:func:`~walkstream.client.draw.portals.cull_portals`, the default
  :attr:`RoomStreamConfig.culling` ``portals``) or, with ``frustum`` or ``none``,
  through the portals whose bounding box meets the view frustum
  (:func:`~walkstream.client.draw.portals.frustum_cells`), within the fog distance,
  to a depth of :attr:`RoomStreamConfig.max_depth`;
* **contents** (one immutable response per cell) are fetched for the visible cells
  in that order, then, with prefetch, for the cells one portal beyond them (where
  the walker may turn next); a cell not visible for :attr:`RoomStreamConfig.flush_s`
  seconds is flushed (the paper's policy) once the cache is fuller than
  :attr:`RoomStreamConfig.flush_fill`, and the cache's byte budget stays in charge.  A cell fetched again after a flush counts as a re-download.
"""

from __future__ import annotations

import asyncio
import contextlib
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from walkstream.client.clock import Clock
from walkstream.client.draw.portals import PortalCull, PortalGraph, cull_portals, frustum_cells
from walkstream.client.net.api import SceneClient
from walkstream.client.stream.cache import Cache
from walkstream.shared.codec.cellmesh import CellMesh
from walkstream.shared.errors import ApiError
from walkstream.shared.roomwire import RoomRecord, Topology

__all__ = ["RoomStreamConfig", "RoomStreamer", "cell_of"]


@dataclass(frozen=True)
class RoomStreamConfig:
    """Knobs of the interior streamer."""

    prefetch: bool = True
    fog_m: float = 40.0
    """Portals farther than this from the eye are not looked through."""
    max_depth: int = 8
    """Portals passed on the way to a visible cell, at most."""
    flush_s: float = 30.0
    """A cell not visible for this long is flushed from memory (while the cache is
    fuller than :attr:`flush_fill`)."""
    flush_fill: float = 0.5
    """The paper flushes to make room: with the cache less full than this share of its
    budget nothing is flushed, so a walk that fits the cache downloads nothing twice."""
    max_in_flight: int = 2
    culling: str = "portals"
    """``portals`` (VSAs), ``frustum`` (portals in the frustum) or ``none`` (as
    ``frustum`` for the cells, every part of them drawn)."""


@dataclass
class RoomStreamStats:
    """What the interior streamer fetched and flushed."""

    requests: int = 0
    cells_received: int = 0
    bytes_received: int = 0
    flushed: int = 0
    refetched: int = 0
    errors: int = 0
    fetched: set[int] = field(default_factory=set)


def _stack_planes(cells: list[RoomRecord]) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Ids and ``(n, k, 4)`` planes padded with rows that every point satisfies."""
    k = max((len(c.planes) for c in cells), default=1)
    out = np.zeros((len(cells), k, 4))
    out[:, :, 3] = -1.0
    for i, c in enumerate(cells):
        out[i, : len(c.planes)] = c.planes
    return np.array([c.id for c in cells], dtype=np.int64), out


def cell_of(planes: NDArray[np.float64], eye: NDArray[np.float64], tol: float = 1e-6) -> NDArray[np.bool_]:
    """``(n,)`` whether the eye ``(3,)`` is behind every plane of each of ``(n, k, 4)`` cells."""
    return np.all(planes[:, :, :3] @ eye + planes[:, :, 3] <= tol, axis=1)


class RoomStreamer:
    """Follows the viewer through an interior and keeps the visible cells' contents loaded.

    Parameters
    ----------
    api:
        Access to the scene.
    clock:
        The replay's clock.
    cache:
        The byte-budget cache; contents are kept as kind ``"mesh"`` under the cell id.
    topology:
        The interior's topology (fetched once, before the walk).
    config:
        Knobs.
    """

    def __init__(self, api: SceneClient, clock: Clock, cache: Cache, topology: Topology, config: RoomStreamConfig) -> None:
        self.api = api
        self.clock = clock
        self.cache = cache
        self.config = config
        self.topology = topology
        self.cells: dict[int, RoomRecord] = {c.id: c for c in topology.cells}
        inside = [c for c in topology.cells if c.kind != "outside" and len(c.planes)]
        self._ids, self._planes = _stack_planes(inside)
        self._row = {int(c): i for i, c in enumerate(self._ids)}
        self.current: int | None = None
        self.stats = RoomStreamStats()
        self.last_visible: dict[int, float] = {}
        self._tasks: dict[int, asyncio.Task[None]] = {}
        self.visible: list[int] = []
        self.graph = PortalGraph.from_topology(topology)
        self.last_cull: PortalCull | None = None

    # -- where the viewer is ---------------------------------------------------

    def locate(self, eye: NDArray[np.float64]) -> int | None:
        """The viewer's cell by the planes: the current one while it holds the eye, then
        a neighbour, then any; outside every cell the current one is kept."""
        e = np.asarray(eye, dtype=np.float64).reshape(3)
        cur = self.current
        if cur is not None and cur in self._row:
            if cell_of(self._planes[self._row[cur] : self._row[cur] + 1], e)[0]:
                return cur
            for n in self.cells[cur].neighbours:
                if n in self._row and cell_of(self._planes[self._row[n] : self._row[n] + 1], e)[0]:
                    self.current = n
                    return n
        hit = np.flatnonzero(cell_of(self._planes, e))
        if len(hit):
            self.current = int(self._ids[hit[0]])
        return self.current

    def visible_cells(
        self,
        eye: NDArray[np.float64],
        view_proj: NDArray[np.float64],
        view: NDArray[np.float64] | None = None,
        proj: NDArray[np.float64] | None = None,
        size: tuple[int, int] | None = None,
    ) -> list[int]:
        """The current cell and those seen from it: through portal culling when
        ``config.culling`` is ``portals`` and the camera (``view``, ``proj``, ``size``) is
        given (its result is kept in :attr:`last_cull`), otherwise through the portals in
        the frustum (breadth first)."""
        self.last_cull = None
        if self.current is None:
            return []
        cfg = self.config
        if cfg.culling == "portals" and view is not None and proj is not None and size is not None:
            self.last_cull = cull_portals(
                self.graph, self.current, eye, view, proj, size, fog_m=cfg.fog_m, max_depth=cfg.max_depth
            )
            return self.last_cull.order
        return frustum_cells(self.graph, self.current, eye, view_proj, fog_m=cfg.fog_m, max_depth=cfg.max_depth)

    def visible_bytes(self, cells: list[int]) -> int:
        """Memory the decoded contents of ``cells`` take (cached ones as cached; the
        others estimated from the topology's triangles: 12 bytes of indices per
        triangle and about one float32 vertex per triangle)."""
        total = 0
        for c in cells:
            m = self.mesh(c)
            if m is not None:
                total += sum(p.positions.nbytes + p.indices.nbytes for p in m.parts)
            else:
                total += 24 * self.cells[c].contents.triangles
        return total

    # -- what is loaded ---------------------------------------------------------

    def mesh(self, cid: int) -> CellMesh | None:
        """Cell ``cid``'s contents if they are in memory."""
        value: CellMesh | None = self.cache.peek("mesh", cid)
        return value

    def tick(
        self,
        t: float,
        eye: NDArray[np.float64],
        view_proj: NDArray[np.float64],
        view: NDArray[np.float64] | None = None,
        proj: NDArray[np.float64] | None = None,
        size: tuple[int, int] | None = None,
    ) -> list[int]:
        """Move the viewer: locate, find the visible cells (:meth:`visible_cells`), fetch
        and flush; returns the visible cells."""
        self.locate(eye)
        vis = self.visible_cells(eye, view_proj, view, proj, size)
        self.visible = vis
        for c in vis:
            self.last_visible[c] = t
        want = list(vis)
        if self.config.prefetch:
            for c in vis:
                for n in self.cells[c].neighbours:
                    if n not in want and self.cells[n].kind != "outside":
                        want.append(n)
        self.cache.set_pins([("mesh", c) for c in vis])
        crowded = self.cache.bytes_used > self.config.flush_fill * self.cache.budget_bytes
        for c in list(self.last_visible) if crowded else []:
            if c not in vis and t - self.last_visible[c] > self.config.flush_s and self.cache.has("mesh", c):
                self.cache.remove("mesh", c)
                self.stats.flushed += 1
                del self.last_visible[c]
        for c in want:
            if len(self._tasks) >= self.config.max_in_flight:
                break
            if c in self._tasks or self.cache.has("mesh", c):
                continue
            self._tasks[c] = asyncio.ensure_future(self._fetch(c))
        return vis

    async def _fetch(self, cid: int) -> None:
        try:
            self.stats.requests += 1
            mesh = await self.api.contents(cid)
            if cid in self.stats.fetched:
                self.stats.refetched += 1
            self.stats.fetched.add(cid)
            self.stats.cells_received += 1
            self.stats.bytes_received += mesh.nbytes
            size = sum(p.positions.nbytes + p.indices.nbytes for p in mesh.parts)
            self.cache.put("mesh", cid, mesh, max(size, 1))
        except ApiError:
            self.stats.errors += 1
        finally:
            self._tasks.pop(cid, None)

    async def close(self) -> None:
        """Cancel what is in flight."""
        for task in list(self._tasks.values()):
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task
        self._tasks.clear()
