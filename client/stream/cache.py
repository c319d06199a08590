"""The client's memory cache: a byte-budget LRU of cells, contents and geometry, with pins.

:class:`Cache` holds what the walk needs in memory under one byte budget, keyed by
``(kind, id)``: tiles of the cell index (``"index"``), cell records (``"cell"``), the
contents downloaded, one kind per content kind (:mod:`walkstream.shared.content.registry`:
an object's parameters, ``"params"``; or its LOD2 mesh when meshes are streamed
instead, ``"mesh"``; an interior cell's meshes by cell id, ``"cellmesh"``, apart from
the objects' entries with the same ids), and the geometry ready to draw (``"geom"``).  What the current view needs (the current cell's record, its PVS
parameters and their geometry) is *pinned* and never evicted.  Over the budget, the
unpinned entries go in this order: geometry first, because it can be rebuilt
without the network; then contents (parameters, meshes, cell meshes); then cells; then index tiles
(small, and what tracking the viewer needs); least recently used first within each
kind.  Index tiles and cell records together keep a reserve (``metadata_share`` of
the budget, 1/8 by default) even when the pinned entries alone fill the budget:
evicting a few kB of them cannot bring a cache that is megabytes over back within
its budget, it only costs round trips to fetch them again.  Every operation is O(1) (one ``OrderedDict`` of evictable entries per
kind, pinned entries kept apart so eviction never has to skip them), apart from
re-pinning, which costs the size of the change.  Re-pinning unpins in key order, so
the order in which entries become evictable again does not hang on string hashing
(which differs from one process to the next): a simulated walk evicts alike every run.

The cache on disk is :mod:`.diskcache`.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable, Iterable
from typing import Any, Literal, cast

from walkstream.shared.content.registry import cache_kinds
from walkstream.shared.errors import InputError

__all__ = ["Kind", "CONTENTS", "KINDS", "CITY_KINDS", "EVICTION_ORDER", "METADATA", "Key", "Cache"]

Kind = Literal["index", "cell", "params", "mesh", "cellmesh", "impostor", "walltex", "geom"]
"""What a :class:`Cache` entry is: an index tile, a cell record, the contents of one
content kind (object parameters, a downloaded object mesh, a cell's meshes, an
impostor image, a wall texture), geometry."""

CONTENTS: tuple[Kind, ...] = cast(tuple[Kind, ...], cache_kinds())
"""The kinds of downloaded contents, one per content kind, in the registry's order."""

KINDS: tuple[Kind, ...] = ("index", "cell", *CONTENTS, "geom")
"""Every entry kind."""

EVICTION_ORDER: tuple[Kind, ...] = ("geom", *CONTENTS, "cell", "index")
"""Over the budget, unpinned entries of these kinds go first to last."""

CITY_KINDS: tuple[Kind, ...] = ("index", "cell", "params", "mesh", "geom")
"""The kinds the city streamer pins (a room streamer sharing the cache pins ``"cellmesh"``)."""

METADATA: tuple[Kind, ...] = ("cell", "index")
"""The kinds that share the metadata reserve (see :class:`Cache`)."""

Key = tuple[str, int]


# ---------------------------------------------------------------------------
# in memory
# ---------------------------------------------------------------------------


class Cache:
    """A byte-budget LRU of index tiles, cell records, parameters and geometry with pinning.

    Parameters
    ----------
    budget_bytes:
        The byte budget (>= 0).  Pinned entries may push the cache over it (counted
        in :attr:`over_budget_events`); unpinned entries never stay over it, except
        index tiles and cell records within the metadata reserve.
    on_evict:
        Called as ``on_evict(kind, id)`` whenever an entry leaves the cache (evicted
        for the budget, or removed with :meth:`remove`), after the cache is updated,
        e.g. so a renderer frees the entry's GPU buffers.
    metadata_share:
        Index tiles and cell records (pinned or not) are evicted for the budget only
        while together they hold more than this share of it (0 to 1).

    Attributes
    ----------
    hits, misses, evictions:
        Per kind: :meth:`get` calls that found / did not find the entry, and entries
        evicted for the budget.
    bytes_used, peak_bytes:
        Bytes held now, and the most held at the end of any operation.
    over_budget_events:
        Operations that left the cache over its budget because the pinned entries
        alone exceed it.
    redownloads, rebuilds:
        Calls of :meth:`note_download` / :meth:`note_build` for an id noted before.

    Notes
    -----
    Thread-safe (one lock); ``on_evict`` is called outside it.
    """

    def __init__(
        self,
        budget_bytes: int,
        on_evict: Callable[[str, int], None] | None = None,
        metadata_share: float = 0.125,
    ) -> None:
        if type(budget_bytes) is not int or budget_bytes < 0:
            raise InputError(f"cache budget: expected a non-negative integer, got {budget_bytes!r}")
        if not 0.0 <= metadata_share <= 1.0:
            raise InputError(f"cache metadata share: expected 0 to 1, got {metadata_share!r}")
        self.budget_bytes = budget_bytes
        self.metadata_share = metadata_share
        self._kind_bytes: dict[str, int] = dict.fromkeys(KINDS, 0)  # pinned or not
        self.on_evict = on_evict
        # evictable entries by kind in LRU order (oldest first); pinned ones apart
        self._lru: dict[str, OrderedDict[int, tuple[Any, int]]] = {k: OrderedDict() for k in KINDS}
        self._held: dict[str, dict[int, tuple[Any, int]]] = {k: {} for k in KINDS}
        self._pins: set[Key] = set()
        self._ever: set[Key] = set()
        self._downloaded: set[int] = set()
        self._built: set[int] = set()
        self._lock = threading.RLock()
        self.hits: dict[str, int] = dict.fromkeys(KINDS, 0)
        self.misses: dict[str, int] = dict.fromkeys(KINDS, 0)
        self.evictions: dict[str, int] = dict.fromkeys(KINDS, 0)
        self.bytes_used = 0
        self.peak_bytes = 0
        self.over_budget_events = 0
        self.redownloads = 0
        self.rebuilds = 0

    # -- entries -------------------------------------------------------------

    @staticmethod
    def _kind(kind: str) -> str:
        if kind not in KINDS:
            raise InputError(f"cache kind: expected one of {', '.join(KINDS)}, got {kind!r:.40}")
        return kind

    def _find(self, kind: str, oid: int) -> tuple[Any, int] | None:
        e = self._lru[kind].get(oid)
        return e if e is not None else self._held[kind].get(oid)

    def put(self, kind: str, oid: int, value: Any, nbytes: int) -> None:
        """Store ``value`` of ``nbytes`` bytes under ``(kind, oid)`` as most recently used.

        A value already there is replaced (without ``on_evict``).  Then unpinned
        entries are evicted while the cache is over its budget, which may be this
        one if it is unpinned and nothing else can go.

        Raises
        ------
        InputError
            An unknown kind or a negative size.
        """
        self._kind(kind)
        if type(nbytes) is not int or nbytes < 0:
            raise InputError(f"cache entry size: expected a non-negative integer, got {nbytes!r}")
        with self._lock:
            old = self._lru[kind].pop(oid, None) or self._held[kind].pop(oid, None)
            if old is not None:
                self.bytes_used -= old[1]
                self._kind_bytes[kind] -= old[1]
            where = self._held if (kind, oid) in self._pins else self._lru
            where[kind][oid] = (value, nbytes)
            self.bytes_used += nbytes
            self._kind_bytes[kind] += nbytes
            self._ever.add((kind, oid))
            evicted = self._shrink()
        self._notify(evicted)

    def get(self, kind: str, oid: int) -> Any:
        """The value under ``(kind, oid)`` (marked most recently used), or None; counted."""
        self._kind(kind)
        with self._lock:
            lru = self._lru[kind]
            e = lru.get(oid)
            if e is not None:
                lru.move_to_end(oid)
            else:
                e = self._held[kind].get(oid)
            if e is None:
                self.misses[kind] += 1
                return None
            self.hits[kind] += 1
            return e[0]

    def peek(self, kind: str, oid: int) -> Any:
        """The value under ``(kind, oid)`` or None, without touching the LRU or counters."""
        self._kind(kind)
        with self._lock:
            e = self._find(kind, oid)
            return None if e is None else e[0]

    def has(self, kind: str, oid: int) -> bool:
        """Whether ``(kind, oid)`` is cached (no LRU touch, not counted)."""
        self._kind(kind)
        with self._lock:
            return oid in self._lru[kind] or oid in self._held[kind]

    def size_of(self, kind: str, oid: int) -> int | None:
        """Bytes of the entry ``(kind, oid)``, or None when it is not cached."""
        self._kind(kind)
        with self._lock:
            e = self._find(kind, oid)
            return None if e is None else e[1]

    def remove(self, kind: str, oid: int) -> bool:
        """Drop ``(kind, oid)`` even if pinned (calls ``on_evict``); whether it was there."""
        self._kind(kind)
        with self._lock:
            e = self._lru[kind].pop(oid, None) or self._held[kind].pop(oid, None)
            if e is None:
                return False
            self.bytes_used -= e[1]
            self._kind_bytes[kind] -= e[1]
        self._notify([(kind, oid)])
        return True

    def ids(self, kind: str) -> list[int]:
        """The ids of the cached entries of ``kind`` (pinned ones last)."""
        self._kind(kind)
        with self._lock:
            return [*self._lru[kind], *self._held[kind]]

    def __len__(self) -> int:
        with self._lock:
            return sum(len(self._lru[k]) + len(self._held[k]) for k in KINDS)

    def __contains__(self, key: object) -> bool:
        if not (isinstance(key, tuple) and len(key) == 2 and key[0] in KINDS):
            return False
        return self.has(key[0], key[1])

    def ever_had(self, kind: str, oid: int) -> bool:
        """Whether ``(kind, oid)`` was ever put into the cache (evicted since or not)."""
        self._kind(kind)
        with self._lock:
            return (kind, oid) in self._ever

    # -- pins ----------------------------------------------------------------

    @property
    def pinned(self) -> frozenset[Key]:
        """The pinned ``(kind, id)`` keys (cached or not yet)."""
        with self._lock:
            return frozenset(self._pins)

    def pin(self, kinds_ids: Iterable[tuple[str, int]]) -> None:
        """Pin more ``(kind, id)`` keys; a key not cached yet is pinned when it arrives."""
        with self._lock:
            for kind, oid in kinds_ids:
                self._pin_one(self._kind(kind), oid)

    def unpin(self, kinds_ids: Iterable[tuple[str, int]]) -> None:
        """Unpin ``(kind, id)`` keys; the cache then shrinks to its budget if it can."""
        with self._lock:
            for kind, oid in kinds_ids:
                self._unpin_one(self._kind(kind), oid)
            evicted = self._shrink()
        self._notify(evicted)

    def set_pinned(self, params_ids: Iterable[int], cell_ids: Iterable[int]) -> None:
        """Pin exactly the given cells and the parameters and geometry of the given objects.

        Typically the current cell (and the one being entered) and its PVS.  Every
        other key is unpinned, and the cache then shrinks to its budget if it can.
        """
        want: set[Key] = {("cell", int(c)) for c in cell_ids}
        for i in params_ids:
            want.add(("params", int(i)))
            want.add(("geom", int(i)))
        with self._lock:
            for kind, oid in sorted(self._pins - want):
                self._unpin_one(kind, oid)
            for kind, oid in sorted(want - self._pins):
                self._pin_one(kind, oid)
            evicted = self._shrink()
        self._notify(evicted)

    def set_pins(self, keys: Iterable[tuple[str, int]], kinds: Iterable[str] | None = None) -> None:
        """Pin exactly ``keys`` (``(kind, id)``), unpinning every other key of ``kinds``
        (default: every kind), then shrink.

        One step, so nothing that stays pinned is evicted in between.  ``kinds`` lets two
        streamers share one cache, each owning the pins of its own kinds.
        """
        want: set[Key] = {(self._kind(k), int(i)) for k, i in keys}
        owned = set(KINDS) if kinds is None else {self._kind(k) for k in kinds}
        with self._lock:
            for kind, oid in sorted({p for p in self._pins if p[0] in owned} - want):
                self._unpin_one(kind, oid)
            for kind, oid in sorted(want - self._pins):
                self._pin_one(kind, oid)
            evicted = self._shrink()
        self._notify(evicted)

    def _pin_one(self, kind: str, oid: int) -> None:
        self._pins.add((kind, oid))
        e = self._lru[kind].pop(oid, None)
        if e is not None:
            self._held[kind][oid] = e

    def _unpin_one(self, kind: str, oid: int) -> None:
        self._pins.discard((kind, oid))
        e = self._held[kind].pop(oid, None)
        if e is not None:
            # it was needed until now: the most recently used of the evictable ones
            self._lru[kind][oid] = e

    # -- budget --------------------------------------------------------------

    def _shrink(self) -> list[Key]:
        """Evict unpinned entries while over budget; the evicted keys.  Holds the lock."""
        evicted: list[Key] = []
        reserve = self.metadata_share * self.budget_bytes
        for kind in EVICTION_ORDER:
            lru = self._lru[kind]
            while self.bytes_used > self.budget_bytes and lru:
                if kind in METADATA and sum(self._kind_bytes[k] for k in METADATA) <= reserve:
                    break
                oid, (_, n) = lru.popitem(last=False)
                self.bytes_used -= n
                self._kind_bytes[kind] -= n
                self.evictions[kind] += 1
                evicted.append((kind, oid))
        if self.bytes_used > self.budget_bytes:
            self.over_budget_events += 1
        self.peak_bytes = max(self.peak_bytes, self.bytes_used)
        return evicted

    def _notify(self, keys: list[Key]) -> None:
        if self.on_evict is not None:
            for kind, oid in keys:
                self.on_evict(kind, oid)

    @property
    def over_budget(self) -> bool:
        """Whether the cache holds more than its budget now (only pinned entries can)."""
        return self.bytes_used > self.budget_bytes

    def pinned_bytes(self) -> int:
        """Bytes held by pinned entries."""
        with self._lock:
            return sum(n for k in KINDS for _, n in self._held[k].values())

    # -- counting ------------------------------------------------------------

    def note_download(self, oid: int) -> bool:
        """Record that the parameters of ``oid`` were downloaded; True if not the first time.

        Call once per download that arrived (not for what came from the disk cache).
        A second download of the same id, whether it was evicted in between or asked
        for twice, counts in :attr:`redownloads`.
        """
        with self._lock:
            again = oid in self._downloaded
            self._downloaded.add(oid)
            self.redownloads += int(again)
            return again

    def note_build(self, oid: int) -> bool:
        """Record that the geometry of ``oid`` was built; True (and counted) if built before."""
        with self._lock:
            again = oid in self._built
            self._built.add(oid)
            self.rebuilds += int(again)
            return again

    def stats(self) -> dict[str, Any]:
        """Counters and sizes as plain data (for reports)."""
        with self._lock:
            return {
                "budget_bytes": self.budget_bytes,
                "bytes_used": self.bytes_used,
                "peak_bytes": self.peak_bytes,
                "entries": {k: len(self._lru[k]) + len(self._held[k]) for k in KINDS},
                "hits": dict(self.hits),
                "misses": dict(self.misses),
                "evictions": dict(self.evictions),
                "over_budget_events": self.over_budget_events,
                "redownloads": self.redownloads,
                "rebuilds": self.rebuilds,
            }
