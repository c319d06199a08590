"""One compared frame: the client's picture against the ground truth, pixel by pixel, with causes.

Both frames come as object-ID images (``(h, w)`` uint32: object id + 1, 0 where no
object shows) and colour images (``(h, w, 3)`` uint8) of the same camera.

differing pixel
    A pixel whose colour differs between the two frames by more than
    :data:`COLOUR_TOLERANCE` in some channel (what the viewer would notice: a missing
    building, a coarser facade, a wrong object in front).
missing pixel
    A pixel where the truth shows object ``j`` and the client's frame does not show
    ``j`` (something else, or nothing).  Each is attributed to the first cause of
    :data:`CAUSES` that applies, in this order:

    ``pvs`` (a)
        ``j`` is not in the PVS of the client's current cell: the visibility bake
        left it out.
    ``not_received`` (b)
        in the PVS, but its parameters had not arrived (or the cell record itself had
        not: then the client knows no PVS at all).
    ``not_built`` (c)
        received but its geometry not yet rebuilt.
    ``lod`` (d)
        ``j`` was drawn at a coarser LOD than LOD2, or the client's pixel shows an
        object drawn at a coarser LOD in front of it (the polygon budget).
    ``culled`` (e)
        none of the above, ``j`` is nearer than any fog distance, and still the client
        does not show it: culled by the client (frustum or any other culling) or any
        other fault of the client's drawing.  Must be zero.
    ``fog`` (f)
        ``j`` lies beyond the fog distance in force (a scene with fog hides it on
        purpose): reported, not counted as a miss.

Everything here is numpy over the whole image; nothing draws.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.shared.errors import InputError

__all__ = [
    "CAUSES",
    "MISS_CAUSES",
    "CAUSE_RGB",
    "COLOUR_TOLERANCE",
    "FrameError",
    "compare_frame",
    "missing_mask",
]

#: the causes of a missing pixel, in the order they are tried (a) to (f)
CAUSES: tuple[str, ...] = ("pvs", "not_received", "not_built", "lod", "culled", "fog")
#: the causes that count as a miss (fog hides objects on purpose)
MISS_CAUSES: tuple[str, ...] = CAUSES[:5]
#: the colour of each cause in a mask of missing pixels (:func:`missing_mask`)
CAUSE_RGB: dict[str, tuple[int, int, int]] = {
    "pvs": (228, 26, 28),
    "not_received": (255, 127, 0),
    "not_built": (230, 200, 0),
    "lod": (55, 126, 220),
    "culled": (220, 0, 220),
    "fog": (0, 150, 150),
}
#: a pixel differs when a colour channel differs by more than this (0-255): two shader
#: programs computing the same lighting may round the last bit differently on a GPU
COLOUR_TOLERANCE = 2


@dataclass(frozen=True, slots=True)
class FrameError:
    """What one compared frame got wrong.

    Attributes
    ----------
    pixels : int
        Pixels of the frame.
    differing : int
        Pixels whose colour differs (see the module docs).
    missing : (6,) int64
        Missing pixels per cause, in :data:`CAUSES` order.
    cause : (h, w) int8
        Per pixel the index of its cause in :data:`CAUSES`, -1 where nothing is missing.
    """

    pixels: int
    differing: int
    missing: NDArray[np.int64]
    cause: NDArray[np.int8]

    @property
    def missing_share(self) -> NDArray[np.float64]:
        """(6,) missing pixels per cause as shares of the frame's pixels."""
        out: NDArray[np.float64] = self.missing / max(self.pixels, 1)
        return out

    @property
    def missed(self) -> int:
        """Missing pixels that count as misses (every cause but ``fog``)."""
        return int(self.missing[: len(MISS_CAUSES)].sum())


def _ids(a: ArrayLike | Iterable[int]) -> NDArray[np.int64]:
    """Sorted unique ids of an array or any iterable of ints."""
    if isinstance(a, np.ndarray):
        return np.unique(a.astype(np.int64))
    return np.unique(np.fromiter((int(i) for i in a), np.int64))  # type: ignore[union-attr, arg-type]


def compare_frame(
    truth_ids: ArrayLike,
    truth_rgb: ArrayLike,
    client_ids: ArrayLike,
    client_rgb: ArrayLike,
    *,
    pvs: ArrayLike | None,
    received: ArrayLike | Iterable[int],
    built: ArrayLike | Iterable[int],
    drawn: Mapping[int, int],
    fogged: ArrayLike | Iterable[int] = (),
) -> FrameError:
    """Compare one client frame with its truth and attribute every missing pixel.

    Parameters
    ----------
    truth_ids, client_ids : (h, w) uint32
        Object id + 1 per pixel, 0 for none.
    truth_rgb, client_rgb : (h, w, 3) uint8
        The colour frames.
    pvs : (k,) int or None
        The PVS of the client's current cell (``None``: no cell known, every object
        counts as outside it).
    received, built : ints
        Objects whose parameters / geometry the client had.
    drawn : mapping id -> lod
        The objects the client drew and the LOD of each.
    fogged : ints
        Objects beyond the fog distance in force (none without fog).

    Returns
    -------
    FrameError
    """
    t = np.asarray(truth_ids)
    c = np.asarray(client_ids)
    trgb = np.asarray(truth_rgb)
    crgb = np.asarray(client_rgb)
    if t.ndim != 2 or t.shape != c.shape or trgb.shape != (*t.shape, 3) or crgb.shape != trgb.shape:
        raise InputError(
            "compare_frame: expected (h, w) id images and (h, w, 3) colour images of one size, "
            f"got {t.shape}, {c.shape}, {trgb.shape}, {crgb.shape}"
        )
    diff = np.abs(trgb.astype(np.int16) - crgb.astype(np.int16)).max(axis=2) > COLOUR_TOLERANCE
    tid = t.astype(np.int64) - 1
    cid = c.astype(np.int64) - 1
    miss = (tid >= 0) & (cid != tid)
    cause = np.full(t.shape, -1, np.int8)
    counts = np.zeros(len(CAUSES), np.int64)
    if miss.any():
        j = tid[miss]
        k = cid[miss]
        u, inv = np.unique(j, return_inverse=True)
        d_ids = np.fromiter(drawn.keys(), np.int64, len(drawn))
        d_lod = np.fromiter(drawn.values(), np.int64, len(drawn))
        order = np.argsort(d_ids)
        d_ids, d_lod = d_ids[order], d_lod[order]

        def lod_of(x: NDArray[np.int64]) -> NDArray[np.int64]:
            if len(d_ids) == 0:
                return np.full(len(x), -1, np.int64)
            pos = np.clip(np.searchsorted(d_ids, x), 0, len(d_ids) - 1)
            return np.where(d_ids[pos] == x, d_lod[pos], -1)

        in_pvs = np.isin(u, _ids(pvs)) if pvs is not None else np.zeros(len(u), bool)
        got = np.isin(u, _ids(received))
        blt = np.isin(u, _ids(built))
        lod_j = lod_of(u)
        # per object: the first of (a), (b), (c), (d) that applies, else undecided (-1)
        per_obj = np.select(
            [~in_pvs, ~got, ~blt, (lod_j >= 0) & (lod_j < 2)], [0, 1, 2, 3], default=-1
        )
        px = per_obj[inv.reshape(-1)]
        lod_k = lod_of(k)
        coarse_front = (lod_k >= 0) & (lod_k < 2)
        fog = np.isin(j, _ids(fogged))
        px = np.where(px >= 0, px, np.where(coarse_front, 3, np.where(fog, 5, 4)))
        cause[miss] = px.astype(np.int8)
        counts = np.bincount(px, minlength=len(CAUSES)).astype(np.int64)
    return FrameError(int(t.size), int(diff.sum()), counts, cause)


def missing_mask(truth_rgb: ArrayLike, cause: ArrayLike) -> NDArray[np.uint8]:
    """A picture of the missing pixels: the truth faded to grey, each missing pixel in its cause's colour.

    Parameters
    ----------
    truth_rgb : (h, w, 3) uint8
        The truth frame.
    cause : (h, w) int
        Per pixel the index of its cause in :data:`CAUSES`, -1 where nothing is missing
        (:attr:`FrameError.cause`).

    Returns
    -------
    (h, w, 3) uint8
    """
    rgb = np.asarray(truth_rgb, np.float64)
    grey = rgb @ np.array([0.299, 0.587, 0.114])
    out = np.repeat((150.0 + 0.4 * grey)[..., None], 3, axis=2).astype(np.uint8)
    c = np.asarray(cause)
    table = np.array([CAUSE_RGB[k] for k in CAUSES], np.uint8)
    hit = c >= 0
    out[hit] = table[c[hit]]
    return out
