"""The service's response cache: a thread-safe LRU of encoded bodies, bounded by bytes."""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Hashable, Iterable
from typing import Any

__all__ = ["LRU"]


# ---------------------------------------------------------------------------
# LRU
# ---------------------------------------------------------------------------


class LRU:
    """A thread-safe least-recently-used map of byte strings bounded by total size.

    Lookups happen on the event loop and fills from worker threads (after a
    database read), hence the lock; it is held for dictionary operations only.
    """

    def __init__(self, max_bytes: int) -> None:
        self._data: OrderedDict[Hashable, Any] = OrderedDict()
        self._sizes: dict[Hashable, int] = {}
        self._bytes = 0
        self._max = max_bytes
        self._lock = threading.Lock()

    def __len__(self) -> int:
        return len(self._data)

    def get(self, key: Hashable) -> Any:
        """The value under ``key`` (marked as recently used), or None."""
        with self._lock:
            value = self._data.get(key)
            if value is not None:
                self._data.move_to_end(key)
            return value

    def get_many(self, keys: Iterable[Hashable]) -> tuple[dict[Hashable, Any], list[Hashable]]:
        """``(found, missing)`` for many keys under one lock; ``missing`` without repeats."""
        found: dict[Hashable, Any] = {}
        missing: dict[Hashable, None] = {}
        with self._lock:
            for k in keys:
                if k in found or k in missing:
                    continue
                value = self._data.get(k)
                if value is None:
                    missing[k] = None
                else:
                    self._data.move_to_end(k)
                    found[k] = value
        return found, list(missing)

    def put(self, key: Hashable, value: Any, size: int) -> None:
        """Store ``value`` of ``size`` bytes, dropping the least recently used beyond the budget."""
        if size > self._max:
            return  # would evict everything else and still not fit
        with self._lock:
            if key in self._data:
                self._bytes -= self._sizes[key]
            self._data[key] = value
            self._data.move_to_end(key)
            self._sizes[key] = size
            self._bytes += size
            while self._bytes > self._max:
                old, _ = self._data.popitem(last=False)
                self._bytes -= self._sizes.pop(old)
