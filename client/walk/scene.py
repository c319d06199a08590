"""What a walk walks through and how it views it: the streamers of the scene's cell models on one cache.

A scene's cells have one of two visibility models (``shared/scene/cellkinds.py``):
street cells a PVS, served by the city :class:`~walkstream.client.stream.streamer.Streamer`;
room cells portals, served by the :class:`~walkstream.client.stream.rooms.RoomStreamer`.
A city scene has street cells only, an interior room cells only, a crossing both,
joined at an entrance.  The frame loop (:mod:`.loop`) asks the scene, never its kind.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from walkstream.client.config import ReplayConfig
from walkstream.client.stream.cache import Cache
from walkstream.client.stream.images import ImpostorImages
from walkstream.client.stream.ringsides import RingSides
from walkstream.client.stream.rooms import RoomStreamer
from walkstream.client.stream.streamer import Streamer
from walkstream.shared.camera import perspective
from walkstream.shared.roomview import VIEW_MIN_FAR_M, VIEW_NEAR_M
from walkstream.shared.roomwire import Entrance
from walkstream.shared.walls import WallSide, WallTable

__all__ = ["STREET_NEAR_M", "STREET_FAR_M", "WalkScene", "walk_projection"]

STREET_NEAR_M = 0.5
"""The street's near plane: nothing is closer than a facade seen from the pavement."""

STREET_FAR_M = 2000.0
"""The street's far plane (the PVS has no fog)."""


@dataclass
class WalkScene:
    """The cell models a walk's scene holds, each with its streamer, on one cache."""

    cache: Cache
    """The one cache of every content kind (keyed by (kind, id))."""
    streets: Streamer | None = None
    """Street cells (a PVS each) and the city's objects; None: the scene has none."""
    rooms: RoomStreamer | None = None
    """Room cells (portals) and their contents; None: the scene has none."""
    entrance: Entrance | None = None
    """Where a street cell joins a room cell (a crossing scene)."""
    images: ImpostorImages | None = None
    """The impostor images' lane (street cells, ``config.impostors``); it asks for
    nothing on a scene without impostors."""
    walls: tuple[WallSide, ...] = ()
    """An interior's textured virtual walls, or a city's rings of walls around its
    cells (``--virtual-walls``; empty: none, or ``config.virtual_walls`` off)."""
    wall_cells: dict[int, tuple[int, int]] = field(default_factory=dict)
    """Each wall's portal id -> its two cells ``(a, b)`` (the topology's; outdoors
    ``(the ringed cell, -1)``)."""
    wall_rings: dict[int, tuple[int, ...]] = field(default_factory=dict)
    """Outdoors: each ringed street cell -> the indices in :attr:`walls` of its ring's
    walls (:mod:`walkstream.server.bake.ringwalls`; empty indoors)."""
    wall_table: WallTable | None = None
    """:attr:`walls` as arrays (every side's zone and weight for many eyes at once)."""
    wall_boxes: NDArray[np.float64] | None = None
    """``(sides, 2, 3)`` each side's quad's box (min, max corners): the frustum test of
    the textures a frame asks for."""
    ring_sides: RingSides | None = None
    """Outdoors: the rings fetched as the walk comes to their cells (None indoors and
    without walls); :attr:`walls` and the tables after it grow as they arrive."""
    wall_images: ImpostorImages | None = None
    """The wall textures' lane (kind ``walltex``; None without walls)."""
    unknown_quality: float = 0.0
    """Download and rewrite quality of a frame whose visible set is not known yet (the
    street cell's record or the room not in): 0 (nothing has arrived); a crossing scene
    counts such frames (before its first street cell is known, drawing nothing) as 1,
    as its figures were first measured."""

    @property
    def starts_indoors(self) -> bool:
        """Whether the walk is in the portal model before it is located (no street cells)."""
        return self.streets is None


def walk_projection(config: ReplayConfig, scene: WalkScene) -> NDArray[np.float64]:
    """The walk's ``(4, 4)`` projection, spanning the near and far planes of the scene's
    cell models: room cells bring :data:`~walkstream.shared.roomview.VIEW_NEAR_M`, street
    cells :data:`STREET_NEAR_M`; street cells reach :data:`STREET_FAR_M`, room cells alone
    twice the fog (:func:`~walkstream.shared.roomview.room_projection`)."""
    w, h = config.size
    near = VIEW_NEAR_M if scene.rooms is not None else STREET_NEAR_M
    if scene.streets is not None:
        far = STREET_FAR_M
    else:
        assert scene.rooms is not None
        far = max(2.0 * scene.rooms.config.fog_m, VIEW_MIN_FAR_M)
    return perspective(config.fov_deg, w / h, near, far).astype(np.float64)
