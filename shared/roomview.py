"""What a viewer in an interior sees: its cell by the planes, the cells portal culling keeps.

The client culls every frame with it (:class:`~walkstream.client.stream.rooms.RoomStreamer`)
and the server once per start bundle (the first view's contents go with the
topology, so the first perfect frame needs no second round trip).  Both must get the
same cells from the same pose, so the camera of an interior view is defined here
once: :func:`room_projection` (near plane :data:`VIEW_NEAR_M`, far plane twice the
fog distance but at least :data:`VIEW_MIN_FAR_M`) and :class:`RoomView` (the
viewport, field of view, fog and depth limit the client walks with).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.shared.camera import camera, perspective
from walkstream.shared.errors import InputError
from walkstream.shared.portalgraph import PortalGraph
from walkstream.shared.portals import cull_portals
from walkstream.shared.scene.cellkinds import LOCATABLE_KINDS

__all__ = [
    "VIEW_NEAR_M",
    "VIEW_MIN_FAR_M",
    "RoomView",
    "room_projection",
    "stack_planes",
    "cell_of",
    "RoomLocator",
    "cells_seen",
]

#: Near plane of an interior view, metres.
VIEW_NEAR_M = 0.1
#: The far plane is twice the fog distance, but never nearer than this (metres).
VIEW_MIN_FAR_M = 50.0


@dataclass(frozen=True)
class RoomView:
    """The camera an interior is walked with: what the server needs to cull as the client does."""

    size: tuple[int, int] = (640, 480)
    """Viewport width and height, pixels."""
    fov_deg: float = 60.0
    """Vertical field of view, degrees."""
    fog_m: float = 40.0
    """Portals farther than this are not looked through (metres)."""
    max_depth: int | None = None
    """Portals passed on the way to a visible cell, at most; None (the default): no
    limit, the walk stops at the fog (a limit would cut a long corridor's far end that
    the fog still shows)."""

    def __post_init__(self) -> None:
        w, h = self.size
        if not (16 <= w <= 8192 and 16 <= h <= 8192):
            raise InputError(f"view {w}x{h}: expected a width and height from 16 to 8192 pixels")
        if not 1.0 <= self.fov_deg <= 170.0:
            raise InputError(f"field of view {self.fov_deg!r} degrees: expected 1 to 170")
        if not 0.0 < self.fog_m <= 10_000.0:
            raise InputError(f"fog {self.fog_m!r} m: expected more than 0 and at most 10000")
        if self.max_depth is not None and not 0 <= self.max_depth <= 256:
            raise InputError(f"depth {self.max_depth!r}: expected 0 to 256 portals")


def room_projection(fov_deg: float, size: tuple[int, int], fog_m: float) -> NDArray[np.float64]:
    """``(4, 4)`` float64 projection of an interior view: ``fov_deg`` vertical, the
    viewport's aspect, :data:`VIEW_NEAR_M` to ``max(2 * fog_m, VIEW_MIN_FAR_M)``."""
    w, h = size
    far = max(2.0 * fog_m, VIEW_MIN_FAR_M)
    return perspective(fov_deg, w / h, VIEW_NEAR_M, far).astype(np.float64)


def stack_planes(cells: Sequence[Any]) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Ids and ``(n, k, 4)`` planes of ``cells`` (records with ``id`` and ``planes``),
    padded with rows that every point satisfies."""
    k = max((len(c.planes) for c in cells), default=1)
    out = np.zeros((len(cells), k, 4))
    out[:, :, 3] = -1.0
    for i, c in enumerate(cells):
        out[i, : len(c.planes)] = c.planes
    return np.array([c.id for c in cells], dtype=np.int64), out


def cell_of(planes: NDArray[np.float64], eye: ArrayLike, tol: float = 1e-6) -> NDArray[np.bool_]:
    """``(n,)`` whether the eye ``(3,)`` is behind every plane of each of ``(n, k, 4)`` cells."""
    e = np.asarray(eye, dtype=np.float64).reshape(3)
    return np.all(planes[:, :, :3] @ e + planes[:, :, 3] <= tol, axis=1)


class RoomLocator:
    """The cell holding a point, by the planes of a topology's inside cells.

    Parameters
    ----------
    cells:
        The topology's cells (records with ``id``, ``kind``, ``planes``,
        ``neighbours``); cells of a kind no viewer is located in (``outside``) and
        cells without planes hold no point.
    """

    def __init__(self, cells: Sequence[Any]) -> None:
        self.cells = {c.id: c for c in cells}
        inside = [c for c in cells if c.kind in LOCATABLE_KINDS and len(c.planes)]
        self.ids, self.planes = stack_planes(inside)
        self.row = {int(c): i for i, c in enumerate(self.ids)}

    def holds(self, cid: int, eye: ArrayLike) -> bool:
        """Whether cell ``cid`` holds ``eye``."""
        row = self.row.get(cid)
        return row is not None and bool(cell_of(self.planes[row : row + 1], eye)[0])

    def locate(self, eye: ArrayLike, cur: int | None = None, anywhere: bool = True) -> int | None:
        """The cell holding ``eye`` looked for from ``cur``: ``cur``, a neighbour, then
        (``anywhere``) every cell; ``cur`` when none holds it (the eye on a shared plane
        stays where it was)."""
        e = np.asarray(eye, dtype=np.float64).reshape(3)
        if cur is not None and cur in self.row:
            if self.holds(cur, e):
                return cur
            for n in self.cells[cur].neighbours:
                if self.holds(n, e):
                    return int(n)
        if anywhere:
            hit = np.flatnonzero(cell_of(self.planes, e))
            if len(hit):
                return int(self.ids[hit[0]])
        return cur


def cells_seen(
    graph: PortalGraph,
    locator: RoomLocator,
    poses: Iterable[tuple[ArrayLike, float, float]],
    view: RoomView,
    closed: frozenset[int] = frozenset(),
) -> list[list[int]]:
    """The cells portal culling keeps from each of ``poses`` (``(eye (3,), yaw, pitch)``,
    as :meth:`~walkstream.shared.paths.RecordedPath.at` gives them), each list in the
    culling's order (nearest first): the cells the client will see from there.  Each
    pose is located from the one before; a pose outside every cell (and not following
    one inside) sees nothing.  ``closed``: portals the walk stops at (virtual walls
    drawn as their textures)."""
    proj = room_projection(view.fov_deg, view.size, view.fog_m)
    out: list[list[int]] = []
    cur: int | None = None
    for xyz, yaw, pitch in poses:
        eye = np.asarray(xyz, dtype=np.float64).reshape(3)
        cur = locator.locate(eye, cur)
        if cur is None:
            out.append([])
            continue
        v = camera(eye, float(yaw), float(pitch)).astype(np.float64)
        pc = cull_portals(graph, cur, eye, v, proj, view.size, fog_m=view.fog_m, max_depth=view.max_depth,
                          closed=closed)
        out.append(list(pc.order))
    return out
