"""A top view of a baked scene: the streets, the cells coloured by PVS size, the buildings, the walks.

What a user looks at to see what a street network became: the typed areas in their
palette colours (grass, water, parking, ...), the street pieces (grey, crossroads
darker), over them the view cells coloured by PVS size with thin outlines (sections
see-through, so that their rectangles and overlaps show), the building footprints on
top, and the recorded path ``SE``.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any

import numpy as np

from walkstream.server.store import CellInfo, SceneReader
from walkstream.shared.areakinds import AREA_MATERIALS, area_z
from walkstream.shared.palette import PALETTE
from walkstream.shared.records import AreaParams

__all__ = ["draw_map", "draw_city"]


def draw_map(reader: SceneReader, path: str | os.PathLike[str], *, dpi: int = 130) -> None:
    """Write a PNG map of ``reader``'s cells (colour = PVS size) over its buildings."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    cells = list(reader.cells())
    fig = Figure(figsize=(9, 8), dpi=dpi)
    ax = fig.add_subplot(1, 1, 1)
    draw_city(fig, ax, reader, cells)
    x0, y0, _, x1, y1, _ = reader.bounds()
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    s = reader.summary()
    ax.set_title(
        f"{s['name']} ({s['version']}): {s['cells']} cells, {s['objects']} objects, "
        f"PVS mean {s['pvs_mean']:.0f} / max {s['pvs_max']}, culled {100 * s['culled_ratio']:.1f} %",
        fontsize=9,
    )
    ax.set_xlabel("x (m, scene-local)")
    ax.set_ylabel("y (m)")
    fig.tight_layout()
    fig.savefig(os.fspath(path))


def draw_city(fig: Any, ax: Any, reader: SceneReader, cells: Sequence[CellInfo]) -> None:
    """Draw the streets, ``cells`` coloured by PVS size (with a colour bar), the building
    footprints, the walk ``SE`` and the viewpoints on a matplotlib ``ax`` of ``fig``."""
    from matplotlib.collections import PatchCollection
    from matplotlib.patches import Polygon as MplPolygon

    buildings = []
    streets, street_colours = [], []
    areas: list[tuple[float, Any, Any]] = []  # height (drawing order), path, colour
    infos = reader.object_info(int(i) for i in reader.object_ids())
    for oid, info in infos.items():
        if info.kind == "building":
            buildings.append(MplPolygon(reader.building(oid).rings[0], closed=True))
        elif info.kind == "area":
            a = reader.area(oid)
            areas.append((area_z(a.kind), _area_patch(a), PALETTE[AREA_MATERIALS[a.kind]] / 255.0))
        else:
            piece = reader.street(oid)
            streets.append(MplPolygon(piece.ring, closed=True))
            street_colours.append({"crossroad": "#a9a9a9", "square": "#cfd8c4"}.get(piece.kind, "#d4d4d4"))
    if areas:  # the areas first, lowest kind first, holes kept
        areas.sort(key=lambda t: t[0])
        ax.add_collection(PatchCollection([p for _, p, _ in areas], facecolor=[c for _, _, c in areas], edgecolor="none"))
    # the streets next, a little wider than their cells where footprints clipped them
    ax.add_collection(
        PatchCollection(streets, facecolor=street_colours, edgecolor="#8c8c8c", linewidth=0.3)
    )
    sizes = np.array([len(c.pvs) for c in cells], dtype=float)
    thin = 0.15 if len(cells) > 1500 else 0.3
    # sections may overlap: see-through, so an overlap shows as a darker rectangle
    sections = bool(cells) and all(c.kind == "section" for c in cells)
    coll = PatchCollection(
        [MplPolygon(c.boundary, closed=True) for c in cells],
        cmap="viridis",
        edgecolor="#202020",
        linewidth=thin,
        alpha=0.6 if sections else 0.9,
    )
    coll.set_array(sizes)
    ax.add_collection(coll)
    fig.colorbar(coll, ax=ax, label="PVS size (objects)", shrink=0.8)
    ax.add_collection(PatchCollection(buildings, facecolor="#9a8f85", edgecolor="#5b524a", linewidth=0.2))
    if "SE" in reader.path_names():
        from walkstream.shared.paths import RecordedPath

        se = RecordedPath.from_msgpack(reader.path_blob("SE"), "SE")
        xy = np.asarray(se.xyz)
        ax.plot(xy[:, 0], xy[:, 1], color="#d62728", linewidth=0.8, label="path SE")
        ax.legend(loc="upper right", fontsize=7)
    for vp in reader.viewpoints():
        ax.annotate("", xy=(vp.x + 25 * np.cos(vp.yaw), vp.y + 25 * np.sin(vp.yaw)), xytext=(vp.x, vp.y),
                    arrowprops={"arrowstyle": "->", "color": "red", "lw": 1.5})


def _area_patch(a: AreaParams) -> Any:
    """A matplotlib patch of an area's polygon with its holes."""
    from matplotlib.patches import PathPatch
    from matplotlib.path import Path as MplPath

    verts, codes = [], []
    for r in a.rings:
        verts += [*r.tolist(), r[0].tolist()]
        codes += [MplPath.MOVETO] + [MplPath.LINETO] * (len(r) - 1) + [MplPath.CLOSEPOLY]
    return PathPatch(MplPath(verts, codes))
