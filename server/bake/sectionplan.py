"""The plan of a city baked into sections (``walkstream bake --cells sections``).

The cells are grown by the driver once the dense visibility field is rendered
(:class:`~.plan.FieldCells`: :mod:`.field`, then :mod:`.sections`); what does not
depend on them is planned here.  The default walks and the start viewpoints are
those of the partition the city would get otherwise (street cells where it has
streets, else grid cells), so a walk on sections is the same walk as on street or
grid cells, and the two bakes compare on equal terms; each viewpoint is then put in
the section holding it.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import shapely

from walkstream.server.bake.cells import make_cells
from walkstream.server.bake.digest import file_digest
from walkstream.server.bake.field import FIELD_HEIGHTS, PointSets, field_lattice, points_meeting
from walkstream.server.bake.navgraph import CellGraph
from walkstream.server.bake.objectrows import object_rows
from walkstream.server.bake.plan import BakePlan, FieldCells, Say, Walk, settings_key
from walkstream.server.bake.scenenav import SceneGraph
from walkstream.server.bake.sections import grow_sections, section_pvs, section_stats
from walkstream.server.bake.sectionsize import sections_for_area
from walkstream.server.bake.settings import BakeSettings
from walkstream.server.bake.viewcell import ViewCell, cell_locator, finish_cells
from walkstream.server.bake.viewpoints import viewpoints
from walkstream.server.bake.walks import default_paths
from walkstream.server.sources.scene import SourceScene
from walkstream.server.store import CellRow, SceneWriter
from walkstream.shared.arrays import F64, I64
from walkstream.shared.buildings import default_grammar, default_grammar_text
from walkstream.shared.errors import InputError

__all__ = ["EYE_HEIGHTS", "HEIGHT_RANGE", "section_plan", "street_angle"]

HEIGHT_RANGE = (1.5, 2.0)
"""Eye heights a section's PVS is valid for (as street and grid cells)."""

EYE_HEIGHTS = FIELD_HEIGHTS
"""The heights every field point is rendered at: the eye height and the top of the range."""


def section_plan(
    scene: SourceScene,
    src: Path,
    out: Path,
    st: BakeSettings,
    *,
    bbox: tuple[float, float, float, float] | None,
    say: Callable[[str], None],
    name: str | None = None,
    summary: dict[str, Any],
) -> BakePlan:
    """The :class:`~.plan.BakePlan` of ``scene`` (already clipped to ``bbox``) in sections.

    ``summary`` (the source's figures) gets the field's and the sections' figures
    (``field_points``, ``field_bytes``, ``field_spacing``, ``sections``,
    ``section_pvs_mean``, ``section_redundancy_mean``, ...) once they are grown.
    """
    base = make_cells(scene, "auto", max_length=st.max_length, cell_size=st.cell_size, bbox=bbox)
    if not base:
        raise InputError(f"{src}: no view cell could be made (no free space?)")
    angle = street_angle(scene) if st.section_shape == "aligned" else 0.0
    lattice = field_lattice(scene, st.field_spacing, EYE_HEIGHTS, margin=st.margin, bbox=bbox, angle=angle)
    if len(lattice) == 0:
        raise InputError(f"{src}: no free field point (no free space?)")
    free = len(lattice)
    if st.section_cover == "walkable":
        # the field only where the walkable cells are: the free space inside the blocks
        # (courtyards, backyards), where no walk goes, is neither rendered nor covered,
        # and the sections' adjacency (what the prefetch follows) is the network's
        lattice = lattice.subset(points_meeting(lattice, shapely.union_all([shapely.Polygon(c.polygon) for c in base])))
        if len(lattice) == 0:
            raise InputError(f"{src}: no field point in the walkable cells (try --section-cover free)")

    digest = file_digest(src)
    settings_dict = st.record() | {"source": str(src), "source_digest": digest}
    key = settings_key({
        "source_digest": digest, "field_spacing": st.field_spacing, "resolution": st.resolution,
        "occluder_lod": st.occluder_lod, "view_distance": st.view_distance, "edge_pass": st.edge_pass,
        "margin": st.margin, "bbox": st.bbox, "bbox_crs": st.bbox_crs, "network": st.network,
        "heights": EYE_HEIGHTS,
    } | ({"thin_pass": st.thin_pass, "thin_depth": st.thin_depth} if st.thin_pass else {}) | ({"angle": round(angle, 9)} if angle else {}) | ({"cover": _digest(lattice.index)} if len(lattice) < free else {}))
    features = ["buildings"] + (["streets"] if scene.streets else []) + ["section_cells"]
    say(f"{src.name}: {len(scene.buildings)} buildings, {len(scene.streets)} street pieces, "
        f"a field of {len(lattice)} points every {st.field_spacing:g} m"
        + ("" if len(lattice) == free else f" in its {len(base)} walkable cells (of {free} free)")
        + (f", turned {math.degrees(angle):.1f} degrees to the streets" if angle else ""))
    grammar = default_grammar()
    city = scene
    made: list[ViewCell] = []

    def grow(sets: PointSets) -> list[tuple[int, I64, F64]]:
        grid = lattice.grid()
        if st.redundancy is None:
            # the default: R from the field, sections of about SECTION_AREA m² each
            r, secs = sections_for_area(lattice, sets, min_size=st.min_size, say=say)
        else:
            r, secs = st.redundancy, grow_sections(lattice, sets, redundancy=st.redundancy, min_size=st.min_size)
        outlines = [s.outline(lattice) for s in secs]
        cells = finish_cells([("section", o) for o in outlines], *HEIGHT_RANGE)
        by_box = {_box(o): k for k, o in enumerate(outlines)}
        order = [by_box[_box(np.asarray(c.polygon))] for c in cells]
        secs = [secs[k] for k in order]
        res = [(c.id, *section_pvs(sec, grid, sets, threshold=st.threshold)) for c, sec in zip(cells, secs, strict=True)]
        made[:] = cells
        summary.update(section_stats(secs, grid, sets, np.array([len(p) for _, p, _ in res], np.int64)))
        summary.update({"redundancy": r, "field_points": len(lattice), "field_bytes": sets.nbytes,
                        "field_spacing": st.field_spacing})
        say(f"R {r}{'' if st.redundancy is not None else ' (from the field)'}: {len(cells)} sections ({summary['sections_relaxed']} of the relaxed pass), PVS mean "
            f"{summary['section_pvs_mean']:.1f}, field {len(lattice)} points, {sets.nbytes / 1e6:.1f} MB")
        return res

    def write_tables(writer: SceneWriter) -> None:
        writer.add_objects(object_rows(city, grammar))
        writer.add_cells(
            CellRow(c.id, c.kind, np.asarray(c.polygon), c.zmin, c.zmax, np.asarray(c.neighbours, np.int64))
            for c in made
        )
        loc = cell_locator(made)
        for k, vp in enumerate(viewpoints(base, city)):
            cid = loc.locate(vp.x, vp.y)
            if cid is not None:
                writer.add_viewpoint(f"start{k}-section{cid}", vp.x, vp.y, vp.z, vp.yaw, cid)

    nav = SceneGraph(CellGraph(base))

    def walks(say: Say) -> list[Walk]:
        return [(path, f"recorded path {path.name}: {path.duration:.0f} s, {path.length_m():.0f} m at "
                       f"{path.speed_kmh:g} km/h")
                for path in default_paths(base, footprints=[b.rings[0] for b in city.buildings],
                                          graph=nav.streets, say=say)]

    return BakePlan(
        name=name or out.stem, crs=scene.crs, origin=scene.origin, grammar_text=default_grammar_text(),
        grammar_version=grammar.id, features=features, settings=settings_dict, pvs=None, rooms=None,
        write_tables=write_tables, walks=walks, summary=summary,
        field=FieldCells(scene, st, lattice, key, grow),
    )


def _digest(index: I64) -> str:
    # the field points a walkable cover keeps name its field (the blocks hold them in turn)
    return hashlib.sha1(np.ascontiguousarray(index, np.int64).tobytes()).hexdigest()[:16]


def _box(outline: F64) -> tuple[float, ...]:
    # every vertex: two rectangles turned by 45 degrees may share their bounding box
    return tuple(round(float(v), 6) for v in np.asarray(outline).ravel())


def street_angle(scene: SourceScene) -> float:
    """The scene's prevailing street direction, radians in ``[0, pi/2)``.

    The edges of the street pieces' outlines (of the footprints when there are no
    streets), weighted by length, each direction taken modulo a right angle: the
    angle of the mean of ``exp(4i theta)`` over them (a grid of streets and its cross
    streets count alike).  0 when there is nothing to measure, or when it is within
    half a degree of the axes.
    """
    rings = [st.ring for st in scene.streets] or [b.rings[0] for b in scene.buildings]
    if not rings:
        return 0.0
    d = np.concatenate([np.roll(r, -1, axis=0) - r for r in rings])
    length = np.hypot(d[:, 0], d[:, 1])
    z = np.sum(length * np.exp(4j * np.arctan2(d[:, 1], d[:, 0])))
    if abs(z) < 1e-9 * max(float(length.sum()), 1.0):
        return 0.0
    a = float(np.angle(z)) / 4.0
    a = a % (math.pi / 2)
    # within half a degree of the axes (a metre over 120 m) the lattice stays axis-aligned
    return 0.0 if min(a, math.pi / 2 - a) < math.radians(0.5) else a
