"""The frame step ``locate``: which cell holds the eye, and so which visibility model the frame uses.

The city streamer locates the eye among the street cells (and, following it,
predicts and plans its own requests); the rooms' locator among the room cells by
their planes.  Indoors when a room cell's planes hold the eye, on the street when a
street cell holds it; otherwise (on a threshold) where it was.  A scene without
street cells is always indoors, one without room cells never.
"""

from __future__ import annotations

from walkstream.client.walk.state import Frame, WalkState

__all__ = ["locate"]


def locate(w: WalkState, f: Frame) -> None:
    """Set ``f.street``, ``f.room``, ``f.held`` and ``w.indoors``."""
    city, rooms = w.scene.streets, w.scene.rooms
    on_street = False
    if city is not None:
        w.predictor.observe(f.wt, f.eye[:2])
        f.street = city.tick(f.t, f.eye[:2], w.predictor)
    if rooms is not None:
        f.room = rooms.locate(f.eye)
        f.held = f.room is not None and rooms.holds(f.room, f.eye)
        if city is not None:
            on_street = city.cellmap.find(f.eye[:2], f.street) is not None
    w.indoors = rooms is not None and (f.held or (w.indoors and not on_street))
