"""``walkstream bench impostor-sampling``: one impostor against its truth, alone, and why they differ.

The colour error's truth (:mod:`walkstream.client.truth.render`) rasterises LOD2: each
pixel holds the lit surface under its centre.  An impostor is an image baked on its
own texel grid, drawn on a quad, read through a texture filter.  This benchmark takes
buildings of a city one at a time, draws the truth's pixels of that building alone
and the impostor's pixels alone (the bake's renderer,
:class:`~walkstream.server.bake.impostorrender.ImpostorRenderer`, and the client's
quad, :class:`~walkstream.client.draw.quads.QuadRenderer`, through the truth's own
:meth:`~walkstream.client.truth.render.TruthRenderer.paint_quads`), and counts the
pixels over ΔE00 :data:`~walkstream.client.truth.colour.VISIBLE_DE` among those either
shows, in three views that separate the causes:

``aligned``
    Orthographic along the image's own direction, the frame's pixels on the image's
    texels (one a pixel): no parallax, no filtering, no resampling; what is left is the
    lighting, the palette, the encoding and the texel's sampling.
``minified``
    The same view with the image at the bake's size, 2.67 texels to a pixel (as a
    D 60 m image sized for 640 x 480 shows at 160 x 120): resampling and filtering.
``on-axis``
    A perspective frame (160 x 120, 60 degrees) from an eye 60-150 m away on the
    image's own axis, the quad as the client places it, the image sized as the bake
    sizes it: the orthographic image's parallax against the perspective view added
    (:func:`~walkstream.shared.impostors.orthographic_parallax`), not yet the bound.
``perspective``
    The client's view: the same frame from an eye at street height anywhere in the
    direction bin the error bound ``A`` picks: the bound added.

Each is run for both samplings of the bake (``point``, ``area``:
:data:`~walkstream.server.bake.impostorrender.IMPOSTOR_SAMPLINGS`) and both minifying
filters of the quad (``nearest``, ``linear``), beside the truth against itself drawn
at 4 x 4 samples a pixel and averaged: what an anti-aliased picture of the very same
geometry scores under the per-pixel measure.

Beside the per-pixel count, each comparison is counted at the viewer's scale too
(S-CIELAB, :func:`~walkstream.client.truth.colour.scielab_delta_e`) at each of the
given pixels per degree (:data:`DEFAULT_PPD`: the 160 x 120 view's own, 1.81, and a
handheld screen's, 24): the pixels over
:data:`~walkstream.client.truth.colour.SCIELAB_VISIBLE_DE` after both pictures are
filtered as the eye sees them at that scale.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from walkstream.client.truth.antialias import Sampling
from walkstream.client.truth.colour import (
    SCIELAB_VISIBLE_DE,
    VISIBLE_DE,
    delta_e_2000,
    pixels_per_degree,
    scielab_delta_e,
    srgb_to_lab,
)
from walkstream.client.truth.render import TruthRenderer
from walkstream.client.walk.impostors import quad_corners, toward_eye
from walkstream.server.bake.impostorrender import IMPOSTOR_SAMPLINGS, ImpostorRenderer
from walkstream.server.bake.objectrows import building_box
from walkstream.shared.buildings import build_lod_batch
from walkstream.shared.camera import look_at, orthographic
from walkstream.shared.errors import InputError
from walkstream.shared.impostors import (
    bin_direction,
    bin_of,
    directions,
    eye_distance,
    half_side,
    image_size,
    level_for,
    texels_needed,
)

__all__ = ["DEFAULT_PPD", "VIEWS", "format_sampling_table", "plot_sampling_picture", "run_sampling_bench"]

VIEWS: tuple[str, ...] = ("aligned", "minified", "on-axis", "perspective")
"""The views of the benchmark (module docstring)."""

DEFAULT_PPD: tuple[float, ...] = (round(pixels_per_degree(120, 60.0), 2), 24.0)
"""Pixels per degree of the viewer-scale columns: the 160 x 120, 60° view seen under its
own angle, and a handheld's screen (about 0.22 mm a pixel at 30 cm: 24 a degree)."""

_FILTERS = ("nearest", "linear")
_ALIGNED_PX = 64
_MINIFIED_PX = 48
_BAKED_TEXELS = 128
_TRUTH_AA = Sampling(grid=4)
_REFERENCE = Sampling(grid=8)


def _wrong(truth: NDArray[np.uint8], other: NDArray[np.uint8], area: NDArray[np.bool_],
           ppds: Sequence[float] = ()) -> list[int]:
    """Pixels of ``area`` over the visible threshold between two ``(h, w, 3)`` pictures, ``area``'s
    size, then per pixels per degree of ``ppds`` those over it at the viewer's scale (S-CIELAB)."""
    de = delta_e_2000(srgb_to_lab(truth), srgb_to_lab(other))
    out = [int((de[area] > VISIBLE_DE).sum()), int(area.sum())]
    return out + [int((scielab_delta_e(truth, other, p)[area] > SCIELAB_VISIBLE_DE).sum()) for p in ppds]


def _add(tally: dict[tuple[str, str, str], list[int]], key: tuple[str, str, str], counts: list[int]) -> None:
    t = tally.setdefault(key, [0] * len(counts))
    for i, v in enumerate(counts):
        t[i] += v


class _Scene:
    """The truth at a frame size, point-sampled and anti-aliased (the renderer's own sampling)."""

    def __init__(self, meshes: dict[int, Any], size: tuple[int, int], ctx: Any = None) -> None:
        self.size = size
        self.truth = TruthRenderer(meshes, size, ctx=ctx)

    def frames(self, oid: int, eye: NDArray[np.float64], view: NDArray[np.float64], proj: NDArray[np.float64] | None,
               samplings: Sequence[Sampling] = (_TRUTH_AA,)) -> tuple[
        NDArray[np.bool_], NDArray[np.uint8], dict[Sampling, NDArray[np.uint8]]
    ]:
        """The building's pixels, the truth, and the truth drawn at each of ``samplings``."""
        flags = self.truth.flags([(-1 - oid, 0)])
        smooth = {}
        for sampling in samplings:
            self.truth.render(eye, view, flags, proj=proj, samples=sampling)
            smooth[sampling] = self.truth.colour()
        idx, _ = self.truth.render(eye, view, flags, proj=proj)
        return idx >= 0, self.truth.colour().copy(), smooth

    def painted(self, quad: tuple[Any, ...], eye: NDArray[np.float64], view: NDArray[np.float64],
                proj: NDArray[np.float64] | None, image_filter: str) -> tuple[NDArray[np.uint8], NDArray[np.bool_]]:
        """The quad alone over the empty frame, drawn as the client draws it, and the pixels it changed."""
        import moderngl

        tr = self.truth
        tr.render(eye, view, np.zeros(len(tr.keys), bool), proj=proj)
        empty = tr.colour().copy()
        gl_filter = moderngl.NEAREST if image_filter == "nearest" else moderngl.LINEAR
        out = tr.paint_quads([quad], view, proj, image_filter=gl_filter)
        return out, np.any(out != empty, axis=2)

    def release(self) -> None:
        self.truth.release()


def run_sampling_bench(
    buildings: Sequence[Any], count: int = 20, error_deg: float = 2.0, seed: int = 1, ctx: Any = None,
    views: Sequence[str] = VIEWS, picture: dict[str, NDArray[np.uint8]] | None = None,
    ppds: Sequence[float] = DEFAULT_PPD, against_aa: bool = False,
    truth_samples: Sequence[Sampling] = (), reference: Sampling = _REFERENCE,
    projections: Sequence[str] = ("ortho",), distance: float = 60.0,
) -> list[dict[str, Any]]:
    """The benchmark's rows (module docstring) over ``count`` of the tallest ``buildings``
    (drawn on ``ctx``, by default a context of its own), for ``views`` (of :data:`VIEWS`).
    ``against_aa`` compares the images with the truth drawn at 4 x 4 samples a pixel and
    averaged (the anti-aliased picture of the same geometry) instead of the truth.
    ``truth_samples``: also one row per view and sampling S (``sampling="truth S"``,
    ``filter`` the ``reference``'s name): the truth drawn at S against the truth drawn at
    ``reference`` (by default 8 x 8), the anti-aliased truth's own error; one sample a
    pixel (``Sampling()``) is the point-sampled truth's.
    ``projections``: the images orthographic (``ortho``, sampling named as it is) and/or
    in perspective from their level's sampling eye (``perspective``, sampling named
    ``"S persp"``; :func:`~walkstream.shared.impostors.eye_distance` for a bake at D
    ``distance``), the on-axis and perspective views from 60-150 m either way.
    ``picture``, when given, receives the middle building's frames (by height) (``"VIEW truth"``,
    ``"VIEW SAMPLING FILTER"``) for :func:`plot_sampling_picture`.

    Returns
    -------
    list of dict
        One row per view, sampling and filter (``view``, ``sampling``, ``filter``,
        ``wrong_share``: pixels over the threshold / pixels of the building or the
        image, ``pixels``, ``scielab_shares``: per pixels per degree of ``ppds`` the
        same share at the viewer's scale), then one ``sampling="truth 4x4"`` row per view.
    """
    if any(not (math.isfinite(p) and p > 0) for p in ppds):
        raise InputError(f"--ppd {list(ppds)}: expected positive pixels per degree")
    if count < 1:
        raise InputError(f"--buildings: expected at least 1, got {count}")
    if not views or any(v not in VIEWS for v in views):
        raise InputError(f"bench impostor-sampling views {list(views)}: expected some of {', '.join(VIEWS)}")
    chosen = sorted(buildings, key=lambda b: -float(b.top))[:count]
    if not chosen:
        raise InputError("bench impostor-sampling: the source has no buildings")
    meshes = build_lod_batch(chosen, 2)
    ids = [int(b.id) for b in chosen]
    boxes = [building_box(b) for b in chosen]
    objects = dict(zip(ids, meshes, strict=True))
    scenes = {"aligned": _Scene(objects, (_ALIGNED_PX, _ALIGNED_PX), ctx)}
    ctx = scenes["aligned"].truth.ctx
    scenes["minified"] = _Scene(objects, (_MINIFIED_PX, _MINIFIED_PX), ctx)
    scenes["perspective"] = scenes["on-axis"] = _Scene(objects, (160, 120), ctx)
    ren = ImpostorRenderer(meshes, ids, boxes, ctx=ctx)
    rng = np.random.default_rng(seed)
    tally: dict[tuple[str, str, str], list[int]] = {}
    image_id = 0
    try:
        for k, oid in enumerate(ids):
            lo, hi = np.asarray(boxes[k][:3], np.float64), np.asarray(boxes[k][3:], np.float64)
            c, r = (lo + hi) / 2.0, float(np.linalg.norm(hi - lo)) / 2.0
            d = float(rng.uniform(60.0, 150.0))
            az = float(rng.uniform(-math.pi, math.pi))
            street = c + d * np.array([math.cos(az), math.sin(az), 0.0])
            street[2] = 1.7
            level = int(level_for(r, float(np.linalg.norm(street - c)), math.radians(error_deg)))
            level = max(level, 0)
            a, e = directions(street, c)
            ia, ie = (int(v) for v in bin_of(level, a, e))
            u = bin_direction(level, ia, ie)
            eyes = {p: math.inf if p == "ortho" else float(eye_distance(r, level, math.radians(error_deg), distance))
                    for p in projections}
            for view_name in views:
                sc = scenes[view_name]
                if view_name in ("on-axis", "perspective"):
                    eye, proj = (street if view_name == "perspective" else c + u * d), None
                else:
                    eye, proj = c + u * (r + 50.0), orthographic(r, 0.5, 2000.0)
                view = np.asarray(look_at(eye, c), np.float64)
                wanted = [_TRUTH_AA, *((reference, *truth_samples) if truth_samples else ())]
                mask, truth, smooth = sc.frames(oid, eye, view, proj, wanted)
                fine = smooth[_TRUTH_AA]
                if picture is not None and k == len(ids) // 2:
                    picture[f"{view_name} truth"] = truth
                _add(tally, (view_name, "truth 4x4", "-"), _wrong(truth, fine, mask, ppds))
                for ts in truth_samples:  # the truth at each sampling against the reference
                    other = truth if ts.point else smooth[ts]
                    _add(tally, (view_name, f"truth {ts}", f"vs {reference}"), _wrong(smooth[reference], other, mask, ppds))
                for sampling, pname in ((s, p) for p in projections for s in IMPOSTOR_SAMPLINGS):
                    at = eyes[pname]
                    corners = quad_corners(boxes[k], level, ia, ie, at)
                    if view_name in ("on-axis", "perspective"):
                        size = int(image_size(texels_needed(half_side(r, at), d, 480, 60.0), _BAKED_TEXELS))
                        quad_at = toward_eye(corners, eye, boxes[k])
                    else:
                        size = _ALIGNED_PX if view_name == "aligned" else _BAKED_TEXELS
                        quad_at = corners
                    img = ren.render(oid, u, size, sampling, eye=at)
                    label = sampling if pname == "ortho" else f"{sampling} persp"
                    for filt in _FILTERS:
                        image_id += 1  # a new id per image: the quad renderer keeps textures by id
                        pic, painted = sc.painted((quad_at, image_id, img, 1.0), eye, view, proj, filt)
                        counts = _wrong(fine if against_aa else truth, pic, mask | painted, ppds)
                        if picture is not None and k == len(ids) // 2:
                            picture[f"{view_name} {label} {filt}"] = pic
                        _add(tally, (view_name, label, filt), counts)
    finally:
        ren.release()
        for name in ("perspective", "minified", "aligned"):
            scenes[name].release()
    order = {v: i for i, v in enumerate(VIEWS)}
    keys = sorted(tally, key=lambda key: (order[key[0]], key[1].startswith("truth"), key[2].startswith("vs"), key[1], key[2]))
    return [
        {"view": v, "sampling": s, "filter": f, "wrong_share": tally[(v, s, f)][0] / max(tally[(v, s, f)][1], 1),
         "pixels": tally[(v, s, f)][1], "buildings": len(ids),
         "scielab_shares": {float(p): tally[(v, s, f)][2 + i] / max(tally[(v, s, f)][1], 1) for i, p in enumerate(ppds)}}
        for v, s, f in keys
    ]


def format_sampling_table(rows: Sequence[dict[str, Any]]) -> str:
    """The rows as a text table."""
    ppds = list(rows[0].get("scielab_shares", {})) if rows else []
    head = (f"{'view':12s} {'sampling':10s} {'filter':8s} {'pixels':>8s}  over dE00 {VISIBLE_DE}"
            + "".join(f"  S-CIELAB {p:g} px/deg" for p in ppds))
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(f"{r['view']:12s} {r['sampling']:10s} {r['filter']:8s} {r['pixels']:8d}  {100.0 * r['wrong_share']:12.1f} %"
                     + "".join(f"  {100.0 * r['scielab_shares'][p]:17.1f} %" for p in ppds))
    return "\n".join(lines)


def plot_sampling_picture(picture: dict[str, NDArray[np.uint8]], path: Any) -> Any:
    """One building's frames per view (rows): the truth, the area-sampled image read
    bilinear, the point-sampled image read nearest (with perspective images too: the
    point-sampled orthographic and perspective images read bilinear), and each image's pixels over the
    threshold; written to ``path`` (PNG), returned."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    views = [v for v in VIEWS if f"{v} truth" in picture]
    cols = [("truth", "truth"), ("area linear", "area, bilinear"), ("point nearest", "point, nearest")]
    if views and f"{views[0]} point linear" not in picture:  # perspective images alone
        cols = [("truth", "truth"), ("point persp linear", "point persp, bilinear"),
                ("point persp nearest", "point persp, nearest")]
    elif views and f"{views[0]} point persp linear" in picture:  # both: orthographic against perspective
        cols = [("truth", "truth"), ("point linear", "point ortho, bilinear"),
                ("point persp linear", "point persp, bilinear")]
    fig = Figure(figsize=(11, 2.3 * len(views)))
    axes = fig.subplots(len(views), 5, squeeze=False)
    for r, v in enumerate(views):
        truth = picture[f"{v} truth"]
        for c, (key, title) in enumerate(cols):
            axes[r][c].imshow(picture[f"{v} {key}"], interpolation="nearest")
            axes[r][c].set_title(f"{v}: {title}" if c == 0 else title, fontsize=8)
        for c, (key, title) in enumerate(cols[1:]):
            de = delta_e_2000(srgb_to_lab(truth), srgb_to_lab(picture[f"{v} {key}"]))
            axes[r][3 + c].imshow(de > VISIBLE_DE, cmap="magma", interpolation="nearest")
            axes[r][3 + c].set_title(f"{title}: over ΔE00 {VISIBLE_DE}", fontsize=8)
        for ax in axes[r]:
            ax.set_xticks([])
            ax.set_yticks([])
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return path
