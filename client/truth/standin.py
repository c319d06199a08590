"""The ``impostor`` hook of the truth: the impostors a frame drew, painted into its pictures.

A compared frame's note carries the impostors the client drew
(:attr:`~walkstream.client.truth.notes.FrameNote.impostors`: each quad with its image
and opacity) and the facade textures drawn over boxes
(:attr:`~walkstream.client.truth.notes.FrameNote.facades`).  :func:`impostor_overlay` is the colour error's hook
(:data:`~walkstream.client.truth.picture.Overlay`): it paints the quads over the
client's picture as the client drew them (the truth renderer's
:meth:`~walkstream.client.truth.render.TruthRenderer.paint_quads`: depth tested
against the picture's geometry, premultiplied blend) and returns the pixels they
changed, whose error the colour comparison puts under ``impostor`` -- and those a
city's ring walls (the note's ``wall_quads``) painted under ``wall``, as an
interior's walls are, so a wall's own error is told from an impostor's; it paints the
facades first, and their pixels stay the boxes' (``lod_colour``), not stand-ins.
:func:`stand_in_ids` is the id comparison's side: a pixel an impostor painted counts
as showing the building the truth shows there when that building was drawn as an
impostor on the frame, so a building drawn as its image is not missing where its
image covers it (and is missing, by its cause, where the image does not).
:func:`wall_stand_in` is the same for the textured virtual walls of an interior: a
culled pixel behind a wall drawn as its texture shows the texture, not a hole (the
culled figures count it under ``wall_pixels``).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.client.truth.notes import FrameNote
from walkstream.client.truth.picture import Overlay, client_keys
from walkstream.client.truth.render import TruthRenderer

__all__ = ["impostor_overlay", "stand_in_ids", "wall_stand_in"]


def impostor_overlay(truth: TruthRenderer, proj: ArrayLike) -> Overlay:
    """The ``impostor`` hook painting a note's impostors and a city's ring walls (its
    ``wall_quads``) with ``truth`` at projection ``proj``: the pixels an impostor shows
    come back as the stand-in mask (cause ``impostor``), those a wall's texture shows as
    the wall mask (cause ``wall``, as an interior's walls)."""

    def paint(note: FrameNote, rgb: NDArray[np.uint8], keys: NDArray[np.int64]) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
        if note.facades:  # the boxes' facades first, part of the boxes' picture (not stand-ins)
            rgb[...] = truth.paint_quads(list(note.facades), note.view, proj)
        imps, walls = [q for _, q in note.impostors], list(note.wall_quads)
        none = np.zeros(rgb.shape[:2], bool)
        if not imps and not walls:
            return none, none
        # one pass, back to front over both kinds, as the client draws them
        out = truth.paint_quads(imps + walls, note.view, proj)
        painted: NDArray[np.bool_] = np.any(out != rgb, axis=2)
        rgb[...] = out
        if not walls:
            return painted, none
        if not imps:
            return none, painted
        wall = painted & _wall_on_top(truth, note, proj, imps, walls, out)
        return painted & ~wall, wall

    return paint


def _wall_on_top(
    truth: TruthRenderer, note: FrameNote, proj: ArrayLike, imps: list[Any], walls: list[Any], out: NDArray[np.uint8]
) -> NDArray[np.bool_]:
    """``(h, w)`` the pixels of the picture ``out`` (impostors and walls painted together)
    where a wall's texture shows rather than an impostor: each kind painted alone over the
    frame's geometry; where both paint, the one whose colour the picture holds (the
    nearer opaque one; one transparent there leaves the other's colour)."""
    alone = []
    for quads in (walls, imps):
        truth.render(note.eye, note.view, truth.flags(client_keys(note)), note.fog, proj=proj)
        under = truth.paint_quads(list(note.facades), note.view, proj) if note.facades else truth.colour()
        over = truth.paint_quads(quads, note.view, proj)
        alone.append((np.any(over != under, axis=2), over.astype(np.int32)))
    (by_wall, wall_rgb), (by_imp, imp_rgb) = alone
    o = out.astype(np.int32)
    nearer = np.abs(o - wall_rgb).sum(axis=2) <= np.abs(o - imp_rgb).sum(axis=2)
    top: NDArray[np.bool_] = by_wall & (~by_imp | nearer)
    return top


def stand_in_ids(
    client_ids: NDArray[np.uint32], truth_ids: NDArray[np.uint32], painted: NDArray[np.bool_], objects: Iterable[int]
) -> NDArray[np.uint32]:
    """``client_ids`` (object id + 1 per pixel) with the pixels an impostor ``painted`` set to
    the truth's building there, where that building is one of the frame's impostor ``objects``."""
    ids = np.fromiter((int(i) + 1 for i in objects), np.int64)
    if not len(ids):
        return client_ids
    take = painted & np.isin(truth_ids.astype(np.int64), ids)
    out = client_ids.copy()
    out[take] = truth_ids[take]
    return out


def wall_stand_in(
    walls: Iterable[ArrayLike], proj: ArrayLike, view: ArrayLike, size: tuple[int, int], depth: NDArray[np.float64]
) -> NDArray[np.bool_]:
    """``(h, w)`` the pixels (row 0 at the top) where a virtual wall drawn as its texture
    stands in for what lies behind it: the pixel's ray meets one of ``walls`` (each
    ``(4, 3)`` quad corners: bottom-left, bottom-right, top-right, top-left) nearer than
    the truth's eye-space ``depth`` there.  What the truth shows there was on the wall's
    texture, not culled (the id comparison's ``wall`` cause)."""
    w, h = int(size[0]), int(size[1])
    out = np.zeros((h, w), bool)
    quads = [np.asarray(q, np.float64).reshape(4, 3) for q in walls]
    if not quads:
        return out
    inv = np.linalg.inv(np.asarray(proj, np.float64) @ np.asarray(view, np.float64))
    V = np.asarray(view, np.float64)
    eye = np.linalg.inv(V)[:3, 3]
    xs = (np.arange(w) + 0.5) / w * 2.0 - 1.0
    ys = 1.0 - (np.arange(h) + 0.5) / h * 2.0  # row 0 at the top
    gx, gy = np.meshgrid(xs, ys)
    far = np.stack([gx, gy, np.ones_like(gx), np.ones_like(gx)], axis=-1) @ inv.T
    ray = far[..., :3] / far[..., 3:4] - eye  # (h, w, 3)
    for q in quads:
        o, u, v = q[0], q[1] - q[0], q[3] - q[0]
        n = np.cross(u, v)
        den = ray @ n
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((o - eye) @ n) / den
            p = eye + ray * t[..., None] - o
            a, b = (p @ u) / (u @ u), (p @ v) / (v @ v)
            zview = -((eye + ray * t[..., None]) @ V[2, :3] + V[2, 3])
            hit = (t > 0) & (a >= 0) & (a <= 1) & (b >= 0) & (b <= 1) & (zview < depth)
        out |= np.nan_to_num(hit, nan=0).astype(bool)
    return out
