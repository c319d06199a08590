"""Image error against frame time of LOD selection (``walkstream bench lod``).

Marvie et al. (2003) claim that sharing a polygon budget by ACH (section 4) gives a
better picture than the usual distance-threshold LOD selection at the same frame
rate.  This benchmark measures it on a baked scene.  For each of a few viewpoints
it renders, headless (:class:`~walkstream.client.draw.frames.FrameRenderer`):

* ``lod2``: every visible object of the cell's PVS at LOD2, the reference;
* ``ach``: :func:`~walkstream.client.draw.allocate.allocate_ach` with budgets that are fractions of
  that reference's triangle count (default 5, 10, 25 and 50 %);
* ``distance``: :func:`~walkstream.client.draw.allocate.allocate_distance` with thresholds ``d1 <= d2``
  (both fitted, or ``d2 = ratio * d1``; see :data:`DISTANCE_RATIO`) from
  :func:`~walkstream.client.draw.allocate.distance_thresholds_for_budget` for the triangles the ACH
  allocation actually used at that budget.  Equal triangle
  counts stand in for equal frame time (what the paper compares); the measured frame
  time of both is reported so the stand-in can be checked.  The ACH count rather
  than the nominal budget is matched because ACH may leave part of the budget
  unspent or, when floor-limited, exceed it.

Image error against the LOD2 frame of the same viewpoint: the share of pixels where
any colour channel differs by more than :data:`PIXEL_TOLERANCE` (of 255), and the mean
absolute colour difference on the 0-255 scale (over all pixels and channels).  Frame
times are the median of ``repeats`` timed draws after one warm-up draw, each finished
(``ctx.finish()``) before the clock stops; the configurations of one viewpoint are
timed round-robin so that drifting machine load spreads over all of them.

Viewpoints: evenly spaced in time along the recorded path ``SE`` when the scene has
one in the current format, otherwise the centroids of street cells (spread over the
cell ids), looking along each cell's long axis towards the middle of the scene.
Every viewpoint uses the PVS and ACH of the cell it stands in.
"""

from __future__ import annotations

import math
import os
import statistics
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from walkstream.shared.errors import CodecError, InputError, WalkstreamError

if TYPE_CHECKING:
    import moderngl

    from walkstream.server.store import CellInfo, SceneReader
    from walkstream.shared.lsystem.grammar import Grammar
    from walkstream.shared.records import Mesh

__all__ = [
    "DEFAULT_DB",
    "DEFAULT_SHARES",
    "EYE_HEIGHT",
    "PIXEL_TOLERANCE",
    "BenchView",
    "format_table",
    "image_error",
    "load_views",
    "plot_lod_bench",
    "run_lod_bench",
    "summary_line",
    "LodGeometry",
    "open_scene",
]

#: The scene ``make demo`` bakes.
DEFAULT_DB = Path("out/demo/city.db")
#: Budgets, as shares of the LOD2 triangle count of the visible objects.
DEFAULT_SHARES: tuple[float, ...] = (0.05, 0.10, 0.25, 0.50)
#: A pixel differs when any channel differs by more than this (0-255 scale).
PIXEL_TOLERANCE = 8
#: Eye height of the cell-centroid viewpoints, metres (clamped into the cell's range).
EYE_HEIGHT = 1.7
#: The recorded path whose positions are used when the scene has it.
PATH_NAME = "SE"

#: ``d2 / d1`` of the distance selection; None (the default) searches both thresholds
#: freely, which matches the ACH triangle count more closely (a fixed ratio of 2
#: leaves distance selection with 20-30 % fewer triangles on the demo city, because
#: one step of d1 moves whole buildings).
DISTANCE_RATIO: float | None = None
#: Relative difference of mean errors below which neither method is said to win.
TIE_TOLERANCE = 0.05

MODES = ("lod2", "ach", "distance")


# --------------------------------------------------------------------------- views


@dataclass(frozen=True, slots=True)
class BenchView:
    """One viewpoint: eye position (local metres), yaw and pitch (radians), its cell."""

    name: str
    eye: tuple[float, float, float]
    yaw: float
    pitch: float
    cell: int


def _locator(reader: SceneReader) -> Any:
    from walkstream.shared.cells import CellLocator

    cells = list(reader.cells())
    return CellLocator([c.id for c in cells], [c.boundary for c in cells])


def _path_views(reader: SceneReader, name: str, count: int) -> tuple[list[BenchView], str]:
    """Viewpoints along a recorded path; an empty list (and why) when it cannot be used."""
    if name not in reader.path_names():
        return [], f"no recorded path {name!r}"
    try:
        from walkstream.shared.paths import RecordedPath

        path = RecordedPath.from_msgpack(reader.path_blob(name), f"path {name!r}")
    except (ImportError, CodecError, InputError) as exc:
        return [], f"path {name!r} unreadable ({exc})"
    ts = (np.arange(count) + 0.5) / count * path.duration
    xyz, yaw, pitch = path.sample(ts)
    cids = _locator(reader).locate_many(xyz[:, :2])
    out = [
        BenchView(
            f"{name}@{t:.1f}s",
            (float(p[0]), float(p[1]), float(p[2])),
            float(y),
            float(pt),
            int(c),
        )
        for t, p, y, pt, c in zip(ts, xyz, yaw, pitch, cids, strict=True)
        if c >= 0
    ]
    if not out:
        return [], f"path {name!r} lies outside every cell"
    return out, f"path {name!r} ({len(out)} positions in cells)"


def _long_axis(boundary: NDArray[np.float64]) -> NDArray[np.float64]:
    """Unit direction of the principal axis of a cell outline."""
    pts = boundary - boundary.mean(axis=0)
    _, vecs = np.linalg.eigh(pts.T @ pts)
    return np.asarray(vecs[:, -1], dtype=np.float64)


def _cell_views(reader: SceneReader, count: int) -> list[BenchView]:
    cells = [c for c in reader.cells() if len(c.pvs)]
    street = [c for c in cells if c.kind == "street"]
    pool = street or cells
    if not pool:
        raise InputError(f"{reader.path}: no cell has a PVS to render")
    # cells that see at least the median number of objects: inside the city, rather
    # than on its edge looking out at empty land
    median = float(np.median([len(c.pvs) for c in pool]))
    pool = [c for c in pool if len(c.pvs) >= median]
    x0, y0, _, x1, y1, _ = reader.bounds()
    middle = np.array([(x0 + x1) / 2, (y0 + y1) / 2])
    picks = sorted({int(round(v)) for v in np.linspace(0, len(pool) - 1, min(count, len(pool)))})
    out = []
    for i in picks:
        c = pool[i]
        centre = c.boundary.mean(axis=0)
        axis = _long_axis(c.boundary)
        # look into the city rather than out of it
        if float(np.dot(middle - centre, axis)) < 0:
            axis = -axis
        z = min(max(EYE_HEIGHT, c.zmin), c.zmax)
        yaw = math.atan2(float(axis[1]), float(axis[0]))
        out.append(
            BenchView(f"{c.kind}{c.id}", (float(centre[0]), float(centre[1]), z), yaw, 0.0, c.id)
        )
    return out


def load_views(
    reader: SceneReader, count: int, path_name: str = PATH_NAME
) -> tuple[list[BenchView], str]:
    """The benchmark's viewpoints and a line saying where they come from.

    Parameters
    ----------
    reader : SceneReader
    count : int
        Viewpoints wanted (>= 1); fewer when the scene has fewer street cells.
    path_name : str
        Recorded path to take them from when present and readable.

    Returns
    -------
    views, source : list[BenchView], str
    """
    if count < 1:
        raise InputError(f"bench lod: --views must be >= 1, got {count}")
    views, why = _path_views(reader, path_name, count)
    if views:
        return views, why
    cells = _cell_views(reader, count)
    return cells, f"{len(cells)} street-cell centroids ({why})"


# --------------------------------------------------------------------------- geometry


@dataclass
class _Object:
    meshes: tuple[Mesh, Mesh, Mesh]
    tri: tuple[int, int, int]
    lo: NDArray[np.float64]
    hi: NDArray[np.float64]
    centre: NDArray[np.float64] = field(init=False)

    def __post_init__(self) -> None:
        self.centre = (self.lo + self.hi) / 2.0


class LodGeometry:
    """Rebuilds the three LODs of objects on demand and keeps them across viewpoints."""

    def __init__(self, reader: SceneReader, grammar: Grammar) -> None:
        self.reader = reader
        self.grammar = grammar
        self.objects: dict[int, _Object] = {}

    def get(self, ids: Sequence[int]) -> list[_Object]:
        from walkstream.shared.areas import build_area
        from walkstream.shared.buildings import build_lods
        from walkstream.shared.streets import build_street

        missing = [i for i in ids if i not in self.objects]
        info = self.reader.object_info(missing)
        for oid in missing:
            if oid not in info:
                raise InputError(f"{self.reader.path}: PVS names object {oid}, not in the scene")
            inf = info[oid]
            if inf.kind == "building":
                meshes = build_lods(self.reader.building(oid), self.grammar)
            else:
                flat = build_area(self.reader.area(oid)) if inf.kind == "area" else build_street(self.reader.street(oid))
                meshes = (flat, flat, flat)
            lo = np.array(inf.bbox[:3], dtype=np.float64)
            hi = np.array(inf.bbox[3:], dtype=np.float64)
            # the grammar may build above the stored box (roofs): take the meshes too
            for m in meshes:
                if m.triangles:
                    lo = np.minimum(lo, m.positions.min(axis=0))
                    hi = np.maximum(hi, m.positions.max(axis=0))
            tri = (meshes[0].triangles, meshes[1].triangles, meshes[2].triangles)
            self.objects[oid] = _Object(meshes, tri, lo, hi)
        return [self.objects[i] for i in ids]


# --------------------------------------------------------------------------- measures


def image_error(
    image: NDArray[np.uint8], reference: NDArray[np.uint8], tolerance: int = PIXEL_TOLERANCE
) -> tuple[float, float]:
    """Share of differing pixels and mean colour error of ``image`` against ``reference``.

    Parameters
    ----------
    image, reference : (h, w, 3) uint8
    tolerance : int
        A pixel differs when any channel differs by more than this.

    Returns
    -------
    differing, mean_error : float, float
        Share of pixels (0..1) and mean absolute channel difference (0..255).
    """
    a = np.asarray(image, dtype=np.int16)
    b = np.asarray(reference, dtype=np.int16)
    if a.shape != b.shape:
        raise InputError(f"image_error: shapes differ: {a.shape} vs {b.shape}")
    if a.size == 0:
        return 0.0, 0.0
    d = np.abs(a - b)
    return float(np.mean(d.max(axis=-1) > tolerance)), float(d.mean())


@dataclass
class _Config:
    mode: str
    share: float
    budget: int
    keys: list[tuple[int, int]]
    triangles: int
    floor_limited: bool
    thresholds: tuple[float, float] | None = None
    times: list[float] = field(default_factory=list)
    image: NDArray[np.uint8] | None = None


def _configs(
    ids: NDArray[np.int64],
    ach: NDArray[np.float64],
    objs: list[_Object],
    view_proj: NDArray[np.float64],
    eye: NDArray[np.float64],
    shares: Sequence[float],
    distance_ratio: float | None,
) -> list[_Config]:
    from walkstream.client.draw.allocate import (
        allocate_ach,
        allocate_distance,
        distance_thresholds_for_budget,
    )
    from walkstream.shared.frustum import frustum_cull

    k = len(objs)
    tri = np.array([o.tri for o in objs], dtype=np.int64).reshape(k, 3)
    lo = np.array([o.lo for o in objs]).reshape(k, 3)
    hi = np.array([o.hi for o in objs]).reshape(k, 3)
    centre = np.array([o.centre for o in objs]).reshape(k, 3)
    available = np.ones((k, 3), bool)
    visible = frustum_cull(lo, hi, view_proj)
    full = int(tri[visible, 2].sum())

    def keys(lod: NDArray[np.int8]) -> list[tuple[int, int]]:
        return [(int(i), int(level)) for i, level in zip(ids, lod, strict=True) if level >= 0]

    ref = np.where(visible, 2, -1).astype(np.int8)
    out = [_Config("lod2", 1.0, full, keys(ref), full, False)]
    dist = np.linalg.norm(centre - eye, axis=1)
    for s in shares:
        budget = int(round(s * full))
        a = allocate_ach(ach, tri, available, visible, budget)
        out.append(_Config("ach", s, budget, keys(a.lod), a.triangles, a.floor_limited))
        th = distance_thresholds_for_budget(
            dist, tri, available, visible, a.triangles, ratio=distance_ratio
        )
        d = allocate_distance(dist, tri, available, visible, th, budget=budget)
        out.append(_Config("distance", s, budget, keys(d.lod), d.triangles, d.floor_limited, th))
    return out


# --------------------------------------------------------------------------- run


def open_scene(db_path: str | os.PathLike[str]) -> SceneReader:
    """The scene database at ``db_path``, or a clear error when there is none."""
    from walkstream.server.store import SceneReader

    if not os.path.exists(db_path):
        raise WalkstreamError(
            f"{os.fspath(db_path)}: no scene database; run `make demo` first or pass one"
        )
    return SceneReader.open(db_path)


def run_lod_bench(
    db_path: str | os.PathLike[str] = DEFAULT_DB,
    *,
    views: int = 8,
    shares: Sequence[float] = DEFAULT_SHARES,
    size: tuple[int, int] = (640, 480),
    repeats: int = 5,
    fov_deg: float = 60.0,
    path_name: str = PATH_NAME,
    images: str | os.PathLike[str] | None = None,
    image_share: float | None = None,
    distance_ratio: float | None = DISTANCE_RATIO,
    ctx: moderngl.Context | None = None,
    progress: bool = True,
) -> list[dict[str, Any]]:
    """Render the viewpoints in every mode and measure image error and frame time.

    Parameters
    ----------
    db_path : path
        Scene database.
    views : int
        Viewpoints (see :func:`load_views`).
    shares : sequence of float
        Budgets as shares (0, 1] of the LOD2 triangle count of the visible objects.
    size : (int, int)
        Frame width and height.
    repeats : int
        Timed draws per configuration (the median is reported), after one warm-up.
    fov_deg : float
        Vertical field of view.
    path_name : str
        Recorded path to take viewpoints from when the scene has it.
    images : path, optional
        Also write a side-by-side PNG of the first viewpoint (LOD2, ACH, distance and
        their differences from LOD2) at ``image_share`` (default: the share closest to
        10 %).
    ctx : moderngl.Context, optional
        GL context (default: a new headless one).
    progress : bool
        Show a tqdm bar on stderr.

    Returns
    -------
    list of dict
        One row per (mode, share), means over the viewpoints: ``mode``, ``share``,
        ``budget``, ``triangles``, ``frame_ms`` (mean of the per-viewpoint medians),
        ``differing_pct``, ``mean_color_error``, ``floor_limited`` (viewpoints),
        ``views``, ``views_from``, ``renderer``, ``size``, ``tolerance``, and
        ``per_view`` (the same figures per viewpoint; distance rows add ``d1``).
    """
    from tqdm import tqdm

    from walkstream.client.draw.frames import FrameRenderer
    from walkstream.shared.camera import camera
    from walkstream.shared.lsystem.grammar import parse_grammar

    sh = [float(s) for s in shares]
    if not sh or any(not (0.0 < s <= 1.0) for s in sh):
        raise InputError(f"bench lod: budget shares must be in (0, 1], got {list(shares)}")
    if repeats < 1:
        raise InputError(f"bench lod: --repeat must be >= 1, got {repeats}")
    reader = open_scene(db_path)
    try:
        grammar = parse_grammar(reader.meta.grammar_text)
        bench_views, source = load_views(reader, views, path_name)
        x0, y0, z0, x1, y1, z1 = reader.bounds()
        far = max(100.0, 1.2 * math.sqrt((x1 - x0) ** 2 + (y1 - y0) ** 2 + (z1 - z0) ** 2))
        geometry = LodGeometry(reader, grammar)
        per_view: list[tuple[BenchView, list[_Config]]] = []
        with FrameRenderer(size, fov_deg=fov_deg, far=far, ctx=ctx) as fr:
            renderer = str(fr.ctx.info.get("GL_RENDERER", "?"))
            bar = tqdm(
                bench_views, desc="bench lod", unit="view", file=sys.stderr, disable=not progress
            )
            for v in bar:
                cell: CellInfo = reader.cell(v.cell)
                ids = cell.pvs
                objs = geometry.get([int(i) for i in ids])
                wanted = {int(i) for i in ids}
                for key in fr.keys():  # keep GPU memory to one PVS
                    assert isinstance(key, tuple)
                    if key[0] not in wanted:
                        fr.forget(key)
                for oid, o in zip(ids, objs, strict=True):
                    for level in range(3):
                        if not fr.has((int(oid), level)):
                            fr.upload((int(oid), level), o.meshes[level])
                view = camera(v.eye, v.yaw, v.pitch)
                vp = fr.proj.astype(np.float64) @ view.astype(np.float64)
                configs = _configs(ids, cell.ach, objs, vp, np.array(v.eye), sh, distance_ratio)
                for rnd in range(repeats + 1):  # round 0: warm-up and snapshot
                    for c in configs:
                        dt = fr.draw(c.keys, view)
                        if rnd == 0:
                            c.image = fr.snapshot()
                        else:
                            c.times.append(dt)
                per_view.append((v, configs))
            bar.close()
    finally:
        reader.close()
    rows = _aggregate(per_view, sh, source, renderer, size)
    if images is not None and per_view:
        want = image_share if image_share is not None else min(sh, key=lambda s: abs(s - 0.1))
        write_side_by_side(per_view[0][0], per_view[0][1], want, images)
    return rows


def _aggregate(
    per_view: list[tuple[BenchView, list[_Config]]],
    shares: list[float],
    source: str,
    renderer: str,
    size: tuple[int, int],
) -> list[dict[str, Any]]:
    keys = [("lod2", 1.0)] + [(m, s) for s in shares for m in ("ach", "distance")]
    rows: list[dict[str, Any]] = []
    for mode, share in keys:
        items = []
        for v, configs in per_view:
            ref = configs[0].image
            c = next(c for c in configs if c.mode == mode and c.share == share)
            assert ref is not None and c.image is not None
            diff, err = image_error(c.image, ref)
            item: dict[str, Any] = {
                "view": v.name,
                "cell": v.cell,
                "budget": c.budget,
                "triangles": c.triangles,
                "frame_ms": 1e3 * statistics.median(c.times),
                "differing_pct": 100.0 * diff,
                "mean_color_error": err,
                "floor_limited": c.floor_limited,
            }
            if c.thresholds is not None:
                item["d1"], item["d2"] = c.thresholds
            items.append(item)

        def mean(name: str, items: list[dict[str, Any]] = items) -> float:
            return float(np.mean([it[name] for it in items])) if items else float("nan")

        rows.append(
            {
                "mode": mode,
                "share": share,
                "budget": mean("budget"),
                "triangles": mean("triangles"),
                "frame_ms": mean("frame_ms"),
                "differing_pct": mean("differing_pct"),
                "mean_color_error": mean("mean_color_error"),
                "floor_limited": sum(bool(it["floor_limited"]) for it in items),
                "views": len(items),
                "views_from": source,
                "renderer": renderer,
                "size": list(size),
                "tolerance": PIXEL_TOLERANCE,
                "per_view": items,
            }
        )
    return rows


# --------------------------------------------------------------------------- output


def _pairs(rows: Sequence[dict[str, Any]]) -> list[tuple[dict[str, Any], dict[str, Any]]]:
    ach = {r["share"]: r for r in rows if r["mode"] == "ach"}
    dist = {r["share"]: r for r in rows if r["mode"] == "distance"}
    return [(ach[s], dist[s]) for s in sorted(ach) if s in dist]


def summary_line(rows: Sequence[dict[str, Any]]) -> str:
    """Whether ACH beats distance selection at equal frame time, from the measured rows."""
    pairs = _pairs(rows)
    if not pairs:
        return "no ACH/distance pairs measured"
    n = len(pairs)
    err_wins = sum(a["mean_color_error"] < d["mean_color_error"] for a, d in pairs)
    px_wins = sum(a["differing_pct"] < d["differing_pct"] for a, d in pairs)
    a_err = float(np.mean([a["mean_color_error"] for a, _ in pairs]))
    d_err = float(np.mean([d["mean_color_error"] for _, d in pairs]))
    a_px = float(np.mean([a["differing_pct"] for a, _ in pairs]))
    d_px = float(np.mean([d["differing_pct"] for _, d in pairs]))
    ratio = float(np.mean([d["frame_ms"] / a["frame_ms"] for a, d in pairs if a["frame_ms"] > 0]))

    def better(x: float, y: float) -> int:
        """1: x clearly lower, -1: clearly higher, 0: within TIE_TOLERANCE."""
        if abs(x - y) <= TIE_TOLERANCE * max(abs(x), abs(y)):
            return 0
        return 1 if x < y else -1

    score = (better(a_err, d_err), better(a_px, d_px))
    if min(score) >= 0 and max(score) > 0:
        verdict = "yes, ACH beats distance here"
    elif max(score) <= 0 and min(score) < 0:
        verdict = "no, distance beats ACH here"
    elif score == (0, 0):
        verdict = f"no clear winner (means within {100 * TIE_TOLERANCE:.0f}%)"
    else:
        verdict = "mixed: each wins on one measure"
    views = pairs[0][0]["views"]
    return (
        f"ACH vs distance at equal triangles ({views} viewpoints): {verdict}. "
        f"Mean colour error {a_err:.2f} vs {d_err:.2f} (ACH lower at {err_wins}/{n} budgets), "
        f"differing pixels {a_px:.1f}% vs {d_px:.1f}% (ACH lower at {px_wins}/{n}); "
        f"distance frame time {ratio:.2f}x ACH's (equal time check)."
    )


def format_table(rows: Sequence[dict[str, Any]]) -> str:
    """The rows as a fixed-width text table with the summary line."""
    head = (
        f"{'mode':<9} {'budget':>7} {'triangles':>10} {'frame ms':>9} "
        f"{'differing %':>12} {'colour err':>11} {'floor-lim':>9}"
    )
    lines = []
    if rows:
        r0 = rows[0]
        w, h = r0["size"]
        lines.append(
            f"viewpoints: {r0['views_from']}; {w}x{h} on {r0['renderer']}; "
            f"differing = any channel off by more than {r0['tolerance']}/255"
        )
    lines += [head, "-" * len(head)]
    for r in rows:
        share = "100%" if r["mode"] == "lod2" else f"{100 * r['share']:.0f}%"
        lines.append(
            f"{r['mode']:<9} {share:>7} {r['triangles']:>10,.0f} {r['frame_ms']:>9.2f} "
            f"{r['differing_pct']:>12.2f} {r['mean_color_error']:>11.2f} "
            f"{r['floor_limited']:>5}/{r['views']:<3}"
        )
    lines.append(summary_line(rows))
    return "\n".join(lines) + "\n"


def plot_lod_bench(rows: Sequence[dict[str, Any]], path: str | os.PathLike[str]) -> None:
    """Write a PNG: image error (two panels) against frame time for ACH and distance.

    Each point is one budget (labelled with its share), means over the viewpoints;
    the LOD2 reference is the star at zero error and a dotted vertical line.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 4.6), dpi=120)
    FigureCanvasAgg(fig)
    ref = [r for r in rows if r["mode"] == "lod2"]
    style = {"ach": ("#1f77b4", "o", "ACH allocation"), "distance": ("#d62728", "s", "distance")}
    for k, (key, label) in enumerate(
        (
            ("mean_color_error", "mean colour error (0-255)"),
            ("differing_pct", "differing pixels (%)"),
        )
    ):
        ax = fig.add_subplot(1, 2, k + 1)
        for mode, (colour, marker, name) in style.items():
            rs = sorted((r for r in rows if r["mode"] == mode), key=lambda r: r["share"])
            if not rs:
                continue
            xs = [r["frame_ms"] for r in rs]
            ys = [r[key] for r in rs]
            ax.plot(xs, ys, color=colour, marker=marker, label=name)
            for r, x, y in zip(rs, xs, ys, strict=True):
                ax.annotate(
                    f"{100 * r['share']:.0f}%",
                    (x, y),
                    xytext=(4, 4),
                    textcoords="offset points",
                    fontsize=7,
                    color=colour,
                )
        for r in ref:
            ax.axvline(r["frame_ms"], color="#555555", linestyle=":", linewidth=1)
            ax.plot([r["frame_ms"]], [0.0], marker="*", markersize=12, color="black", label="LOD2")
        ax.set_xlabel("frame time (ms, median per viewpoint, mean over viewpoints)")
        ax.set_ylabel(label)
        ax.set_ylim(bottom=0)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
    if rows:
        r0 = rows[0]
        fig.suptitle(
            f"LOD selection: image error against frame time "
            f"({r0['views']} viewpoints, {r0['size'][0]}x{r0['size'][1]})",
            fontsize=11,
        )
    fig.tight_layout()
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    fig.savefig(os.fspath(path), format="png")


def write_side_by_side(
    view: BenchView,
    configs: Sequence[_Config],
    share: float,
    path: str | os.PathLike[str],
) -> None:
    """PNG of one viewpoint: LOD2, ACH and distance frames, and their differences from LOD2."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    ref = configs[0]
    shares = sorted({c.share for c in configs if c.mode == "ach"})
    s = min(shares, key=lambda x: abs(x - share))
    ach = next(c for c in configs if c.mode == "ach" and c.share == s)
    dist = next(c for c in configs if c.mode == "distance" and c.share == s)
    assert ref.image is not None and ach.image is not None and dist.image is not None
    h, w = ref.image.shape[:2]
    fig = Figure(figsize=(3 * 4.2, 2 * 4.2 * h / w + 0.9), dpi=110)
    FigureCanvasAgg(fig)

    def panel(i: int, img: NDArray[Any], title: str, **kw: Any) -> None:
        ax = fig.add_subplot(2, 3, i)
        ax.imshow(img, interpolation="nearest", **kw)
        ax.set_title(title, fontsize=9)
        ax.set_axis_off()

    panel(1, ref.image, f"LOD2 reference: {ref.triangles:,} triangles")
    panel(2, ach.image, f"ACH {100 * s:.0f}%: {ach.triangles:,} triangles")
    panel(
        3,
        dist.image,
        f"distance (d1={dist.thresholds[0] if dist.thresholds else 0:.0f} m): {dist.triangles:,} triangles",
    )
    for i, c, name in ((5, ach, "ACH"), (6, dist, "distance")):
        assert c.image is not None
        d = np.abs(c.image.astype(np.int16) - ref.image.astype(np.int16)).max(axis=-1)
        frac, err = image_error(c.image, ref.image)
        panel(
            i,
            d,
            f"|{name} - LOD2|: {100 * frac:.1f}% differ, mean error {err:.2f}",
            cmap="magma",
            vmin=0,
            vmax=255,
        )
    ax = fig.add_subplot(2, 3, 4)
    ax.set_axis_off()
    ax.text(
        0.02,
        0.5,
        f"viewpoint {view.name}\ncell {view.cell}\nbudget {100 * s:.0f}% of LOD2 = {ach.budget:,}\n"
        f"differing: any channel > {PIXEL_TOLERANCE}/255",
        fontsize=9,
        va="center",
    )
    fig.tight_layout()
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    fig.savefig(os.fspath(path), format="png")


# --------------------------------------------------------------------------- CLI
