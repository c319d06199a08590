"""The bake's entry: read the sources, plan the scene by its kind, hand it to the one driver.

:func:`bake` reads a city (GeoJSON, OpenStreetMap), an interior (an IFC model, a
``walkstream-interior`` file) or both (a crossing scene, ``--interior``), turns it
into a :class:`~.plan.BakePlan` (:func:`city_plan` here,
:func:`~.interior.interior_plan`, :func:`~.crossing.crossing_plan`) and bakes it with
:func:`~.driver.drive`, which bakes the cells by their kind and resumes any of them.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import shapely

from walkstream.server.bake.cells import make_cells
from walkstream.server.bake.digest import file_digest
from walkstream.server.bake.driver import drive
from walkstream.server.bake.field import FIELD_HEIGHTS, PointSets
from walkstream.server.bake.fieldsampling import (
    cell_field_points,
    field_cell_pvs,
    sampling_lattice,
)
from walkstream.server.bake.impostorsettings import ImpostorSettings
from walkstream.server.bake.interior import interior_plan
from walkstream.server.bake.navgraph import CellGraph
from walkstream.server.bake.objectrows import object_rows
from walkstream.server.bake.plan import (
    BakePlan,
    FieldCells,
    ImpostorCells,
    PvsCells,
    RingCells,
    Say,
    Walk,
    settings_key,
)
from walkstream.server.bake.scenenav import SceneGraph
from walkstream.server.bake.settings import BakeSettings
from walkstream.server.bake.viewcell import ViewCell
from walkstream.server.bake.viewpoints import viewpoints
from walkstream.server.bake.walks import default_paths
from walkstream.server.bake.wallplan import WallSettings
from walkstream.server.sources.clip import clip_scene, local_bbox
from walkstream.server.sources.interior import InteriorScene
from walkstream.server.sources.read import read_source
from walkstream.server.sources.scene import SourceScene
from walkstream.server.store import CellRow, SceneWriter
from walkstream.shared.arrays import F64, I64
from walkstream.shared.buildings import default_grammar, default_grammar_text
from walkstream.shared.errors import InputError

__all__ = ["bake", "bake_interior", "city_plan"]


# ------------------------------------------------------------------ the bake


def bake(
    source: str | os.PathLike[str],
    output: str | os.PathLike[str],
    *,
    settings: BakeSettings | None = None,
    name: str | None = None,
    workers: int = 1,
    scheduler: str | None = None,
    progress: Callable[[int, int], None] | None = None,
    log: Callable[[str], None] | None = None,
    max_cells: int | None = None,
    interior: str | os.PathLike[str] | None = None,
    building: str | None = None,
    impostors: ImpostorSettings | None = None,
    walls: WallSettings | None = None,
    stage: Callable[[str, str], None] | None = None,
) -> dict[str, Any]:
    """Bake ``source`` (GeoJSON, OpenStreetMap, an IFC model or an interior file) into ``output``.

    The reader is chosen by the file's ending (:func:`~walkstream.server.sources.read.read_source`);
    the scene is planned by its kind (a city, an interior, with ``interior`` a crossing)
    and baked by the one driver (:func:`~walkstream.server.bake.driver.drive`).

    Parameters
    ----------
    source, output:
        Input GeoJSON file and the database to write (replaced atomically on success).
    settings:
        Cells, view distance, resolution, occluder LOD, ... (defaults: :class:`BakeSettings`).
    name:
        Scene name (default: the database file's stem).
    workers:
        Local processes rendering cells (each makes its own GL context).
    scheduler:
        ``tcp://HOST:PORT`` of a Dask distributed scheduler to send the cell tasks to.
    progress:
        Called with ``(done, total)`` as the running step's items finish.
    log:
        Called with one-line messages about the stages.
    stage:
        Called with ``(step, unit)`` as each step starts (what ``progress`` counts;
        :func:`~walkstream.server.bake.driver.drive`).
    max_cells:
        Stop after this many new cells without finishing the database (for tests of
        interruption and resume; the work file stays for the next run).
    interior, building:
        An interior to place in one of the city's buildings (an object or feature
        id, or ``auto``), joined to the street at its entrance: a crossing scene
        (:func:`~walkstream.server.bake.crossing.crossing_plan`).
    impostors:
        Bake impostor images of a city's far and complex buildings
        (:mod:`~walkstream.server.bake.impostorplan`; None: none, the database as
        before impostors existed).
    walls:
        Textured virtual walls across an interior's open rooms
        (:mod:`~walkstream.server.bake.wallplan`), or around a city's cells whose
        PVS is large (:mod:`~walkstream.server.bake.ringwalls`); None: none, the
        database as before.

    Returns
    -------
    dict
        The database summary (``SceneReader.summary``) plus ``resumed_cells``, what
        the scene kind's plan adds (``source``, ...) and, with rooms,
        ``contents_encode_s``; empty when ``max_cells`` stopped it early.
    """
    st = (settings or BakeSettings()).check()
    if impostors is not None:
        impostors.check()
    if workers < 1:
        raise InputError(f"--workers: expected >= 1, got {workers}")
    say = log or (lambda _msg: None)
    t0 = time.perf_counter()
    src = Path(source)
    if walls is not None:
        walls.check()
        if interior is not None:
            raise InputError("--virtual-walls: an interior's option; a crossing scene (--interior) has no walls yet")
    if impostors is not None and interior is not None:
        raise InputError("--impostors: a city's option; a scene with --interior has no impostors yet")
    if interior is not None:
        from walkstream.server.bake.crossing import crossing_plan

        plan = crossing_plan(src, Path(interior), Path(output), building=building, settings=st, name=name, say=say)
    else:
        scene = read_source(src, network=st.network)
        if isinstance(scene, InteriorScene):
            if impostors is not None:
                raise InputError(f"--impostors: {src.name} is an interior; impostors are a city's")
            plan = interior_plan(scene, src, output, name=name, say=say, import_seconds=time.perf_counter() - t0,
                                 walls=walls)
        else:
            plan = city_plan(scene, src, Path(output), st, name=name, say=say, impostors=impostors, walls=walls)
    return drive(plan, output, workers=workers, scheduler=scheduler, progress=progress, log=log,
                 max_cells=max_cells, started=t0, stage=stage)


def bake_interior(
    scene: InteriorScene,
    source: str | os.PathLike[str],
    output: str | os.PathLike[str],
    *,
    name: str | None = None,
    workers: int = 1,
    scheduler: str | None = None,
    progress: Callable[[int, int], None] | None = None,
    log: Callable[[str], None] | None = None,
    import_seconds: float = 0.0,
    cellmesh_version: int = 4,
) -> dict[str, Any]:
    """Bake an interior already read (``source`` its file) into ``output``: :func:`bake`
    with the contents codec ``cellmesh_version`` picked (3; 2 and 1 only to compare, as
    ``walkstream bench interiors`` does).

    Returns
    -------
    dict
        As :func:`bake`, with the summary of :func:`~.interior.interior_plan`.
    """
    t0 = time.perf_counter() - import_seconds
    plan = interior_plan(scene, source, output, name=name, say=log or (lambda _msg: None),
                         import_seconds=import_seconds, cellmesh_version=cellmesh_version)
    return drive(plan, output, workers=workers, scheduler=scheduler, progress=progress, log=log, started=t0)


def city_plan(
    scene: SourceScene,
    src: Path,
    out: Path,
    st: BakeSettings,
    *,
    name: str | None = None,
    say: Callable[[str], None] = lambda _msg: None,
    impostors: ImpostorSettings | None = None,
    walls: WallSettings | None = None,
) -> BakePlan:
    """The :class:`~.plan.BakePlan` of a city: its view cells (street or grid), PVS cells only;
    its default walks routed on the street part of its :class:`~.scenenav.SceneGraph`
    (sections: :func:`~.sectionplan.section_plan`); with ``impostors`` the images of its
    far and complex buildings too (:class:`~.plan.ImpostorCells`: the settings record
    gains the key ``impostors`` and the features ``impostors``, so a bake without them
    is unchanged).

    The plan's summary adds ``source``, ``source_issues`` (features skipped or repaired),
    ``source_skipped`` (skipped) and ``source_notes``.
    """
    for note in scene.notes:
        say(f"{src.name}: {note}")
    bbox = st.bbox
    if bbox is not None:
        bbox = local_bbox(scene, bbox, st.bbox_crs)
        scene = clip_scene(scene, bbox)
    if st.cells == "sections":
        from walkstream.server.bake.sectionplan import section_plan

        if impostors is not None:
            raise InputError(f"{src}: --impostors works with street or grid cells, not sections")

        return section_plan(scene, src, out, st, bbox=bbox, say=say, name=name, summary=_source_summary(scene, src))
    if st.cells == "auto" and not scene.streets:
        say(f"{src.name}: no street network (after filtering): grid cells")
    cells = make_cells(
        scene, st.cells, max_length=st.max_length, cell_size=st.cell_size, bbox=bbox
    )
    if not cells:
        raise InputError(f"{src}: no view cell could be made (no free space?)")
    kind = "grid" if cells[0].kind == "grid" else "street"
    features = ["buildings"] + (["streets"] if scene.streets else []) + [f"{kind}_cells"]
    areas = f", {len(scene.areas)} areas" if scene.areas else ""
    say(f"{src.name}: {len(scene.buildings)} buildings, {len(scene.streets)} street pieces{areas}, {len(cells)} {kind} cells")
    grammar = default_grammar()
    settings_dict = st.record() | {"source": str(src), "source_digest": file_digest(src)}
    if impostors is not None:
        settings_dict["impostors"] = impostors.record()
        features.append("impostors")
    if walls is not None:
        settings_dict["walls"] = walls.record_outdoors()
        features.append("walls")
    city = scene

    def write_tables(writer: SceneWriter) -> None:
        writer.add_objects(object_rows(city, grammar))
        writer.add_cells(
            CellRow(c.id, c.kind, np.asarray(c.polygon), c.zmin, c.zmax, np.asarray(c.neighbours, np.int64))
            for c in cells
        )
        for vp in viewpoints(cells, city):
            writer.add_viewpoint(vp.name, vp.x, vp.y, vp.z, vp.yaw, vp.cell)

    nav = SceneGraph(CellGraph(cells))

    def walks(say: Say) -> list[Walk]:
        return [(path, f"recorded path {path.name}: {path.duration:.0f} s, {path.length_m():.0f} m at "
                       f"{path.speed_kmh:g} km/h")
                for path in default_paths(cells, footprints=[b.rings[0] for b in city.buildings],
                                          graph=nav.streets, say=say)]

    summary = _source_summary(scene, src)
    imp = None
    if impostors is not None:
        rows = [r for r in object_rows(city, grammar) if r.kind == "building"]
        imp = ImpostorCells(city, impostors, {r.id: r.bbox for r in rows}, {r.id: r.tris[2] for r in rows},
                            settings_key(settings_dict))
    rings = None
    if walls is not None:
        rings = RingCells(city, walls, {r.id: r.bbox for r in object_rows(city, grammar)}, st.view_distance,
                          settings_key(settings_dict))
    pvs: PvsCells | None = PvsCells(scene, st, cells, settings_key(settings_dict))
    fc = None
    if st.sampling == "field":
        pvs, fc = None, _field_cells(scene, st, cells, settings_dict, summary, say)
    return BakePlan(
        name=name or out.stem, crs=scene.crs, origin=scene.origin, grammar_text=default_grammar_text(),
        grammar_version=grammar.id, features=features, settings=settings_dict,
        pvs=pvs, rooms=None, write_tables=write_tables,
        walks=walks, summary=summary, impostors=imp, field=fc, rings=rings,
    )


def _field_cells(
    scene: SourceScene, st: BakeSettings, cells: list[ViewCell], settings_dict: dict[str, Any],
    summary: dict[str, Any], say: Say,
) -> FieldCells:
    """Street or grid cells sampled from the dense field (``--sampling field``, :mod:`~.fieldsampling`)."""
    lattice = sampling_lattice(cells, [shapely.Polygon(b.rings[0], b.rings[1:]) for b in scene.buildings],
                               st.field_spacing, margin=st.margin)
    if len(lattice) == 0:
        raise InputError(f"--sampling field: no free field point in the {len(cells)} cells (no free space?)")
    # the field's folder: the cells' geometry and what each point renders decide it
    key = settings_key({k: v for k, v in settings_dict.items() if k not in ("threshold", "source")}
                       | {"field_heights": FIELD_HEIGHTS, "field": "cells"})
    say(f"sampling the {len(cells)} cells from a field of {len(lattice)} points every {st.field_spacing:g} m")

    def assign(sets: PointSets) -> list[tuple[int, I64, F64]]:
        res = field_cell_pvs(lattice, sets, cells, threshold=st.threshold)
        summary.update({"field_points": len(lattice), "field_bytes": sets.nbytes, "field_spacing": st.field_spacing,
                        "field_points_per_cell": float(np.mean([len(cell_field_points(lattice, np.asarray(c.polygon)))
                                                                for c in cells]))})
        return res

    return FieldCells(scene, st, lattice, key, assign, cells=cells)



def _source_summary(scene: SourceScene, src: Path) -> dict[str, Any]:
    summary: dict[str, Any] = {
        "source": str(src),
        "source_issues": len(scene.issues),
        "source_skipped": sum(1 for i in scene.issues if i.action == "skipped"),
    }
    if scene.notes:
        summary["source_notes"] = " | ".join(scene.notes)
    return summary
