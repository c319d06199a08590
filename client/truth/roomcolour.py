"""Colour error of a walk with rooms: what the client drew against the full scene at its full view.

The colour figures of a city walk (:mod:`walkstream.client.truth.missing`) for an
interior walk and a crossing walk.  Each noted frame is drawn twice by the one truth
renderer (:class:`~walkstream.client.truth.render.TruthRenderer`, so that a frame
drawn whole has no error at all):

the full scene
    every room part and city object (at LOD2), **without fog**: the scene as far as the
    projection reaches.  This is the difference from the culled-pixel check
    (:mod:`walkstream.client.truth.culled`), which draws its truth at the frame's fog
    so that what the fog hides on purpose is not a miss; here what the budget's fog hid
    is error, because that is what a better way of drawing the far (virtual walls,
    impostors) must win back.
the client's picture
    the room parts it drew and the city objects it drew, each at the LOD it drew it
    (the coarser forms given to the renderer, :func:`~walkstream.client.truth.picture.forms_of`),
    at the fog in force, and the virtual walls it drew painted over them as it drew
    them (their textures, depth tested against the parts, premultiplied, at their
    opacity: :meth:`~walkstream.client.truth.render.TruthRenderer.paint_quads`, the
    impostors' hook).

Both are compared with :func:`~walkstream.client.truth.colour.compare_colour` (mean
linear-RGB error, ΔE00, pixels over the visible threshold, PSNR).  Where the client's
picture shows another thing than the full scene in another colour (the same colour is
no loss: coincident surfaces tie in depth either way), the pixel's cause (an id cause of
:data:`~walkstream.client.truth.compare.CAUSES`) is, in this order: ``fog`` when the
full scene's surface there lies beyond the frame's fog distance (the budget's fog hid
it); ``not_received`` for a part of a visible cell whose contents had not arrived, or
an object of the visible set not yet received; ``not_built`` for one received and not
built; ``pvs`` for an object outside the visible set; ``lod`` for an object drawn at a
coarser LOD; ``culled`` for anything else left out (portal culling; the culled-pixel
check says whether that was wrong).  Where what the frame kept (drew, or waited for)
lies at the same depth as the full scene's surface (within the culled-pixel check's
:data:`~walkstream.client.truth.culled.TIE_M`: coincident surfaces, a wall's piece in
two cells, show either key), the pixel takes the kept thing's cause instead, as that
check counts it: late if it was waited for, none if it was drawn.  A pixel a wall's texture painted is the wall's:
its colour cause is ``wall`` (:data:`~walkstream.client.truth.colour.COLOUR_CAUSES`),
and it is not counted as lacking by an id cause (the texture stands in, as the
culled-pixel check counts it under ``wall_pixels``), so the error with walls is the
error of what the viewer saw.

Poses in solid geometry are left out as the culled-pixel check leaves them out
(:data:`~walkstream.client.truth.culled.SOLID_NEAR`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from walkstream.client.report.colour import ColourLog
from walkstream.client.report.truth import TruthLog
from walkstream.client.truth.colour import COLOUR_CAUSES, compare_colour
from walkstream.client.truth.compare import CAUSES
from walkstream.client.truth.culled import SOLID_NEAR, TIE_M, kept_keys
from walkstream.client.truth.missing import ColourWorst
from walkstream.client.truth.notes import FrameNote
from walkstream.client.truth.picture import client_keys
from walkstream.client.truth.render import TruthRenderer, object_key
from walkstream.client.truth.seam import SeamMeter, still_quads, wall_pixels
from walkstream.client.truth.solid import SolidProbe

__all__ = ["RoomColour", "pixel_distance", "room_colour"]

_PVS, _NOT_RECEIVED, _NOT_BUILT, _LOD, _CULLED, _FOG = (
    CAUSES.index(c) for c in ("pvs", "not_received", "not_built", "lod", "culled", "fog")
)


@dataclass(frozen=True)
class RoomColour:
    """The colour figures of a walk with rooms."""

    log: TruthLog
    """One row per compared frame: differing pixels, pixels the client lacks by cause
    (against the full scene without fog) and the colour figures (``log.colour``)."""
    worst: ColourWorst | None
    """The compared frame with the largest mean colour error, as images."""
    fog_m: NDArray[np.float64]
    """``(n,)`` the fog distance of each compared frame (``inf``: none)."""
    seam: SeamMeter | None = None
    """The seam at the walls' zone borders (None: no frame drew a wall)."""


def _causes(note: FrameNote, ki: NDArray[np.int64], oid_of: NDArray[np.int64], cell_of: NDArray[np.int64],
            is_part: NDArray[np.bool_]) -> NDArray[np.int64]:
    """``(h, w)`` the id cause (an index of :data:`CAUSES`, fog apart) of the frame lacking
    the key ``ki`` of each pixel (module docs: the order the causes are told in)."""
    oid = oid_of[ki]
    waiting = np.isin(cell_of[ki], np.asarray(note.waiting, np.int64)) & is_part[ki]
    in_pvs = np.isin(oid, note.pvs if note.pvs is not None else np.zeros(0, np.int64))
    received = np.isin(oid, note.received)
    built = np.isin(oid, note.built)
    coarse = np.isin(oid, np.array([i for i, lod, _ in note.drawn if lod < 2], np.int64))
    obj = oid >= 0
    c = np.full(ki.shape, _CULLED, np.int64)
    c = np.where(obj & coarse, _LOD, c)
    c = np.where(obj & in_pvs & received & ~built, _NOT_BUILT, c)
    c = np.where(obj & in_pvs & ~received, _NOT_RECEIVED, c)
    c = np.where(obj & ~in_pvs, _PVS, c)
    out: NDArray[np.int64] = np.where(waiting, _NOT_RECEIVED, c)
    return out


def pixel_distance(depth: NDArray[np.float64], proj: NDArray[np.float64]) -> NDArray[np.float64]:
    """``(h, w)`` the distance from the eye of each pixel's surface, metres, from its
    eye-space depth ``(h, w)`` (row 0 at the top) and the projection: the fog is a
    distance, the depth buffer a depth along the view axis."""
    h, w = depth.shape
    x = (2.0 * (np.arange(w) + 0.5) / w - 1.0) / float(proj[0, 0])
    y = (1.0 - 2.0 * (np.arange(h) + 0.5) / h) / float(proj[1, 1])
    factor = np.sqrt(1.0 + x[None, :] ** 2 + y[:, None] ** 2)
    out: NDArray[np.float64] = depth * factor
    return out


def room_colour(
    truth: TruthRenderer,
    notes: Sequence[FrameNote],
    *,
    solid: SolidProbe | None = None,
    progress: Callable[[int, int], None] | None = None,
    viewer_ppd: float | None = None,
) -> RoomColour:
    """Compare each noted frame that knew its visible set with the full scene (module docs).

    ``truth`` holds every room part, the city objects at LOD2 and the coarser forms the
    frames drew (``forms=forms_of(notes)``); it must be drawn with its own projection
    (the client's).  ``viewer_ppd``: the display's pixels per degree of the viewer-scale
    (S-CIELAB) figures (None: not measured).
    """
    ppd = None if viewer_ppd is None else float(viewer_ppd)
    n_keys = len(truth.keys)
    # one identity per thing shown: a room part is itself, an object's forms are the object
    ident = np.arange(n_keys, dtype=np.int64)
    oid_of = truth.object_ids(np.arange(n_keys)).astype(np.int64) - 1
    for k in np.flatnonzero(oid_of >= 0).tolist():
        ident[k] = truth.index.get(object_key(int(oid_of[k])), k)
    is_part = oid_of < 0
    cell_of = np.where(is_part, np.array([key[0] for key in truth.keys], np.int64).reshape(-1), -1)
    rows: list[tuple[int, float, float, NDArray[np.float64],
               tuple[float, float, float, float, NDArray[np.float64], NDArray[np.float64], float, float,
                     NDArray[np.float64]], float]] = []
    worst: ColourWorst | None = None
    seam: SeamMeter | None = None
    seen_quads: list[Any] = []  # the last frame's wall quads: its textures by id
    for j, note in enumerate(notes):
        if progress is not None:
            progress(j + 1, len(notes))
        if note.pvs is None:
            continue
        if solid is not None and math.isfinite(solid.nearest(note.eye, SOLID_NEAR * truth.near)):
            continue
        t_idx, t_depth = truth.render(note.eye, note.view)
        t_rgb = truth.colour()
        drawn = client_keys(note)
        c_idx, c_depth = truth.render(note.eye, note.view, truth.flags(drawn), note.fog)
        c_rgb = truth.colour()
        wall = np.zeros(t_idx.shape, bool)
        if note.wall_quads:  # the walls over the parts, as the client drew them
            painted = truth.paint_quads(note.wall_quads, note.view)
            wall = np.any(painted != c_rgb, axis=2)
            c_rgb = painted
        if note.seam_walls or seam is not None:
            seam = seam or SeamMeter()
            still = None
            earlier = seam.earlier(note.seam_walls)
            if any(e is not None for e in earlier):  # the frame held still: motion and look apart
                images = {-1 - q[1]: q[2] for q in [*seen_quads, *note.wall_quads]}
                quads = still_quads(note.seam_walls, earlier, images)
                if quads is not None:
                    truth.render(note.eye, note.view, truth.flags(drawn), note.fog)
                    still = truth.paint_quads(quads, note.view)
            seam.add(c_rgb, note.seam_walls, wall_pixels(note.seam_walls, note.view, truth.proj, c_depth), still)
            seen_quads = list(note.wall_quads)
        shown = t_idx >= 0
        ti = np.maximum(t_idx, 0)
        ci = np.maximum(c_idx, 0)
        differ = np.any(t_rgb != c_rgb, axis=2)
        # another thing in the same colour is no loss: coincident surfaces (a slab's top
        # under a room's floor, a piece of wall in two cells) tie in depth either way
        lacks = shown & differ & ((c_idx < 0) | (ident[ti] != ident[ci]))
        cause = np.full(t_idx.shape, -1, np.int64)
        if lacks.any():
            beyond = pixel_distance(t_depth, truth.proj) > note.fog
            c = _causes(note, ti, oid_of, cell_of, is_part)
            left_out = lacks & (c == _CULLED)
            if left_out.any():
                # what the frame kept (drew, or waited for) at the same depth is no culling,
                # as the culled-pixel check counts it: coincident surfaces (a wall's piece in
                # two cells) show either key, so the cause is the kept key's own
                kept_flags = truth.flags(kept_keys(truth, note)[1])
                k_idx, k_depth = truth.render(note.eye, note.view, kept_flags, note.fog)
                tie = left_out & (k_idx >= 0) & (k_depth <= t_depth + TIE_M)
                if tie.any():
                    ki = np.maximum(k_idx, 0)
                    own = np.where(truth.flags(drawn)[ki], -1, _causes(note, ki, oid_of, cell_of, is_part))
                    c = np.where(tie, own, c)
            c = np.where(beyond, _FOG, c)
            cause = np.where(lacks & ~wall, c, -1)
        lods = truth.lods(c_idx)
        err = compare_colour(t_rgb, c_rgb, id_cause=cause, coarse=(lods >= 0) & (lods < 2), wall=wall, ppd=ppd)
        pixels = err.pixels
        missing = np.bincount(cause[cause >= 0], minlength=len(CAUSES)).astype(np.float64) / pixels
        differing = float(np.count_nonzero(differ)) / pixels
        rows.append((note.frame, note.t, differing, missing,
                     (err.mean_error, err.delta_e_mean, err.visible_share, err.psnr_db, err.cause_shares, err.error_shares,
                      err.scielab_delta_e_mean, err.scielab_visible_share, err.scielab_cause_shares),
                     note.fog))
        if worst is None or err.mean_error > worst.mean_error:
            worst = ColourWorst(note.frame, note.t, err.mean_error, err.visible_share, err.psnr_db, c_rgb, t_rgb,
                                err.delta_e, None if ppd is None else err.scielab_visible_share, err.scielab_delta_e, ppd)
    frames = np.array([r[0] for r in rows], np.int64)
    times = np.array([r[1] for r in rows], np.float64)

    def col(k: int) -> NDArray[np.float64]:
        return np.array([r[4][k] for r in rows], np.float64)

    colour = ColourLog(frames, times, col(0), col(1), col(2), col(3),
                       np.array([r[4][4] for r in rows]).reshape(-1, len(COLOUR_CAUSES)),
                       np.array([r[4][5] for r in rows]).reshape(-1, len(COLOUR_CAUSES)),
                       delta_e_scielab_mean=None if ppd is None else col(6),
                       visible_scielab=None if ppd is None else col(7),
                       causes_scielab=None if ppd is None else np.array([r[4][8] for r in rows]).reshape(-1, len(COLOUR_CAUSES)),
                       viewer_ppd=ppd)
    log = TruthLog(frames, times, np.array([r[2] for r in rows], np.float64),
                   np.array([r[3] for r in rows]).reshape(-1, len(CAUSES)), colour)
    return RoomColour(log, worst, np.array([r[5] for r in rows], np.float64), seam)
