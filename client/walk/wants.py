"""The frame step ``wants``: what the walk asks for beyond what each streamer plans itself.

The city streamer plans its records and objects by need time (in its tick, at
``locate``); the rooms' streamer the visible rooms and those ahead (in its tick, at
``visible``).  What neither sees is the interior ahead of an entrance: once the
city's predicted route reaches the entrance's street cell, or the door is within
:data:`~walkstream.client.stream.entrance.DOOR_AHEAD_S` seconds' walk, the rooms
:mod:`~walkstream.client.stream.entrance` names, in the order the walk comes to them,
go first into the rooms' wants.
"""

from __future__ import annotations

import numpy as np

from walkstream.client.stream.entrance import DOOR_AHEAD_S, door_ahead, entrance_view, seen_ahead
from walkstream.client.walk.state import Frame, WalkState

__all__ = ["wants"]


def wants(w: WalkState, f: Frame) -> None:
    """Set ``f.ahead`` (and note when the prefetch before an entrance began)."""
    e, city, rooms = w.scene.entrance, w.scene.streets, w.scene.rooms
    if e is None or city is None or rooms is None or w.door is None:
        return
    door = w.door
    speed = float(np.linalg.norm(w.predictor.velocity()))
    near_door = float(np.linalg.norm(f.eye[:2] - door[:2])) <= max(speed, 1.0) * DOOR_AHEAD_S
    soon = rooms.config.prefetch and (near_door or e.street in city.need or f.street == e.street)
    if soon and w.frames.prefetch_from is None:
        w.frames.prefetch_from = f.wt
    if soon and not w.indoors:
        if f.t - w.planned >= rooms.config.replan_s:
            w.planned = f.t
            w.seen = seen_ahead(rooms, e, f.eye, f.view, w.proj, w.size, w.predictor.velocity(), door)
        if w.from_entrance is None:
            w.from_entrance = entrance_view(rooms, e, door, w.proj, w.size)
        f.ahead = [*w.seen, *w.from_entrance, *door_ahead(rooms, e)]
