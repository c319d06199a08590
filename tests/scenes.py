"""Small scene databases for server tests, built without the real bake.

A generated city (:func:`~walkstream.server.sources.citygen.generate_city`) is loaded, cut into
view cells, and given made-up PVS lists (the ``k`` objects nearest to each cell's
centroid, with equal ACH), so tests get a real-shaped database in well under a
second.  Import from test modules: ``from scenes import build_city_db``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from walkstream.server.bake.cells import make_cells
from walkstream.server.sources.citygen import generate_city
from walkstream.server.sources.geojson import load_geojson_dict
from walkstream.server.sources.scene import SourceScene
from walkstream.server.store import CellRow, ObjectRow, SceneWriter
from walkstream.shared.buildings import default_grammar_text
from walkstream.shared.lsystem.grammar import parse_grammar
from walkstream.shared.paths import RecordedPath

__all__ = ["CityDb", "build_city_db", "add_default_paths", "PATH_NAME", "PATH", "PATH_DATA"]

PATH_NAME = "tour/1"
"""The name of the recorded path every test database holds (with a slash on purpose)."""

PATH = RecordedPath(
    PATH_NAME,
    t=np.array([0.0, 0.5, 1.0]),
    xyz=np.array([[0.0, 0.0, 1.75], [1.0, 0.0, 1.75], [2.0, 0.5, 1.75]]),
    yaw=np.array([0.0, 0.0, 0.25]),
    pitch=np.zeros(3),
    speed_kmh=7.5,
)
"""That path (a ``walkstream-path`` of :mod:`walkstream.shared.paths`; every number is exact in
float32, so the stored blob unpacks to exactly :data:`PATH_DATA`)."""

PATH_DATA = PATH.to_dict()
"""What that path's stored msgpack unpacks to."""


@dataclass(frozen=True)
class CityDb:
    """A baked test scene: its file, name, version and what was put into it."""

    path: Path
    name: str
    version: str
    object_ids: tuple[int, ...]
    pvs: dict[int, tuple[int, ...]]
    centroids: dict[int, tuple[float, float]]


@lru_cache(maxsize=4)
def _source(size: float, seed: int) -> SourceScene:
    return load_geojson_dict(generate_city(size, seed), name="city")


def build_city_db(
    path: Path,
    *,
    name: str = "tiny",
    size: float = 200.0,
    seed: int = 1,
    k: int = 20,
    drop: dict[int, set[int]] | None = None,
) -> CityDb:
    """Bake a small generated city into ``path`` with made-up PVS lists.

    Parameters
    ----------
    path:
        The database file to write.
    name:
        Scene name.
    size, seed:
        Passed to :func:`~walkstream.server.sources.citygen.generate_city`.
    k:
        PVS size: each cell sees the ``k`` objects nearest to its centroid.
    drop:
        Cell id -> objects left out of that cell's PVS (a planted miss).
    """
    scene = _source(size, seed)
    cells = make_cells(scene)
    rows = [ObjectRow.of(b, tris=(12, 40, 300)) for b in scene.buildings] + [
        ObjectRow.of(s, tris=(2, 2, 2)) for s in scene.streets
    ]
    ids = np.array([r.id for r in rows], dtype=np.int64)
    centres = np.array([[(r.bbox[0] + r.bbox[3]) / 2, (r.bbox[1] + r.bbox[4]) / 2] for r in rows])
    text = default_grammar_text()
    pvs: dict[int, tuple[int, ...]] = {}
    with SceneWriter.create(
        path,
        name=name,
        crs=scene.crs,
        origin=scene.origin,
        grammar_text=text,
        grammar_version=parse_grammar(text).id,
        features=["street_cells"],
        settings={"source": "citygen", "size": size, "seed": seed, "k": k},
    ) as w:
        w.add_objects(rows)
        w.add_cells(
            CellRow(c.id, c.kind, c.polygon, c.zmin, c.zmax, np.array(c.neighbours, dtype=np.int64))
            for c in cells
        )
        for c in cells:
            d = np.hypot(*(centres - np.array(c.centroid)).T)
            near = ids[np.argsort(d, kind="stable")[:k]]
            near = near[~np.isin(near, sorted((drop or {}).get(c.id, set())))]
            w.set_pvs(c.id, near, np.ones(len(near)))
            pvs[c.id] = tuple(sorted(int(i) for i in near))
        first = cells[0]
        w.add_viewpoint("start", *first.centroid, 1.7, 0.0, cell=first.id)
        w.add_path(PATH_NAME, PATH.to_msgpack())
        version = w.finish(0.5)
    return CityDb(
        path=path,
        name=name,
        version=version,
        object_ids=tuple(int(i) for i in ids),
        pvs=pvs,
        centroids={c.id: c.centroid for c in cells},
    )


def add_default_paths(db: Path) -> None:
    """Record the bake's default paths (``SE``, ``SM``, ``drive``) into a test database."""
    from walkstream.server.bake.walks import default_paths
    from walkstream.server.store import SceneReader, write_path

    r = SceneReader.open(db)
    try:
        cells = list(r.cells())
    finally:
        r.close()
    for p in default_paths(cells):
        write_path(db, p.name, p.to_msgpack())
