"""Why the PVS misses what a walker sees, pose by pose (``walkstream bench pvs-misses``).

``bench stream --truth-every N`` says how many of a frame's pixels show an object
missing from the PVS of the viewer's cell (cause ``pvs``); this benchmark says *why*
each such object was left out.  It needs no streaming: the ``pvs`` cause depends only
on where the eye is and on the stored PVS, so it walks a database's recorded path
itself, every ``every`` seconds of walk time (``bench stream``'s every 25th frame at
25 fps is every second), and at each pose:

1. renders the ground truth (:class:`~walkstream.client.truth.render.TruthRenderer`,
   every object at LOD2, the client's camera: 640 x 480, 60 degrees);
2. locates the eye in its cell as the client does (2D, the cells' outlines) and lists
   the objects the truth shows that the cell's stored PVS lacks, with their pixels;
3. for each missed object, renders the six cube faces *from the eye itself* with the
   bake's renderer to tell the reasons apart, the first that holds:

   ``sampling``
       the eye sees it at the bake's resolution and occluder LOD: the cell's sample
       points missed what a position between them sees (their placement over the
       cell, its edges and heights);
   ``resolution``
       the eye sees it with the bake's LOD only at the *client's* angular
       resolution (cube faces of :func:`client_face_pixels`: as many pixels per
       degree as the client's frame at the centre): under a bake pixel;
   ``geometry``
       the eye sees it at the client's resolution only with every object at LOD2
       (the geometry the truth draws sticks out of the boxes the bake renders);
   ``pixel centres``
       no cube face from the eye shows it even then: a sliver under a pixel that
       the truth's pixel centres catch and the cube faces' do not;
   ``outside``
       the eye is in no cell (no PVS at all).

The floor the per-frame figure puts under the PVS: an object that alone covers more
than :data:`OVER_SHARE` of some pose's frame must be in the PVS of that pose's cell, or
the pose is over whatever else the PVS holds.  ``floor`` gathers those objects per
visited cell and sets their count beside the stored PVS's over the same cells, and
beside a yardstick database's (``yardstick``: the same source baked another way, for
example ``--sampling corners --resolution 64``, the first bake, against which the issue
bounds the PVS).  It is a floor, not the whole need: several objects under the share
together can put a pose over too.  ``need`` estimates the whole need: at each pose the
objects left when the least-seen are left out while they stay within the share
together, gathered per cell (each pose chooses alone, so a PVS chosen for all its poses
at once could hold a little less).

Besides, per pose: whether the eye is inside its cell's outline, its distance to the
outline and to the nearest of the cell's sample points (the bake's own
:func:`~walkstream.server.bake.workers.cell_points`, with the far band's axis points of
:func:`~walkstream.server.bake.workers.band_points` when the bake has them), and its height against the
cell's eye-height range.  The figures are ``bench stream``'s: the share of poses whose
``pvs`` pixels exceed 0.01 % of the frame, and their mean share.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
import shapely

from walkstream.benchmarks.visinput import scene_from_database
from walkstream.server.bake.idpack import meshes_for_scene
from walkstream.server.bake.settings import BakeSettings
from walkstream.server.bake.visibility import VisibilityRenderer
from walkstream.server.bake.workers import band_points, cell_points
from walkstream.shared.camera import camera
from walkstream.shared.cells import CellLocator
from walkstream.shared.errors import InputError
from walkstream.shared.paths import RecordedPath

if TYPE_CHECKING:
    import moderngl

__all__ = ["REASONS", "OVER_SHARE", "client_face_pixels", "frame_need", "pvs_floor", "run_pvs_misses", "format_pvs_misses"]

#: the reasons an object is missed, in the order they are tried (see the module docs)
REASONS: tuple[str, ...] = ("sampling", "resolution", "geometry", "pixel centres", "outside")
#: a pose is "over" when its ``pvs`` pixels exceed this share of the frame (the issue's 0.01 %)
OVER_SHARE = 1e-4


def client_face_pixels(width: int, fov_deg: float) -> int:
    """Pixels of a 90-degree cube face with the client's pixels per degree at both centres.

    A perspective image is coarsest at its centre (per degree), so a face this wide is
    at least as fine as the client's frame everywhere: ``width / tan(fov / 2)``.

    >>> client_face_pixels(640, 60.0)
    1109
    """
    if width < 1 or not 0.0 < fov_deg < 180.0:
        raise InputError(f"client_face_pixels: expected width >= 1 and 0 < fov < 180, got {width}, {fov_deg}")
    return int(math.ceil(width / math.tan(math.radians(fov_deg) / 2.0) - 1e-9))


def run_pvs_misses(
    database: str | os.PathLike[str],
    paths: Sequence[str],
    *,
    every: float = 1.0,
    size: tuple[int, int] = (640, 480),
    fov_deg: float = 60.0,
    top: int = 5,
    yardstick: str | os.PathLike[str] | None = None,
    ctx: moderngl.Context | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> dict[str, Any]:
    """Every pose's ``pvs`` misses along the paths, each missed object with its reason.

    Parameters
    ----------
    database : path
        A baked city database (street or grid cells with a PVS, recorded paths).
    paths : sequence of str
        Names of its recorded paths.
    every : float
        Seconds of walk time between poses (> 0).
    size, fov_deg
        The client's frame and horizontal field of view (the truth's camera).
    top : int
        Objects listed per pose in ``rows`` (the largest misses); every missed
        object of a pose over :data:`OVER_SHARE` counts in ``reasons`` whatever ``top``.
    yardstick : path, optional
        Another bake of the same source and cells whose PVS sizes ``floor`` compares with.
    ctx : moderngl.Context, optional
        Context for every renderer; by default one is made and released.
    progress : callable, optional
        Called with ``(poses done, poses total)``.

    Returns
    -------
    dict
        ``paths``: per path ``{"poses", "over", "mean", "reasons": {reason: pixels}}``
        (the reasons of every missed pixel of the poses over :data:`OVER_SHARE`, the
        poses that count; the probes are not rendered for the others);
        ``floor``: :func:`pvs_floor` over the visited cells;
        ``rows``: per pose over :data:`OVER_SHARE`, ``{"path", "t", "cell", "share",
        "eye", "inside", "to_outline", "to_sample", "zrange", "objects": [{"id",
        "kind", "pixels", "depth", "reason"}]}``; ``probe_resolution``, ``settings``.
    """
    from walkstream.client.truth.render import TruthRenderer
    from walkstream.server.store import SceneReader
    from walkstream.shared.gl import create_context

    if not every > 0 or not math.isfinite(every):
        raise InputError(f"--every {every}: expected a positive number of seconds")
    scene, cells, baked, settings = scene_from_database(database)
    other = _yardstick(yardstick, cells) if yardstick is not None else None
    with SceneReader.open(database) as reader:
        known = reader.path_names()
        bad = [p for p in paths if p not in known]
        if bad:
            raise InputError(f"--paths: no recorded path {bad[0]!r} in {database} (it has: {', '.join(known) or 'none'})")
        walks = {p: RecordedPath.from_msgpack(reader.path_blob(p), p) for p in paths}
    bs = BakeSettings(**{k: v for k, v in settings.items() if k in BakeSettings.__dataclass_fields__})
    loc = CellLocator.of_kinds(
        [c.id for c in cells], [c.kind for c in cells], [c.polygon for c in cells], [[c.zmin, c.zmax] for c in cells]
    )
    by_id = {c.id: c for c in cells}
    kind = {b.id: "building" for b in scene.buildings} | {s.id: s.kind for s in scene.streets}
    kind |= {a.id: "area" for a in scene.areas}
    footprints = shapely.STRtree([shapely.Polygon(b.rings[0], b.rings[1:]) for b in scene.buildings])
    probe = client_face_pixels(size[0], fov_deg)

    own = ctx is None
    gl = create_context() if ctx is None else ctx
    m_bake, i_bake = meshes_for_scene(scene, bs.occluder_lod)
    m_lod2, i_lod2 = meshes_for_scene(scene, 2)
    renderers: list[Any] = []
    try:
        truth = TruthRenderer(dict(zip(i_lod2.tolist(), m_lod2, strict=True)), size, fov_deg=fov_deg, near=0.5, ctx=gl)
        renderers.append(truth)
        key_id = np.array([-1 - k[0] for k in truth.keys], np.int64)
        probes = []
        for meshes, ids, res in ((m_bake, i_bake, bs.resolution), (m_bake, i_bake, probe), (m_lod2, i_lod2, probe)):
            probes.append(VisibilityRenderer(meshes, ids, resolution=res, view_distance=bs.view_distance, ctx=gl,
                                             max_points_per_pass=1))
            renderers.append(probes[-1])
        total = sum(len(np.arange(0.0, w.duration, every)) for w in walks.values())
        done, rows, figures = 0, [], {}
        must: dict[int, set[int]] = {}
        need: dict[int, set[int]] = {}
        frame = float(size[0] * size[1])
        for name, walk in walks.items():
            shares, reasons = [], dict.fromkeys(REASONS, 0)
            for t in np.arange(0.0, walk.duration, every):
                xyz, yaw, pitch = walk.at(float(t))
                eye = np.asarray(xyz, np.float64)
                keys, depth = truth.render(eye, camera(eye, float(yaw), float(pitch)).astype(np.float64))
                shown = keys >= 0
                obj = key_id[keys[shown]]
                cid = loc.locate(float(eye[0]), float(eye[1]))
                pvs = baked.get(cid, np.zeros(0, np.int64)) if cid is not None else np.zeros(0, np.int64)
                ids, px = np.unique(obj, return_counts=True)
                if cid is not None:
                    n_ids, m_ids = frame_need(ids, px, frame)
                    need.setdefault(cid, set()).update(n_ids.tolist())
                    must.setdefault(cid, set()).update(m_ids.tolist())
                out = ~np.isin(ids, pvs)
                share = float(px[out].sum()) / frame
                shares.append(share)
                done += 1
                if progress is not None:
                    progress(done, total)
                if share <= OVER_SHARE:
                    continue  # the probes are the slow part: only the poses that count
                seen = [dict(zip(*(a.tolist() for a in r.cell_counts(eye[None])), strict=True)) for r in probes]
                listed: list[dict[str, Any]] = []
                for j in np.flatnonzero(out)[np.argsort(-px[out], kind="stable")]:
                    o = int(ids[j])
                    r = "outside" if cid is None else next(
                        (REASONS[k] for k in range(3) if seen[k].get(o, 0) > 0), "pixel centres"
                    )
                    reasons[r] += int(px[j])
                    if len(listed) < top:
                        listed.append({"id": o, "kind": kind.get(o, "?"), "pixels": int(px[j]),
                                       "depth": float(depth[shown][obj == o].min()), "reason": r})
                rows.append(_pose_row(name, float(t), eye, cid, share, listed, by_id, bs, footprints))
            sh = np.asarray(shares) if shares else np.zeros(1)
            figures[name] = {"poses": len(shares), "over": float(np.mean(sh > OVER_SHARE)), "mean": float(sh.mean()),
                             "reasons": reasons}
        return {"paths": figures, "rows": rows, "probe_resolution": probe, "settings": settings,
                "floor": pvs_floor(must, baked, other) | {"need_mean": float(np.mean([len(v) for v in need.values()]))
                                                           if need else 0.0}}
    finally:
        for r in renderers:
            r.release()
        if own:
            gl.release()


def frame_need(ids: np.ndarray, pixels: np.ndarray, frame: float) -> tuple[np.ndarray, np.ndarray]:
    """What a PVS must hold for one frame to stay within :data:`OVER_SHARE` of its ``frame`` pixels.

    ``ids``/``pixels``: the objects the frame's truth shows and their pixels.  Returns
    ``(need, must)``: the objects left when the least-seen are left out while they stay
    within the share together (the fewest that frame can do with), and those that alone
    cover more than the share (no PVS without them keeps the frame within it).

    >>> need, must = frame_need(np.array([4, 5, 6]), np.array([900, 2, 1]), 10_000.0)
    >>> need.tolist(), must.tolist()
    ([5, 4], [4, 5])
    """
    order = np.argsort(pixels, kind="stable")
    spare = np.cumsum(pixels[order]) <= OVER_SHARE * frame
    return ids[order[~spare]], ids[pixels > OVER_SHARE * frame]


def pvs_floor(
    must: dict[int, set[int]], baked: dict[int, np.ndarray], yardstick: dict[int, np.ndarray] | None = None,
) -> dict[str, Any]:
    """The objects each visited cell's PVS must hold, against the stored PVS and a yardstick's.

    ``must`` maps a visited cell to the objects that alone put one of its poses over
    :data:`OVER_SHARE`.  Returns the means over those cells of the must-hold objects
    (``must_mean``), of the stored PVS (``pvs_mean``) and of the yardstick's
    (``yardstick_mean``, None without one), the must-hold objects the stored PVS lacks
    (``lacking``), and ``must_ratio`` = ``must_mean / yardstick_mean``: over the issue's
    bound, no PVS that keeps every pose under the share fits the bound in these cells.
    """
    cells = sorted(must)

    def mean(sizes: list[int]) -> float:
        return float(np.mean(sizes)) if sizes else 0.0

    mm = mean([len(must[c]) for c in cells])
    ym = mean([len(yardstick.get(c, ())) for c in cells]) if yardstick is not None else None
    return {
        "cells": len(cells),
        "must_mean": mm,
        "pvs_mean": mean([len(baked.get(c, ())) for c in cells]),
        "yardstick_mean": ym,
        "must_ratio": mm / ym if ym else None,
        "lacking": int(sum(len(must[c] - set(np.asarray(baked.get(c, ())).tolist())) for c in cells)),
    }


def _yardstick(path: str | os.PathLike[str], cells: Sequence[Any]) -> dict[int, np.ndarray]:
    """The PVS of another bake of the same cells (``--yardstick``); a clear error when its cells differ."""
    _, ycells, ybaked, _ = scene_from_database(path)
    same = len(ycells) == len(cells) and all(
        a.id == b.id and np.shape(a.polygon) == np.shape(b.polygon) and np.allclose(a.polygon, b.polygon)
        for a, b in zip(ycells, cells, strict=True)
    )
    if not same:
        raise InputError(f"--yardstick {path}: its cells are not the database's (bake the same source with the same cell settings)")
    return ybaked


def _pose_row(
    path: str, t: float, eye: np.ndarray, cid: int | None, share: float, objects: list[dict[str, Any]],
    by_id: dict[int, Any], bs: BakeSettings, footprints: shapely.STRtree,
) -> dict[str, Any]:
    """One pose over the share: where the eye is against its cell and the cell's sample points."""
    row: dict[str, Any] = {"path": path, "t": t, "cell": cid, "share": share, "eye": eye.round(2).tolist(),
                           "objects": objects, "inside": False, "to_outline": math.nan, "to_sample": math.nan,
                           "zrange": None}
    if cid is None:
        return row
    c = by_id[cid]
    poly = shapely.Polygon(c.polygon)
    p = shapely.Point(float(eye[0]), float(eye[1]))
    # the band's axis points (``--far-axis``) are samples too: a pose near one is not far from every sample
    pts = band_points(bs, cell_points(bs, c.polygon, c.zmin, c.zmax, footprints), np.asarray(c.polygon, np.float64),
                      c.zmin, c.zmax, footprints)
    row.update(
        inside=bool(poly.covers(p)),
        to_outline=float(poly.exterior.distance(p)),
        to_sample=float(np.hypot(*(pts[:, :2] - eye[:2]).T).min()) if len(pts) else math.nan,
        zrange=[float(c.zmin), float(c.zmax)],
    )
    return row


def format_pvs_misses(result: dict[str, Any], worst: int = 8) -> str:
    """The figures and reasons per path, then the ``worst`` poses with their missed objects."""
    lines = [f"{'path':<10} {'poses':>5} {'over 0.01%':>10} {'mean':>9}  pixels missed by reason"]
    for name, f in result["paths"].items():
        tot = sum(f["reasons"].values()) or 1
        why = ", ".join(f"{k} {v} ({100 * v / tot:.0f} %)" for k, v in f["reasons"].items() if v)
        lines.append(f"{name:<10} {f['poses']:>5} {100 * f['over']:>9.1f}% {f['mean']:>9.2e}  {why or '-'}")
    fl = result.get("floor")
    if fl and fl["cells"]:
        ys = "" if fl["yardstick_mean"] is None else (
            f", the yardstick's {fl['yardstick_mean']:.1f}: the floor is {fl['must_ratio']:.2f} x the yardstick's")
        lines.append(
            f"floor over the {fl['cells']} visited cells: {fl['must_mean']:.1f} objects a cell that alone put a pose "
            f"over 0.01 % (the PVS must hold them; {fl['lacking']} not in the stored PVS), stored PVS "
            f"{fl['pvs_mean']:.1f}{ys}"
        )
        nr = "" if not fl["yardstick_mean"] else f" ({fl['need_mean'] / fl['yardstick_mean']:.2f} x the yardstick's)"
        lines.append(
            f"need (estimate): {fl['need_mean']:.1f} objects a cell keep every pose of its cell under 0.01 % "
            f"when each pose leaves out its least-seen objects{nr}"
        )
    rows = sorted(result["rows"], key=lambda r: -r["share"])[:worst]
    if rows:
        lines.append("")
        lines.append(f"worst poses (probe faces {result['probe_resolution']} px: the client's pixels per degree)")
    for r in rows:
        z = "-" if r["zrange"] is None else f"{r['zrange'][0]:.2f}-{r['zrange'][1]:.2f}"
        lines.append(
            f"{r['path']} t {r['t']:.0f} s  cell {r['cell']}  {100 * r['share']:.4f} %  eye {r['eye']}  "
            f"inside {r['inside']}  to outline {r['to_outline']:.1f} m  to nearest sample {r['to_sample']:.1f} m  z {z}"
        )
        for o in r["objects"]:
            lines.append(f"    {o['kind']:<10} {o['id']:>6} {o['pixels']:>5} px at {o['depth']:6.1f} m  {o['reason']}")
    return "\n".join(lines)
