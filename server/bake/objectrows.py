"""A city scene's objects as store rows: buildings with their predicted triangles and box, street pieces, areas."""

from __future__ import annotations

from typing import Any

from walkstream.server.sources.scene import SourceScene
from walkstream.server.store import ObjectRow
from walkstream.shared.buildings import predict_triangles
from walkstream.shared.lsystem.grammar import Grammar

__all__ = ["building_box", "object_rows"]


def object_rows(scene: SourceScene, grammar: Grammar) -> list[ObjectRow]:
    """Every building (triangles per LOD predicted by ``grammar``), street piece and area of ``scene``."""
    rows = [ObjectRow.of(b, tris=predict_triangles(b, grammar), bbox=building_box(b)) for b in scene.buildings]
    rows += [ObjectRow.of(s, tris=(len(s.ring) - 2,) * 3) for s in scene.streets]
    rows += [ObjectRow.of(a, tris=(sum(len(r) for r in a.rings) + 2 * len(a.rings) - 4,) * 3) for a in scene.areas]
    return rows


def building_box(b: Any) -> tuple[float, float, float, float, float, float]:
    """``minx, miny, minz, maxx, maxy, maxz`` of what the grammar builds from building ``b``."""
    lo, hi = b.rings[0].min(axis=0), b.rings[0].max(axis=0)
    # the grammar builds a parapet above the eaves and ledges just outside the walls
    return (float(lo[0]) - 0.5, float(lo[1]) - 0.5, 0.0, float(hi[0]) + 0.5, float(hi[1]) + 0.5, b.top + 1.0)
