"""What a frame loop notes of a compared frame for the ground truth: what it drew and what it lacked.

One note for every scene kind (:meth:`~walkstream.client.truth.recorder.TruthRecorder.record`
makes them): the camera, the city objects drawn with their LOD, the objects the visible
set named (its PVS) and which of them had arrived and were built, the room parts drawn,
the room cells visible whose contents had not arrived, the fog in force, and the
impostors drawn (their quads and images).  The
figures compare against it: a city's missing pixels by cause
(:mod:`walkstream.client.truth.missing`), the culled pixels of a walk with rooms
(:mod:`walkstream.client.truth.culled`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from walkstream.shared.records import Mesh

__all__ = ["FrameNote"]


@dataclass(frozen=True)
class FrameNote:
    """What the client had and drew on one compared frame (noted during the walk)."""

    frame: int
    t: float
    eye: NDArray[np.float64]
    view: NDArray[np.floating[Any]]
    """The view matrix as the loop drew with it (its dtype kept: the client's frame is drawn again from it)."""
    cell: int | None
    """The client's current cell (None while it knows none)."""
    pvs: NDArray[np.int64] | None
    """The city objects the frame's visible set names (its cell's PVS as the client has
    it); None when the frame knew no visible set yet (the cell record had not arrived)."""
    received: NDArray[np.int64]
    """Objects whose parameters had arrived."""
    built: NDArray[np.int64]
    """Objects whose geometry was built: an object of :attr:`pvs` not built is late, not culled."""
    drawn: tuple[tuple[int, int, Mesh], ...]
    """``(object id, lod, mesh)`` of each object drawn, in the client's draw order."""
    parts: tuple[tuple[int, int], ...]
    """``(cell, part)`` of each room part drawn."""
    waiting: tuple[int, ...]
    """Room cells visible whose contents had not arrived: late, not culled."""
    fog: float
    """The fog distance in force (``inf``: none)."""
    impostors: tuple[tuple[int, Any], ...] = ()
    """``(object id, quad)`` of each impostor drawn (:data:`~walkstream.client.draw.quads.Quad`:
    corners, image id, premultiplied RGBA, opacity), in draw order."""
    facades: tuple[Any, ...] = ()
    """The facade quads drawn over boxes (:data:`~walkstream.client.draw.quads.Quad`), in
    draw order: painted into the client's picture before the impostors, their pixels
    staying the boxes' (``lod_colour``)."""
    walls: tuple[Any, ...] = ()
    """The ``(4, 3)`` corners of each virtual wall drawn as its texture alone (its portal
    closed: the cells behind it not drawn)."""
    wall_quads: tuple[Any, ...] = ()
    """Every virtual wall drawn, closed or fading over the geometry in its blend zone,
    as the client drew it (:data:`~walkstream.client.draw.quads.Quad`: corners, texture
    key, premultiplied RGBA, opacity), in draw order: the colour truth paints them."""
    seam_walls: tuple[Any, ...] = ()
    """The same walls as :class:`~walkstream.client.truth.seam.SeamWall` (which side, which
    textures at which shares), in draw order: the seam at zone borders is measured on them."""
