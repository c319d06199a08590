"""The interior ahead of an entrance: which rooms to fetch before the walker reaches the door.

A walk on the street towards a building's entrance will see rooms through the open door
before it crosses it.  These functions name them, in the order the walk comes to them,
for the rooms' streamer to fetch ahead (:meth:`~walkstream.client.stream.rooms.RoomStreamer.tick`'s
``ahead``): the rooms the predicted motion sees through the entrance
(:func:`seen_ahead`), those seen from fixed poses in front of the door and just inside
(:func:`entrance_view`), then the doorway and the rooms a few portals beyond it
(:func:`door_ahead`).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from walkstream.client.stream.roommotion import predicted_view
from walkstream.client.stream.rooms import RoomStreamer
from walkstream.shared.camera import camera, look_at
from walkstream.shared.roomwire import Entrance

__all__ = ["DOOR_AHEAD_S", "DOOR_DEPTH", "ENTRANCE_POSES_M", "LOOK_AHEAD_S", "door_ahead", "entrance_view", "seen_ahead"]

DOOR_AHEAD_S = 8.0
"""Prefetch the interior once the door is this many seconds' walk away (at the eye's speed)."""

LOOK_AHEAD_S: tuple[float, ...] = (0.0, 1.0, 2.0, 3.0, 5.0, 8.0)
"""Prefetch: the seconds ahead at which the rooms seen through the entrance are predicted."""

DOOR_DEPTH = 8
"""Prefetch of the interior: the doorway and the rooms up to this many portals beyond it."""

ENTRANCE_POSES_M: tuple[float, ...] = (10.0, 5.0, 2.0, 0.5)
"""Prefetch: the rooms seen through the entrance from these distances in front of it come
right after those the predicted motion sees."""


def entrance_view(
    rooms: RoomStreamer, e: Entrance, door: NDArray[np.float64], proj: NDArray[np.float64], size: tuple[int, int]
) -> list[int]:
    """The rooms the walk in will see, in the order it comes to them: through the
    entrance from :data:`ENTRANCE_POSES_M` metres in front of it (farthest first),
    facing the door (within 60 degrees either way; from the nearest pose every way),
    then from the doorway and from a metre into each cell beyond it, every way."""
    inner = np.asarray(rooms.cells[e.doorway].outline, np.float64).mean(axis=0)
    out_dir = door[:2] - inner
    out_dir = out_dir / max(float(np.linalg.norm(out_dir)), 1e-9)
    facing = math.atan2(-out_dir[1], -out_dir[0])
    z = min(float(p[4][:, 2].min()) for p in rooms.topology.portals if p[0] == e.portal) + 1.6
    every = np.radians(np.arange(0.0, 360.0, 30.0))
    poses: list[tuple[int, NDArray[np.float64], NDArray[np.float64]]] = []
    for k, d in enumerate(ENTRANCE_POSES_M):
        near = k == len(ENTRANCE_POSES_M) - 1
        yaws = every if near else facing + np.radians(np.arange(-60.0, 61.0, 30.0))
        poses.append((e.street, np.array([*(door[:2] + d * out_dir), z]), yaws))
    poses.append((e.doorway, np.array([*inner, z]), every))
    for r in rooms.cells[e.doorway].portals:
        if r.cell in rooms.foreign or rooms.cells[r.cell].kind == "outside":
            continue
        mid = np.asarray(r.polygon, np.float64).mean(axis=0)[:2]
        step = mid - inner
        step = step / max(float(np.linalg.norm(step)), 1e-9)
        poses.append((r.cell, np.array([*(mid + step), z]), every))
    out: list[int] = []
    for cell, eye, yaws in poses:
        for yaw in yaws:
            out += rooms.seen_from(cell, eye, camera(eye, float(yaw), 0.0).astype(np.float64), proj, size)
    return [c for c in dict.fromkeys(out) if c not in rooms.foreign]


def door_ahead(rooms: RoomStreamer, e: Entrance) -> list[int]:
    """The doorway, then the cells up to :data:`DOOR_DEPTH` portals beyond it, nearest first
    (neither the street nor the building's outside)."""
    out = [e.doorway]
    frontier = [e.doorway]
    for _ in range(DOOR_DEPTH):
        nxt = []
        for c in frontier:
            for n in rooms.cells[c].neighbours:
                if n not in out and n in rooms.cells and n not in rooms.foreign and rooms.cells[n].kind != "outside":
                    out.append(n)
                    nxt.append(n)
        frontier = nxt
    return out


def seen_ahead(
    rooms: RoomStreamer,
    e: Entrance,
    eye: NDArray[np.float64],
    view: NDArray[np.float64],
    proj: NDArray[np.float64],
    size: tuple[int, int],
    velocity: NDArray[np.float64],
    door: NDArray[np.float64],
) -> list[int]:
    """The rooms seen through the entrance from where the eye will be (moving on at
    ``velocity`` for each of :data:`LOOK_AHEAD_S`, while it comes nearer the door),
    looking the way it looks now and straight at the door, nearest in time first."""
    out: list[int] = []
    v = np.array([*np.asarray(velocity, np.float64).reshape(2), 0.0])
    last = float(np.linalg.norm(eye[:2] - door[:2]))
    for h in LOOK_AHEAD_S:
        e2 = eye + h * v
        d = float(np.linalg.norm(e2[:2] - door[:2]))
        if h and d >= last:
            break
        last = d
        aim = np.array([door[0], door[1], e2[2]])
        views = [predicted_view(view, eye, e2)]
        if d > 0.5:
            views.append(look_at(e2, aim).astype(np.float64))
        for v2 in views:
            out += rooms.seen_from(e.street, e2, v2, proj, size)
    return [c for c in dict.fromkeys(out) if c not in rooms.foreign]
