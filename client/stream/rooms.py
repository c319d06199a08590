"""Interior streaming: which cell the viewer is in, which cells it may see, their contents fetched.

An interior is walked like this (Mulloni et al.'s cell manager):

* the **viewer's cell** is the cell whose plane set holds the eye (a linear check of
  the current cell, its neighbours, then all cells; the eye on a shared plane stays
  in the cell it was in; outside every cell it keeps the last one);
* the **visible cells** are found by portal culling with visible screen areas
  (:func:`~walkstream.shared.portals.cull_portals`, the default
  :attr:`RoomStreamConfig.culling` ``portals``) or, with ``frustum`` or ``none``,
  through the portals whose bounding box meets the view frustum
  (:func:`~walkstream.shared.portals.frustum_cells`), within the fog distance
  (no depth limit unless :attr:`RoomStreamConfig.max_depth` gives one);
* **contents** are fetched in the order the walk will need them, in batches
  (``POST .../rooms/contents``, :meth:`SceneClient.contents_batch`: every missing visible
  cell, then predicted ones up to :attr:`RoomStreamConfig.batch_bytes`; each cell is
  usable as soon as its part is in; ``batch_bytes`` 0: one request per cell) (:meth:`RoomStreamer.wanted`): the visible cells, then, with prefetch,
  the cells that the *predicted* motion (the eye moving on at its velocity of the last
  :attr:`RoomStreamConfig.velocity_s` seconds, looking the same way, or turning on at its
  rate of those seconds while it turns fast enough, :meth:`RoomStreamer.turn_rate`) makes visible
  through the portal graph within the fog, :attr:`RoomStreamConfig.lookahead_s` ahead
  and nearest in time first (where the predicted eye first passes into another cell or
  would walk into a wall, the views turned by :attr:`RoomStreamConfig.turns_ahead_deg`
  too), then the cells visible in the last
  :attr:`RoomStreamConfig.recent_s` seconds (the walker may turn round), then the cells
  up to :attr:`RoomStreamConfig.beyond_portals` portals beyond the visible ones (where the
  walker may turn; the outside cell, one portal beyond every room with a window, last).  What is fetched ahead stops at
  :attr:`RoomStreamConfig.prefetch_share` of the cache's byte budget and is pinned
  with the visible cells, so prefetching never pushes out a cell needed sooner.  The
  requests go out through the link's
  :class:`~walkstream.client.stream.scheduler.RequestScheduler`: the streamer is one of
  its lanes (:meth:`RoomStreamer.offer`), and a crossing walk shares it with the city's
  streamer, the scheduler starting whichever lane's next request is needed sooner (a
  visible cell now, one ahead when the eye would reach its box at its speed);
* **flush**: a cell not visible for :attr:`RoomStreamConfig.flush_s` seconds
  (``--flush-after``) is flushed, the paper's policy; by default
  (:attr:`RoomStreamConfig.flush_policy` ``crowded``) only while the cache is fuller
  than :attr:`RoomStreamConfig.flush_fill` (90 %) of its budget, so a walk that fits the cache
  downloads nothing twice; ``paper`` flushes whatever the fill.  The cache's byte-budget
  LRU stays in charge either way.  A cell fetched again after a flush or an eviction
  counts as a re-download.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from walkstream.client.clock import Clock
from walkstream.client.content.cellmesh import CELLMESH_CONTENT, decoded_bytes
from walkstream.client.net.api import SceneClient
from walkstream.client.stream.cache import Cache
from walkstream.client.stream.cachedcull import RoomCullCache
from walkstream.client.stream.roomlate import LateCells
from walkstream.client.stream.roommotion import RoomMotion, turned_view
from walkstream.client.stream.scheduler import Flight, Offer, RequestScheduler
from walkstream.client.tasks import reap
from walkstream.shared.codec.cellbatch import CELLBATCH_MAX_CELLS
from walkstream.shared.codec.cellmesh import CellMesh
from walkstream.shared.content.cellmesh import KIND as CELLMESH
from walkstream.shared.errors import ApiError, InputError, StreamCut
from walkstream.shared.portalgraph import PortalGraph
from walkstream.shared.portals import PortalCull, cull_portals, frustum_cells
from walkstream.shared.roomview import RoomLocator
from walkstream.shared.roomwire import RoomRecord, Topology
from walkstream.shared.scene.placement import ContentsPlacement, placement_for
from walkstream.shared.screenrects import CENTRE_MARGIN_PX, TOUCH_MARGIN_PX

__all__ = ["FLUSH_POLICIES", "RoomStreamConfig", "RoomStreamer"]

"""A heading turning at least this fast (radians a second) is predicted to go on turning."""

_HEAD_BYTES = 200
"""A response's status line and headers (the scheduler's estimate of the bytes on the link)."""

#: ``--flush-policy`` choices (see :attr:`RoomStreamConfig.flush_policy`).
FLUSH_POLICIES: tuple[str, ...] = ("crowded", "paper")


@dataclass(frozen=True)
class RoomStreamConfig:
    """Knobs of the interior streamer."""

    prefetch: bool = True
    fog_m: float = 40.0
    """Portals farther than this from the eye are not looked through."""
    max_depth: int | None = None
    """Portals passed on the way to a visible cell, at most (None: no limit, the walk
    stops at the fog; see :class:`~walkstream.shared.roomview.RoomView`)."""
    flush_s: float = 30.0
    """A cell not visible for this long is flushed from memory (``--flush-after``)."""
    flush_policy: str = "crowded"
    """``paper``: flush every cell not visible for :attr:`flush_s` (Mulloni et al.);
    ``crowded`` (default): only while the cache is fuller than :attr:`flush_fill` (90 %).
    The default is a choice: flushing frees memory nobody else wants while the cache
    has room, and every flushed cell the walk sees again is downloaded twice (on the
    3-minute office tour with the default cache, 39 re-downloads against 0)."""
    flush_fill: float = 0.9
    """The ``crowded`` policy's gate, a share of the cache's budget (0.5 flushed cells that
    came back: on the office tour with a 600 kB cache 97.5 % perfect frames and 38
    re-downloads against 99.4 % and 14 with 0.9)."""
    lookahead_s: tuple[float, ...] = (0.5, 1.0, 2.0, 3.0, 4.0)
    """Prefetch: how far ahead (seconds of predicted motion) the visible cells are
    predicted, nearest first."""
    turns_deg: tuple[float, ...] = ()
    """Prefetch: after the predicted motion, the cells seen from where the eye is now
    turned by these angles about the vertical.  None by default: on the office tour
    with a 400 kB cache (90, -90, 180) fetched 28 % more bytes for no more perfect
    frames (93.6 % both)."""
    turns_ahead_deg: tuple[float, ...] = (90.0, -90.0)
    """Prefetch: where the predicted motion first enters another cell (a walker through a
    door), and at its last pose before it would walk into a wall (not while the walker
    turns already), also the cells seen from there turned by these angles about the
    vertical: a walker leaving a room turns into the corridor, whose length shows at once
    (on a generated office's tour, 10 kB of cells within 0.3 s of the turn), and a walker
    facing a wall turns before it.  With the start hold and the outside cell last, the
    first 30 s of seed 13's tour 96.53 -> 100 % perfect frames (the door), the duplex's
    tour 97.83 -> 98.84 % (the door) -> 100 % (the wall)."""
    velocity_s: float = 0.5
    """Prefetch: the eye's velocity is measured over this many seconds."""
    replan_s: float = 0.25
    """Prefetch: the predicted cells are worked out again this often (seconds)."""
    recent_s: float = 10.0
    """Cells visible within this many seconds are kept ahead of the cells one portal
    beyond (the walker who turns round sees them again)."""
    prefetch_share: float = 0.7
    """Prefetch stops once the wanted cells (visible first) fill this share of the
    cache's budget (the rest keeps cells seen earlier; on the office tour with a 400 kB
    cache and a 50 % flush gate 0.5 / 0.7 / 0.9 gave 93.3 / 95.6 / 93.6 % perfect frames)."""
    beyond_portals: int = 1
    """Prefetch, last: the cells up to this many portals beyond the visible ones, nearest
    first (only while the link has nothing needed sooner: they come after every other
    wanted cell)."""
    max_in_flight: int = 2
    """Contents requests (batches or single cells) in flight at once."""
    batch_bytes: int = 8000
    """A batch holds every missing visible cell, then the predicted ones while the stored
    bytes of its cells stay within this (a long batch of prefetch would hold back a cell
    that becomes visible meanwhile); 0: one request per cell (the older path)."""
    culling: str = "portals"
    """``portals`` (VSAs), ``frustum`` (portals in the frustum) or ``none`` (as
    ``frustum`` for the cells, every part of them drawn)."""
    cull_cache: str = ""
    """``portals``: ``guard`` or ``frustum`` reuse the culling while the view stays within a guard
    (:mod:`.cachedcull`); empty (default): each frame culled anew."""
    cull_guard: tuple[float, float] = (0.3, 10.0)
    """``cull_cache``: the step (m) and the turn (degrees) a guard allows."""

    def __post_init__(self) -> None:
        if self.flush_policy not in FLUSH_POLICIES:
            raise InputError(f"flush policy {self.flush_policy!r}: expected one of {', '.join(FLUSH_POLICIES)}")
        if not 0.0 <= self.flush_fill <= 1.0:
            raise InputError(f"flush fill {self.flush_fill!r}: expected a share of the cache from 0 to 1")
        if self.beyond_portals < 0:
            raise InputError(f"prefetch {self.beyond_portals} portals beyond: expected 0 or more")
        if self.batch_bytes < 0:
            raise InputError(f"contents batch of {self.batch_bytes} bytes: expected 0 (one cell per request) or more")
        if not (self.flush_s >= 0.0 and np.isfinite(self.flush_s)):
            raise InputError(f"flush after {self.flush_s!r} s: expected a finite number of seconds >= 0")


@dataclass
class RoomStreamStats:
    """What the interior streamer fetched and flushed."""

    requests: int = 0
    cells_received: int = 0
    bytes_received: int = 0
    flushed: int = 0
    refetched: int = 0
    errors: int = 0
    bundled: int = 0
    """Cells whose contents came in the start bundle (:meth:`RoomStreamer.adopt`)."""
    heads: int = 0
    """... of which first as heads (:mod:`~walkstream.shared.codec.cellhead`)."""
    fetched: set[int] = field(default_factory=set)


class RoomStreamer(RoomMotion):
    """Follows the viewer through an interior and keeps the visible cells' contents loaded.

    Parameters
    ----------
    api:
        Access to the scene.
    clock:
        The replay's clock.
    cache:
        The byte-budget cache; contents are kept as kind ``"cellmesh"`` under the cell id
        (:mod:`walkstream.shared.content.cellmesh`), apart from any object's entries.
    topology:
        The interior's topology (fetched once, before the walk).
    config:
        Knobs.
    foreign:
        Cells the topology holds for the portal walk only (see :attr:`foreign`).
    placements:
        Where contents come in an interior's own frame (a crossing scene's entrances'
        :class:`~walkstream.shared.scene.placement.ContentsPlacement`): each cell they
        hold is placed in the scene's frame as it is stored, before the cache sees it.
    scheduler:
        The link's request scheduler, shared with the walk's other streamers (by
        default one of its own, with room for this streamer's requests).
    """

    def __init__(
        self, api: SceneClient, clock: Clock, cache: Cache, topology: Topology, config: RoomStreamConfig,
        foreign: Iterable[int] = (), placements: Iterable[ContentsPlacement] = (), *,
        scheduler: RequestScheduler | None = None,
    ) -> None:
        self.api = api
        self.placements = tuple(placements)
        """Moves of contents from an interior's own frame into the scene's (none: in the scene's)."""
        self.scheduler = scheduler if scheduler is not None else RequestScheduler(config.max_in_flight + 1)
        """The link's request scheduler (this streamer is one of its lanes)."""
        self.scheduler.join(self)
        self._want: list[int] = []
        self._vis: set[int] = set()
        self._eye = np.zeros(3)
        self.foreign = frozenset(int(c) for c in foreign)
        """Cells of another model in the topology (a street cell joined at an entrance):
        the portal walk passes them, their contents are never asked for."""
        self.clock = clock
        self.cache = cache
        self.config = config
        self.fog_m: float = config.fog_m
        self.closed: frozenset[int] = frozenset()
        """Virtual walls (portal ids) the portal walk stops at this frame: drawn as their
        texture (:mod:`walkstream.client.walk.walls`); empty without walls."""
        self.due_closed: frozenset[int] = frozenset()
        """The walls the walk stops at as baked (every one the viewer sees at full
        texture weight, its texture held or not): the cells needed now are those of
        that walk (:attr:`due_visible`); a wall whose texture is still missing leaves
        :attr:`closed` open, so the cells behind it are drawn when held, but they are
        not needed now: its texture is (the walls' lane asks for it next)."""
        self.due_visible: list[int] = []
        """The cells of the walk as baked this frame (:attr:`due_closed`)."""
        """The fog distance in force this frame: portals farther are not looked through.
        The frame loop's lever (the budget tightens it); ``config.fog_m`` is the default."""
        self.topology = topology
        self.cells: dict[int, RoomRecord] = {c.id: c for c in topology.cells}
        self._where = RoomLocator(topology.cells)
        self.current: int | None = None
        self.stats = RoomStreamStats()
        self.last_visible: dict[int, float] = {}
        self._tasks: dict[int, asyncio.Task[None]] = {}
        self._adopted: set[asyncio.Task[None]] = set()
        self.visible: list[int] = []
        self.graph = PortalGraph.from_topology(topology)
        self.last_cull: PortalCull | None = None
        self.cull_cache = RoomCullCache(self.graph, lambda p: self._where.locate(p, self.current), *self.config.cull_guard) \
            if self.config.cull_cache and self.config.culling == "portals" else None
        RoomMotion.__init__(self, self.config.velocity_s)
        self._ahead: list[int] = []
        self._planned_t = -np.inf
        self._bytes_per_triangle = 32.0
        self._decoded: dict[int, tuple[CellMesh, int]] = {}
        self.plan_s = 0.0
        """CPU seconds the last :meth:`tick` spent predicting (not the frame's culling)."""
        self.walk_s = 0.0
        """CPU seconds (``time.thread_time``) of the frame's portal walks: those of the last
        :meth:`tick` and of the :meth:`visible_cells` calls after it."""
        self._received = [0, 0]  # decoded bytes, triangles
        self.late = LateCells()
        """Each cell's wait from wanted to arrived, and the frames it was missing from
        (the walk's measure step notes those: :meth:`note_missing`)."""

    # -- where the viewer is ---------------------------------------------------

    def locate(self, eye: NDArray[np.float64]) -> int | None:
        """The viewer's cell by the planes: the current one while it holds the eye, then
        a neighbour, then any; outside every cell the current one is kept."""
        self.current = self._where.locate(eye, self.current)
        return self.current

    def holds(self, cid: int, eye: NDArray[np.float64]) -> bool:
        """Whether cell ``cid``'s planes hold ``eye`` (a crossing walk is indoors then)."""
        return self._where.holds(cid, eye)

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
        t0 = time.thread_time()
        if self.cull_cache is not None and (cached := self.cull_cache.cells(
                self.current, eye, view, proj, size, fog_m=self.fog_m, closed=self.closed)) is not None:
            self.walk_s += time.thread_time() - t0
            return cached
        if self.current is None:
            return []
        cull, order = self._cells_from(self.current, eye, view_proj, view, proj, size, self.closed)
        self.last_cull = cull
        self.walk_s += time.thread_time() - t0
        return order

    def _cells_from(
        self,
        cell: int,
        eye: NDArray[np.float64],
        view_proj: NDArray[np.float64],
        view: NDArray[np.float64] | None,
        proj: NDArray[np.float64] | None,
        size: tuple[int, int] | None,
        closed: frozenset[int] = frozenset(),
        margin_px: float = CENTRE_MARGIN_PX,
    ) -> tuple[PortalCull | None, list[int]]:
        # ``closed`` (the virtual walls drawn as textures) only for the frame's view: a
        # predicted pose's cells (the prefetch) are seen through them, so that the cells
        # behind a wall are in when the viewer comes near enough to open it; likewise a
        # predicted pose keeps every pixel a portal touches (``margin_px``), not only the
        # centres it covers, so a door about to open beyond a sliver is fetched before it shows
        cfg = self.config
        if cfg.culling == "portals" and view is not None and proj is not None and size is not None:
            pc = cull_portals(self.graph, cell, eye, view, proj, size, fog_m=self.fog_m, max_depth=cfg.max_depth,
                              closed=closed, margin_px=margin_px)
            return pc, pc.order
        return None, frustum_cells(self.graph, cell, eye, view_proj, fog_m=self.fog_m, max_depth=cfg.max_depth)

    def seen_from(
        self,
        cell: int,
        eye: NDArray[np.float64],
        view: NDArray[np.float64],
        proj: NDArray[np.float64],
        size: tuple[int, int],
    ) -> list[int]:
        """The cells seen from ``cell`` with the camera ``view``, ``proj`` at ``eye`` (a
        predicted pose: nothing is kept of it)."""
        return self._cells_from(cell, eye, proj @ view, view, proj, size, margin_px=TOUCH_MARGIN_PX)[1]

    def visible_bytes(self, cells: list[int]) -> int:
        """Memory the decoded contents of ``cells`` take (cached ones as cached; the
        others estimated from the topology's triangles at the bytes per triangle of the
        contents received so far, 32 before any)."""
        total = 0
        sizes = self._decoded
        for c in cells:
            m = self.mesh(c)
            if m is not None:
                # summed over the parts once per mesh (asked for every visible cell, every frame)
                known = sizes.get(c)
                if known is None or known[0] is not m:
                    known = sizes[c] = (m, decoded_bytes(m))
                total += known[1]
            else:
                total += round(self._bytes_per_triangle * self.cells[c].contents.triangles)
        return total

    # -- what is loaded ---------------------------------------------------------

    def mesh(self, cid: int) -> CellMesh | None:
        """Cell ``cid``'s contents if they are in memory."""
        value: CellMesh | None = self.cache.peek(CELLMESH.cache_kind, cid)
        return value

    def tick(
        self,
        t: float,
        eye: NDArray[np.float64],
        view_proj: NDArray[np.float64],
        view: NDArray[np.float64] | None = None,
        proj: NDArray[np.float64] | None = None,
        size: tuple[int, int] | None = None,
        *,
        cell: int | None | Literal["locate"] = "locate",
        shown: Sequence[int] = (),
        ahead: Sequence[int] = (),
    ) -> list[int]:
        """Move the viewer: locate, find the visible cells (:meth:`visible_cells`), flush,
        and fetch what the walk will need, in the order it will need it (:meth:`wanted`);
        returns the visible cells.

        A walk that leaves the interior (a crossing) says where the portal walk starts
        (``cell``: a street cell joined at an entrance, or None for no portal walk),
        which cells it draws besides the visible ones (``shown``, fetched as visible),
        and which it will need soon (``ahead``, fetched before any other prefetch)."""
        e = np.asarray(eye, dtype=np.float64).reshape(3)
        if cell == "locate":
            self.locate(e)
        else:
            self.current = cell
        self.walk_s = 0.0
        vis = self.visible_cells(e, view_proj, view, proj, size)
        self.visible = vis
        due = vis
        if self.due_closed != self.closed and self.current is not None:
            # some wall's texture is still missing: what is needed now is the walk as baked
            due = self._cells_from(self.current, e, view_proj, view, proj, size, self.due_closed)[1]
        self.due_visible = due
        for c in vis:
            self.last_visible[c] = t
        self.observe(t, e)
        if view is not None:
            self._observe_heading(t, view)
        self._eye = e
        want = self.wanted(t, e, due, view_proj, view, proj, size)
        seen = list(dict.fromkeys([*vis, *shown]))
        vis = due
        if shown or ahead or self.foreign:
            first = [c for c in dict.fromkeys([*due, *shown]) if c not in self.foreign]
            want = [c for c in dict.fromkeys([*first, *ahead, *want]) if c not in self.foreign]
            vis = first
        self._flush(t, want)
        self.late.wanted(t, (c for c in want if not self.cache.has(CELLMESH.cache_kind, c)))
        # what is wanted and in memory stays: the LRU evicts only what nobody needs soon
        # pinned before they arrive too: a wanted cell is never evicted by its own arrival
        self.cache.set_pins([(CELLMESH.cache_kind, c) for c in want], kinds=(CELLMESH.cache_kind,))
        self._request(want, set(vis))
        return seen

    def _request(self, want: list[int], vis: set[int]) -> None:
        """Hand the scheduler the wanted cells (``vis`` needed now) and let it start
        what the link has room for (see :meth:`offer`).

        The wants hold for this dispatch only: when another lane's request ends
        between frames, this streamer offers nothing until its next tick (asking then
        from the last frame's wants moved the crossing walk over GPRS on a 400 m city
        from 99.9 to 98.3 % perfect frames: prefetch batches went out a frame early,
        made of other cells)."""
        self._want = want
        self._vis = vis
        self.scheduler.dispatch()
        self._want = []

    def in_flight(self) -> int:
        """Contents requests on the link now (the start bundle's too)."""
        return len(set(self._tasks.values()))

    def outstanding_bytes(self) -> float:
        """Stored bytes of the cells asked for and not received yet, and each request's head."""
        return float(sum(self.cells[c].contents.nbytes for c in self._tasks) + _HEAD_BYTES * self.in_flight())

    def offer(self) -> Offer | None:
        """The next request for the wanted cells neither in memory nor in flight, in
        order: one per cell, or a batch (every missing visible cell, then more up to
        ``batch_bytes``), while fewer than ``max_in_flight`` requests are in flight (one
        more for visible cells when only prefetch is; no prefetch while visible cells
        are).  It is needed when its first cell is (:meth:`need_s`)."""
        cfg = self.config
        vis = self._vis
        missing = [c for c in self._want if c not in self._tasks and not self.cache.has(CELLMESH.cache_kind, c)]
        if not missing:
            return None
        busy = self.in_flight()
        if not cfg.batch_bytes:
            if busy >= cfg.max_in_flight:
                return None
            return Offer(self.need_s(missing[0]), lambda: self._launch(missing[:1]))
        visible_in_flight = any(c in vis for c in self._tasks)
        if missing[0] not in vis and visible_in_flight:
            # a second stream only splits the link: prefetch waits for the visible cells
            return None
        # a newly visible cell never waits behind batches of prefetch: it may take one more
        if busy >= cfg.max_in_flight + (0 if visible_in_flight or missing[0] not in vis else 1):
            return None
        # while visible cells are on their way, a batch for newly visible ones takes no prefetch
        cap = 0 if visible_in_flight else cfg.batch_bytes
        batch: list[int] = []
        size = 0
        for c in missing[:CELLBATCH_MAX_CELLS]:
            nbytes = self.cells[c].contents.nbytes
            if batch and c not in vis and size + nbytes > cap:
                break
            batch.append(c)
            size += nbytes
        return Offer(self.need_s(batch[0]), lambda: self._launch(batch))

    def need_s(self, cid: int) -> float:
        """Seconds until cell ``cid`` is needed: 0 for a visible one, otherwise the eye's
        distance to the cell's box at its speed (at least 1 m/s)."""
        if cid in self._vis:
            return 0.0
        rec = self.cells[cid]
        if not len(rec.outline):
            return float("inf")
        lo = np.array([*np.min(rec.outline, axis=0), rec.zmin])
        hi = np.array([*np.max(rec.outline, axis=0), rec.zmax])
        gap = np.maximum(np.maximum(lo - self._eye, self._eye - hi), 0.0)
        return float(np.linalg.norm(gap)) / max(float(np.linalg.norm(self.velocity())), 1.0)

    def _launch(self, cells: list[int]) -> None:
        """Start one request for ``cells`` (a batch, or one cell's own request when
        ``batch_bytes`` is 0)."""
        run = self._fetch_batch if self.config.batch_bytes else self._fetch
        task = self.scheduler.launch(self, "contents", cells, run).task
        assert task is not None
        for c in cells:
            self._tasks[c] = task
        self.late.asked(self.clock.now(), cells, (self.cells[c].contents.nbytes for c in cells))

    def note_missing(self, t: float, cells: Sequence[int]) -> None:
        """The frame at ``t`` showed ``cells`` without their contents (see :attr:`late`)."""
        if cells:
            self.late.missing(t, cells, self.outstanding_bytes())

    def _flush(self, t: float, want: list[int]) -> None:
        """The paper's policy: drop cells not visible for ``flush_s`` (``crowded``: only
        while the cache is fuller than ``flush_fill``), but none of ``want``."""
        cfg = self.config
        if cfg.flush_policy == "crowded" and self.cache.bytes_used <= cfg.flush_fill * self.cache.budget_bytes:
            return
        shown = set(want)
        for c in list(self.last_visible):
            if c not in shown and t - self.last_visible[c] > cfg.flush_s:
                if self.cache.has(CELLMESH.cache_kind, c):
                    self.cache.remove(CELLMESH.cache_kind, c)
                    self.stats.flushed += 1
                del self.last_visible[c]

    def predicted(
        self,
        eye: NDArray[np.float64],
        view_proj: NDArray[np.float64],
        view: NDArray[np.float64] | None = None,
        proj: NDArray[np.float64] | None = None,
        size: tuple[int, int] | None = None,
    ) -> list[int]:
        """The cells the predicted motion makes visible, in the order it reaches them:
        for each horizon of ``lookahead_s`` the eye moved on at :meth:`velocity`, looking
        the same way (or, while :meth:`turn_rate` is 20 degrees a second or more, turned
        on at that rate, half a turn at most: on the duplex's tour, 92.53 -> 94.52 %
        perfect frames), culled from its cell as the frame is (the prediction stops where
        the moved eye leaves the cells through a wall: its cell is none of the last
        one's neighbours), and where the moved eye first enters another cell or would next
        walk into a wall, the cells seen from there turned by ``turns_ahead_deg`` (a walker
        through a door turns into what lies beyond it, one facing a wall turns before it);
        then those seen from here turned by ``turns_deg``."""
        if self.current is None or view is None:
            return []
        v = self.velocity()
        turning = self.turning()
        out: list[int] = []
        cell: int | None = self.current
        crossed = False  # the turns ahead: once where the predicted walk first enters another cell
        last: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None

        def turns(c: int, e2: NDArray[np.float64], view2: NDArray[np.float64]) -> None:
            for deg in self.config.turns_ahead_deg:
                view3 = turned_view(view2, e2, deg)
                vp3 = view_proj @ np.linalg.inv(view) @ view3
                out.extend(self._cells_from(c, e2, vp3, view3, proj, size, margin_px=TOUCH_MARGIN_PX)[1])

        for h in self.config.lookahead_s if np.any(v) or turning else ():
            e2, view2 = self.view_ahead(eye, view, h)
            nxt = self._where.locate(e2, cell, anywhere=False)
            if nxt is None or not self._where.holds(nxt, e2):
                if last is not None and cell is not None and not turning:
                    turns(cell, *last)  # ... and where it would walk into a wall: it turns there
                break
            last = (e2, view2)
            cell = nxt
            vp2 = view_proj @ np.linalg.inv(view) @ view2
            out.extend(self._cells_from(cell, e2, vp2, view2, proj, size, margin_px=TOUCH_MARGIN_PX)[1])
            if not crossed and cell != self.current:
                crossed = True
                turns(cell, e2, view2)
        for deg in self.config.turns_deg:
            view2 = turned_view(view, eye, deg)
            vp2 = view_proj @ np.linalg.inv(view) @ view2
            out.extend(self._cells_from(self.current, eye, vp2, view2, proj, size, margin_px=TOUCH_MARGIN_PX)[1])
        return list(dict.fromkeys(out))  # each cell where it is first needed

    def wanted(
        self,
        t: float,
        eye: NDArray[np.float64],
        vis: list[int],
        view_proj: NDArray[np.float64],
        view: NDArray[np.float64] | None = None,
        proj: NDArray[np.float64] | None = None,
        size: tuple[int, int] | None = None,
    ) -> list[int]:
        """The cells to hold, in the order the walk will need them: ``vis``, then (with
        prefetch) those of :meth:`predicted` (worked out again every ``replan_s``), those
        visible in the last ``recent_s`` seconds (latest first), then those one portal
        beyond ``vis``; the prefetched ones up to ``prefetch_share`` of the cache's budget."""
        want = list(vis)
        if not self.config.prefetch:
            return want
        self.plan_s = 0.0
        if t - self._planned_t >= self.config.replan_s:
            self._planned_t = t
            t0 = time.thread_time()
            self._ahead = self.predicted(eye, view_proj, view, proj, size)
            self.plan_s = time.thread_time() - t0
        have = set(want)
        room = self.config.prefetch_share * self.cache.budget_bytes - self.visible_bytes(want)
        beyond = self._beyond(vis, self.config.beyond_portals)
        recent = sorted((c for c, seen in self.last_visible.items() if t - seen <= self.config.recent_s),
                        key=lambda c: -self.last_visible[c])
        # the outside cell (the building's shell, seen through any window) is one portal
        # beyond nearly every room: it comes last, when the link has nothing else to carry
        # (or sooner, when the predicted view or a recent one shows it)
        beyond = [c for c in beyond if self.cells[c].kind != "outside"] + \
            [c for c in beyond if self.cells[c].kind == "outside"]
        for c in [*self._ahead, *recent, *beyond]:
            if c in have or c in self.foreign:
                continue
            room -= self.visible_bytes([c])
            if room < 0:
                break
            have.add(c)
            want.append(c)
        return want

    def _beyond(self, vis: list[int], portals: int) -> list[int]:
        """The cells 1 to ``portals`` portals beyond ``vis``, nearest first (breadth first
        through the neighbours)."""
        seen = set(vis)
        ring = list(vis)
        out: list[int] = []
        for _ in range(portals):
            nxt: list[int] = []
            for c in ring:
                for n in self.cells[c].neighbours:
                    if n not in seen:
                        seen.add(n)
                        nxt.append(n)
            out.extend(nxt)
            ring = nxt
        return out

    async def _fetch(self, f: Flight) -> None:
        cid = f.ids[0]
        try:
            self.stats.requests += 1
            self._store(cid, await self.api.contents(cid))
        except ApiError:
            self.stats.errors += 1
        finally:
            self._tasks.pop(cid, None)
            self.scheduler.landed(f)

    async def _fetch_batch(self, f: Flight) -> None:
        """One batch: each cell stored as its part arrives (:meth:`_receive`)."""
        self.stats.requests += 1
        try:
            await self._receive(f.ids, self.api.contents_batch(f.ids))
        finally:
            self.scheduler.landed(f)

    def busy(self) -> bool:
        """Whether contents are on the link: a request of this streamer's scheduler, or
        the start bundle's first view still coming."""
        return bool(self._adopted) or self.scheduler.in_flight() > 0

    def adopt(self, cells: list[int], parts: AsyncIterator[tuple[int, CellMesh]]) -> None:
        """Take the contents of ``cells`` already on their way (the interior start
        bundle's first view): in flight, so not asked for again, until their part
        arrives from ``parts``."""
        task = asyncio.ensure_future(self._receive(cells, parts, bundled=True))
        self._adopted.add(task)  # it may read on (the manifest) after its last cell
        task.add_done_callback(self._adopted.discard)
        for c in cells:
            self._tasks[c] = task
        self.late.asked(self.clock.now(), cells, (self.cells[c].contents.nbytes for c in cells))

    async def _receive(
        self, cells: list[int], parts: AsyncIterator[tuple[int, CellMesh]], bundled: bool = False
    ) -> None:
        """Store each cell as its part arrives, and no longer in flight; a stream cut
        short leaves the cells it did not bring to be asked for again."""
        try:
            async for cid, mesh in parts:
                self._store(cid, mesh)
                if not mesh.missing:  # a head's cell stays in flight: it comes whole later
                    self.stats.bundled += bundled
                    self._tasks.pop(cid, None)
        except (ApiError, StreamCut):
            self.stats.errors += 1
        finally:
            for c in cells:
                if self._tasks.get(c) is asyncio.current_task():
                    del self._tasks[c]
                    if (m := self.mesh(c)) is not None and m.missing:  # a head alone: ask for it whole
                        self.cache.remove(CELLMESH.cache_kind, c)

    def _store(self, cid: int, mesh: CellMesh) -> None:
        """Keep a received cell's contents, placed in the scene's frame (and count it)."""
        placed = placement_for(self.placements, cid)
        if placed is not None:
            mesh = placed.place(mesh)
        if mesh.missing:  # a cell's head (cellhead.py): drawn meanwhile, counted when whole
            self.stats.heads += 1
            self.cache.put(CELLMESH.cache_kind, cid, *CELLMESH_CONTENT.cache_entry(b"", mesh))
            return
        if cid in self.stats.fetched:
            self.stats.refetched += 1
        self.stats.fetched.add(cid)
        self.stats.cells_received += 1
        self.stats.bytes_received += mesh.nbytes
        self.late.arrived(self.clock.now(), cid)
        self._received[0] += decoded_bytes(mesh)
        self._received[1] += self.cells[cid].contents.triangles
        if self._received[1]:
            self._bytes_per_triangle = self._received[0] / self._received[1]
        self.cache.put(CELLMESH.cache_kind, cid, *CELLMESH_CONTENT.cache_entry(b"", mesh))

    async def close(self) -> None:
        """Cancel what is in flight."""
        await reap(set(self._tasks.values()) | self._adopted)
        self._tasks.clear()
