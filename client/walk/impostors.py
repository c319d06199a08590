"""Part of the frame step ``allocate``: which far buildings the frame draws as impostors.

On a scene baked with ``--impostors`` the current street cell's record lists the
buildings it may draw as images (:class:`~walkstream.shared.impostorwire.CellImpostors`).
Each frame (:func:`frame_impostors`): the image of the viewer's direction bin and
its opacity by distance and error (:func:`~walkstream.client.draw.impostors.choose_impostors`),
moved towards it in time (:func:`~walkstream.client.draw.impostors.fade_towards`: an
image arriving, a building joining or leaving the cell's list fades rather than
switching in one frame; a building drawn as its image that the next cell does not list
keeps the row that listed it while its image is held, so its blend by distance runs on
rather than being cut to the fade: :func:`kept_rows`);
(once the first cell's parameters are all in: the start-up waits for no image) the
images wanted from the impostor lane (:class:`~walkstream.client.stream.images.ImpostorImages`,
needed now, so before the buildings' parameters), and with prefetch on the images the
predicted cells will draw, at their need times (:func:`ahead_wants`); of those held, the ones that fit
the texture budget, the farthest dropped first
(:func:`~walkstream.client.draw.impostors.fit_textures`).  Each kept image is one
:class:`DrawnImpostor`: a quad fixed to its baking direction (the image is an
orthographic view along the bin's direction over the building's bounding square, or
a perspective view from the level's sampling eye onto the square through the centre
that holds the sphere's silhouette from there, so the quad in that plane puts each
texel where the bake saw it; the error bound keeps the viewer's direction near it), two triangles and one draw for the budget and the
device.  A building at opacity 1 is drawn as its image alone (its geometry is left
out of the allocation); between 0 and 1 both are drawn, the image over the geometry.

Without impostors in the record, ``config.impostors`` off, or no street cells,
nothing is chosen and the frame is what it was.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from walkstream.client.draw.impostors import FADE_S, choose_impostors, fade_towards, fit_textures
from walkstream.client.walk.state import Frame, WalkState
from walkstream.shared.impostors import bin_direction, bin_of, directions, half_side, image_basis

__all__ = ["AHEAD_S", "DrawnImpostor", "ahead_wants", "frame_impostors", "hold_blend_lods", "kept_rows", "quad_corners",
           "replaced", "toward_eye"]

AHEAD_S = 6.0
"""How far ahead (seconds of predicted motion) the images of the cells ahead are wanted."""


@dataclass(frozen=True)
class DrawnImpostor:
    """One impostor a frame draws."""

    object: int
    image: int
    alpha: float
    """Opacity over the geometry (1: the image alone)."""
    corners: NDArray[np.float64]
    """``(4, 3)`` the quad's corners, world space: bottom-left, bottom-right, top-right, top-left
    of the image."""
    nbytes: int
    """The texture's bytes."""


def quad_corners(
    box: tuple[float, ...] | NDArray[np.float64], level: int, ia: int, ie: int, eye: float = math.inf
) -> NDArray[np.float64]:
    """The corners of the quad of a building's ``box`` (``lo`` then ``hi``) for the image
    of bin ``(ia, ie)`` at ``level``: the bounding sphere's square across the bin's
    direction, through the centre; for a perspective image (``eye`` its sampling eye's
    distance, :meth:`~walkstream.shared.impostorwire.CellImpostors.eye`) the larger square that
    holds the sphere's silhouette from that eye, where the bake's off-axis projection
    put its image (:func:`~walkstream.shared.impostors.half_side`)."""
    b = np.asarray(box, np.float64).reshape(2, 3)
    c = b.mean(axis=0)
    r = float(half_side(float(np.linalg.norm(b[1] - b[0])) / 2.0, eye))
    right, up = image_basis(bin_direction(level, ia, ie))
    right, up = np.asarray(right, np.float64) * r, np.asarray(up, np.float64) * r
    return np.stack([c - right - up, c + right - up, c + right + up, c - right + up])


def toward_eye(
    corners: NDArray[np.float64], eye: NDArray[np.float64], box: tuple[float, ...] | NDArray[np.float64]
) -> NDArray[np.float64]:
    """``corners`` ``(4, 3)`` scaled about ``eye`` to the front of the bounding sphere of
    ``box``: the same quad on the screen, in front of its own building's geometry.

    The quad through the building's centre is depth tested against the meshes, so
    while the building fades from geometry to image (both drawn) its own front faces
    hid most of the image, and the image appeared when the geometry went, in one frame:
    a pop.  Scaled about the eye, every point of the quad projects where it did (the
    texture lands on the same pixels); only its depth moves, to the sphere's front, so
    the image covers its own building and is still hidden by any nearer one.
    """
    b = np.asarray(box, np.float64).reshape(2, 3)
    e = np.asarray(eye, np.float64).reshape(3)
    span = float(np.linalg.norm(b.mean(axis=0) - e))
    radius = float(np.linalg.norm(b[1] - b[0])) / 2.0
    if span <= radius:
        return corners
    out: NDArray[np.float64] = e + (np.asarray(corners, np.float64) - e) * ((span - radius) / span)
    return out


def frame_impostors(w: WalkState, f: Frame) -> list[DrawnImpostor]:
    """The impostors frame ``f`` draws (see the module docstring); wants the missing images.

    A building drawn as its image that the current cell does not list but its PVS holds
    (the walker entered a cell with a point within ``D`` of it, or whose record is not in yet) keeps
    the row of the cell that listed it while its image is held (:func:`kept_rows`): its
    opacity follows the blend by the eye's own distance and error to 0, as for a listed
    building, rather than being cut to the fade in time at the cell's border (five
    times steeper at ``D`` 250 m on SE: the blend's 25 m take 6 s, the fade 2 s)."""
    city, lane = w.scene.streets, w.scene.images
    if city is None or lane is None:
        return []
    rec = None if f.street is None else city.cells.get(f.street)
    imp = None if rec is None else rec.impostors
    listed = [] if imp is None else [(r, imp) for r in imp.rows]
    kept = kept_rows(w.impostor_rows, w.impostors_shown, {r.object for r, _ in listed}, lane.held)
    if kept:  # only a building the frame's PVS still holds (one it left fades out, as before)
        pvs = set(w.objects.pvs)
        kept = [(r, i) for r, i in kept if r.object in pvs]
    if not listed and not kept:
        w.impostor_rows = {}
        return _faded(w, f, {})  # no list (yet): the images drawn fade out
    if not lane.started:
        # the start-up: the first cell's parameters before any image, so the first
        # perfect frame does not wait for images sharing the link (it needs none)
        if not all(city.has_object(i) for i in w.objects.pvs):
            return []
        lane.started = True
    cfg = w.config
    pairs = listed + kept
    head = pairs[0][1]  # one bake: every record's D, A and projection are the same
    rows = [r for r, _ in pairs]
    eyes = [head.eye(r) for r in rows] if head.perspective else None
    choices = choose_impostors(rows, f.eye, head.d, head.bound, cfg.impostor_blend_m, cfg.impostor_perspective, eyes,
                               cfg.impostor_max_size_deg)
    wants = ahead_wants(w, f) if cfg.prefetch else {}
    # a kept building wants no new image (another bin's): it is on its way to geometry
    wants.update({c.image: 0.0 for c in choices[:len(listed)] if c.image is not None})
    lane.want(wants)
    held = {c.image: int(getattr(lane.image(c.image), "nbytes", 0))
            for c in choices if c.image is not None and lane.held(c.image)}
    # an image not held yet: geometry until it comes
    choices = [c if c.image is None or c.image in held else c.__class__(c.object, None, 0.0, c.distance, c.error)
               for c in choices]
    by_object = {r.object: (r, i) for r, i in pairs}
    target: dict[int, DrawnImpostor] = {}
    for c in fit_textures(choices, held, cfg.texture_budget_bytes):
        if c.image is None:
            continue
        r, rec_imp = by_object[c.object]
        lo, hi = np.asarray(r.box[:3], np.float64), np.asarray(r.box[3:], np.float64)
        az, el = directions(f.eye, (lo + hi) / 2.0)
        ia, ie = bin_of(r.level, az, el)
        corners = toward_eye(quad_corners(r.box, r.level, int(ia), int(ie), rec_imp.eye(r)), f.eye, r.box)
        target[c.object] = DrawnImpostor(c.object, c.image, c.alpha, corners, held[c.image])
    out = _faded(w, f, target)
    w.impostor_rows = {o: by_object[o] for o in w.impostors_shown if o in by_object}
    return out


def hold_blend_lods(w: WalkState, f: Frame) -> None:
    """Let the geometry of a building whose image is blending over it (opacity strictly
    between 0 and 1) only go down in LOD: where the allocation (``f.alloc``) picks a
    finer LOD than the frame before drew, the coarser one is kept, its triangles counted.

    The budget's allocation moves a far building of a few pixels between LOD 0 and 1
    every few frames (the ``pda`` budget on SE), and under the blend that change lands on
    the switching building: 32 of its 222 frame-to-frame changes on the first 12 s of SE,
    0.005-0.02 each against 0.001 for the blend's own step.  Down only, so the change
    happens at most once a blend and the frame never draws more than the allocation
    chose (keeping the LOD of the frame before either way put the frame over its budget
    on 143 of 305 frames, the finer LOD of the two, and the ``pda`` frame rate within 10 %
    fell from 97.7 to 91.1 %).  It is let go when the blend ends."""
    last, w.blend_lods = w.blend_lods, {}
    alloc = f.alloc
    blending = {d.object for d in f.impostors if 0.0 < d.alpha < 1.0}
    if alloc is None or not blending:
        return
    o = w.objects
    lod = alloc.lod.copy()
    triangles = int(alloc.triangles)
    for k, g in enumerate(o.geoms):
        if g.id not in blending or k >= len(lod):
            continue
        now, was = int(lod[k]), last.get(g.id)
        if now >= 0 and was is not None and 0 <= was < now and bool(o.avail[k, was]):
            triangles += int(o.tri[k, was] - o.tri[k, now])
            lod[k] = now = was
        w.blend_lods[g.id] = now
    if triangles != alloc.triangles or not np.array_equal(lod, alloc.lod):
        f.alloc = dataclasses.replace(alloc, lod=lod, triangles=triangles)


def kept_rows(
    rows: dict[int, tuple[Any, Any]], shown: dict[int, DrawnImpostor], listed: set[int], held: Callable[[int], bool]
) -> list[tuple[Any, Any]]:
    """The ``(row, record)`` pairs of ``rows`` (the buildings the last frame drew as images,
    :attr:`~walkstream.client.walk.state.WalkState.impostor_rows`) whose building is still
    ``shown``, not among the current cell's ``listed`` objects, and whose image is ``held``:
    the buildings whose blend by distance runs on (:func:`frame_impostors`), by object id."""
    return [rows[o] for o in sorted(rows) if o in shown and o not in listed and held(shown[o].image)]


def _faded(w: WalkState, f: Frame, target: dict[int, DrawnImpostor]) -> list[DrawnImpostor]:
    """The impostors drawn: each building's opacity rises towards ``target``'s at most at
    the rate of :func:`~walkstream.client.draw.impostors.fade_towards` (an image
    arriving fades in) and follows it down (the distance blend and the error bound fall
    smoothly by themselves); a building the cell no longer lists, or whose image is not
    held or over the texture budget, fades out at that rate on the image it was drawn
    with while the lane still holds it; another image of the same building (the viewer
    crossed into another direction bin) cross-fades from the last (:func:`_cross_faded`).
    Remembered in ``w.impostors_shown`` for the next frame."""
    lane = w.scene.images
    fade = FADE_S if w.config.impostor_fade_s is None else w.config.impostor_fade_s
    dt = f.wt - w.impostors_wt if math.isfinite(w.impostors_wt) else math.inf
    w.impostors_wt = f.wt
    out: list[DrawnImpostor] = []
    shown_next: dict[int, DrawnImpostor] = {}
    for obj in sorted(target.keys() | w.impostors_shown.keys()):
        want, last = target.get(obj), w.impostors_shown.get(obj)
        shown = 0.0 if last is None else last.alpha
        if want is not None:
            # in: at most the fade's rate; out: as the distance blend and the error bound
            # say (smooth by themselves; held back, the image would outstay its bound)
            alpha = min(want.alpha, fade_towards(shown, want.alpha, dt, fade))
            base: DrawnImpostor | None = want
        else:  # not listed, not held or over the budget: fading out on the last image
            alpha = fade_towards(shown, 0.0, dt, fade)
            base = last if last is not None and lane is not None and lane.held(last.image) else None
        if base is None or alpha <= 0.0:
            w.impostors_old.pop(obj, None)
            continue
        shown_now = dataclasses.replace(base, alpha=alpha)
        shown_next[obj] = shown_now
        out.extend(_cross_faded(w, last, shown_now, dt, fade))
    w.impostors_shown = shown_next
    return out


def _cross_faded(
    w: WalkState, last: DrawnImpostor | None, now: DrawnImpostor, dt: float, fade: float
) -> list[DrawnImpostor]:
    """``now`` drawn over the image the building showed before, when the viewer's direction
    crossed into another bin: the old image's share falls from 1 to 0 over the fade
    (``w.impostors_old``), composed so that the geometry keeps ``1 - alpha``, the old
    image ``alpha (1 - t)`` and the new ``alpha t`` (``t`` the new one's share): the old
    drawn first at ``alpha (1 - t) / (1 - alpha t)``, the new over it at ``alpha t``."""
    lane = w.scene.images
    if last is not None and last.image != now.image and fade > 0.0 and lane is not None and lane.held(last.image):
        w.impostors_old[now.object] = (last, 1.0)  # a new crossing starts from what was drawn
    if now.object in w.impostors_old:
        old, share = w.impostors_old[now.object]
        share -= max(dt, 0.0) / fade if fade > 0.0 else 1.0
        if share <= 0.0 or lane is None or not lane.held(old.image) or old.image == now.image:
            del w.impostors_old[now.object]
        else:
            w.impostors_old[now.object] = (old, share)
    if now.object not in w.impostors_old:
        return [now]
    old, share = w.impostors_old[now.object]
    a, t = now.alpha, 1.0 - share
    under = a * (1.0 - t) / (1.0 - a * t) if a * t < 1.0 else 0.0
    return [dataclasses.replace(old, alpha=under), dataclasses.replace(now, alpha=a * t)]


def ahead_wants(w: WalkState, f: Frame) -> dict[int, float]:
    """Images the predicted cells will draw: image id -> need, seconds from now.

    For each cell the streamer predicts (its need times, :attr:`Streamer.need`) other
    than the current one, whose record is in and lists impostors, the images chosen for
    the viewer where the motion predictor puts them at that time (the eye moved by the
    velocity times the need), within :data:`AHEAD_S`.  An image two cells want is
    needed at the earlier time.  The lane asks for them in order of need, the images
    of the current cell (need 0) first.
    """
    city = w.scene.streets
    if city is None:
        return {}
    velocity = np.asarray(city.velocity, np.float64)
    cfg = w.config
    out: dict[int, float] = {}
    for cell, t in sorted(city.need.items(), key=lambda kv: kv[1]):
        if cell == f.street or not 0.0 <= t <= AHEAD_S:
            continue
        rec = city.cells.get(cell)
        imp = None if rec is None else rec.impostors
        if imp is None or not imp.rows:
            continue
        eye = np.asarray(f.eye, np.float64).copy()
        eye[:2] += velocity * t
        eyes = [imp.eye(r) for r in imp.rows] if imp.perspective else None
        for c in choose_impostors(imp.rows, eye, imp.d, imp.bound, cfg.impostor_blend_m, cfg.impostor_perspective, eyes,
                                  cfg.impostor_max_size_deg):
            if c.image is not None and c.image not in out:
                out[c.image] = float(t)
    return out


def replaced(ids: list[int], drawn: list[DrawnImpostor]) -> NDArray[np.bool_]:
    """Which of ``ids`` (the frame's objects) are drawn as their image alone."""
    alone = {d.object for d in drawn if d.alpha >= 1.0}
    return np.array([i in alone for i in ids], bool)
