"""Pictures of an interior: a plan of each storey (cells coloured by triangles, portals as
thick lines, the tour), and the meshes of a storey cut away above eye height."""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from walkstream.server.store import SceneReader
from walkstream.shared.arrays import F64
from walkstream.shared.errors import InputError
from walkstream.shared.records import Mesh

__all__ = ["PlanCell", "PlanPortal", "draw_storeys", "draw_interior_map", "storey_meshes"]

_PORTAL_COLOURS = {
    "door": "#d62728",
    "window": "#1f77b4",
    "opening": "#ff7f0e",
    "virtual": "#ff7f0e",
    "split": "#9467bd",
    "void": "#17becf",
    "stair": "#2ca02c",
    "wall": "#8c564b",
}


@dataclass(frozen=True)
class PlanCell:
    """What the plan needs of a cell."""

    id: int
    kind: str
    name: str
    storey: int
    outline: F64
    triangles: int


@dataclass(frozen=True)
class PlanPortal:
    """What the plan needs of a portal: its kind, polygon ``(k, 3)`` and cells."""

    kind: str
    polygon: F64
    a: int
    b: int


def draw_storeys(
    cells: Sequence[PlanCell],
    portals: Sequence[PlanPortal],
    storey_names: Sequence[str],
    path: str | os.PathLike[str],
    *,
    title: str = "",
    walk: F64 | None = None,
    ranges: F64 | None = None,
    dpi: int = 110,
) -> int:
    """Write a PNG with one plan per storey that has cells; returns how many plans.

    Cells are coloured by their triangle count (one colour scale for all storeys);
    doorway cells are hatched; portals are thick lines (doors red, windows blue,
    open boundaries orange, splits of one room purple, floor holes cyan, stairs
    green); a horizontal portal is drawn as its outline.  ``walk`` ``(n, 3)``, if
    given with ``ranges`` (``(storeys, 2)`` height ranges), is drawn on the storey of
    each of its points.
    """
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import colormaps
    from matplotlib.collections import LineCollection, PatchCollection
    from matplotlib.colors import Normalize
    from matplotlib.figure import Figure
    from matplotlib.patches import Polygon as MplPolygon

    storeys = sorted({c.storey for c in cells if c.storey >= 0})
    n = max(1, len(storeys))
    span = np.ptp(np.concatenate([c.outline for c in cells if c.storey >= 0]), axis=0) if cells else np.ones(2)
    # long, narrow buildings: one storey per row, so each plan is readable
    cols = 1 if span[1] < 0.6 * span[0] else min(n, 3)
    rows = (n + cols - 1) // cols
    inside = [c for c in cells if c.storey >= 0]
    pts = np.concatenate([c.outline for c in inside]) if inside else np.zeros((1, 2))
    lo, hi = pts.min(axis=0) - 1.0, pts.max(axis=0) + 1.0
    aspect = (hi[1] - lo[1]) / max(hi[0] - lo[0], 1e-6)
    panel_w = 10.0 if cols == 1 else 5.2
    fig = Figure(figsize=(panel_w * cols, panel_w * rows * min(max(aspect, 0.35), 2.0) + 0.8), dpi=dpi)
    tri = np.array([c.triangles for c in inside], dtype=float)
    norm = Normalize(vmin=0.0, vmax=max(1.0, float(tri.max()) if len(tri) else 1.0))
    cmap = colormaps["viridis"]
    by_cell = {c.id: c for c in cells}
    axes = []
    for i, k in enumerate(storeys or [0]):
        ax = fig.add_subplot(rows, cols, i + 1)
        axes.append(ax)
        mine = [c for c in inside if c.storey == k]
        rooms = [c for c in mine if c.kind != "doorway"]
        doors = [c for c in mine if c.kind == "doorway"]
        coll = PatchCollection([MplPolygon(c.outline, closed=True) for c in rooms], cmap=cmap, norm=norm,
                               edgecolor="white", linewidth=0.6)
        coll.set_array(np.array([c.triangles for c in rooms], dtype=float))
        ax.add_collection(coll)
        dcoll = PatchCollection([MplPolygon(c.outline, closed=True) for c in doors], cmap=cmap, norm=norm,
                                edgecolor="black", linewidth=0.3, hatch="////")
        dcoll.set_array(np.array([c.triangles for c in doors], dtype=float))
        ax.add_collection(dcoll)
        segs, colours, widths = [], [], []
        for p in portals:
            ca, cb = by_cell.get(p.a), by_cell.get(p.b)
            on = [c for c in (ca, cb) if c is not None and c.storey >= 0]
            if p.kind in ("void", "stair"):
                lower = min(on, key=lambda c: c.storey) if on else None
                if lower is None or lower.storey != k and (max(c.storey for c in on) != k):
                    continue
                ring = np.concatenate([p.polygon[:, :2], p.polygon[:1, :2]])
                ax.plot(ring[:, 0], ring[:, 1], color=_PORTAL_COLOURS[p.kind], lw=1.6,
                        ls="--" if lower.storey != k else "-")
                continue
            if not any(c.storey == k for c in on):
                continue
            xy = p.polygon[:, :2]
            span = xy.max(axis=0) - xy.min(axis=0)
            axis = int(np.argmax(span))
            order = np.argsort(xy[:, axis])
            segs.append([xy[order[0]], xy[order[-1]]])
            colours.append(_PORTAL_COLOURS.get(p.kind, "black"))
            widths.append(3.0 if p.kind in ("door", "window") else 2.0)
        if segs:
            ax.add_collection(LineCollection(segs, colors=colours, linewidths=widths, capstyle="butt"))
        for c in rooms:
            if c.outline.size and len(mine) <= 60:
                cx, cy = c.outline.mean(axis=0)
                ax.text(cx, cy, c.name[:14], fontsize=5, ha="center", va="center", color="white")
        if walk is not None and ranges is not None and len(walk):
            st = np.searchsorted(np.asarray(ranges)[:, 0], walk[:, 2], side="right") - 1
            w = np.where((st == k)[:, None], walk[:, :2], np.nan)
            ax.plot(w[:, 0], w[:, 1], color="#e377c2", lw=1.2)
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_aspect("equal")
        name = storey_names[k] if 0 <= k < len(storey_names) else str(k)
        ax.set_title(f"storey {name}: {len(mine)} cell{'' if len(mine) == 1 else 's'}", fontsize=9)
        ax.tick_params(labelsize=6)
    fig.colorbar(
        matplotlib.cm.ScalarMappable(norm=norm, cmap=cmap), ax=axes, label="triangles per cell", shrink=0.8
    )
    if title:
        fig.suptitle(title, fontsize=9)
    fig.savefig(os.fspath(path))
    return len(storeys)



def draw_interior_map(reader: SceneReader, path: str | os.PathLike[str], *, walk: str | None = "tour") -> int:
    """:func:`draw_storeys` of an interior scene database (with its ``walk`` drawn, if it has one)."""
    from walkstream.shared.paths import RecordedPath

    rooms = reader.rooms()
    info = reader.contents_info()
    cells = [
        PlanCell(c.id, c.kind, rooms[c.id].name, rooms[c.id].storey, np.asarray(c.boundary),
                 info[c.id].triangles if c.id in info else 0)
        for c in reader.cells()
    ]
    portals = [PlanPortal(p.kind, np.asarray(p.polygon), p.a, p.b) for p in reader.portals()]
    storeys = reader.storeys()
    ranges = np.array([[s.zmin, s.zmax] for s in storeys]) if storeys else None
    line = None
    if walk is not None and walk in reader.path_names():
        p = RecordedPath.from_msgpack(reader.path_blob(walk), f"{reader.path}: path {walk!r}")
        line = np.asarray(p.sample(np.linspace(0.0, p.duration, max(2, int(p.duration * 4))))[0])
    s = reader.summary()
    title = (
        f"{s['name']}: {s['cells_inside']} cells ({s['doorways']} doorways), {s['portals']} portals, "
        f"{s['triangles']:,} triangles in cells; tour in pink"
    )
    return draw_storeys(cells, portals, [st.name for st in storeys], path, title=title, walk=line, ranges=ranges)


def storey_meshes(reader: SceneReader, storey: int, cut: float = 1.4) -> list[Mesh]:
    """The contents of one storey's cells cut off ``cut`` metres above its floor (a cut-away)."""
    from walkstream.server.bake.roomgeom import clip_polygons, fan_triangles
    from walkstream.shared.codec.cellmesh import decode_cell_mesh

    rooms = reader.rooms()
    storeys = reader.storeys()
    if not 0 <= storey < len(storeys):
        raise InputError(f"storey {storey}: the scene has storeys 0 to {len(storeys) - 1}")
    z = storeys[storey].zmin + cut
    plane = np.array([0.0, 0.0, 1.0, -z])
    out: list[Mesh] = []
    for cid, r in rooms.items():
        if r.storey != storey:
            continue
        cm = decode_cell_mesh(reader.contents(cid), f"{reader.path}: cell {cid}")
        for part in cm.parts:
            tri = part.positions.astype(np.float64)[part.indices.astype(np.int64)]
            if len(tri) == 0:
                continue
            poly, count = clip_polygons(tri, np.full(len(tri), 3, np.int64), plane)
            keep = count >= 3
            ft, _ = fan_triangles(poly[keep], count[keep])
            if len(ft) == 0:
                continue
            pos = ft.reshape(-1, 3)
            idx = np.arange(len(pos)).reshape(-1, 3)
            n = np.repeat(np.cross(ft[:, 1] - ft[:, 0], ft[:, 2] - ft[:, 0]), 3, axis=0)
            n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
            out.append(Mesh(pos, n, idx, np.full(len(pos), part.material, np.uint8)))
    return out
