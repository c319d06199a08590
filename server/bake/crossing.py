"""The bake of a crossing scene: a city and a building's interior in one database, joined at its entrance.

``walkstream bake city.geojson -o scene.db --interior office.json [--building ID|auto]``.
The interior is placed in the building's footprint with its entrance door on the
facade that faces the nearest street cell (:mod:`~.siting` says which building, which
door and what fits; :mod:`~.placement` how it is turned and moved; a door set back from
the street gets a front path cell, :mod:`~.frontpath`); a portal of kind ``door``
(source ``entrance``) joins that street cell to the door's doorway cell, and the
``entrances`` table records it.

One id space: the city's cells keep their ids ``0 .. n-1`` (the same cells, PVS
and ACH as the city alone would get), the interior's cells follow from ``n`` (rooms,
doorways and the interior's ``outside``) with their portals, rooms, stairs and
contents.  The interior is cut into cells in its own frame and moved whole
(:func:`~.placement.moved`): the same cells and portals as the interior alone.  Its
contents are encoded in the city's frame; cellmesh/3's boxes and axis rectangles need
faces along the axes, so a turned interior's contents are larger (the 16 x 14 m
office of the tests turned 3.6 degrees: 27.3 kB alone, 67.8 kB placed).  The manifest lists the city's features plus ``rooms``, ``portals``,
``meshes`` and ``entrances``; its ``kind`` is ``crossing``.

**What stands for the building from the street.**  The interior's own outer shell:
the contents of its ``outside`` cell (its outer walls with the entrance's real hole
and its windows, the roof), drawn wherever a street cell's PVS holds the building's
object id (the ``entrances`` table: ``building`` is drawn as cell ``shell``).  Why:

- *No double-drawn walls.*  The grammar's building and the interior's walls would
  stand in the same place, both drawn, fighting in depth.  Only the shell is drawn.
- *No hole where the facade meets the door.*  The grammar's facade knows nothing of
  the door; the shell is cut from the same model as the doorway cell, so the hole in
  the outer wall is exactly the portal the walk passes.
- *The PVS stays right.*  The building's object is kept under its id (the street
  cells' PVS name it, the client asks for it as before), but its parameters become a
  stand-in: the shell's plan shrunk by :data:`STAND_IN_INSET` (the grammar's ledges
  reach that far out) and its height less :data:`STAND_IN_PARAPET` (the grammar's
  parapet), so the occluder the PVS is rendered with lies inside the shell and
  hides nothing the shell would not: the PVS stays conservative.
- *Seen from inside*, the street is what the entrance portal leads to: the client's
  visible set switches model at the door (portals indoors, the street cell's PVS
  outdoors).

A party wall the building shared keeps the neighbour's blank side, and the shell's
windows face it: what the data says of the building is replaced by the interior.
Resuming an interrupted crossing bake is not offered: it starts over.
"""

from __future__ import annotations

import hashlib
import math
import os
import time
from collections.abc import Callable
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any

import numpy as np
import shapely
from shapely.geometry.polygon import orient

from walkstream.server.bake.cells import make_cells
from walkstream.server.bake.crossnav import ENTER_NAME, SceneGraph, front_of
from walkstream.server.bake.digest import file_digest
from walkstream.server.bake.frontpath import with_front_path
from walkstream.server.bake.interior import (
    INTERIOR_FEATURES,
    interior_parts,
    interior_settings,
    write_interior_tables,
)
from walkstream.server.bake.navgraph import CellGraph
from walkstream.server.bake.objectrows import object_rows
from walkstream.server.bake.placement import entrance_door, interior_shell, moved
from walkstream.server.bake.roomwalks import TOUR_NAME
from walkstream.server.bake.settings import BakeSettings
from walkstream.server.bake.siting import site_interior, street_cells
from walkstream.server.bake.viewpoints import viewpoints
from walkstream.server.bake.walks import default_paths
from walkstream.server.bake.workers import run_tasks
from walkstream.server.sources.clip import clip_scene, local_bbox
from walkstream.server.sources.interior import InteriorScene
from walkstream.server.sources.read import read_source
from walkstream.server.store import (
    CellRow,
    EntranceInfo,
    PortalInfo,
    SceneReader,
    SceneWriter,
)
from walkstream.shared.buildings import default_grammar, default_grammar_text
from walkstream.shared.errors import InputError
from walkstream.shared.records import BuildingParams

__all__ = [
    "CROSSING_FEATURE",
    "STAND_IN_INSET",
    "STAND_IN_PARAPET",
    "bake_crossing",
]

CROSSING_FEATURE = "entrances"
"""The feature a crossing scene lists (with the interior's ``rooms``, ``portals``, ``meshes``)."""
STAND_IN_INSET = 0.5
"""Metres the stand-in building's footprint lies inside the shell's plan."""
STAND_IN_PARAPET = 1.0
"""Metres the stand-in's eaves lie below the shell's top (the grammar's parapet)."""

def _stand_in(b: BuildingParams, shell: shapely.Geometry, top: float) -> BuildingParams:
    inner = shapely.buffer(shell, -STAND_IN_INSET, join_style="mitre")
    parts = [g for g in shapely.get_parts(inner) if isinstance(g, shapely.Polygon) and not g.is_empty]
    if not parts:
        raise InputError(f"building {b.id}: the interior's shell is too thin for a stand-in")
    poly = orient(max(parts, key=lambda g: g.area).simplify(0.01), 1.0)
    pts = np.asarray(poly.exterior.coords)[:-1]
    floors = max(1, b.floors)
    height = max(top - STAND_IN_PARAPET, 1.0)
    return replace(b, rings=(pts,), neighbour_heights=(np.zeros(len(pts)),), floors=floors,
                   floor_height=height / floors)


def bake_crossing(
    source: str | os.PathLike[str],
    interior_source: str | os.PathLike[str],
    output: str | os.PathLike[str],
    *,
    building: str | None = None,
    settings: BakeSettings | None = None,
    name: str | None = None,
    workers: int = 1,
    scheduler: str | None = None,
    progress: Callable[[int, int], None] | None = None,
    log: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Bake a city ``source`` with the interior ``interior_source`` in one of its buildings.

    Arguments as for :func:`~.pipeline.bake`; ``building`` as for :func:`~.siting.site_interior`.

    Returns
    -------
    dict
        The database summary plus ``source``, ``interior``, ``building``,
        ``entrance_gap_m`` (door to street cell) and ``enter`` (the crossing walk).
    """
    st = (settings or BakeSettings()).check()
    if workers < 1:
        raise InputError(f"--workers: expected >= 1, got {workers}")
    src, isrc, out = Path(source), Path(interior_source), Path(output)
    say = log or (lambda _msg: None)
    t0 = time.perf_counter()
    city = read_source(src, network=st.network)
    if isinstance(city, InteriorScene):
        raise InputError(f"{src}: an interior; the first source of a crossing scene is a city")
    inner = read_source(isrc, network=st.network)
    if not isinstance(inner, InteriorScene):
        raise InputError(f"--interior {isrc}: not an interior (an IFC model or a walkstream-interior file)")
    bbox = None if st.bbox is None else local_bbox(city, st.bbox, st.bbox_crs)
    if bbox is not None:
        city = clip_scene(city, bbox)
    cells = make_cells(city, st.cells, max_length=st.max_length, cell_size=st.cell_size, bbox=bbox)
    if not cells:
        raise InputError(f"{src}: no view cell could be made (no free space?)")
    kind = "grid" if cells[0].kind == "grid" else "street"
    # ---- the interior, baked in its own frame, then moved into its building
    local = interior_parts(inner, isrc, workers=workers, scheduler=scheduler, say=say)
    siting = site_interior(city, cells, inner, building, layout=local.layout)
    k, placement, gap = siting.index, siting.placement, siting.fit.gap
    old = city.buildings[k]
    baked = moved(local, placement)
    layout = baked.layout
    shell = shapely.Polygon(placement.xy(np.asarray(interior_shell(inner).exterior.coords)))
    top = max(float(e.vertices[:, 2].max()) for e in inner.elements if len(e.vertices)) + placement.dz
    stand_in = _stand_in(old, shell, top)
    city = replace(city, buildings=tuple(stand_in if i == k else b for i, b in enumerate(city.buildings)))
    say(f"{isrc.name} placed in building {old.id} ({old.source_id}): turned {math.degrees(placement.angle):.1f} deg, "
        f"its entrance {gap:.2f} m from the street (match {siting.fit.match:.2f})")
    door = entrance_door(layout, siting.door.portal)
    if siting.path is not None:  # a front path from the street to the door (server/bake/frontpath.py)
        cells = with_front_path(cells, siting.path, door.middle + door.normal * 0.1)
    offset = len(cells)
    streets, polys = street_cells(cells)
    tree = shapely.STRtree(polys)
    front_pt = shapely.Point(door.middle + door.normal * 0.1)
    street = streets[int(tree.query_nearest(front_pt)[0])]
    floor = float(layout.cells[door.doorway].zmin)
    entrance = front_of(shapely.Polygon(street.polygon), door.middle, door.normal, floor, len(layout.portals),
                        street.id, door.doorway)
    # ---- the walks
    city_graph = CellGraph(cells)
    scene_graph = SceneGraph(city_graph, baked.graph, [entrance])
    enter, room = scene_graph.enter_walk(ENTER_NAME)
    # ---- the database
    features = (["buildings"] + (["streets"] if city.streets else []) + [f"{kind}_cells"]
                + list(INTERIOR_FEATURES) + [CROSSING_FEATURE])
    grammar = default_grammar()
    settings_dict = asdict(st) | {
        "source": str(src),
        "source_digest": file_digest(src),
        "interior": interior_settings(inner, isrc),
        "building": int(old.id),
        "placement": {"angle": placement.angle, "shift": list(placement.shift), "dz": placement.dz},
    }
    writer = SceneWriter.create(
        out, name=name or out.stem, crs=city.crs, origin=city.origin, grammar_text=default_grammar_text(),
        grammar_version=grammar.id, features=features, settings=settings_dict, resume=False,
    )
    try:
        writer.add_objects(object_rows(city, grammar))
        doorway = door.doorway + offset
        writer.add_cells(
            CellRow(c.id, c.kind, np.asarray(c.polygon), c.zmin, c.zmax,
                    np.asarray(sorted(set(c.neighbours) | ({doorway} if c.id == street.id else set())), np.int64))
            for c in cells
        )
        for vp in viewpoints(cells, city):
            writer.add_viewpoint(vp.name, vp.x, vp.y, vp.z, vp.yaw, vp.cell)
        encode_s = write_interior_tables(writer, inner, baked, offset=offset, links={doorway: [street.id]})
        outer = layout.portals[door.portal]
        writer.add_portals([PortalInfo(entrance.portal, street.id, doorway, outer.polygon, "door", "entrance", "entrance")])
        writer.add_entrances([EntranceInfo(entrance.portal, int(old.id), street.id, doorway, layout.outside + offset)])
        key = hashlib.sha256(repr(sorted(settings_dict.items())).encode()).hexdigest()[:16]
        finished = 0
        if progress:
            progress(0, len(cells))
        for results in run_tasks(city, st, key, cells, workers, scheduler):
            for cid, pvs, ach in results:
                writer.set_pvs(cid, pvs, ach)
                finished += 1
            if progress:
                progress(finished, len(cells))
        for path in default_paths(cells, footprints=[b.rings[0] for b in city.buildings], graph=city_graph, say=say):
            writer.add_path(path.name, path.to_msgpack())
            say(f"recorded path {path.name}: {path.duration:.0f} s, {path.length_m():.0f} m at {path.speed_kmh:g} km/h")
        walk = baked.walk
        x, y, z = walk.xyz[0]
        writer.add_viewpoint("entrance", float(x), float(y), float(z), float(walk.yaw[0]), baked.start + offset)
        writer.add_path(TOUR_NAME, walk.to_msgpack())
        writer.add_path(ENTER_NAME, enter.to_msgpack())
        say(f"recorded path {ENTER_NAME}: {enter.duration:.0f} s, {enter.length_m():.0f} m, from the street to {room} and back")
        writer.finish(time.perf_counter() - t0)
    finally:
        writer.close()
    with SceneReader.open(out) as reader:
        summary = reader.summary()
    summary.update({
        "source": str(src), "interior": str(isrc), "building": int(old.id), "entrance_gap_m": round(gap, 3),
        "enter": {"seconds": round(enter.duration, 1), "metres": round(enter.length_m(), 1), "room": room},
        "contents_encode_s": encode_s, "resumed_cells": 0,
    })
    return summary
