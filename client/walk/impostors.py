"""Part of the frame step ``allocate``: which far buildings the frame draws as impostors.

On a scene baked with ``--impostors`` the current street cell's record lists the
buildings it may draw as images (:class:`~walkstream.shared.wire.CellImpostors`).
Each frame (:func:`frame_impostors`): the image of the viewer's direction bin and
its opacity by distance and error (:func:`~walkstream.client.draw.impostors.choose_impostors`);
(once the first cell's parameters are all in: the start-up waits for no image) the
images wanted from the impostor lane (:class:`~walkstream.client.stream.images.ImpostorImages`,
needed now, so before the buildings' parameters), and with prefetch on the images the
predicted cells will draw, at their need times (:func:`ahead_wants`); of those held, the ones that fit
the texture budget, the farthest dropped first
(:func:`~walkstream.client.draw.impostors.fit_textures`).  Each kept image is one
:class:`DrawnImpostor`: a quad fixed to its baking direction (the image is an
orthographic view along the bin's direction over the building's bounding square, so
the quad in that plane puts each texel where the bake saw it; the error bound keeps
the viewer's direction near it), two triangles and one draw for the budget and the
device.  A building at opacity 1 is drawn as its image alone (its geometry is left
out of the allocation); between 0 and 1 both are drawn, the image over the geometry.

Without impostors in the record, ``config.impostors`` off, or no street cells,
nothing is chosen and the frame is what it was.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from walkstream.client.draw.impostors import choose_impostors, fit_textures
from walkstream.client.walk.state import Frame, WalkState
from walkstream.shared.impostors import bin_direction, bin_of, directions, image_basis

__all__ = ["AHEAD_S", "DrawnImpostor", "ahead_wants", "frame_impostors", "quad_corners", "replaced"]

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


def quad_corners(box: tuple[float, ...] | NDArray[np.float64], level: int, ia: int, ie: int) -> NDArray[np.float64]:
    """The corners of the quad of a building's ``box`` (``lo`` then ``hi``) for the image
    of bin ``(ia, ie)`` at ``level``: the bounding sphere's square across the bin's direction."""
    b = np.asarray(box, np.float64).reshape(2, 3)
    c = b.mean(axis=0)
    r = float(np.linalg.norm(b[1] - b[0])) / 2.0
    right, up = image_basis(bin_direction(level, ia, ie))
    right, up = np.asarray(right, np.float64) * r, np.asarray(up, np.float64) * r
    return np.stack([c - right - up, c + right - up, c + right + up, c - right + up])


def frame_impostors(w: WalkState, f: Frame) -> list[DrawnImpostor]:
    """The impostors frame ``f`` draws (see the module docstring); wants the missing images."""
    city, lane = w.scene.streets, w.scene.images
    if city is None or lane is None or f.street is None:
        return []
    rec = city.cells.get(f.street)
    imp = None if rec is None else rec.impostors
    if imp is None or not imp.rows:
        return []
    if not lane.started:
        # the start-up: the first cell's parameters before any image, so the first
        # perfect frame does not wait for images sharing the link (it needs none)
        if not all(city.has_object(i) for i in w.objects.pvs):
            return []
        lane.started = True
    blend = w.config.impostor_blend_m
    choices = choose_impostors(imp.rows, f.eye, imp.d, imp.bound, *(() if blend is None else (blend,)))
    wants = ahead_wants(w, f) if w.config.prefetch else {}
    wants.update({c.image: 0.0 for c in choices if c.image is not None})
    lane.want(wants)
    held = {c.image: int(getattr(lane.image(c.image), "nbytes", 0))
            for c in choices if c.image is not None and lane.held(c.image)}
    # an image not held yet: geometry until it comes
    choices = [c if c.image is None or c.image in held else c.__class__(c.object, None, 0.0, c.distance, c.error)
               for c in choices]
    rows = {r.object: r for r in imp.rows}
    out = []
    for c in fit_textures(choices, held, w.config.texture_budget_bytes):
        if c.image is None:
            continue
        r = rows[c.object]
        lo, hi = np.asarray(r.box[:3], np.float64), np.asarray(r.box[3:], np.float64)
        az, el = directions(f.eye, (lo + hi) / 2.0)
        ia, ie = bin_of(r.level, az, el)
        out.append(DrawnImpostor(c.object, c.image, c.alpha, quad_corners(r.box, r.level, int(ia), int(ie)),
                                 held[c.image]))
    return out


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
        for c in choose_impostors(imp.rows, eye, imp.d, imp.bound):
            if c.image is not None and c.image not in out:
                out[c.image] = float(t)
    return out


def replaced(ids: list[int], drawn: list[DrawnImpostor]) -> NDArray[np.bool_]:
    """Which of ``ids`` (the frame's objects) are drawn as their image alone."""
    alone = {d.object for d in drawn if d.alpha >= 1.0}
    return np.array([i in alone for i in ids], bool)
