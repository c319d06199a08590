"""The worst frame of a walk with rooms as images: the frame, its truth, and a mask of what was culled.

Like a city walk's worst frame (:mod:`walkstream.client.truth.missing`), so that a user
sees where culling hid something, not only how much: the frame as the client drew it
(the truth renderer drawing only the keys the frame drew), the truth of everything, and
a mask of its culled pixels coloured by the cell whose part the truth shows there
(:func:`cell_rgb`), the pinholes white, what the frame shows grey underneath.
"""

from __future__ import annotations

import colorsys
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from walkstream.client.truth.culled import CulledRow, check_kept, kept_keys
from walkstream.client.truth.notes import FrameNote
from walkstream.client.truth.render import TruthRenderer

__all__ = ["PINHOLE_RGB", "CulledFrame", "cell_rgb", "culled_view", "worst_row"]

#: The mask colour of a pinhole (a single-pixel crack, reported apart).
PINHOLE_RGB = (255, 255, 255)


@dataclass(frozen=True)
class CulledFrame:
    """A compared frame as images (``(h, w, 3) uint8`` each) and its figures."""

    frame: int
    t: float
    culled_pixels: int
    pinholes: int
    client: NDArray[np.uint8]
    truth: NDArray[np.uint8]
    mask: NDArray[np.uint8]
    cells: tuple[int, ...]
    """The cells whose parts show in the culled pixels (the mask's colours)."""


def cell_rgb(cell: int) -> tuple[int, int, int]:
    """A cell's colour in the mask: hues spread by the golden ratio, so neighbouring ids differ."""
    r, g, b = colorsys.hsv_to_rgb((cell * 0.618033988749895) % 1.0, 0.85, 1.0)
    return int(255 * r), int(255 * g), int(255 * b)


def worst_row(rows: Sequence[CulledRow]) -> CulledRow | None:
    """The compared frame with the most culled pixels, then the most pinholes (None: none missed any)."""
    best = max((r for r in rows if not r.refused), key=lambda r: (r.culled_pixels, r.pinholes), default=None)
    return best if best is not None and (best.culled_pixels or best.pinholes) else None


def culled_view(truth: TruthRenderer, note: FrameNote) -> CulledFrame:
    """Draw a noted frame, its truth and its culled-pixel mask (see the module docstring)."""
    drawn, kept = kept_keys(truth, note)
    chk = check_kept(truth, kept, note.eye, note.view, note.fog)
    truth.render(note.eye, note.view, None, note.fog)
    whole = truth.colour()
    truth.render(note.eye, note.view, truth.flags(drawn), note.fog)
    client = truth.colour()
    assert chk.mask is not None and chk.ids is not None and chk.pinhole_mask is not None
    culled = chk.mask & ~chk.pinhole_mask
    grey = (0.35 * client.mean(axis=2, keepdims=True)).astype(np.uint8)
    mask = np.repeat(grey, 3, axis=2)
    keys = truth.keys
    cells = sorted({keys[i][0] for i in np.unique(chk.ids[culled]).tolist()})
    cell_of = np.array([k[0] for k in keys] + [-1], np.int64)[chk.ids]  # -1 indexes the pad: nothing
    for c in cells:
        mask[culled & (cell_of == c)] = cell_rgb(c)
    mask[chk.pinhole_mask] = PINHOLE_RGB
    return CulledFrame(note.frame, note.t, int(np.count_nonzero(culled)), chk.pinholes, client, whole, mask,
                       tuple(int(c) for c in cells))
