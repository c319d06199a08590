"""A plan of each storey of an interior: cells coloured by triangles, portals as thick lines."""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from walkstream.shared.arrays import F64

__all__ = ["PlanCell", "PlanPortal", "draw_storeys"]

_PORTAL_COLOURS = {
    "door": "#d62728",
    "window": "#1f77b4",
    "opening": "#ff7f0e",
    "virtual": "#ff7f0e",
    "split": "#9467bd",
    "void": "#17becf",
    "stair": "#2ca02c",
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
    cols = min(n, 3)
    rows = (n + cols - 1) // cols
    inside = [c for c in cells if c.storey >= 0]
    pts = np.concatenate([c.outline for c in inside]) if inside else np.zeros((1, 2))
    lo, hi = pts.min(axis=0) - 1.0, pts.max(axis=0) + 1.0
    aspect = (hi[1] - lo[1]) / max(hi[0] - lo[0], 1e-6)
    fig = Figure(figsize=(5.2 * cols, 5.2 * rows * min(max(aspect, 0.35), 2.0) + 0.8), dpi=dpi)
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
        ax.set_title(f"storey {name}: {len(mine)} cells", fontsize=9)
        ax.tick_params(labelsize=6)
    fig.colorbar(
        matplotlib.cm.ScalarMappable(norm=norm, cmap=cmap), ax=axes, label="triangles per cell", shrink=0.8
    )
    if title:
        fig.suptitle(title, fontsize=9)
    fig.savefig(os.fspath(path))
    return len(storeys)

