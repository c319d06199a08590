"""A top view of a baked scene: cells coloured by PVS size over the footprints."""

from __future__ import annotations

import os

import numpy as np

from walkstream.server.store import SceneReader

__all__ = ["draw_map"]


def draw_map(reader: SceneReader, path: str | os.PathLike[str], *, dpi: int = 130) -> None:
    """Write a PNG map of ``reader``'s cells (colour = PVS size) over its buildings."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.collections import PatchCollection
    from matplotlib.figure import Figure
    from matplotlib.patches import Polygon as MplPolygon

    cells = list(reader.cells())
    fig = Figure(figsize=(9, 8), dpi=dpi)
    ax = fig.add_subplot(1, 1, 1)
    sizes = np.array([len(c.pvs) for c in cells], dtype=float)
    coll = PatchCollection(
        [MplPolygon(c.boundary, closed=True) for c in cells], cmap="viridis", edgecolor="white", linewidth=0.2
    )
    coll.set_array(sizes)
    ax.add_collection(coll)
    fig.colorbar(coll, ax=ax, label="PVS size (objects)", shrink=0.8)
    buildings = []
    infos = reader.object_info(int(i) for i in reader.object_ids())
    for oid, info in infos.items():
        if info.kind == "building":
            buildings.append(MplPolygon(reader.building(oid).rings[0], closed=True))
    ax.add_collection(PatchCollection(buildings, facecolor="#9a8f85", edgecolor="#5b524a", linewidth=0.2))
    for vp in reader.viewpoints():
        ax.annotate("", xy=(vp.x + 25 * np.cos(vp.yaw), vp.y + 25 * np.sin(vp.yaw)), xytext=(vp.x, vp.y),
                    arrowprops={"arrowstyle": "->", "color": "red", "lw": 1.5})
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
