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
(:func:`~.placement.moved`): the same cells and portals as the interior alone, in
the city's frame (locating the eye and the portal walk need them there).  Its
**contents** stay in the interior's own frame, as the interior alone stores them, and
the entrance's :class:`~walkstream.shared.scene.placement.ContentsPlacement` (the
``placements`` table, sent with ``GET .../entrances``) moves them into the city's
where the client decodes them.  Why: cellmesh/3's boxes and axis rectangles need faces
along the axes, so contents encoded after the turn lose them (the 16 x 14 m office of
the tests, turned 3.6 degrees: 67.8 kB placed against 27.3 kB in its own frame).  The
manifest lists the city's features plus ``rooms``, ``portals``, ``meshes`` and
``entrances``; its ``kind`` is ``crossing``.

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
A crossing is baked by the one driver (:func:`~.driver.drive`) like any scene:
:func:`crossing_plan` plans it (PVS cells for the city, room cells for the interior),
and an interrupted bake resumes like a city's, to the same version.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import shapely
from shapely.geometry.polygon import orient

from walkstream.server.bake.cells import make_cells
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
from walkstream.server.bake.placement import Placement, entrance_door, interior_shell, moved
from walkstream.server.bake.plan import BakePlan, PvsCells, RoomCells, Say, Walk, settings_key
from walkstream.server.bake.roomwalks import TOUR_NAME
from walkstream.server.bake.scenenav import ENTER_NAME, SceneGraph, front_of
from walkstream.server.bake.settings import BakeSettings
from walkstream.server.bake.siting import site_interior, street_cells
from walkstream.server.bake.viewpoints import viewpoints
from walkstream.server.bake.walks import default_paths
from walkstream.server.sources.clip import clip_scene, local_bbox
from walkstream.server.sources.interior import InteriorScene
from walkstream.server.sources.read import read_source
from walkstream.server.store import (
    CellRow,
    EntranceInfo,
    PortalInfo,
    SceneWriter,
)
from walkstream.shared.buildings import default_grammar, default_grammar_text
from walkstream.shared.errors import InputError
from walkstream.shared.records import BuildingParams
from walkstream.shared.scene.placement import ContentsPlacement

__all__ = [
    "CROSSING_FEATURE",
    "STAND_IN_INSET",
    "STAND_IN_PARAPET",
    "crossing_plan",
]

CROSSING_FEATURE = "entrances"
"""The feature a crossing scene lists (with the interior's ``rooms``, ``portals``, ``meshes``)."""
STAND_IN_INSET = 0.5
"""Metres the stand-in building's footprint lies inside the shell's plan."""
STAND_IN_PARAPET = 1.0
"""Metres the stand-in's eaves lie below the shell's top (the grammar's parapet)."""

def _contents_placement(p: Placement, cells: tuple[int, int]) -> ContentsPlacement:
    """The move of the interior's contents (cells ``cells[0] .. cells[1]``) into the city, as stored."""
    return ContentsPlacement(float(p.angle), (float(p.shift[0]), float(p.shift[1])), float(p.dz),
                             (int(cells[0]), int(cells[1])))


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


def crossing_plan(
    source: Path,
    interior_source: Path,
    output: Path,
    *,
    building: str | None = None,
    settings: BakeSettings | None = None,
    name: str | None = None,
    say: Say = lambda _msg: None,
) -> BakePlan:
    """The :class:`~.plan.BakePlan` of a city ``source`` with the interior ``interior_source``
    in one of its buildings: PVS cells (the city's) and room cells (the interior's).

    Arguments as for :func:`~.pipeline.bake`; ``building`` as for :func:`~.siting.site_interior`.
    The plan's summary adds ``source``, ``interior``, ``building``, ``entrance_gap_m``
    (door to street cell) and ``enter`` (the crossing walk).
    """
    st = (settings or BakeSettings()).check()
    src, isrc, out = Path(source), Path(interior_source), Path(output)
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
    # ---- the interior, planned in its own frame, then moved into its building
    local = interior_parts(inner, isrc, say=say)
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
    nav = SceneGraph(CellGraph(cells), baked.graph, [entrance])
    enter, room = nav.enter_walk(ENTER_NAME)
    # ---- the database
    features = (["buildings"] + (["streets"] if city.streets else []) + [f"{kind}_cells"]
                + list(INTERIOR_FEATURES) + [CROSSING_FEATURE])
    grammar = default_grammar()
    settings_dict = st.record() | {
        "source": str(src),
        "source_digest": file_digest(src),
        "interior": interior_settings(inner, isrc),
        "building": int(old.id),
        "placement": {"angle": placement.angle, "shift": list(placement.shift), "dz": placement.dz},
    }
    doorway = door.doorway + offset
    walk = baked.walk

    def write_tables(writer: SceneWriter) -> None:
        writer.add_objects(object_rows(city, grammar))
        writer.add_cells(
            CellRow(c.id, c.kind, np.asarray(c.polygon), c.zmin, c.zmax,
                    np.asarray(sorted(set(c.neighbours) | ({doorway} if c.id == street.id else set())), np.int64))
            for c in cells
        )
        for vp in viewpoints(cells, city):
            writer.add_viewpoint(vp.name, vp.x, vp.y, vp.z, vp.yaw, vp.cell)
        # the topology moved into the city; the contents stay in the interior's own frame
        # (the driver writes them unmoved) and the entrance says where they stand
        write_interior_tables(writer, inner, baked, offset=offset, links={doorway: [street.id]})
        outer = layout.portals[door.portal]
        writer.add_portals([PortalInfo(entrance.portal, street.id, doorway, outer.polygon, "door", "entrance", "entrance")])
        cells_in = (offset, offset + max(c.id for c in layout.cells))
        writer.add_entrances([EntranceInfo(entrance.portal, int(old.id), street.id, doorway, layout.outside + offset,
                                           _contents_placement(placement, cells_in))])
        x, y, z = walk.xyz[0]
        writer.add_viewpoint("entrance", float(x), float(y), float(z), float(walk.yaw[0]), baked.start + offset)

    def walks(say: Say) -> list[Walk]:
        out = [(path, f"recorded path {path.name}: {path.duration:.0f} s, {path.length_m():.0f} m at "
                      f"{path.speed_kmh:g} km/h")
               for path in default_paths(cells, footprints=[b.rings[0] for b in city.buildings], graph=nav.streets,
                                         say=say)]
        return out + [(walk, f"recorded path {TOUR_NAME}: {walk.duration:.0f} s, {walk.length_m():.0f} m"),
                      (enter, f"recorded path {ENTER_NAME}: {enter.duration:.0f} s, {enter.length_m():.0f} m, "
                              f"from the street to {room} and back")]

    return BakePlan(
        name=name or out.stem, crs=city.crs, origin=city.origin, grammar_text=default_grammar_text(),
        grammar_version=grammar.id, features=features, settings=settings_dict,
        pvs=PvsCells(city, st, cells, settings_key(settings_dict)),
        rooms=RoomCells(inner, local.layout, offset=offset), write_tables=write_tables, walks=walks,
        summary={
            "source": str(src), "interior": str(isrc), "building": int(old.id), "entrance_gap_m": round(gap, 3),
            "enter": {"seconds": round(enter.duration, 1), "metres": round(enter.length_m(), 1), "room": room},
        },
    )
