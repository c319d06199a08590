"""The floor under ``wall1%``: the walls' visibly wrong share of the frame with ideal textures
(``walkstream bench wall-floor DB SOURCE --report REPORT``).

Issue 28 asks that a ring wall's texture leave at most 1 % of the frame visibly wrong
(CIEDE2000 over :data:`~walkstream.client.truth.colour.VISIBLE_DE`) on 99 % of the
compared frames; the truth counts it as the cause ``wall`` (``colour_wall`` of a
report's ``truth.csv``), and ``wall1%`` is the share of compared frames where it is at
most 1 %.  Zones, parallax and the codec each take some of the error; this settles what
is left when all three are perfect and only the texel density stays: the same walk
replayed (in this process, ``walkstream replay DB --clock sim ...``, its report written
to ``REPORT``), and at each compared frame the frame's colour error measured again, by
the truth's own code (:func:`~walkstream.client.truth.picture.colour_error`, its
``impostor`` hook painting the walls with the truth's
:meth:`~walkstream.client.truth.render.TruthRenderer.paint_quads`, the client's
:class:`~walkstream.client.draw.quads.QuadRenderer`: nearest texel when minified,
bilinear when magnified), with each wall quad's texture replaced:

``today``
    the stored texture as the client laid it (the replay's own ``colour_wall``);
``zone``
    the zone's texture rendered again here from its sampling point at the stored
    density (the ring's objects left as holes as the bake leaves them,
    :func:`ring_holes`), no codec, laid by the client's warp: the stored texture less
    its codec (the same texels when the bake stored them lossless);
``zone webp75``
    the same through WebP at quality 75 and back (the outdoor default's codec);
``eye xM``
    the **ideal** texture: rendered from the frame's own eye through the wall's quad
    (:meth:`~walkstream.server.bake.wallrender.WallRenderer.render` with ``eye``: no
    zone, no parallax, no codec) at ``M`` times the stored texels a metre, drawn on the
    quad unwarped (``M`` = 1: the floor at today's density);
``frame xF``
    the same with ``F`` texels a frame pixel where the wall's plane is nearest the eye
    (:func:`frame_width`): a check on the measure itself, which goes to 0 only as ``F``
    grows, since the truth is point-sampled and a texture is the scene sampled on
    another grid (what stays is on the truth's edges, :func:`edge_mask`).

The other quads, the geometry, the fog and the opacities (a wall blending into the
geometry or into its neighbour zone) stay as the client drew them.  Per variant the
table gives ``wall1%`` (frames with the walls' visibly wrong share at most 1 % of the
frame), that share's median, 90th and 99th percentile and mean, the walls' painted
share, the texels a metre, with ``--viewer-ppd P`` the same count at the viewer's scale
(S-CIELAB), and what the textures would cost: raw (texels x 4 bytes) and as WebP at
quality 75 and lossless, for the distinct textures the compared frames drew rendered
from their zones' sampling points as the bake stores them (:func:`texture_costs`), and
scaled to the walk (its texture bytes sent times each codec's ratio to the stored
bytes).  Writes ``floor.csv`` (per frame), ``floor.json`` and with ``--plot``
``floor.png`` into ``REPORT`` beside the replay's report.  Ring walls only: an
interior's walls are rendered without their crossing objects' holes.
"""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["FloorRun", "edge_mask", "frame_width", "ideal_quads", "measure", "ring_holes", "summarise", "table",
           "texture_costs", "texture_id", "write"]

Replay = Callable[[str, Mapping[str, Any], str], Any]
"""``replay(server, options, title)``: one replay with ``walkstream replay``'s options
(the CLI's ``replay_with_options``), its report written, its result returned."""

VISIBLE_SHARE = 0.01
"""The issue's bound on a frame's walls' visibly wrong share (as ``benchmarks/walls.py``)."""
MAX_WIDTH = 2048
"""The widest texture rendered (texels), so a wall seen from very near stays renderable."""
_FIRST_KEY = -(1 << 30)
"""Keys of the replaced textures count down from here: negative (a wall's, read nearest
when minified) and never reused, as the quad renderer keeps a texture by its key."""


def texture_id(key: int) -> int:
    """The wall texture id of a wall quad's image key (the client keys them ``-1 - id``)."""
    return -1 - int(key)


def frame_width(length: float, distance: float, proj_11: float, height_px: int, per_pixel: float) -> int:
    """Texels across a wall ``length`` metres long so that ``per_pixel`` texels fall on a
    frame pixel where its plane is nearest the eye (``distance`` metres; nowhere on the
    wall is a pixel smaller): a view ``height_px`` pixels high whose projection's
    ``[1, 1]`` is ``proj_11`` (``1 / tan(fov / 2)``) puts ``height_px proj_11 / (2 d)``
    pixels on a metre at ``d``; capped at :data:`MAX_WIDTH`."""
    ppm = height_px * proj_11 / (2.0 * max(distance, 0.05))
    return int(min(MAX_WIDTH, max(4, math.ceil(per_pixel * ppm * length))))


def edge_mask(rgb: NDArray[np.uint8]) -> NDArray[np.bool_]:
    """``(h, w)`` the pixels of an sRGB picture ``(h, w, 3)`` visibly different (ΔE00 over
    :data:`~walkstream.client.truth.colour.VISIBLE_DE`) from one of their four neighbours:
    where a point-sampled picture changes within a pixel, so that any image resampled
    on another grid (a texture) can miss by a pixel and count visibly wrong."""
    from walkstream.client.truth.colour import VISIBLE_DE, delta_e_2000, srgb_to_lab

    lab = srgb_to_lab(np.asarray(rgb))
    out = np.zeros(lab.shape[:2], bool)
    across = delta_e_2000(lab[:, 1:], lab[:, :-1]) > VISIBLE_DE
    down = delta_e_2000(lab[1:], lab[:-1]) > VISIBLE_DE
    out[:, 1:] |= across
    out[:, :-1] |= across
    out[1:] |= down
    out[:-1] |= down
    return out


def ring_holes(ring: Sequence[Any], ids: NDArray[np.int64], boxes: NDArray[np.float64]) -> tuple[int, ...]:
    """The objects a ring's textures leave as holes (kept as geometry), as the bake
    chose them (:func:`~walkstream.server.bake.ringwalls.plan_ring_walls`): every object
    ``ids`` whose box ``boxes`` ``(m, 6)`` meets the ring's rectangle (the bake's reach
    from the region's rectangle at most the ring's distance ``r`` is the reach from the
    rectangle pushed out by ``r``, the ring itself, being 0).  ``ring``: the ring's four
    wall sides (wall ``k`` runs from the ring's corner ``k + 1`` to corner ``k``)."""
    from walkstream.server.bake.ringwalls import ring_reach
    from walkstream.shared.walls import RING_SIDES

    by_k = {int(s.portal) % RING_SIDES: s for s in ring}
    if len(by_k) != RING_SIDES:
        return ()
    corners = np.array([by_k[k].p1 for k in range(RING_SIDES)], np.float64)
    u, v = corners[1] - corners[0], corners[3] - corners[0]
    half = np.array([np.linalg.norm(u), np.linalg.norm(v)]) / 2.0
    axes = np.stack([u / (2.0 * half[0]), v / (2.0 * half[1])])
    hit = ring_reach(np.asarray(boxes, np.float64).reshape(-1, 6), corners.mean(axis=0), axes, half) <= 1e-9
    return tuple(int(i) for i in np.asarray(ids)[hit])


def ideal_quads(quads: Sequence[Any], image: Callable[[int], NDArray[np.uint8] | None],
                keys: Callable[[], int], warp: bool = False) -> list[Any]:
    """``quads`` (a note's wall quads: corners, key, RGBA, opacity) with each texture
    replaced by ``image(texture id)`` under a fresh key ``keys()`` (a quad it gives None
    for kept as it is); ``warp`` False lays the new texture on the quad as it is (its
    corners' own texture coordinates dropped: a texture rendered from the eye through
    the quad needs none), True keeps the client's warp.  The opacities stay."""
    out = []
    for corners, key, rgba, alpha in quads:
        img = image(texture_id(key))
        c = np.asarray(corners, np.float64)
        if img is None or len(c) != 4:  # a depth mesh (--wall-depth) is left as drawn
            out.append((corners, key, rgba, alpha))
            continue
        out.append((c if warp else c[:, :3], keys(), img, alpha))
    return out


def summarise(shares: Sequence[float]) -> dict[str, float]:
    """``wall1`` (share of frames at most :data:`VISIBLE_SHARE`), ``median``, ``p90``,
    ``p99`` and ``mean`` of per-frame shares (0..1 of the frame)."""
    a = np.asarray(shares, np.float64)
    if a.size == 0:
        return {"wall1": math.nan, "median": math.nan, "p90": math.nan, "p99": math.nan, "mean": math.nan}
    return {"wall1": float((a <= VISIBLE_SHARE).mean()), "median": float(np.median(a)),
            "p90": float(np.percentile(a, 90)), "p99": float(np.percentile(a, 99)), "mean": float(a.mean())}


@dataclass
class FloorRun:
    """What one run measured: per compared frame and variant the walls' share of the frame."""

    variants: list[str]
    frames: list[int] = field(default_factory=list)
    wrong: dict[str, list[float]] = field(default_factory=dict)
    """Variant -> per frame the share of the frame's pixels visibly wrong under ``wall``."""
    painted: dict[str, list[float]] = field(default_factory=dict)
    """Variant -> per frame the share of the frame's pixels a wall's texture painted."""
    texels: dict[str, list[float]] = field(default_factory=dict)
    """Variant -> per wall drawn its texture's texels a metre (along the wall)."""
    edges: list[float] = field(default_factory=list)
    """Per frame the share of the frame's pixels a wall painted (today) that are edges of
    the truth (:func:`edge_mask`)."""
    scielab: dict[str, list[float]] = field(default_factory=dict)
    """Variant -> per frame the share visibly wrong under ``wall`` at the viewer's scale
    (S-CIELAB, ``viewer_ppd``; empty when not measured)."""
    costs: dict[str, dict[str, float]] = field(default_factory=dict)
    """Variant -> the textures' cost (:func:`texture_costs`)."""
    summary: dict[str, Any] = field(default_factory=dict)
    """The replay's summary."""
    ppd: float | None = None
    """The viewer's pixels a degree the viewer-scale shares were counted at (None: not counted)."""


def _variants(densities: Sequence[float], frame_res: Sequence[float]) -> list[str]:
    return ["today", "zone", "zone webp75", *(f"eye x{m:g}" for m in densities), *(f"frame x{f:g}" for f in frame_res)]


def texture_costs(ren: Any, sides: dict[tuple[int, int], Any], info: Mapping[int, tuple[int, ...]],
                  tids: Sequence[int], densities: Sequence[float], holes: Callable[[Any], Sequence[int]],
                  stored: dict[int, tuple[str, bytes]]) -> dict[str, dict[str, float]]:
    """``eye xM`` -> bytes of the textures ``tids`` at ``M`` times their stored width,
    rendered from their zones' sampling points as the bake stores them (``holes(side)``
    left out): ``raw`` (texels x 4), ``webp75`` (WebP at quality 75, the outdoor default)
    and ``lossless`` (WebP lossless); ``stored``, the database's bytes of the same
    textures, and ``stored_diff``, the mean difference (levels of 255, over every channel
    and texel) between the stored textures decoded and the render at ``M`` = 1 (the
    stored texture rebuilt here, less its codec)."""
    from walkstream.shared.codec.image import encode_image
    from walkstream.shared.content.walltex import decode_walltex

    out: dict[str, dict[str, float]] = {}
    for m in densities:
        raw = webp = lossless = 0
        diffs = []
        for tid in tids:
            portal, side, zone, width = info[tid][:4]
            s = sides[(portal, side)]
            img = ren.render(s, zone, max(4, round(m * width)), holes(s))
            raw += img.shape[0] * img.shape[1] * 4
            webp += len(encode_image(img, "webp", 75))
            lossless += len(encode_image(img, "webp-lossless"))
            if m == 1.0 and tid in stored:
                dec = np.asarray(decode_walltex(stored[tid][1]))
                if dec.shape == img.shape:
                    diffs.append(float(np.abs(dec.astype(np.int16) - img.astype(np.int16)).mean()))
        out[f"eye x{m:g}"] = {"raw": raw, "webp75": webp, "lossless": lossless,
                              "stored": float(sum(info[t][5] for t in tids)), "textures": len(tids),
                              "stored_diff": float(np.mean(diffs)) if diffs else math.nan}
    return out


def measure(db: str, source: str, report: str, replay: Replay, *, path: str = "bench", device: str = "pda",
            size: str = "160x120", duration: str = "60s", truth_every: int = 25, bandwidth: str = "56kbit",
            rtt: str = "200ms", fps: float = 25.0, densities: Sequence[float] = (1.0, 2.0, 4.0),
            frame_res: Sequence[float] = (1.0,), costs: bool = True, viewer_ppd: float | None = None,
            samples: Mapping[str, str] | None = None) -> FloorRun:
    """Replay ``db`` (baked from ``source``) on ``path`` with the simulated clock by
    ``replay`` (in this process: the truth runs here), its report into ``report``, and measure each compared frame's walls again with each
    variant's textures (see the module docs); with ``viewer_ppd`` at the viewer's scale
    too (S-CIELAB at that many pixels a degree, the replay's ``--viewer-ppd``); ``samples``
    the replay's ``truth_samples`` and ``picture_samples`` (an anti-aliased measure)."""
    import walkstream.client.replay  # noqa: F401  (first: the truth's modules import each other through it)
    import walkstream.client.truth.missing as missing
    import walkstream.client.truth.recorder as recorder
    from walkstream.client.truth.colour import COLOUR_CAUSES
    from walkstream.server.bake.wallrender import WallRenderer, wall_elements
    from walkstream.server.sources.read import read_source
    from walkstream.server.store import SceneReader
    from walkstream.shared.codec.image import decode_image, encode_image
    from walkstream.shared.walls import WallSide, ring_cell

    reader = SceneReader.open(db)
    sides = {(s.portal, s.side): s for s in (WallSide.from_row(r) for r in reader.wall_sides())}
    info = reader.wall_texture_info()
    from walkstream.shared.errors import InputError

    if not sides or not info:
        raise InputError(f"{db}: no virtual walls (bake with --virtual-walls)")
    if reader.meta.kind != "city":
        raise InputError(f"{db}: an interior; the floor is measured on a city's ring walls only")
    elements = wall_elements(read_source(source, network="walk"))
    ids = reader.object_ids()
    objects = reader.object_info(ids.tolist())
    boxes = np.array([objects[int(i)].bbox for i in ids], np.float64).reshape(-1, 6)
    rings: dict[int, list[Any]] = {}
    for s in sides.values():
        rings.setdefault(ring_cell(s.portal), []).append(s)
    hole_cache: dict[int, tuple[int, ...]] = {}

    def holes(s: Any) -> tuple[int, ...]:
        c = ring_cell(s.portal)
        if c not in hole_cache:
            hole_cache[c] = ring_holes(rings[c], ids, boxes)
        return hole_cache[c]

    wall = COLOUR_CAUSES.index("wall")
    run = FloorRun(_variants(densities, frame_res), ppd=viewer_ppd)
    for v in run.variants:
        run.wrong[v], run.painted[v], run.texels[v], run.scielab[v] = [], [], [], []
    seen: set[int] = set()
    counter = [_FIRST_KEY]

    def fresh() -> int:
        counter[0] -= 1
        return counter[0]

    orig_figures, orig_colour = recorder.missing_figures, missing.colour_error

    def record(v: str, err: Any, pic: Any) -> None:
        run.wrong[v].append(float(err.causes[wall]) / err.pixels)
        run.painted[v].append(0.0 if pic.wall is None else float(pic.wall.mean()))
        run.scielab[v].append(float(err.scielab_causes[wall]) / err.pixels if err.ppd is not None else 0.0)

    def figures(ts: Any, truth: Any, *args: Any, **kw: Any) -> Any:
        ren = WallRenderer(elements, ctx=truth.ctx)

        def colour_error(truth: Any, st: Any, t_rgb: Any, cause: Any, proj: Any, overlay: Any, ppd: Any,
                         samples: Any) -> Any:
            h = truth.size[1]
            p11 = float(np.asarray(proj)[1, 1])
            for v in run.variants[1:]:  # the replaced textures first; the frame's own last
                if not st.wall_quads or overlay is None:
                    run.wrong[v].append(0.0)
                    run.painted[v].append(0.0)
                    run.scielab[v].append(0.0)
                    continue
                cache: dict[tuple[int, int, int], NDArray[np.uint8]] = {}

                def image(tid: int, v: str = v, cache: dict[tuple[int, int, int], NDArray[np.uint8]] = cache
                          ) -> NDArray[np.uint8] | None:
                    if tid not in info:
                        return None
                    portal, sd, zone, width = info[tid][:4]
                    s = sides[(portal, sd)]
                    if v.startswith("zone"):
                        w, eye = width, None
                    elif v.startswith("eye"):
                        w, eye = max(4, round(float(v[5:]) * width)), st.eye
                    else:
                        dist = abs(float((np.asarray(st.eye[:2]) - np.asarray(s.p0)) @ s.normal))
                        w, eye = frame_width(s.length, dist, p11, h, float(v[7:])), st.eye
                    k = (portal, sd, zone if eye is None else -1)
                    if k not in cache:
                        img = ren.render(s, zone, w, holes(s), eye=eye)
                        if v == "zone webp75":  # the outdoor default codec, through and back
                            img = decode_image(encode_image(img, "webp", 75), "wall texture")
                        cache[k] = img
                        run.texels[v].append(w / s.length)
                    return cache[k]

                note = replace(st, wall_quads=tuple(ideal_quads(st.wall_quads, image, fresh, warp=v.startswith("zone"))))
                err, pic = orig_colour(truth, note, t_rgb, cause, proj, overlay, ppd, samples)
                record(v, err, pic)
            err, pic = orig_colour(truth, st, t_rgb, cause, proj, overlay, ppd, samples)
            run.frames.append(int(st.frame))
            record("today", err, pic)
            run.edges.append(0.0 if pic.wall is None else float((edge_mask(np.asarray(t_rgb)) & pic.wall).mean()))
            for q in st.wall_quads:
                tid = texture_id(q[1])
                if tid in info:
                    seen.add(tid)
                    run.texels["today"].append(info[tid][3] / sides[info[tid][0], info[tid][1]].length)
            return err, pic

        missing.colour_error = colour_error  # type: ignore[assignment]  # the truth loop calls it by its module name
        try:
            out = orig_figures(ts, truth, *args, **kw)
            if costs and seen:
                run.costs = texture_costs(ren, sides, info, sorted(seen), densities, holes,
                                          reader.wall_textures(sorted(seen)))
            return out
        finally:
            missing.colour_error = orig_colour
            ren.release()

    recorder.missing_figures = figures
    try:
        result = replay(db, {
            "path": path, "device": device, "clock": "sim", "duration": duration, "size": size,
            "truth_every": truth_every, "bandwidth": bandwidth, "rtt": rtt, "fps": fps, "report": report,
            "no_plots": True, "viewer_ppd": viewer_ppd, **(samples or {})}, f"replay {path} (wall floor)")
    finally:
        recorder.missing_figures = orig_figures
        reader.close()
    run.summary = dict(result.summary)
    return run


def table(run: FloorRun) -> str:
    """The Markdown table of a :class:`FloorRun`: per variant the walls' visibly wrong
    share of the frame (and at the viewer's scale, when measured), and for the stored
    textures and each density what they would cost."""
    sent = (run.summary.get("walls") or {}).get("texture_bytes")
    base = run.costs.get("eye x1", {})
    scale = run.ppd is not None
    walled = int(np.count_nonzero(np.asarray(run.painted.get("today", [])) > 0))
    head = [f"{len(run.frames)} compared frames, {walled} of them drawing a wall"]
    if base:
        head.append(f"{base['textures']:.0f} distinct textures drawn on them, stored {base['stored'] / 1e3:.1f} kB "
                    f"(decoded against the render here: {base['stored_diff']:.2f} levels of 255 apart)")
    if sent:
        head.append(f"texture bytes sent on the walk {sent / 1e3:.1f} kB")
    if run.edges:
        e = 100 * np.asarray(run.edges)
        head.append(f"the walls' pixels on the truth's edges {e.mean():.2f} % of the frame on average "
                    f"(median {np.median(e):.2f}, max {e.max():.2f} %; of the walls' pixels "
                    f"{100 * e.sum() / max(100 * float(np.sum(run.painted['today'])), 1e-9):.0f} %)")
    cols = ["textures", "texels a metre (mean)", "`wall1%`", "median", "90th pct", "99th pct", "mean",
            "wall pixels, mean of the frame"]
    if scale:
        cols += ["`wall1%` viewer-scale", "median viewer-scale"]
    cols += ["raw kB", "WebP 75 kB", "lossless kB", "walk, WebP 75 / lossless kB"]
    lines = ["; ".join(head), "", "| " + " | ".join(cols) + " |", "|---|" + "---:|" * (len(cols) - 1)]
    for v in run.variants:
        s = summarise(run.wrong[v])
        tex = np.mean(run.texels[v]) if run.texels[v] else math.nan
        row = [v, f"{tex:.1f}", f"{100 * s['wall1']:.1f} %", f"{100 * s['median']:.2f} %", f"{100 * s['p90']:.2f} %",
               f"{100 * s['p99']:.2f} %", f"{100 * s['mean']:.2f} %",
               f"{100 * float(np.mean(run.painted[v])) if run.painted[v] else math.nan:.1f} %"]
        if scale:
            sc = summarise(run.scielab.get(v, []))
            row += [f"{100 * sc['wall1']:.1f} %", f"{100 * sc['median']:.2f} %"]
        c = run.costs.get(v)
        if v == "today" and base:  # the stored textures as they are, in the database's codec
            row += [f"{base['raw'] / 1e3:.0f}", "", "", f"{base['stored'] / 1e3:.1f} stored"
                    + (f", {sent / 1e3:.0f} sent" if sent else "")]
        elif c and base.get("stored"):
            walk = (f"{sent * c['webp75'] / base['stored'] / 1e3:.0f} / {sent * c['lossless'] / base['stored'] / 1e3:.0f}"
                    if sent else "")
            row += [f"{c['raw'] / 1e3:.0f}", f"{c['webp75'] / 1e3:.1f}", f"{c['lossless'] / 1e3:.1f}", walk]
        else:
            row += ["", "", "", ""]
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines)


def write(run: FloorRun, folder: Path, plot: bool) -> None:
    """``floor.csv`` (per frame and variant the walls' share) and ``floor.json`` (the
    summaries and costs) into ``folder``; with ``plot`` ``floor.png`` (each variant's
    shares sorted, the issue's 1 % and 99 % marked)."""
    with open(folder / "floor.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["frame", *(f"wrong {v}" for v in run.variants), *(f"painted {v}" for v in run.variants),
                    "edges today"])
        for i, fr in enumerate(run.frames):
            w.writerow([fr, *(f"{run.wrong[v][i]:.6f}" for v in run.variants),
                        *(f"{run.painted[v][i]:.6f}" for v in run.variants), f"{run.edges[i]:.6f}"])
    (folder / "floor.json").write_text(json.dumps(
        {"frames": len(run.frames), "summaries": {v: summarise(run.wrong[v]) for v in run.variants},
         "edges": summarise(run.edges),
         "viewer_ppd": run.ppd,
         "viewer_scale": {v: summarise(run.scielab[v]) for v in run.variants} if run.ppd is not None else None,
         "texels_per_metre": {v: float(np.mean(t)) if t else None for v, t in run.texels.items()},
         "costs": run.costs}, indent=2))
    if not plot:
        return
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    for v in run.variants:
        a = np.sort(100 * np.asarray(run.wrong[v]))
        ax.plot(np.arange(1, len(a) + 1) / max(len(a), 1) * 100, a, label=v, drawstyle="steps-post")
    ax.axhline(100 * VISIBLE_SHARE, color="k", lw=0.8, ls="--")
    ax.axvline(99, color="k", lw=0.8, ls=":")
    ax.set_xlabel("compared frames, % (sorted)")
    ax.set_ylabel("walls' visibly wrong pixels, % of the frame")
    ax.set_yscale("symlog", linthresh=0.1)
    ax.set_ylim(bottom=0.0)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(folder / "floor.png", dpi=110)
    plt.close(fig)
