"""The interior walk's culling reused from frame to frame (``walkstream replay --cull-cache``).

An opt-in: with it the streamer's portal walk for the frame's own view and the frame's
parts culling are one :class:`~walkstream.shared.cullcache.CullCache` answer, made for a
guard view that holds every view the eye takes within a short step and turn, and handed
out again while the frames stay within it.  The answer holds every part the frame
sees and more (the guard's cells are fetched as visible; the parts are the guard's,
not the frame's), so the frame costs a few numpy checks instead of a walk and a
parts culling while the guard serves.

What the frame's own culling does and the cached one leaves to the guard: the
triangles' test of the kept parts (:mod:`walkstream.shared.trianglecull`, it needs the
frame's visible screen areas) and the count of frames whose fog falls short of the
nearest portal in view are not made; ``max_depth`` is not applied (the guard walks to
the fog).  The predicted poses (the prefetch) and the walk as baked (a virtual wall's
texture due) are walked anew as before.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping

import numpy as np
from numpy.typing import NDArray

from walkstream.shared.cullcache import CachedCull, CullCache
from walkstream.shared.partcull import Boxes
from walkstream.shared.portalgraph import PortalGraph

__all__ = ["RoomCullCache"]


class RoomCullCache:
    """One interior walk's :class:`~walkstream.shared.cullcache.CullCache` and the parts'
    boxes it culls.

    Parameters
    ----------
    graph : PortalGraph
        The interior's portals.
    locate : callable
        The cell holding a point ``(3,)`` (None outside every cell), without moving the
        viewer: the next guard is made for the cell the walker is about to enter.
    move_m, turn_deg : float
        The step and the turn a guard allows (:class:`~walkstream.shared.cullcache.CullCache`).

    Attributes
    ----------
    boxes : dict of int -> ((n, 3), (n, 3)) float arrays
        Per loaded cell its parts' boxes, the walk's own dict (replaced per cell, never
        changed in place): a cell whose boxes are replaced is a miss.
    last : CachedCull or None
        The last frame's answer (None when the frame was not culled through the cache).
    """

    def __init__(self, graph: PortalGraph, locate: Callable[[NDArray[np.float64]], int | None],
                 move_m: float = 0.3, turn_deg: float = 10.0) -> None:
        self.cache = CullCache(graph, locate=locate, move_m=move_m, turn_deg=turn_deg)
        self.boxes: Boxes = {}
        self.last: CachedCull | None = None
        self._culled: dict[int, object] = {}  # the boxes the last answer culled, per cell

    def cells(
        self,
        start: int | None,
        eye: NDArray[np.float64],
        view: NDArray[np.float64] | None,
        proj: NDArray[np.float64] | None,
        size: tuple[int, int] | None,
        *,
        fog_m: float = math.inf,
        closed: frozenset[int] = frozenset(),
    ) -> list[int] | None:
        """The cells seen from ``start`` with the camera ``view``, ``proj`` ``(4, 4)`` at
        ``eye`` ``(3,)`` (the guard's, a superset of the frame's own walk), the parts to
        draw kept in :attr:`last`; None (and :attr:`last` None) without a start cell or a
        camera, for the streamer's own walk."""
        self.last = None
        if start is None or view is None or proj is None or size is None:
            return None
        self.last = self.cache.cull(start, eye, view, proj, size, self.boxes, fog_m=fog_m, closed=closed)
        self._culled = {c: self.boxes.get(c) for c in self.last.masks}
        return list(self.last.order)

    def masks(self, loaded: Mapping[int, object]) -> dict[int, NDArray[np.bool_]]:
        """The last answer's parts to draw of the ``loaded`` cells, copies the frame may
        change (the fog budget cuts them; the cached arrays are shared and read-only).  A
        cell whose boxes were replaced since the culling (a head made whole) is left out:
        the caller culls it as a cell drawn besides the walk's."""
        if self.last is None:
            return {}
        return {c: m.copy() for c, m in self.last.masks.items() if c in loaded and self.boxes.get(c) is self._culled[c]}

    def head_clear(self, cid: int, gone: NDArray[np.int64]) -> bool:
        """Whether the last answer draws none of cell ``cid``'s parts ``gone`` ``(k,)`` (a
        head whose stand-ins the guard drops draws all it would draw whole)."""
        m = None if self.last is None else self.last.masks.get(cid)
        return m is not None and len(m) > int(gone.max(initial=-1)) and not bool(m[gone].any())
