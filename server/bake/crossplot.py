"""A top view of a crossing scene: the city as :func:`~.mapplot.draw_map` draws it, with the
building's rooms in plan, the entrance portal and the crossing walk; and a close-up of the building.

Left: the streets, the city's cells coloured by PVS size, the footprints; in the
building that holds the interior, the plan of the entrance's storey (rooms light,
doorways hatched), its portals (doors red, windows blue, the rest orange), the
entrance portal (thick magenta) and the ``enter`` walk (pink; dashed where it runs
on another storey).  Right: the same around the building, 25 m beyond it each way.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from walkstream.server.bake.mapplot import draw_city
from walkstream.server.bake.scenenav import ENTER_NAME
from walkstream.server.store import CellInfo, SceneReader
from walkstream.shared.paths import RecordedPath

__all__ = ["draw_crossing_map"]

_PORTAL_COLOURS = {"door": "#d62728", "window": "#1f77b4"}
_ENTRANCE_COLOUR = "#e41a9c"
_WALK_COLOUR = "#ff69b4"
_AROUND = 25.0  # metres shown beyond the building in the close-up


def _plan(ax: Any, reader: SceneReader, cells: dict[int, CellInfo], storey: int, walk: Any) -> None:
    from matplotlib.collections import LineCollection, PatchCollection
    from matplotlib.patches import Polygon as MplPolygon

    rooms = reader.rooms()
    mine = [c for c in cells.values() if c.id in rooms and rooms[c.id].storey == storey]
    ax.add_collection(PatchCollection([MplPolygon(c.boundary, closed=True) for c in mine if c.kind == "room"],
                                      facecolor="#f3e9d2", edgecolor="#6b5b45", linewidth=0.4, zorder=3))
    ax.add_collection(PatchCollection([MplPolygon(c.boundary, closed=True) for c in mine if c.kind == "doorway"],
                                      facecolor="#e0d3b8", edgecolor="black", linewidth=0.3, hatch="////", zorder=3))
    entrances = {e.portal for e in reader.entrances()}
    ids = {c.id for c in mine}
    segs, colours, widths = [], [], []
    for p in reader.portals():
        if p.kind in ("void", "stair") or not ({p.a, p.b} & ids):
            continue
        xy = p.polygon[:, :2]
        axis = int(np.argmax(xy.max(axis=0) - xy.min(axis=0)))
        order = np.argsort(xy[:, axis])
        segs.append([xy[order[0]], xy[order[-1]]])
        if p.id in entrances:
            colours.append(_ENTRANCE_COLOUR)
            widths.append(5.0)
        else:
            colours.append(_PORTAL_COLOURS.get(p.kind, "#ff7f0e"))
            widths.append(1.6)
    if segs:
        ax.add_collection(LineCollection(segs, colors=colours, linewidths=widths, capstyle="butt", zorder=4))
    if walk is not None:
        xyz, here = walk
        same = np.where(here[:, None], xyz[:, :2], np.nan)
        other = np.where(~here[:, None], xyz[:, :2], np.nan)
        ax.plot(same[:, 0], same[:, 1], color=_WALK_COLOUR, lw=1.4, zorder=5, label=f"path {ENTER_NAME}")
        ax.plot(other[:, 0], other[:, 1], color=_WALK_COLOUR, lw=1.0, ls="--", zorder=5)


def draw_crossing_map(reader: SceneReader, path: str | os.PathLike[str], *, dpi: int = 130) -> None:
    """Write the PNG of the module docstring for a crossing scene database."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    cells = {c.id: c for c in reader.cells()}
    rooms = reader.rooms()
    entrances = reader.entrances()
    doorway = cells[entrances[0].doorway] if entrances else None
    storey = rooms[doorway.id].storey if doorway is not None else 0
    walk = None
    if ENTER_NAME in reader.path_names():
        p = RecordedPath.from_msgpack(reader.path_blob(ENTER_NAME), f"{reader.path}: path {ENTER_NAME!r}")
        xyz = np.asarray(p.sample(np.linspace(0.0, p.duration, max(2, int(p.duration * 4))))[0])
        storeys = reader.storeys()
        lo, hi = (storeys[storey].zmin, storeys[storey].zmax) if storeys else (-np.inf, np.inf)
        walk = (xyz, (xyz[:, 2] >= lo) & (xyz[:, 2] < hi) | (xyz[:, 2] < lo + 2.5))
    fig = Figure(figsize=(16, 8), dpi=dpi)
    whole, near = fig.add_subplot(1, 2, 1), fig.add_subplot(1, 2, 2)
    city = [c for c in cells.values() if c.id not in rooms]
    inside = [c for c in cells.values() if c.id in rooms and c.kind != "outside"]
    for ax in (whole, near):
        draw_city(fig, ax, reader, city)
        _plan(ax, reader, cells, storey, walk)
        ax.set_aspect("equal")
        ax.set_xlabel("x (m, scene-local)")
        ax.set_ylabel("y (m)")
    x0, y0, _, x1, y1, _ = reader.bounds()
    whole.set_xlim(x0, x1)
    whole.set_ylim(y0, y1)
    pts = np.concatenate([c.boundary for c in inside]) if inside else np.zeros((1, 2))
    lo2, hi2 = pts.min(axis=0) - _AROUND, pts.max(axis=0) + _AROUND
    near.set_xlim(lo2[0], hi2[0])
    near.set_ylim(lo2[1], hi2[1])
    near.legend(loc="upper right", fontsize=7)
    s = reader.summary()
    whole.set_title(f"{s['name']} ({s['version']}): {len(city)} city cells, {s['objects']} objects, "
                    f"{s['cells_inside']} room cells, {s['entrances']} entrance", fontsize=9)
    building = f"building {entrances[0].building}" if entrances else "the building"
    near.set_title(f"{building}: storey {storey}'s plan, the entrance (magenta), path {ENTER_NAME} (pink)", fontsize=9)
    fig.tight_layout()
    fig.savefig(os.fspath(path))
