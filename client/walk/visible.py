"""The frame step ``visible``: the visible set by the current cell's model.

*Indoors* (the portal model): the portal walk from the room cell
(:func:`~walkstream.shared.portals.cull_portals`, in the rooms' streamer's tick, which
also fetches what it finds).  The perfect frame is defined at the scene's default fog:
the visible cells are those within it, unless their contents do not fit the memory
budget, when the fog tightens until they do.  When the walk reaches the street (an
entrance portal leads to the street cell, which the topology holds as a
:attr:`~walkstream.client.stream.rooms.RoomStreamer.foreign` cell) or a building's
outside (its windows), the street cell's PVS is visible too.

On an interior baked with ``--virtual-walls``, the walls whose texture the viewer
sees close the walk first (:mod:`.walls`): the portal walk stops there and the
frame draws their textures.  What is due now is the walk as baked (every wall at full
texture weight closes it, its texture held or not: those cells, then those
textures); a texture not in yet leaves its wall open, and the perfect frame is the
frame with nothing missing: the cells behind that wall are drawn and must be held.

*On the street* (the PVS model): the current street cell's PVS, and on a city baked
with ``--virtual-walls`` the walls of its ring carrying the far field
(:func:`~.walls.ring_walls`).  An entrance's
building stands in it as its shell (the interior's ``outside`` cell,
:class:`~walkstream.shared.roomwire.Entrance`), never as its own parameters, and when it
does, a portal walk from the shell through its openings (the entrance, the windows)
gives the rooms seen from the street, out to :data:`OUTDOOR_FOG_M`.
"""

from __future__ import annotations

import time

from walkstream.client.walk.state import Frame, WalkState
from walkstream.client.walk.walls import drawn_walls, frame_walls, ring_walls, want_wall_textures

__all__ = ["OUTDOOR_FOG_M", "visible"]

OUTDOOR_FOG_M = 800.0
"""Outdoors the rooms are seen through the shell's openings out to the bake's view
distance (the city's PVS has no fog)."""


def visible(w: WalkState, f: Frame) -> None:
    """Set the frame's visible room cells, street cells (their PVS in ``w.objects``) and fog."""
    e, city, rooms = w.scene.entrance, w.scene.streets, w.scene.rooms
    f.t_cull = time.thread_time()
    if rooms is not None and w.indoors:
        rooms.fog_m = w.indoor_fog
        walls = frame_walls(w, f)  # which virtual walls close the walk this frame
        vis = rooms.tick(f.t, f.eye, f.vp, f.view, w.proj, w.size, cell=f.room)
        default = list(vis)
        # the textures of the walls of the walk as baked (the cells due now)
        want_wall_textures(w, f, rooms.due_visible)
        fog = w.indoor_fog
        while rooms.visible_bytes(vis) > rooms.cache.budget_bytes and fog > 2.0:
            fog *= 0.8
            rooms.fog_m = fog
            vis = rooms.visible_cells(f.eye, f.vp, f.view, w.proj, w.size)
        if fog < w.indoor_fog:
            w.frames.tightened += 1
        if e is not None and (e.street in vis or e.shell in vis):  # the street through the door or a window
            f.pvs_cells = list(dict.fromkeys([e.street, *([f.street] if f.street is not None else [])]))
        f.fog = fog
        f.walls = drawn_walls(walls, vis)
    else:
        if rooms is not None:
            rooms.closed = rooms.due_closed = frozenset()
        if f.street is not None:
            f.pvs_cells = [f.street]
        if rooms is None and (w.scene.wall_rings or w.scene.ring_sides is not None):
            f.walls = ring_walls(w, f)
        default = vis = []
        if rooms is not None:
            rec = city.cells.get(f.street) if city is not None and f.street is not None else None
            shows = e is not None and rec is not None and bool((rec.pvs == e.building).any())
            rooms.fog_m = OUTDOOR_FOG_M
            f.shown = [e.shell] if shows and e is not None else []
            # the walk from the shell passes every outer door and window in view (a door
            # back from the street is seen from street cells other than its own)
            start = e.shell if shows and e is not None else (e.street if e is not None and f.street == e.street else None)
            default = vis = rooms.tick(f.t, f.eye, f.vp, f.view, w.proj, w.size, cell=start,
                                       shown=f.shown, ahead=f.ahead)
            f.fog = OUTDOOR_FOG_M
    foreign = rooms.foreign if rooms is not None else frozenset()
    f.rooms_seen = vis
    f.room_cells = [c for c in vis if c not in foreign]
    f.default_room_cells = [c for c in default if c not in foreign]
    if city is not None:
        w.objects.update(f.pvs_cells, city, w.scene.cache, -1 if e is None else e.building, far=f.far_walls,
                          eye=f.eye, far_all=f.far_all)
