"""The ``impostor`` hook of the truth: the impostors a frame drew, painted into its pictures.

A compared frame's note carries the impostors the client drew
(:attr:`~walkstream.client.truth.notes.FrameNote.impostors`: each quad with its image
and opacity).  :func:`impostor_overlay` is the colour error's hook
(:data:`~walkstream.client.truth.picture.Overlay`): it paints the quads over the
client's picture as the client drew them (the truth renderer's
:meth:`~walkstream.client.truth.render.TruthRenderer.paint_quads`: depth tested
against the picture's geometry, premultiplied blend) and returns the pixels they
changed, whose error the colour comparison puts under ``impostor``.
:func:`stand_in_ids` is the id comparison's side: a pixel an impostor painted counts
as showing the building the truth shows there when that building was drawn as an
impostor on the frame, so a building drawn as its image is not missing where its
image covers it (and is missing, by its cause, where the image does not).
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.client.truth.notes import FrameNote
from walkstream.client.truth.picture import Overlay
from walkstream.client.truth.render import TruthRenderer

__all__ = ["impostor_overlay", "stand_in_ids"]


def impostor_overlay(truth: TruthRenderer, proj: ArrayLike) -> Overlay:
    """The ``impostor`` hook painting a note's impostors with ``truth`` at projection ``proj``."""

    def paint(note: FrameNote, rgb: NDArray[np.uint8], keys: NDArray[np.int64]) -> NDArray[np.bool_]:
        if not note.impostors:
            return np.zeros(rgb.shape[:2], bool)
        out = truth.paint_quads([q for _, q in note.impostors], note.view, proj)
        mask: NDArray[np.bool_] = np.any(out != rgb, axis=2)
        rgb[...] = out
        return mask

    return paint


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
