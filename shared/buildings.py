"""Rebuild building geometry from compact parameters with the building grammar.

The grammar text (``shared/grammars/building.lsys``) is data: the server sends it to
each client once and only :class:`~walkstream.shared.records.BuildingParams` travel per
building.  This module seeds the derivation from a building's parameters and hands
the terminal modules to the interpreter.
"""

from __future__ import annotations

from functools import lru_cache
from importlib import resources

import numpy as np

from walkstream.shared.errors import InputError
from walkstream.shared.geometry import ring_edges, triangulate_rings
from walkstream.shared.lsystem.derive import Modules, derive
from walkstream.shared.lsystem.grammar import Grammar, parse_grammar
from walkstream.shared.lsystem.interpret import EdgeFrames, count_triangles, interpret
from walkstream.shared.records import BuildingParams, Mesh

__all__ = [
    "LODS",
    "default_grammar_text",
    "default_grammar",
    "edge_frames",
    "derive_building",
    "build_lod",
    "build_lods",
    "predict_triangles",
]

#: the levels of detail every building has
LODS = (0, 1, 2)


def default_grammar_text() -> str:
    """The text of the built-in building grammar."""
    return resources.files("walkstream.shared").joinpath("grammars/building.lsys").read_text(encoding="utf-8")


@lru_cache(maxsize=1)
def default_grammar() -> Grammar:
    """The built-in building grammar, parsed once."""
    return parse_grammar(default_grammar_text())


def edge_frames(b: BuildingParams) -> EdgeFrames:
    """Edge frames and cap triangulation of a building's footprint."""
    p0, p1 = ring_edges(b.rings)
    d = p1 - p0
    length = np.hypot(d[:, 0], d[:, 1])
    safe = np.where(length > 0, length, 1.0)
    direction = d / safe[:, None]
    # exterior CCW and holes CW: the building's material is always on the left,
    # so the outward normal is the right-hand perpendicular
    normal = np.column_stack([direction[:, 1], -direction[:, 0]])
    cap_xy = np.concatenate(b.rings)
    return EdgeFrames(p0, direction, normal, length, cap_xy, triangulate_rings(b.rings))


def _seeds_and_globals(
    b: BuildingParams, lod: int, frames: EdgeFrames
) -> tuple[dict[str, np.ndarray], dict[str, float]]:
    nb = np.concatenate(b.neighbour_heights)
    edges = np.column_stack([np.arange(len(frames.length), dtype=np.float64), frames.length, nb])
    free = frames.length[nb <= 0]
    globals_ = {
        "S": float(b.style),
        "F": float(b.floors),
        "FH": b.floor_height,
        "H": b.height,
        "LOD": float(lod),
        "LMAX": float(free.max()) if len(free) else 0.0,
    }
    return {"Building": np.zeros((1, 0)), "Edge": edges}, globals_


def derive_building(
    b: BuildingParams, lod: int, grammar: Grammar | None = None, frames: EdgeFrames | None = None
) -> Modules:
    """Derive a building at ``lod``; returns the terminal modules by symbol."""
    if lod not in LODS:
        raise InputError(f"lod: expected one of {LODS}, got {lod!r}")
    g = grammar or default_grammar()
    fr = frames or edge_frames(b)
    seeds, globals_ = _seeds_and_globals(b, lod, fr)
    return derive(g, seeds, globals_)


def build_lod(b: BuildingParams, lod: int, grammar: Grammar | None = None) -> Mesh:
    """Rebuild one LOD of a building as a mesh in scene-local metres."""
    frames = edge_frames(b)
    return interpret(derive_building(b, lod, grammar, frames), frames)


def build_lods(b: BuildingParams, grammar: Grammar | None = None) -> tuple[Mesh, Mesh, Mesh]:
    """Rebuild all three LODs, sharing the footprint analysis."""
    frames = edge_frames(b)
    m0, m1, m2 = (interpret(derive_building(b, lod, grammar, frames), frames) for lod in LODS)
    return m0, m1, m2


def predict_triangles(b: BuildingParams, grammar: Grammar | None = None) -> tuple[int, int, int]:
    """Triangle counts of the three LODs from the derivation alone (no geometry built)."""
    frames = edge_frames(b)
    t0, t1, t2 = (count_triangles(derive_building(b, lod, grammar, frames), frames) for lod in LODS)
    return t0, t1, t2
