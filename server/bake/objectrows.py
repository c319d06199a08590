"""A city scene's objects as store rows: buildings with their predicted triangles and box, street pieces, areas."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

from walkstream.server.sources.scene import SourceScene
from walkstream.server.store import ObjectRow
from walkstream.shared.buildings import predict_triangles
from walkstream.shared.codec.params import stored_form
from walkstream.shared.lsystem.grammar import Grammar

__all__ = ["building_box", "object_rows", "stored_scene"]


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


def stored_scene(scene: SourceScene) -> SourceScene:
    """``scene`` with every object as the database stores it and every client rebuilds it
    (:func:`~walkstream.shared.codec.params.stored_form`: on the centimetre): what a bake
    renders into pictures a client shows beside its own geometry (wall textures, impostor
    images) is built from this, so both show the same door on the same side."""
    return replace(scene, buildings=tuple(stored_form(b) for b in scene.buildings),
                   streets=tuple(stored_form(s) for s in scene.streets),
                   areas=tuple(stored_form(a) for a in scene.areas))
