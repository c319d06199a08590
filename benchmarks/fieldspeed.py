"""How fast the dense visibility field renders: ``walkstream bench field``.

The field's points of a city (the walkable cover the sections bake uses, every
``--field-spacing`` metres) are taken in runs of ``--points`` consecutive field points
from ``--starts`` places spread over the lattice, each at both eye heights in the
field's order, and rendered side by side in one run by

- ``plain``: the bake's ID renderer one pass after the other, as the field's blocks
  were rendered before
  (:meth:`~walkstream.server.bake.visibility.VisibilityRenderer.each_point_counts`);
- ``bake``: the field's renderer today, two passes in flight
  (:meth:`~walkstream.server.bake.fieldrender.FieldRenderer.field_counts`);
- ``culled``: the plain renderer with exact occlusion culling (:mod:`.fieldcull`,
  tried, not adopted),

alternating run by run so that all see the same load.  A row gives the renders
(point and height) per second of wall time and per CPU second (every thread of this
process: the rasteriser's too), the triangles set up against the plain render, the
faces drawn twice, and the points whose counts equal the plain render's (visible
set, and pixels too).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np
import shapely

from walkstream.benchmarks.fieldcull import CulledRenderer
from walkstream.server.bake.cells import make_cells
from walkstream.server.bake.field import FIELD_BLOCK, FIELD_HEIGHTS, field_lattice, points_meeting
from walkstream.server.bake.fieldrender import FieldRenderer
from walkstream.server.bake.idpack import meshes_for_scene
from walkstream.server.bake.settings import BakeSettings
from walkstream.server.bake.visibility import VisibilityRenderer
from walkstream.server.sources.read import read_source
from walkstream.server.sources.scene import SourceScene
from walkstream.shared.errors import InputError, WalkstreamError

__all__ = ["format_field_speed", "run_field_speed"]


def _field_points(scene: SourceScene, spacing: float) -> np.ndarray:
    """``(n, 2)`` the field points of the walkable cover (as ``bake --cells sections``)."""
    st = BakeSettings(cells="sections", field_spacing=spacing)
    base = make_cells(scene, "auto", max_length=st.max_length, cell_size=st.cell_size, bbox=None)
    lat = field_lattice(scene, st.field_spacing, FIELD_HEIGHTS, margin=st.margin)
    if base:
        lat = lat.subset(points_meeting(lat, shapely.union_all([shapely.Polygon(c.polygon) for c in base])))
    out: np.ndarray = lat.eyes
    return out


def run_field_speed(
    source: Path, *, points: int = FIELD_BLOCK, starts: int = 4, spacing: float = 4.0, resolution: int = 128
) -> dict[str, Any]:
    """Render the same field points plain and culled; see the module docstring.

    Returns
    -------
    dict
        ``scene``, ``objects``, ``triangles``, ``renders`` and per renderer (``plain``,
        ``bake``, ``culled``) ``wall_s``, ``cpu_s``, ``renders_per_s``, ``renders_per_cpu_s``; for
        ``culled`` also ``triangles_share``, ``faces_redrawn``, ``faces_appended``,
        ``passes_plain``; for ``bake`` and ``culled`` ``same_sets`` and ``same_counts``
        (points equal to the plain render's), ``max_pixel_difference``.
    """
    if points < 1 or starts < 1:
        raise InputError(f"bench field: --points and --starts must be at least 1, got {points} and {starts}")
    if not source.exists():
        raise WalkstreamError(f"{source}: no such source")
    scene = read_source(source)
    if not isinstance(scene, SourceScene):
        raise InputError(f"{source}: bench field takes a city (footprints and streets), not an interior")
    eyes = _field_points(scene, spacing)
    if len(eyes) == 0:
        raise InputError(f"{source}: no field point in the walkable cells")
    firsts = sorted({int(k * max(len(eyes) - points, 0) / max(starts - 1, 1)) for k in range(starts)})
    runs = []
    for a in firsts:
        e = eyes[a : a + points]
        # the field's order: every eye at the first height, then at the second
        runs.append(np.vstack([np.column_stack([e, np.full(len(e), z)]) for z in FIELD_HEIGHTS]))
    meshes, ids = meshes_for_scene(scene, 0)
    plain = VisibilityRenderer(meshes, ids, resolution=resolution)
    bake = FieldRenderer(meshes, ids, resolution=resolution)
    culled = CulledRenderer(meshes, ids, resolution=resolution)
    calls = (("plain", plain, plain.each_point_counts), ("bake", bake, bake.field_counts),
             ("culled", culled, culled.field_counts))
    times = {name: [0.0, 0.0] for name, _, _ in calls}
    same = {name: [0, 0, 0] for name in ("bake", "culled")}  # sets, counts, worst pixel difference
    try:
        for pts in runs:
            got = {}
            for name, r, call in calls:
                assert r.ctx is not None
                r.ctx.__enter__()  # each renderer has its own context
                w, c = time.perf_counter(), time.process_time()
                got[name] = call(pts)
                times[name][0] += time.perf_counter() - w
                times[name][1] += time.process_time() - c
            for name, tally in same.items():
                for (ia, pa), (ib, pb) in zip(got["plain"], got[name], strict=True):
                    if np.array_equal(ia, ib):
                        tally[0] += 1
                        tally[1] += bool(np.array_equal(pa, pb))
                        if len(pa):
                            tally[2] = max(tally[2], int(np.abs(pa - pb).max()))
                    else:
                        tally[2] = max(tally[2], int(max(pa.sum(), pb.sum())))
        n = sum(len(p) for p in runs)
        out: dict[str, Any] = {"scene": source.name, "objects": len(ids),
                               "triangles": int(sum(m.indices.size // 3 for m in meshes)), "renders": n}
        for name, (w, c) in times.items():
            out[name] = {"wall_s": w, "cpu_s": c, "renders_per_s": n / w if w else None,
                         "renders_per_cpu_s": n / c if c else None}
        s = culled.stats
        out["culled"].update({
            "triangles_share": s["triangles"] / s["triangles_plain"] if s["triangles_plain"] else None,
            "faces_redrawn": s["faces_redrawn"] / s["faces"] if s["faces"] else None,
            "faces_appended": s["faces_appended"] / s["faces"] if s["faces"] else None,
            "passes_plain": s["passes_plain"], "passes": s["passes"],
        })
        for name, (sets, counts, worst) in same.items():
            out[name].update({"same_sets": sets, "same_counts": counts, "max_pixel_difference": worst})
        return out
    finally:
        culled.release()
        bake.release()
        plain.release()


def format_field_speed(rows: list[dict[str, Any]]) -> str:
    """One line per scene and renderer."""
    head = (f"{'scene':<22} {'renderer':<8} {'renders':>7} {'per s':>7} {'x plain':>7} {'per CPU-s':>9} {'x plain':>7} "
            f"{'triangles':>9} {'redrawn':>7} {'same sets':>9} {'same px':>8} {'max dpx':>7}")
    lines = [head, "-" * len(head)]
    for r in rows:
        base, wall = r["plain"]["renders_per_cpu_s"], r["plain"]["renders_per_s"]
        for name in ("plain", "bake", "culled"):
            f = r[name]
            tri = (f"{100 * (f['triangles_share'] or 0):>8.0f}% {100 * (f['faces_redrawn'] or 0):>6.0f}%"
                   if name == "culled" else f"{'100%':>9} {'-':>7}")
            extra = (f"{tri} {f['same_sets']:>9} {f['same_counts']:>8} {f['max_pixel_difference']:>7}"
                     if name != "plain" else f"{tri} {'-':>9} {'-':>8} {'-':>7}")
            lines.append(
                f"{r['scene']:<22} {name:<8} {r['renders']:>7} {f['renders_per_s']:>7.1f} {f['renders_per_s'] / wall:>7.2f} "
                f"{f['renders_per_cpu_s']:>9.1f} "
                f"{f['renders_per_cpu_s'] / base:>7.2f} {extra}")
    return "\n".join(lines)
