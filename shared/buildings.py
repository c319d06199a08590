"""Rebuild building geometry from compact parameters with the building grammar.

The grammar text (``shared/grammars/building.lsys``) is data: the server sends it to
each client once and only :class:`~walkstream.shared.records.BuildingParams` travel per
building.  This module seeds the derivation from a building's parameters and hands
the terminal modules to the interpreter.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache
from importlib import resources

import mapbox_earcut
import numpy as np

from walkstream.shared.errors import InputError, WalkstreamError
from walkstream.shared.geometry import ring_edges, triangulate_rings
from walkstream.shared.landmarks import shortest_edge
from walkstream.shared.lsystem.batch import FrameBatch, block_offsets, derive_batch, interpret_batch
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
    "frame_batch",
    "build_lod_batch",
    "build_lods_batch",
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
        **_landmark_globals(b),
    }
    return {"Building": np.zeros((1, 0)), "Edge": edges}, globals_


def _landmark_globals(b: BuildingParams) -> dict[str, float]:
    """The grammar's landmark globals: kind ``K``, shortest exterior edge ``LMIN``, crown top ``T``."""
    if b.kind == 0:
        # a plain building's crown rules never fire; skip the footprint's edges
        return {"K": 0.0, "LMIN": 0.0, "T": b.height}
    return {"K": float(b.kind), "LMIN": shortest_edge(b.rings[0]), "T": b.top}


def _landmark_arrays(buildings: Sequence[BuildingParams]) -> dict[str, np.ndarray]:
    """:func:`_landmark_globals` of a batch, ``(count,)`` each (one pass over the buildings)."""
    rows = [_landmark_globals(b) for b in buildings]
    return {k: np.array([g[k] for g in rows]) for k in ("K", "LMIN", "T")}


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


def frame_batch(buildings: Sequence[BuildingParams]) -> FrameBatch:
    """:func:`edge_frames` of many footprints at once, concatenated.

    The same values as :func:`edge_frames` building by building (the same
    element-wise arithmetic); only the cap triangulation (earcut) is still one call
    per footprint.
    """
    rings = [r for b in buildings for r in b.rings]
    count = len(buildings)
    ring_len = np.fromiter((len(r) for r in rings), np.int64, len(rings))
    ring_owner = np.repeat(np.arange(count), [len(b.rings) for b in buildings])
    edge_start = block_offsets(np.bincount(ring_owner, ring_len, count).astype(np.int64))
    ring_start = block_offsets(ring_len)[:-1]
    p0 = np.concatenate(rings) if rings else np.zeros((0, 2))
    nxt = np.arange(1, len(p0) + 1)
    nxt[ring_start + ring_len - 1] = ring_start
    d = p0[nxt] - p0
    length = np.hypot(d[:, 0], d[:, 1])
    safe = np.where(length > 0, length, 1.0)
    direction = d / safe[:, None]
    # exterior CCW and holes CW: the outward normal is the right-hand perpendicular
    normal = np.column_stack([direction[:, 1], -direction[:, 0]])

    # earcut per footprint, on coordinates relative to its first vertex (as triangulate_rings)
    edge_owner = np.repeat(np.arange(count), np.diff(edge_start))
    local = p0 - p0[edge_start[:-1]][edge_owner] if count else p0
    ends = (ring_start + ring_len - edge_start[ring_owner]).astype(np.uint32)
    ring_first = block_offsets(np.bincount(ring_owner, minlength=count))
    tris = []
    for b in range(count):
        e0, e1 = edge_start[b], edge_start[b + 1]
        tris.append(mapbox_earcut.triangulate_float64(local[e0:e1], ends[ring_first[b] : ring_first[b + 1]]))
    idx = np.asarray(np.concatenate(tris) if tris else np.zeros(0), np.int64).reshape(-1, 3)
    tri_start = block_offsets(np.array([len(t) // 3 for t in tris], np.int64))
    g = idx + edge_start[:-1][np.repeat(np.arange(count), np.diff(tri_start))][:, None]
    a, b_, c = local[g[:, 0]], local[g[:, 1]], local[g[:, 2]]
    cross = (b_[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b_[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    flip = cross < 0
    idx[flip] = idx[flip][:, ::-1]
    frames = EdgeFrames(p0, direction, normal, length, p0, idx)
    return FrameBatch(frames, edge_start, edge_start, tri_start)


def _derive_batch(
    buildings: Sequence[BuildingParams], lod: int, grammar: Grammar, batch: FrameBatch
) -> list[Mesh]:
    count = batch.size
    fr = batch.frames
    owner = np.repeat(np.arange(count), np.diff(batch.edge_start))
    nb = np.concatenate([h for b in buildings for h in b.neighbour_heights])
    local_edge = np.arange(len(owner)) - batch.edge_start[:-1][owner]
    edges = np.column_stack([local_edge.astype(np.float64), fr.length, nb])
    free = nb <= 0
    lmax = np.zeros(count)
    np.maximum.at(lmax, owner[free], fr.length[free])
    globals_ = {
        "S": np.array([float(b.style) for b in buildings]),
        "F": np.array([float(b.floors) for b in buildings]),
        "FH": np.array([b.floor_height for b in buildings]),
        "H": np.array([b.height for b in buildings]),
        "LOD": float(lod),
        "LMAX": lmax,
        **_landmark_arrays(buildings),
    }
    modules, owners = derive_batch(
        grammar,
        {"Building": np.zeros((count, 0)), "Edge": edges},
        {"Building": np.arange(count), "Edge": owner},
        globals_,
        count,
    )
    return interpret_batch(modules, owners, batch)


def build_lod_batch(
    buildings: Sequence[BuildingParams], lod: int, grammar: Grammar | None = None
) -> list[Mesh]:
    """Rebuild one LOD of many buildings at once: what :func:`build_lod` makes for each.

    Parameters
    ----------
    buildings: the buildings, any number (an empty batch gives an empty list).
    lod: the level of detail, one of :data:`LODS`.
    grammar: the building grammar (the built-in one by default).

    Returns
    -------
    list of Mesh
        One mesh per building, in order: the same triangles in the same order as
        :func:`build_lod`, positions equal.  When the batch fails (a derivation over
        the grammar's limits) the buildings are rebuilt one by one, so the error
        names the same building as :func:`build_lod` would.
    """
    return [m[0] for m in _batch(buildings, (lod,), grammar)]


def build_lods_batch(
    buildings: Sequence[BuildingParams], grammar: Grammar | None = None
) -> list[tuple[Mesh, Mesh, Mesh]]:
    """All three LODs of many buildings at once (see :func:`build_lod_batch`)."""
    return [(m[0], m[1], m[2]) for m in _batch(buildings, LODS, grammar)]


def _batch(
    buildings: Sequence[BuildingParams], lods: tuple[int, ...], grammar: Grammar | None
) -> list[list[Mesh]]:
    for lod in lods:
        if lod not in LODS:
            raise InputError(f"lod: expected one of {LODS}, got {lod!r}")
    if not buildings:
        return []
    g = grammar or default_grammar()
    batch = frame_batch(buildings)
    try:
        per_lod = [_derive_batch(buildings, lod, g, batch) for lod in lods]
    except WalkstreamError:
        # find (and raise for) the building at fault exactly as the one-by-one path does
        return [[build_lod(b, lod, g) for lod in lods] for b in buildings]
    return [[per_lod[k][i] for k in range(len(lods))] for i in range(len(buildings))]
