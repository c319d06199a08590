"""A city's ring walls fetched ring by ring, for the street cells the walk comes to.

A city baked with ``--virtual-walls`` rings regions of its street cells with four
textured walls (:mod:`walkstream.server.bake.ringwalls`).  Every side of every ring in
one request before the walk was West Oakland's 2,080 sides, 44 kB compressed: six
seconds of a 56 kbit/s link in front of the first frame, against 1.5 s for the whole
first view without walls.  A walk needs only the rings of the cells it comes to, so
:class:`RingSides` asks for them as it comes to them (``GET .../walls?cells=...``): the
current cell's first, then the cells of the predicted route in the order it reaches
them, at most one request on the link at a time.  Until a ringed cell's ring is in, the
frame draws that cell's whole far field as geometry (the cell's record lists it apart),
as it does behind a wall whose texture is missing: never a hole.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Iterable

from walkstream.client.net.api import SceneClient
from walkstream.client.tasks import reap
from walkstream.shared.errors import ApiError, StreamCut
from walkstream.shared.walls import WallSide, ring_cell

__all__ = ["RING_CELLS_A_REQUEST", "RingSides"]

RING_CELLS_A_REQUEST = 32
"""Street cells one request names (those the route reaches first)."""


class RingSides:
    """The rings of the street cells the walk comes to, fetched as it comes to them.

    Parameters
    ----------
    api:
        The scene's client.
    arrived:
        Called with the sides of each answer (possibly empty: cells without a ring).
    waiting:
        See :attr:`waiting` (None: no start bundle brings a ring).
    """

    def __init__(self, api: SceneClient, arrived: Callable[[tuple[WallSide, ...]], None],
                 waiting: Callable[[], bool] | None = None) -> None:
        self.api = api
        self.arrived = arrived
        self.waiting = waiting
        """True while the start bundle still brings the start cell's ring: nothing is
        asked for and every cell counts as held (the walker stands at its start until
        the bundle is in)."""
        self.asked: set[int] = set()
        """Cells asked for (in flight or answered)."""
        self.known: set[int] = set()
        """Cells whose ring (or lack of one) is held."""
        self.requests = 0
        """Requests sent."""
        self._task: asyncio.Task[None] | None = None

    def held(self, cell: int) -> bool:
        """Whether the ring of ``cell`` (or that it has none) is known (or coming in the
        start bundle, :attr:`waiting`)."""
        return cell in self.known or (self.waiting is not None and self.waiting())

    def adopt(self, sides: tuple[WallSide, ...]) -> None:
        """Rings that came another way (the start bundle's): their cells are known."""
        cells = {ring_cell(s.portal) for s in sides}
        self.asked |= cells
        self.known |= cells
        self.arrived(sides)

    def want(self, cells: Iterable[int]) -> None:
        """Ask for the rings of ``cells`` (most urgent first) not asked for yet, when no
        request is on the link (the next frame asks again for what is left)."""
        if (self._task is not None and not self._task.done()) or (self.waiting is not None and self.waiting()):
            return
        new: list[int] = []
        for c in cells:
            c = int(c)
            if c >= 0 and c not in self.asked and c not in new:
                new.append(c)
                if len(new) >= RING_CELLS_A_REQUEST:
                    break
        if not new:
            return
        self.asked.update(new)
        self.requests += 1
        self._task = asyncio.create_task(self._fetch(new))

    async def _fetch(self, cells: list[int]) -> None:
        try:
            sides = await self.api.walls(cells)
        except (ApiError, StreamCut):  # asked again by a later frame
            self.asked.difference_update(cells)
            return
        self.known.update(cells)
        self.arrived(sides)

    async def close(self) -> None:
        """Stop the request in flight."""
        if self._task is not None and not self._task.done():
            await reap([self._task])
