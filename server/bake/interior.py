"""An interior's part of a bake: cells and portals, each cell's contents, the tour, its tables.

:func:`interior_plan` plans an interior alone (an IFC model or a
``walkstream-interior`` file) for the one driver (:func:`~.driver.drive`); a
crossing scene (:mod:`~.crossing`) uses the same parts.  No visibility is baked:
the client culls through portals (Mulloni et al.), so what the database holds is the
paper's topological file (cells as plane sets with outline and height range, portals
as polygons with the two cells they join, triangles per cell) plus the contents of
every cell as one compact blob.

The contents of cells are independent tasks on plain arrays
(:func:`~.roomcontents.contents_task`), run by the one chunk runner
(:func:`~.chunks.run_chunks`: here, in ``workers`` local processes or on a Dask
cluster) from :func:`room_contents`; the driver alone writes the database.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import shapely

from walkstream.server.bake.chunks import run_chunks
from walkstream.server.bake.digest import file_digest
from walkstream.server.bake.floorroute import FloorObstacle
from walkstream.server.bake.outsidetiles import OUTSIDE_TILE_M, outside_parts
from walkstream.server.bake.plan import BakePlan, RoomCells
from walkstream.server.bake.roomcontents import REACH, Part, contents_task, outside_mask
from walkstream.server.bake.roomlayout import RoomLayout
from walkstream.server.bake.roomnav import RoomGraph
from walkstream.server.bake.rooms import room_layout
from walkstream.server.bake.roomwalks import TOUR_NAME, entrance_cell, tour
from walkstream.server.bake.scenenav import SceneGraph
from walkstream.server.bake.wallplan import WallSettings, plan_walls
from walkstream.server.sources.interior import InteriorScene
from walkstream.server.store import (
    CellRow,
    ContentsInfo,
    PortalInfo,
    RoomInfo,
    SceneWriter,
    StairInfo,
    StoreyInfo,
)
from walkstream.shared.codec.cellmesh import (
    CELLMESH_FORMAT,
    CELLMESH_V1,
    CELLMESH_V2,
    CELLMESH_V3,
    decode_cell_mesh,
    encode_cell_mesh,
    raw_bytes,
)
from walkstream.shared.codec.planarmesh import area_tolerance, grid_error, mesh_area
from walkstream.shared.errors import InputError, RouteError
from walkstream.shared.paths import RecordedPath

__all__ = [
    "CONTENTS_CHUNK",
    "INTERIOR_FEATURES",
    "InteriorParts",
    "STANDING",
    "floor_obstacles",
    "furniture_footprints",
    "interior_parts",
    "interior_plan",
    "interior_settings",
    "room_contents",
    "write_contents",
    "write_interior_tables",
]

INTERIOR_FEATURES = ("rooms", "portals", "meshes")
"""The features an interior lists (and the optional tables it gets)."""

CONTENTS_CHUNK = 16
"""Cells per contents task (plain numpy, quicker than a cell's PVS)."""


def room_contents(
    scene: InteriorScene,
    layout: RoomLayout,
    *,
    workers: int = 1,
    scheduler: str | None = None,
    progress: Callable[[int, int], None] | None = None,
    outside_tile: float = OUTSIDE_TILE_M,
) -> dict[int, list[Part]]:
    """Every cell's contents (:mod:`~.roomcontents`): the element triangles clipped to
    each room and doorway in chunks by the one chunk runner (:func:`~.chunks.run_chunks`),
    and what no cell holds whole to the ``outside`` cell, its long groups cut into
    columns of ``outside_tile`` metres (:mod:`~.outsidetiles`; 0: one part per element
    and material)."""
    inside = [c for c in layout.cells if c.kind != "outside"]
    soup = np.concatenate([e.soup for e in scene.elements]) if scene.elements else np.zeros((0, 3, 3))
    elem = np.concatenate([np.full(len(e.triangles), e.id, np.int64) for e in scene.elements]) if scene.elements else np.zeros(0, np.int64)
    mat = np.concatenate([e.materials.astype(np.int64) for e in scene.elements]) if scene.elements else np.zeros(0, np.int64)
    parts: dict[int, list[Part]] = {}
    held = np.zeros(len(soup), bool)
    for res in run_chunks(
        contents_task, [(c.id, c.planes) for c in inside], (soup, elem, mat), size=CONTENTS_CHUNK,
        workers=workers, scheduler=scheduler, progress=progress, total=len(layout.cells),
    ):
        for cid, ps, whole in res:
            parts[cid] = ps
            held[whole] = True
    om = outside_mask(soup, [(c.outline, c.zmin, c.zmax) for c in inside], held)
    # cut into columns (:mod:`~.outsidetiles`): a long facade per column, each culled by its own box
    parts[layout.outside] = outside_parts(soup[om], elem[om], mat[om], outside_tile)
    if progress:
        progress(len(layout.cells), len(layout.cells))
    return parts


@dataclass
class InteriorParts:
    """What an interior bake plans before it writes: the cells and portals, the walking
    graph and the tour (see :func:`interior_parts`); ``parts`` (each cell's contents)
    stays empty until the driver clips them (:func:`room_contents`)."""

    layout: RoomLayout
    parts: dict[int, list[Part]]
    notes: list[str]
    graph: RoomGraph
    start: int
    walk: RecordedPath
    coverage: dict[str, Any]


def interior_parts(
    scene: InteriorScene, src: Path, *, say: Callable[[str], None] = lambda _msg: None,
    wall_pitch: float | None = None,
) -> InteriorParts:
    """Cells, portals, walking graph and tour of an interior (its plan; the contents are
    the driver's, :func:`room_contents`); ``wall_pitch`` cuts open rooms by virtual walls
    (:func:`~.rooms.room_layout`)."""
    layout = room_layout(scene, wall_pitch)
    inside = [c for c in layout.cells if c.kind != "outside"]
    say(
        f"{src.name}: {len(scene.rooms)} rooms on {len(scene.storeys)} storeys -> {len(inside)} cells "
        f"({sum(1 for c in inside if c.kind == 'doorway')} doorways), {len(layout.portals)} portals, "
        f"{len(layout.stairs)} stairs, {scene.triangles:,} triangles"
    )
    notes = list(scene.notes) + layout.notes
    for n in notes:
        say(f"note: {n}")
    # ---- the tour
    obstacles = floor_obstacles(scene)
    graph = SceneGraph(rooms=RoomGraph(layout.cells, layout.portals, layout.stairs, obstacles)).rooms
    start = entrance_cell(layout.cells, layout.portals)
    try:
        walk, coverage = tour(graph, start, obstacles=[o.footprint for o in obstacles])
    except RouteError as exc:  # pragma: no cover - a tour always exists from a room cell
        raise InputError(f"{src}: no tour could be recorded ({exc})") from exc
    return InteriorParts(layout, {}, notes, graph, start, walk, coverage)


STANDING = frozenset({"furniture", "column", "door", "stair", "railing"})
"""Element kinds a walk goes around (walls and slabs bound the cells themselves).  A door's
leaf swung open stands in the room it opens into (its frame lies in the wall: grown by
the clearance it reaches no farther than the wall's own); a stair and its railings fill
the floor under them, where a walker has no headroom, and on the storey above they stand
in the slab's hole: a walk keeps its clearance from them on both (the stair's own walk
is its walking line)."""


_ARRIVAL = 0.1
"""How far (metres) above its top a stair counts as standing: its top is the floor it
climbs to, where its footprint is the opening it comes up through."""


def floor_obstacles(scene: InteriorScene, below: float = 2.0, kinds: frozenset[str] = STANDING) -> list[FloorObstacle]:
    """What stands on a floor and is walked around: elements of ``kinds``
    (:data:`STANDING`) whose bottom is within ``below`` metres above a storey's floor, as
    footprints (convex hulls, scene-local) with their height range."""
    floors = np.array([s.elevation for s in scene.storeys], np.float64)
    out = []
    for e in scene.elements:
        if e.kind not in kinds or len(e.vertices) == 0:
            continue
        z0, z1 = float(e.vertices[:, 2].min()), float(e.vertices[:, 2].max())
        if len(floors) and float(np.min(np.abs(z0 - floors))) > below:
            continue
        if e.kind == "stair":
            z1 += _ARRIVAL  # the stair's opening in the floor it climbs to
        out.append(FloorObstacle(shapely.MultiPoint(np.asarray(e.vertices[:, :2], np.float64)).convex_hull, z0, z1))
    return out


def furniture_footprints(scene: InteriorScene, below: float = 2.0) -> list[shapely.Geometry]:
    """The footprints of :func:`floor_obstacles`: what a walk across a lone room keeps
    clear of."""
    return [o.footprint for o in floor_obstacles(scene, below)]


def interior_settings(scene: InteriorScene, src: Path, cellmesh_version: int = 4) -> dict[str, Any]:
    """The bake settings an interior records (what identifies its input and codec)."""
    return {
        "source": str(src),
        "source_digest": file_digest(src),
        "source_format": scene.source_format,
        "reach": REACH,
        "cellmesh": {1: CELLMESH_V1, 2: CELLMESH_V2, 3: CELLMESH_V3}.get(cellmesh_version, CELLMESH_FORMAT),
        "origin_z": scene.origin[2],
    }


def write_interior_tables(
    writer: SceneWriter,
    scene: InteriorScene,
    baked: InteriorParts,
    *,
    offset: int = 0,
    links: dict[int, list[int]] | None = None,
) -> None:
    """Write an interior's cells, storeys, rooms, portals and stairs (the contents are
    :func:`write_contents`'s).

    ``offset`` is added to every cell id (an interior placed in a scene after its
    city cells); ``links`` adds neighbours from outside the interior (cell id with
    the offset -> ids of other cells: the street cell an entrance joins).  Portal,
    stair and storey ids are the interior's own.
    """
    layout = baked.layout
    neighbours: dict[int, set[int]] = {c.id + offset: set() for c in layout.cells}
    for p in layout.portals:
        neighbours[p.a + offset].add(p.b + offset)
        neighbours[p.b + offset].add(p.a + offset)
    for cid, others in (links or {}).items():
        neighbours[cid].update(others)
    writer.add_cells(
        CellRow(c.id + offset, c.kind, c.outline, c.zmin, c.zmax, np.array(sorted(neighbours[c.id + offset]), np.int64))
        for c in layout.cells
    )
    writer.add_storeys(
        StoreyInfo(k, s.name, float(layout.ranges[k][0]), float(layout.ranges[k][1]))
        for k, s in enumerate(scene.storeys)
    )
    writer.add_rooms(RoomInfo(c.id + offset, c.name, c.room, c.storey, c.planes) for c in layout.cells)
    writer.add_portals(
        PortalInfo(p.id, p.a + offset, p.b + offset, p.polygon, p.kind, p.source, p.name) for p in layout.portals
    )
    writer.add_stairs(
        StairInfo(k, s.portal, s.lower + offset, s.upper + offset, s.path, s.name) for k, s in enumerate(layout.stairs)
    )


def write_contents(
    writer: SceneWriter, layout: RoomLayout, parts: dict[int, list[Part]], *, offset: int = 0,
    cellmesh_version: int = 4,
) -> float:
    """Encode and write every cell's contents (ids plus ``offset``), then mark the cells
    done (a room cell has no PVS: once its contents are stored it is baked).  Returns
    the seconds spent encoding.

    Raises
    ------
    InputError
        A part's area changed in encoding.
    """
    encode_s = 0.0
    for c in layout.cells:
        ps = [p for p in parts.get(c.id, []) if len(p[3])]
        t_enc = time.perf_counter()
        blob = encode_cell_mesh(ps, version=cellmesh_version)
        encode_s += time.perf_counter() - t_enc
        nv = nt = 0
        # the error as measured (the grid's rounding of what was encoded), not the bound;
        # the decoded surface must keep each part's area (the codec's merging checks it too)
        err = 0.0
        if ps:
            back = decode_cell_mesh(blob, f"cell {c.id}")
            nv, nt = back.vertices, back.triangles
            err = max(grid_error(part[2]) for part in ps)
            for q, part in zip(back.parts, ps, strict=True):
                a0, a1 = mesh_area(part[2], part[3]), mesh_area(q.positions, q.indices)
                if abs(a1 - a0) > area_tolerance(part[2], part[3]):
                    raise InputError(f"cell {c.id}: element {part[0]}: area {a1} m2 after encoding, {a0} m2 before")
        writer.add_contents(ContentsInfo(nt, nv, len(ps), len(blob), raw_bytes(nv, nt), err, cell=c.id + offset), blob)
    for c in layout.cells:
        writer.set_pvs(c.id + offset, np.zeros(0, np.int64), np.zeros(0))
    return encode_s


def interior_plan(
    scene: InteriorScene,
    source: str | os.PathLike[str],
    output: str | os.PathLike[str],
    *,
    name: str | None = None,
    say: Callable[[str], None] = lambda _msg: None,
    import_seconds: float = 0.0,
    cellmesh_version: int = 4,
    walls: WallSettings | None = None,
) -> BakePlan:
    """The :class:`~.plan.BakePlan` of an interior alone: room cells only.

    ``walls`` (``--virtual-walls``) cuts open rooms by textured virtual walls
    (:mod:`~.wallplan`): the ``walls`` feature, its settings recorded.

    ``cellmesh_version`` picks the cell-contents codec (3, planar polygons, boxes and
    rectangles on a 1 mm grid; 2 and 1 only to compare, as ``walkstream bench interiors`` does).
    The plan's summary adds ``source``, ``import_seconds``, ``notes`` (what the bake
    wants the user to know, e.g. portals found from the geometry), ``portal_sources``,
    ``issues`` and ``tour`` (what the default walk covers).
    """
    src, out = Path(source), Path(output)
    baked = interior_parts(scene, src, say=say, wall_pitch=None if walls is None else walls.pitch)
    layout, walk, coverage, start = baked.layout, baked.walk, baked.coverage, baked.start
    settings = interior_settings(scene, src, cellmesh_version)
    features = list(INTERIOR_FEATURES)
    wall_plan = None
    if walls is not None:
        settings["walls"] = walls.record()
        features.append("walls")
        wall_plan = plan_walls(scene, layout, walls)

    def write_tables(writer: SceneWriter) -> None:
        write_interior_tables(writer, scene, baked)
        x, y, z = walk.xyz[0]
        writer.add_viewpoint("entrance", float(x), float(y), float(z), float(walk.yaw[0]), start)

    def walks(_say: Callable[[str], None]) -> list[tuple[RecordedPath, str]]:
        return [(walk, (
            f"recorded path {TOUR_NAME}: {walk.duration:.0f} s, {walk.length_m():.0f} m; passes "
            f"{coverage['visited']} of {coverage['reachable']} reachable rooms ({coverage['rooms']} in all) on "
            f"{coverage['storeys_visited']} of {coverage['storeys_reachable']} storeys"
        ))]

    return BakePlan(
        name=name or out.stem, crs=scene.crs, origin=(scene.origin[0], scene.origin[1]), grammar_text="",
        grammar_version="", features=features, settings=settings, pvs=None,
        rooms=RoomCells(scene, layout, cellmesh_version=cellmesh_version, walls=walls, wall_plan=wall_plan),
        write_tables=write_tables, walks=walks,
        summary={
            "source": str(src),
            "import_seconds": import_seconds,
            "notes": baked.notes,
            "portal_sources": dict(layout.sources),
            "issues": [f"{i.feature_id}: {i.problem} ({i.action})" for i in scene.issues],
            "tour": coverage,
        },
    )
