"""The client's picture of a compared frame, drawn by the one truth renderer, and its colour error.

A compared frame's colour error (:mod:`walkstream.client.truth.colour`) needs two
pictures of one camera drawn alike: the full scene (every object within the view
distance at LOD2: :meth:`~walkstream.client.truth.render.TruthRenderer.colour_frame`)
and the client's picture -- the objects the client drew, each at the LOD it drew it,
at the fog in force (:func:`client_picture`).  Both come from the same
:class:`~walkstream.client.truth.render.TruthRenderer` (same shader, light and
palette; the client's coarser forms uploaded as ``forms``, :func:`forms_of`), so a
frame drawn at LOD2 throughout has no colour error at all and any error left is the
client's choice of what and how to draw.  An object the client drew at LOD2 is drawn
from the truth's own LOD2 mesh (the same parameters through the same grammar: the id
comparison already holds the client's LOD2 to it); its coarser forms are the client's
own meshes as the frame noted them.

The ``impostor`` hook: the client's picture is geometry only.  A part that draws an
image in place of an object (an impostor) passes ``overlay``: a callable given the
frame's note, the picture (``(h, w, 3)`` uint8, written in place) and the per-pixel
key index of the geometry under it, that paints the images the client drew over the
picture and returns two ``(h, w)`` bool masks of the pixels it painted: where an
impostor shows, whose error is attributed to ``impostor``, and where a virtual wall's
texture shows (a city's ring walls), attributed to ``wall`` as an interior's walls are
(:data:`~walkstream.client.truth.colour.COLOUR_CAUSES`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.client.truth.antialias import Sampling
from walkstream.client.truth.colour import ColourError, compare_colour, pixels_per_degree
from walkstream.client.truth.notes import FrameNote
from walkstream.client.truth.render import TruthRenderer, form_key, object_key
from walkstream.shared.records import Mesh

__all__ = ["Overlay", "ClientPicture", "client_keys", "forms_of", "client_picture", "colour_error", "view_ppd"]

Overlay = Callable[[FrameNote, NDArray[np.uint8], NDArray[np.int64]], tuple[NDArray[np.bool_], NDArray[np.bool_]]]
"""``overlay(note, rgb, keys) -> (stand_in, wall)``: the ``impostor`` hook (see the module docs)."""


@dataclass(frozen=True)
class ClientPicture:
    """What the client drew on one frame, as the truth renderer draws it."""

    rgb: NDArray[np.uint8]
    """``(h, w, 3)`` the picture, row 0 at the top."""
    ids: NDArray[np.uint32]
    """``(h, w)`` object id + 1 per pixel, 0 where none shows (images an ``overlay`` painted aside)."""
    coarse: NDArray[np.bool_]
    """``(h, w)`` pixels showing an object drawn at a coarser LOD than LOD2, with the facade
    pictures an ``overlay`` painted over the boxes (the boxes' picture)."""
    stand_in: NDArray[np.bool_] | None
    """``(h, w)`` pixels an ``overlay`` painted with an impostor (None without one)."""
    wall: NDArray[np.bool_] | None = None
    """``(h, w)`` pixels an ``overlay`` painted with a virtual wall's texture (None without one)."""


def client_keys(note: FrameNote) -> list[tuple[int, int]]:
    """The truth renderer's keys of what a noted frame drew: its room parts, its objects
    at LOD2 (:func:`~.render.object_key`) or at the coarser LOD it drew them (:func:`~.render.form_key`)."""
    objs = [object_key(i) if lod >= 2 else form_key(i, lod) for i, lod, _ in note.drawn]
    return [*note.parts, *objs]


def forms_of(notes: Iterable[FrameNote]) -> dict[tuple[int, int], Mesh]:
    """``(object id, lod) -> mesh`` of every form coarser than LOD2 the noted frames drew."""
    out: dict[tuple[int, int], Mesh] = {}
    for st in notes:
        for i, lod, mesh in st.drawn:
            if 0 <= lod < 2:
                out.setdefault((int(i), int(lod)), mesh)
    return out


def client_picture(
    truth: TruthRenderer, note: FrameNote, proj: ArrayLike | None = None, overlay: Overlay | None = None,
    samples: Sampling | None = None,
) -> ClientPicture:
    """Draw the objects ``note`` says the client drew, each at its LOD, from its camera and at its fog.

    ``truth`` must hold the coarser forms the note drew (``forms=forms_of(notes)``);
    objects it lacks are left out, as :meth:`TruthRenderer.colour_frame` leaves them.
    ``samples``: the picture's colour anti-aliased so (a client drawing with a GPU's
    anti-aliasing; :mod:`walkstream.client.truth.antialias`); None: point-sampled, as
    the client draws.  Its ids and masks stay point-sampled.
    """
    idx, _ = truth.render(note.eye, note.view, truth.flags(client_keys(note)), note.fog, proj=proj, samples=samples)
    rgb = truth.colour()
    lods = truth.lods(idx)
    coarse = (lods >= 0) & (lods < 2)
    ids = truth.object_ids(idx)
    if overlay is None:
        return ClientPicture(rgb, ids, coarse, None)
    before = rgb.copy()
    stand_in, wall = overlay(note, rgb, idx)
    stand_in, wall = np.asarray(stand_in, bool), np.asarray(wall, bool)
    # what the overlay painted that is neither a stand-in nor a wall is a box's facade picture:
    # the box's coarse form, also where the quad's edge covers a pixel the box's own id does not
    coarse |= np.any(rgb != before, axis=2) & ~stand_in & ~wall
    return ClientPicture(rgb, ids, coarse, stand_in, wall)


def colour_error(
    truth: TruthRenderer,
    note: FrameNote,
    truth_rgb: ArrayLike,
    id_cause: ArrayLike,
    proj: ArrayLike | None = None,
    overlay: Overlay | None = None,
    ppd: float | None = None,
    samples: Sampling | None = None,
) -> tuple[ColourError, ClientPicture]:
    """The colour error of one compared frame: its client picture against the full scene ``truth_rgb``.

    ``id_cause`` is the frame's id-based cause per pixel
    (:attr:`~walkstream.client.truth.compare.FrameError.cause`).  The viewer-scale
    (S-CIELAB) figures are measured at ``ppd`` pixels per degree (the view's own is
    :func:`view_ppd`); None: not measured (their filtering costs 0.1-1 s a frame).
    ``samples`` is the client picture's sampling (:func:`client_picture`).
    """
    pic = client_picture(truth, note, proj, overlay, samples)
    err = compare_colour(truth_rgb, pic.rgb, id_cause=id_cause, coarse=pic.coarse, stand_in=pic.stand_in,
                         wall=pic.wall, ppd=ppd)
    return err, pic


def view_ppd(proj: ArrayLike, height_px: int) -> float:
    """Pixels per degree at the centre of a view of projection ``proj`` (4, 4) and ``height_px`` rows."""
    fov = math.degrees(2.0 * math.atan(1.0 / float(np.asarray(proj)[1, 1])))
    return pixels_per_degree(int(height_px), fov)
