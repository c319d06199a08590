"""What an interior's start bundle brought of its textured virtual walls: the wall sides and the first view's textures.

Asked for with ``walls=true`` (:attr:`~walkstream.client.config.ReplayConfig.start_walls`):
the bundle carries every wall side (what ``GET .../walls`` sends) and the textures of
the walls the first view sees (:mod:`walkstream.server.service.firstwalls`).  The
walls' image lane does not exist yet while the bundle streams (it is made once the
sides are known), so the textures wait here and go into the walk's cache when the
lane is attached (:meth:`StartWalls.attach`); a texture arriving after that goes
straight in.  A server that sends no walls part leaves :attr:`StartWalls.sides`
None: the replay then asks for the sides itself, as before.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from walkstream.client.stream.images import ImpostorImages
from walkstream.shared.walls import WallSide

__all__ = ["StartWalls"]


class StartWalls:
    """The wall parts of one start bundle (see the module docstring)."""

    def __init__(self) -> None:
        self.sides: tuple[WallSide, ...] | None = None
        """Every wall side, once the bundle's ``walls`` part is in (None: not sent)."""
        self.nbytes = 0
        """Bytes of the wall parts on the wire (sides and textures)."""
        self.coming: set[int] = set()
        """Textures the bundle announced and has not brought yet: the lane does not ask
        for them (:meth:`ImpostorImages.expect`)."""
        self._textures: list[tuple[int, Any, int]] = []
        self._lane: ImpostorImages | None = None
        self._on_sides: Callable[[tuple[WallSide, ...]], None] | None = None

    def add_sides(self, sides: tuple[WallSide, ...], nbytes: int) -> None:
        """The bundle's ``walls`` part arrived (handed on when :meth:`on_sides` was set)."""
        self.sides = sides
        self.nbytes += int(nbytes)
        if self._on_sides is not None:
            self._on_sides(sides)

    def on_sides(self, take: Callable[[tuple[WallSide, ...]], None]) -> None:
        """Hand the sides to ``take``: now when they are in, else as they arrive (a city's
        start ring comes after the first view's objects, once the walk is set up)."""
        self._on_sides = take
        if self.sides is not None:
            take(self.sides)

    def expect(self, ids: list[int]) -> None:
        """The bundle announced textures ``ids`` (a ``walltex`` part): they are on their
        way, and the lane leaves them to the bundle."""
        new = set(ids) - self.coming
        self.coming |= new
        if self._lane is not None:
            self._lane.expect(new)

    def ended(self) -> None:
        """The bundle ended: what it did not bring the lane may ask for again."""
        if self._lane is not None:
            self._lane.expect(self.coming, False)
        self.coming.clear()

    def add_texture(self, tid: int, rgba: Any, nbytes: int) -> None:
        """One of the bundle's textures arrived (kept until the lane is attached)."""
        self.coming.discard(tid)
        self.nbytes += int(nbytes)
        if self._lane is not None:
            self._lane.adopt(tid, rgba, nbytes)
            self._lane.expect({tid}, False)
        else:
            self._textures.append((tid, rgba, nbytes))

    def attach(self, lane: ImpostorImages) -> None:
        """The walls' lane is made: the textures received so far go into its cache, the
        later ones as they come."""
        self._lane = lane
        lane.expect(self.coming)
        for tid, rgba, nbytes in self._textures:
            lane.adopt(tid, rgba, nbytes)
        self._textures.clear()
