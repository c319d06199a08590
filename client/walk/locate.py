"""The frame step ``locate``: which cell holds the eye, and so which visibility model the frame uses.

The city streamer locates the eye among the street cells (and, following it,
predicts and plans its own requests); the rooms' locator among the room cells by
their planes.  The frame's model is the visibility model of the kind of the cell
holding the eye (:func:`~walkstream.shared.scene.cellkinds.visibility_of`): portals
when a room cell's planes hold it, the PVS when a street cell holds it; otherwise (on
a threshold) the model it had.  A scene without street cells is always in the portal
model, one without room cells never.
"""

from __future__ import annotations

from walkstream.client.walk.state import Frame, WalkState
from walkstream.shared.scene.cellkinds import visibility_of

__all__ = ["locate"]


def locate(w: WalkState, f: Frame) -> None:
    """Set ``f.street``, ``f.room``, ``f.held`` and ``w.indoors`` (the portal model holds the eye)."""
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
    if rooms is None:
        w.indoors = False
    elif f.held and f.room is not None:
        w.indoors = visibility_of(rooms.cells[f.room].kind) == "portals"
    else:  # on the street, or on a threshold: where it was
        w.indoors = w.indoors and not on_street
