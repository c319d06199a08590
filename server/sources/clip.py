"""Cut a source scene down to a box (``--bbox``)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import shapely
from numpy.typing import NDArray

from walkstream.server.sources.scene import SourceScene
from walkstream.shared.errors import InputError

__all__ = ["clip_scene"]


def clip_scene(scene: SourceScene, bbox: tuple[float, float, float, float]) -> SourceScene:
    """Keep the objects whose footprint centre lies in ``bbox`` (scene-local metres).

    Ids are renumbered densely (buildings first) so PVS id lists stay compact.
    """
    box = shapely.box(*bbox)

    def inside(ring: NDArray[np.float64]) -> bool:
        c = ring.mean(axis=0)
        return bool(shapely.contains_xy(box, c[0], c[1]))

    buildings = [b for b in scene.buildings if inside(b.rings[0])]
    streets = [s for s in scene.streets if inside(s.ring)]
    if not buildings and not streets:
        raise InputError(f"--bbox {bbox}: no object of the scene lies inside it")
    buildings = [replace(b, id=i) for i, b in enumerate(buildings)]
    streets = [replace(s, id=len(buildings) + i) for i, s in enumerate(streets)]
    return replace(scene, buildings=tuple(buildings), streets=tuple(streets))
