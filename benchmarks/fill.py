"""``walkstream bench fill``: where the GL device's frame time goes, per shading path.

The real-clock gl rows of ``bench budget`` spend most of a frame in ``ctx.finish()``
(Mesa llvmpipe rasterising) even at the budget's floor of a few hundred triangles, so
the cost is per pixel, not per triangle.  This benchmark times ``finish`` for four
frames at each viewpoint of a recorded walk, drawn by the client's
:class:`~walkstream.client.draw.frames.FrameRenderer` with both lighting paths
(``shading="fragment"``: the per-fragment program with the fog branch, the path
before; ``"vertex"``: lighting per vertex, no fog code), interleaved in one run:

``clear``
    the clear alone (colour and depth of the whole frame);
``streets``
    the visible streets only (the ground);
``floor``
    every visible object at LOD0 (what the budget draws at its floor);
``lod2``
    every visible object at LOD2.

It also compares the two paths' frames pixel by pixel (largest difference of a
channel, 0-255, and the share of pixels that differ at all) and their object-id
images (which object each pixel shows; they must be equal).
"""

from __future__ import annotations

import math
import os
import statistics
import sys
from collections.abc import Hashable, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from walkstream.benchmarks.lod import LodGeometry, load_views, open_scene
from walkstream.shared.errors import InputError

if TYPE_CHECKING:
    import moderngl

__all__ = ["CASES", "format_fill_table", "run_fill_bench"]

#: The frames timed at each viewpoint, in table order.
CASES: tuple[str, ...] = ("clear", "streets", "floor", "lod2")


def run_fill_bench(
    db_path: str | os.PathLike[str],
    views: int = 6,
    path_name: str = "SE",
    size: tuple[int, int] = (1280, 960),
    repeats: int = 6,
    progress: bool = True,
    ctx: moderngl.Context | None = None,
) -> dict[str, Any]:
    """Time ``ctx.finish()`` per case and shading path, and compare the frames.

    Parameters
    ----------
    db_path : path
        Baked scene database.
    views : int
        Viewpoints taken from the recorded path ``path_name`` (or street cells).
    size : (int, int)
        Frame width and height in pixels.
    repeats : int
        Timed rounds per viewpoint; every round draws each case with each path in turn.
    progress : bool
        Show a tqdm bar on stderr.
    ctx : moderngl.Context, optional
        GL context (default: a new headless one, released afterwards).

    Returns
    -------
    dict
        ``rows``: one per case with ``case``, ``triangles`` (median), and per path
        ``finish_<path>`` / ``issue_<path>`` (median ms); ``max_diff`` (largest channel
        difference between the paths over the floor and LOD2 frames), ``diff_pct``
        (share of their pixels that differ), ``ids_equal`` (object-id images equal),
        ``renderer``, ``size``, ``views_from``.
    """
    from tqdm import tqdm

    from walkstream.client.draw.frames import FrameRenderer
    from walkstream.client.draw.meshes import SHADINGS
    from walkstream.shared.camera import camera
    from walkstream.shared.frustum import frustum_cull
    from walkstream.shared.gl import create_context
    from walkstream.shared.lsystem.grammar import parse_grammar

    if repeats < 1:
        raise InputError(f"bench fill: --repeat must be >= 1, got {repeats}")
    reader = open_scene(db_path)
    grammar = parse_grammar(reader.meta.grammar_text)
    bench_views, source = load_views(reader, views, path_name)
    x0, y0, z0, x1, y1, z1 = reader.bounds()
    far = max(100.0, 1.2 * math.sqrt((x1 - x0) ** 2 + (y1 - y0) ** 2 + (z1 - z0) ** 2))
    geometry = LodGeometry(reader, grammar)
    own_ctx = ctx is None
    gl = create_context() if ctx is None else ctx
    # one context for both renderers: moderngl does not switch between contexts
    renderers = {s: FrameRenderer(size, far=far, ctx=gl, shading=s) for s in SHADINGS}
    times: dict[tuple[str, str], list[tuple[float, float]]] = {}
    tris: dict[str, list[int]] = {c: [] for c in CASES}
    max_diff, differing, pixels, ids_equal = 0, 0, 0, True
    try:
        bar = tqdm(
            bench_views, desc="bench fill", unit="view", file=sys.stderr, disable=not progress
        )
        for v in bar:
            ids = [int(i) for i in reader.cell(v.cell).pvs]
            objs = geometry.get(ids)
            info = reader.object_info(ids)
            for fr in renderers.values():
                for key in fr.keys():  # keep GPU memory to one PVS
                    assert isinstance(key, tuple)
                    if key[0] not in info:
                        fr.forget(key)
                for oid, o in zip(ids, objs, strict=True):
                    for level in (0, 2):
                        fr.upload((oid, level), o.meshes[level])
            view = camera(v.eye, v.yaw, v.pitch)
            proj = renderers[SHADINGS[0]].proj
            vp = proj.astype(np.float64) @ view.astype(np.float64)
            lo = np.array([o.lo for o in objs]).reshape(-1, 3)
            hi = np.array([o.hi for o in objs]).reshape(-1, 3)
            seen = [i for i, s in zip(ids, frustum_cull(lo, hi, vp).tolist(), strict=True) if s]
            cases: dict[str, list[Hashable]] = {
                "clear": [],
                "streets": [(i, 0) for i in seen if info[i].kind != "building"],
                "floor": [(i, 0) for i in seen],
                "lod2": [(i, 2) for i in seen],
            }
            for rnd in range(repeats + 1):  # round 0 warms up
                for case, keys in cases.items():
                    for s, fr in renderers.items():
                        fr.draw(keys, view)
                        if rnd:
                            times.setdefault((case, s), []).append(
                                (1e3 * fr.last_finish_s, 1e3 * fr.last_issue_s)
                            )
                    if rnd:
                        tris[case].append(fr.last_triangles)
            for case in ("floor", "lod2"):
                imgs, id_imgs = [], []
                for fr in renderers.values():
                    fr.draw(cases[case], view)
                    imgs.append(fr.snapshot().astype(np.int16))
                    id_imgs.append(fr.draw_ids(cases[case], view))  # type: ignore[arg-type]
                d = np.abs(imgs[0] - imgs[1]).max(axis=2)
                max_diff = max(max_diff, int(d.max()))
                differing += int((d > 0).sum())
                pixels += int(d.size)
                ids_equal = ids_equal and bool(np.array_equal(id_imgs[0], id_imgs[1]))
        bar.close()
        renderer = str(gl.info.get("GL_RENDERER", "?"))
    finally:
        for fr in renderers.values():
            fr.release()
        if own_ctx:
            gl.release()
        reader.close()
    rows = []
    for case in CASES:
        row: dict[str, Any] = {"case": case, "triangles": int(statistics.median(tris[case]))}
        for s in SHADINGS:
            row[f"finish_{s}"] = statistics.median(t[0] for t in times[(case, s)])
            row[f"issue_{s}"] = statistics.median(t[1] for t in times[(case, s)])
        rows.append(row)
    return {
        "rows": rows,
        "max_diff": max_diff,
        "diff_pct": 100.0 * differing / max(pixels, 1),
        "ids_equal": ids_equal,
        "renderer": renderer,
        "size": list(size),
        "views_from": source,
    }


def format_fill_table(
    result: dict[str, Any], shadings: Sequence[str] = ("fragment", "vertex")
) -> str:
    """The fill benchmark as a text table: finish ms per case, the two paths side by side."""
    a, b = shadings
    w, h = result["size"]
    lines = [
        f"{w}x{h}, {result['renderer']}, {result['views_from']}; medians of ctx.finish() ms",
        f"{'case':<8} {'triangles':>9} {'finish ' + a:>16} {'finish ' + b:>14} {'ratio':>6}",
    ]
    for r in result["rows"]:
        fa, fb = r[f"finish_{a}"], r[f"finish_{b}"]
        ratio = fa / fb if fb > 0 else math.inf
        lines.append(f"{r['case']:<8} {r['triangles']:>9,} {fa:>16.2f} {fb:>14.2f} {ratio:>5.2f}x")
    lines.append(
        f"frames {a} vs {b} (floor and lod2): largest channel difference {result['max_diff']}/255, "
        f"{result['diff_pct']:.2f} % of pixels differ; object-id images "
        + ("equal" if result["ids_equal"] else "DIFFER")
    )
    return "\n".join(lines)
