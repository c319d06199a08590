"""The first view's wall textures: what an interior's start bundle carries so the first frames' walls are closed.

On an interior baked with ``--virtual-walls`` a wall whose texture the client does not
hold stays open: the portal walk goes through it and the cells behind, out to the fog,
are part of the frame and must be held before a frame is perfect.  A start bundle that
brings only cells leaves every wall of the first view open (the production hall's
first view was 31 cells).  So the bundle (``GET /v1/start ... &walls=true``) brings the
wall sides and, before the contents, the textures of the walls the first pose sees
at full weight (:func:`first_wall_textures`: their zone's texture, as the client's
:func:`~walkstream.client.walk.walls.frame_walls` picks it); the first view's cells
are then those of the walk with those walls closed, as the client will walk it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.shared.camera import camera
from walkstream.shared.frustum import frustum_cull
from walkstream.shared.roomcompact import decode_topology_compact
from walkstream.shared.roomview import RoomView, room_projection
from walkstream.shared.walls import WallSide, WallTable

__all__ = ["FIRST_WALL_TEXTURES", "SceneWalls", "first_wall_textures", "scene_walls"]

FIRST_WALL_TEXTURES = 16
"""At most this many textures in a start bundle (the nearest first): about 0.9 kB each."""


@dataclass(frozen=True)
class SceneWalls:
    """An interior's wall sides as the client holds them (those on the topology's wall
    portals), their table, boxes and the cell each side faces from."""

    sides: tuple[WallSide, ...]
    table: WallTable
    lo: NDArray[np.float64]
    hi: NDArray[np.float64]
    viewer_cell: NDArray[np.int64]
    """``(k,)`` the cell on the viewer's side of each side."""

    @classmethod
    def of(cls, rows: list[list[float | int]] | list[tuple[float | int, ...]], topology: bytes) -> SceneWalls:
        """From the stored wall rows and the interior's compact topology's bytes."""
        topo = decode_topology_compact(topology, "topology")
        cells = {int(p[0]): (int(p[2]), int(p[3])) for p in topo.portals if p[1] == "wall"}
        sides = tuple(s for r in rows if (s := WallSide.from_row(r, "stored wall")).portal in cells)
        viewer = np.array([cells[s.portal][0 if s.side == 0 else 1] for s in sides], np.int64)
        corners = np.array([s.corners() for s in sides], np.float64).reshape(-1, 4, 3)
        return cls(sides, WallTable(sides), corners.min(axis=1), corners.max(axis=1), viewer)


def first_wall_textures(
    walls: SceneWalls, pose: tuple[ArrayLike, float, float], view: RoomView,
    reached: object = None,
) -> tuple[list[int], frozenset[int]]:
    """The textures of the walls the viewer at ``pose`` (``(eye (3,), yaw, pitch)``)
    sees at full weight (within the frustum, nearest first, at most
    :data:`FIRST_WALL_TEXTURES`) and their portals, to close in the first view's walk.

    ``reached`` (a callable taking the closed portals and giving the cells the walk
    reaches) keeps only the walls on the viewer's side of a reached cell: a wall two
    cells behind a closed one is never drawn."""
    if not walls.sides:
        return [], frozenset()
    eye = np.asarray(pose[0], np.float64).reshape(3)
    zones, dist, weights = walls.table.views(eye[None, :])
    vp = room_projection(view.fov_deg, view.size, view.fog_m) @ camera(eye, float(pose[1]), float(pose[2])).astype(
        np.float64)
    seen = frustum_cull(walls.lo, walls.hi, vp)
    full = np.flatnonzero((weights[0] >= 1.0) & seen)
    full = full[np.argsort(dist[0, full], kind="stable")][:FIRST_WALL_TEXTURES]
    if reached is not None and len(full):
        cells = set(reached(frozenset(walls.sides[k].portal for k in full.tolist())))  # type: ignore[operator]
        full = np.array([k for k in full.tolist() if int(walls.viewer_cell[k]) in cells], np.int64)
    ks = full.tolist()
    return ([walls.sides[k].textures[int(zones[0, k])] for k in ks],
            frozenset(walls.sides[k].portal for k in ks))


_WALLS: dict[tuple[str, str], SceneWalls] = {}


def scene_walls(scene: Any, topology: bytes) -> SceneWalls:
    """The :class:`SceneWalls` of a served scene (``scene.reader``'s stored sides,
    ``topology`` its compact topology's bytes), made once per scene version."""
    key = (str(scene.name), str(scene.version))
    got = _WALLS.get(key)
    if got is None:
        got = SceneWalls.of(list(scene.reader.wall_sides()), topology)
        if len(_WALLS) >= 8:  # a few scenes at once; a replaced file gets a new version
            _WALLS.pop(next(iter(_WALLS)))
        _WALLS[key] = got
    return got

