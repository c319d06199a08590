"""A city start bundle's ring walls: the start cell's ring and the textures its first seconds see.

On a city baked with ``--virtual-walls`` a street cell ringed by textured walls
(:mod:`walkstream.server.bake.ringwalls`) draws its far field as geometry while a ring
wall in view has no texture, and the walker standing at its start waits for that far
field too.  So a start bundle asked for with ``walls=true`` brings the rings of the
cells the path's first seconds pass (``walls``, the rows ``GET .../walls?cells=``
sends) and the textures of the ring walls its poses see in those seconds, each with
the time its walk first sees it (:func:`first_rings`).  Those its first
:data:`HOLD_TEXTURES_S` see come with the first view (the walker stands at its start
for them: a texture asked for once it walks would come a round trip and its bytes
later, and the far field its wall then leaves to geometry is tens of objects); the
later ones come in the order the walk needs them, among the bundle's other parts
(:mod:`~walkstream.server.service.startbundle`).  The other rings the client asks for
as its walk comes to their cells.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from walkstream.server.service.http import Encoded, encode
from walkstream.server.service.streetheads import POSE_STEP_S, STREET_VIEW_FAR_M, STREET_VIEW_NEAR_M
from walkstream.shared.camera import camera, perspective
from walkstream.shared.frustum import frustum_cull
from walkstream.shared.paths import RecordedPath
from walkstream.shared.roomview import RoomView
from walkstream.shared.walls import WallSide, WallTable, walls_wire

if TYPE_CHECKING:
    from walkstream.server.service.scenes import Scene

__all__ = ["FIRST_RING_TEXTURES", "HOLD_TEXTURES_S", "first_rings"]

FIRST_RING_TEXTURES = 12
"""At most this many textures in a city's start bundle (those seen first)."""

HOLD_TEXTURES_S = POSE_STEP_S
"""The textures the path's poses see up to this many seconds come with the first view:
the walk crosses into the next zone of a wall beside it within a fraction of a second
(West Oakland's ``SE``: 0.08 s after it starts walking), sooner than a request could
bring that zone's texture."""


def first_rings(scene: Scene, path: RecordedPath, view: RoomView,
                lead_s: float) -> tuple[Encoded, list[int], list[tuple[int, float]]] | None:
    """The rings of the cells ``path``'s poses pass in its first ``lead_s`` seconds (every
    :data:`~walkstream.server.service.streetheads.POSE_STEP_S`), as ``GET
    .../walls?cells=`` sends them (msgpack), and the textures of their walls those poses
    see (facing the eye, in the frustum), in the order first seen, at most
    :data:`FIRST_RING_TEXTURES`: ``(rings, first, later)``, ``first`` the ids of those
    the poses up to :data:`HOLD_TEXTURES_S` see, ``later`` the others as ``(id, seconds
    into the path it is first seen)``; None when no pose stands in a ringed cell (or the
    scene has no walls)."""
    if not scene.has_walls:
        return None
    w, h = view.size
    proj = perspective(view.fov_deg, w / h, STREET_VIEW_NEAR_M, STREET_VIEW_FAR_M).astype(np.float64)
    cells: list[int] = []
    seen_at: dict[int, float] = {}
    steps = int(np.floor(min(lead_s, path.duration) / POSE_STEP_S + 1e-9)) + 1
    for k in range(steps):
        t = k * POSE_STEP_S
        xyz, yaw, pitch = path.at(t)
        eye = np.asarray(xyz, np.float64).reshape(3)
        found = scene.locator.locate(float(eye[0]), float(eye[1]))
        if found is None:
            continue
        cid = int(found)
        rows = scene.ring_sides.get(cid, [])
        if not rows:
            continue
        if cid not in cells:
            cells.append(cid)
        sides = tuple(WallSide.from_row(r, "stored wall") for r in rows)
        corners = np.array([s.corners() for s in sides], np.float64).reshape(-1, 4, 3)
        zones, _d, weights = WallTable(sides).views(eye[None, :])
        seen = frustum_cull(corners.min(axis=1), corners.max(axis=1), proj @ camera(eye, float(yaw), float(pitch)).astype(np.float64))
        for j in np.flatnonzero((weights[0] > 0.0) & seen).tolist():
            tid = sides[j].textures[int(zones[0, j])]
            if tid not in seen_at and len(seen_at) < FIRST_RING_TEXTURES:
                seen_at[tid] = t
    if not cells:
        return None
    rows = [r for c in cells for r in scene.ring_sides[c]]
    first = [tid for tid, t in seen_at.items() if t <= HOLD_TEXTURES_S + 1e-9]
    later = [(tid, t) for tid, t in seen_at.items() if t > HOLD_TEXTURES_S + 1e-9]
    return encode(walls_wire(rows), "msgpack", scene.version, "walls-" + ",".join(map(str, cells))), first, later
