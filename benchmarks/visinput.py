"""What ``walkstream bench visibility`` runs on: a scene, its view cells, and a sample of them.

The scene is read from a scene database itself (objects, cells, PVS, view distance,
:func:`scene_from_database`), so a database baked from any source works; a source
file's scene is read by the caller.  :func:`pick_cells` spreads the sample over the
scene.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from walkstream.server.bake.cells import make_cells
from walkstream.server.bake.viewcell import ViewCell
from walkstream.server.sources.scene import SourceScene
from walkstream.shared.arrays import I64
from walkstream.shared.errors import InputError

__all__ = ["BenchInput", "scene_from_database", "load_bench_input", "pick_cells"]


@dataclass(frozen=True, slots=True)
class BenchInput:
    """What the benchmark runs on: a scene, its view cells, the view distance, a baked PVS."""

    scene: SourceScene
    cells: list[ViewCell]
    view_distance: float
    source: str
    baked: dict[int, I64] | None = None
    """Cell id -> PVS as stored in the database (None for a source file)."""
    settings: dict[str, Any] | None = None
    """The database's bake settings."""


def scene_from_database(path: str | os.PathLike[str]) -> tuple[SourceScene, list[ViewCell], dict[int, I64], dict[str, Any]]:
    """The scene, cells, stored PVS and bake settings of a scene database, from the file alone.

    Buildings, street pieces and typed areas (kind ``area``).
    """
    from walkstream.server.store import SceneReader

    with SceneReader.open(path) as reader:
        meta = reader.meta
        info = reader.object_info(reader.object_ids().tolist())
        buildings = tuple(reader.building(i) for i, o in info.items() if o.kind == "building")
        streets = tuple(
            reader.street(i) for i, o in info.items() if o.kind in ("street", "crossroad", "square")
        )
        areas = tuple(reader.area(i) for i, o in info.items() if o.kind == "area")
        cells, baked = [], {}
        for c in reader.cells():
            cells.append(
                ViewCell(c.id, c.kind, np.asarray(c.boundary), c.zmin, c.zmax, tuple(int(n) for n in c.neighbours))
            )
            baked[c.id] = np.asarray(c.pvs, np.int64)
    scene = SourceScene(meta.name, meta.crs, meta.origin, buildings, streets, areas=areas)
    return scene, cells, baked, meta.settings


def load_bench_input(path: str | os.PathLike[str], *, scene: SourceScene | None = None) -> BenchInput:
    """Scene and cells from a scene database, or from a source file.

    Parameters
    ----------
    path:
        A baked scene database (its objects, cells, stored PVS and view distance are
        used; any source it was baked from), or a city source file (GeoJSON,
        OpenStreetMap: any format :func:`~walkstream.server.sources.read.read_source`
        reads), or pass the loaded ``scene``.  A source gets
        ``make_cells(scene, "auto")`` and an 800 m view distance.
    scene:
        The scene of a source file read by the caller.

    Raises
    ------
    InputError
        When the file cannot be read as either.
    """
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: no such file")
    if scene is None:
        with p.open("rb") as f:
            is_db = f.read(16) == b"SQLite format 3\x00"
        if not is_db:
            from walkstream.server.sources.read import READERS, read_source

            if not any(p.name.lower().endswith(e) for e in READERS):
                raise InputError(
                    f"{p}: neither a scene database nor a scene source ({', '.join(sorted(READERS))})"
                )
            source = read_source(p)
            if not isinstance(source, SourceScene):
                raise InputError(f"{p}: an interior; bench visibility compares the PVS of city cells")
            scene = source
    if scene is not None:
        return BenchInput(scene, make_cells(scene, "auto"), 800.0, str(p))
    sc, cells, baked, settings = scene_from_database(p)
    return BenchInput(sc, cells, float(settings.get("view_distance", 800.0)), str(p), baked, settings)


def _morton(q: I64) -> I64:
    """Z-order keys of integer points ``(n, 2)`` in ``[0, 2**16)``."""
    key = np.zeros(len(q), np.int64)
    for bit in range(16):
        key |= ((q[:, 0] >> bit) & 1) << (2 * bit)
        key |= ((q[:, 1] >> bit) & 1) << (2 * bit + 1)
    return key


def pick_cells(cells: Sequence[ViewCell], sample: int, *, seed: int = 0) -> list[ViewCell]:
    """``sample`` cells spread over the scene, deterministically.

    Street cells (kind ``"street"``) are preferred when there are any, else every cell
    is a candidate.  The candidates are ordered along a Z-order curve of their
    centroids and cut into ``sample`` runs of equal length; one cell is drawn from each
    run (uniformly, with a generator seeded by ``seed``), so the sample covers the
    scene evenly without favouring its border.  Returned in cell-id order.
    """
    if int(sample) < 1:
        raise InputError(f"sample: expected >= 1 cells, got {sample}")
    cand = [c for c in cells if c.kind == "street"] or list(cells)
    if not cand:
        raise InputError("the scene has no view cells to benchmark")
    if len(cand) <= int(sample):
        return sorted(cand, key=lambda c: c.id)
    xy = np.array([c.centroid for c in cand], np.float64)
    lo = xy.min(axis=0)
    span = float(max((xy.max(axis=0) - lo).max(), 1e-9))
    q = np.clip((xy - lo) / span * 65535.0, 0, 65535).astype(np.int64)
    order = np.argsort(_morton(q), kind="stable")
    rng = np.random.default_rng(seed)
    edges = np.linspace(0, len(cand), int(sample) + 1).round().astype(np.int64)
    picks = [int(order[rng.integers(a, b)]) for a, b in zip(edges[:-1], edges[1:], strict=True)]
    return sorted((cand[i] for i in picks), key=lambda c: c.id)
