"""Colour error of one frame against its truth: linear-RGB error, CIEDE2000 ΔE, visible pixels, PSNR, causes.

Both pictures are ``(h, w, 3)`` uint8 sRGB of the same camera, drawn by the one truth
renderer (:mod:`walkstream.client.truth.picture`): the client's picture (its objects
at the LOD it drew them) and the full scene (every object at LOD2).  The figures,
numpy over the whole image:

mean error
    Mean over pixels and channels of ``|client - truth|`` in *linear* RGB (the sRGB
    transfer curve undone, IEC 61966-2-1), 0..1: a share of full scale.  Linear,
    because light adds there: a dark window drawn as a pale wall counts for the
    light that is wrong, not for the gamma-compressed code values.
ΔE
    CIEDE2000 (Sharma, Wu and Dalal 2005, ``kL = kC = kH = 1``) between the two
    pixels' CIELAB (D65) colours.  CIEDE2000 rather than CIE76: CIE76 is the plain
    distance in CIELAB, which overstates differences of saturated colours and
    understates those of near-neutrals by up to a factor of a few; a city is mostly
    near-neutral facades, greys and a pale sky, exactly where CIE76 is least uniform.
visible pixels
    Pixels with ΔE00 > :data:`VISIBLE_DE` (2.3).  ΔE00 is scaled so that about one
    unit is a just-noticeable difference between two large uniform patches side by
    side; a pixel of a moving picture is neither large nor side by side, so the
    threshold sits above one JND -- at 2.3, the JND usually quoted for CIELAB (Mahy,
    Van Eycken and Oosterlinck 1994), so that the figure reads as "a noticeably
    different pixel".  It is also above rounding: every channel one level of 255
    off, in any direction, stays at or under ΔE00 2.29 for every colour of the
    palette at every shade from the ambient light to full light, and for the sky
    (``tests/test_colour.py`` checks it; near-neutral dark greys are the worst case,
    where CIEDE2000 is most sensitive to a hue shift).  Both pictures come from one
    renderer, so a frame drawn at LOD2 throughout has no error at all.
PSNR
    ``10 log10(255² / MSE)`` over the sRGB code values of all three channels, dB;
    identical pictures have no error and an infinite PSNR (:func:`psnr` returns
    ``inf``; JSON has no infinity, so the report writes :data:`PSNR_CAP_DB`).
causes
    Every visible pixel is attributed to one of :data:`COLOUR_CAUSES`: where the
    client's picture lacks the truth's object, that pixel's id-based cause
    (:data:`~walkstream.client.truth.compare.CAUSES`, unchanged); where an
    image-based stand-in drew the pixel, ``impostor`` (``wall`` where it is a virtual
    wall's texture, indoors); where the client shows the
    right object (or an object where the truth shows sky) drawn at a coarser LOD
    than LOD2, ``lod_colour`` (its box has no windows); anything else is ``other``
    (the right object at LOD2 and still the wrong colour: must be zero).

The ``impostor`` hook: an image-based part that stands in for an object paints its
pixels into the client's picture and hands their mask as ``stand_in`` to
:func:`compare_colour` (through the ``overlay`` of
:func:`~walkstream.client.truth.picture.client_picture`); those pixels are its
error, whatever the id comparison says of them.  A virtual wall's texture hands its
mask as ``wall`` the same way.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.client.truth.compare import CAUSES
from walkstream.shared.errors import InputError

__all__ = [
    "VISIBLE_DE",
    "PSNR_CAP_DB",
    "COLOUR_CAUSES",
    "COLOUR_CAUSE_RGB",
    "ColourError",
    "srgb_to_linear",
    "srgb_to_lab",
    "delta_e_2000",
    "psnr",
    "compare_colour",
    "heat_map",
]

#: ΔE00 above which a pixel counts as visibly wrong (see the module docs).
VISIBLE_DE = 2.3

#: The PSNR the report writes for identical pictures (dB).  Any real difference between
#: 8-bit pictures of fewer than 10**10 values scores less: one level off in one value
#: of 10**10 gives 48.1 + 100 = 148.1 dB.
PSNR_CAP_DB = 150.0

#: The causes of a visibly wrong pixel: the id-based causes, then the colour ones.
COLOUR_CAUSES: tuple[str, ...] = (*CAUSES, "impostor", "lod_colour", "other", "wall")

#: The colour of each colour cause in pictures and plots (the id causes keep theirs).
COLOUR_CAUSE_RGB: dict[str, tuple[int, int, int]] = {
    "impostor": (0, 158, 115),
    "lod_colour": (86, 180, 233),
    "other": (90, 90, 90),
    "wall": (204, 121, 167),
}

_IMPOSTOR, _LOD_COLOUR, _OTHER, _WALL = (COLOUR_CAUSES.index(c) for c in ("impostor", "lod_colour", "other", "wall"))

# sRGB (IEC 61966-2-1) to XYZ, D65 white
_RGB_TO_XYZ = np.array(
    [[0.4124564, 0.3575761, 0.1804375], [0.2126729, 0.7151522, 0.0721750], [0.0193339, 0.1191920, 0.9503041]]
)
_WHITE = _RGB_TO_XYZ.sum(axis=1)


def _linear_table() -> NDArray[np.float64]:
    c = np.arange(256, dtype=np.float64) / 255.0
    t = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    t.flags.writeable = False
    return t


_LINEAR = _linear_table()


def srgb_to_linear(rgb: ArrayLike) -> NDArray[np.float64]:
    """Linear RGB (0..1) of sRGB code values (uint8, 0..255), same shape."""
    a = np.asarray(rgb)
    if a.dtype != np.uint8:
        raise InputError(f"srgb_to_linear: expected uint8 sRGB, got {a.dtype}")
    out: NDArray[np.float64] = _LINEAR[a]
    return out


def srgb_to_lab(rgb: ArrayLike) -> NDArray[np.float64]:
    """CIELAB (D65) of sRGB code values: ``(..., 3)`` uint8 -> ``(..., 3)`` float (L*, a*, b*)."""
    xyz = srgb_to_linear(rgb) @ _RGB_TO_XYZ.T / _WHITE
    d = 6.0 / 29.0
    f = np.where(xyz > d**3, np.cbrt(xyz), xyz / (3 * d * d) + 4.0 / 29.0)
    return np.stack([116.0 * f[..., 1] - 16.0, 500.0 * (f[..., 0] - f[..., 1]), 200.0 * (f[..., 1] - f[..., 2])], axis=-1)


def delta_e_2000(lab1: ArrayLike, lab2: ArrayLike) -> NDArray[np.float64]:
    """CIEDE2000 colour difference (``kL = kC = kH = 1``) of ``(..., 3)`` CIELAB arrays.

    The formula of Sharma, Wu and Dalal (2005), vectorised; their test data (34
    pairs) are matched to 4 decimals (``tests/test_colour.py``).
    """
    a1 = np.asarray(lab1, np.float64)
    a2 = np.asarray(lab2, np.float64)
    if a1.shape != a2.shape or a1.shape[-1:] != (3,):
        raise InputError(f"delta_e_2000: expected two (..., 3) Lab arrays of one shape, got {a1.shape}, {a2.shape}")
    l1, x1, y1 = a1[..., 0], a1[..., 1], a1[..., 2]
    l2, x2, y2 = a2[..., 0], a2[..., 1], a2[..., 2]
    c7 = ((np.hypot(x1, y1) + np.hypot(x2, y2)) / 2.0) ** 7
    g = 0.5 * (1.0 - np.sqrt(c7 / (c7 + 25.0**7)))
    p1, p2 = (1.0 + g) * x1, (1.0 + g) * x2
    c1, c2 = np.hypot(p1, y1), np.hypot(p2, y2)
    h1 = np.degrees(np.arctan2(y1, p1)) % 360.0
    h2 = np.degrees(np.arctan2(y2, p2)) % 360.0
    chroma0 = (c1 * c2) == 0.0
    dh = h2 - h1
    dh = np.where(dh > 180.0, dh - 360.0, np.where(dh < -180.0, dh + 360.0, dh))
    dh = np.where(chroma0, 0.0, dh)
    d_l = l2 - l1
    d_c = c2 - c1
    d_h = 2.0 * np.sqrt(c1 * c2) * np.sin(np.radians(dh) / 2.0)
    lm = (l1 + l2) / 2.0
    cm = (c1 + c2) / 2.0
    hs = h1 + h2
    hm = np.where(np.abs(h1 - h2) <= 180.0, hs / 2.0, np.where(hs < 360.0, (hs + 360.0) / 2.0, (hs - 360.0) / 2.0))
    hm = np.where(chroma0, hs, hm)
    t = (
        1.0
        - 0.17 * np.cos(np.radians(hm - 30.0))
        + 0.24 * np.cos(np.radians(2.0 * hm))
        + 0.32 * np.cos(np.radians(3.0 * hm + 6.0))
        - 0.20 * np.cos(np.radians(4.0 * hm - 63.0))
    )
    d_theta = 30.0 * np.exp(-(((hm - 275.0) / 25.0) ** 2))
    cm7 = cm**7
    r_c = 2.0 * np.sqrt(cm7 / (cm7 + 25.0**7))
    s_l = 1.0 + 0.015 * (lm - 50.0) ** 2 / np.sqrt(20.0 + (lm - 50.0) ** 2)
    s_c = 1.0 + 0.045 * cm
    s_h = 1.0 + 0.015 * cm * t
    r_t = -np.sin(np.radians(2.0 * d_theta)) * r_c
    q_l, q_c, q_h = d_l / s_l, d_c / s_c, d_h / s_h
    out: NDArray[np.float64] = np.sqrt(np.maximum(q_l**2 + q_c**2 + q_h**2 + r_t * q_c * q_h, 0.0))
    return out


def psnr(a: ArrayLike, b: ArrayLike) -> float:
    """PSNR of two uint8 pictures over every value, dB (``inf`` when they are identical)."""
    x = np.asarray(a)
    y = np.asarray(b)
    if x.shape != y.shape or x.dtype != np.uint8 or y.dtype != np.uint8:
        raise InputError(f"psnr: expected two uint8 pictures of one shape, got {x.shape} {x.dtype}, {y.shape} {y.dtype}")
    if x.size == 0:
        return math.inf
    mse = float(np.mean((x.astype(np.float64) - y.astype(np.float64)) ** 2))
    return math.inf if mse == 0.0 else 10.0 * math.log10(255.0**2 / mse)


@dataclass(frozen=True, slots=True)
class ColourError:
    """The colour error of one compared frame (see the module docs).

    Attributes
    ----------
    pixels : int
        Pixels of the frame.
    mean_error : float
        Mean absolute linear-RGB error per pixel and channel, 0..1 of full scale.
    delta_e_mean : float
        Mean ΔE00 over the frame's pixels.
    visible : int
        Pixels with ΔE00 > :data:`VISIBLE_DE`.
    psnr_db : float
        PSNR of the sRGB pictures, dB (``inf``: identical).
    causes : (len(COLOUR_CAUSES),) int64
        Visible pixels per cause, in :data:`COLOUR_CAUSES` order (they sum to ``visible``).
    delta_e : (h, w) float32
        ΔE00 per pixel.
    error_causes : (len(COLOUR_CAUSES),) float64
        ``mean_error`` split by cause: each differing pixel's linear-RGB error, summed
        per cause (every differing pixel, visible or not, attributed as the visible
        ones are) over ``3 * pixels``; they sum to ``mean_error``.  Where the error
        comes from, weighted by how wrong each pixel is.
    """

    pixels: int
    mean_error: float
    delta_e_mean: float
    visible: int
    psnr_db: float
    causes: NDArray[np.int64]
    delta_e: NDArray[np.float32]
    error_causes: NDArray[np.float64] | None = None

    @property
    def visible_share(self) -> float:
        """Visible pixels as a share of the frame."""
        return self.visible / max(self.pixels, 1)

    @property
    def error_shares(self) -> NDArray[np.float64]:
        """``error_causes`` (zeros when not measured)."""
        if self.error_causes is None:
            return np.zeros(len(COLOUR_CAUSES))
        return self.error_causes

    @property
    def cause_shares(self) -> NDArray[np.float64]:
        """Visible pixels per cause as shares of the frame."""
        out: NDArray[np.float64] = self.causes / max(self.pixels, 1)
        return out


def compare_colour(
    truth_rgb: ArrayLike,
    client_rgb: ArrayLike,
    *,
    id_cause: ArrayLike | None = None,
    coarse: ArrayLike | None = None,
    stand_in: ArrayLike | None = None,
    wall: ArrayLike | None = None,
) -> ColourError:
    """The colour error of the client's picture against the truth's (see the module docs).

    Parameters
    ----------
    truth_rgb, client_rgb : (h, w, 3) uint8
        The full scene and the client's picture, same camera.
    id_cause : (h, w) int, optional
        Per pixel the index of its id-based cause in
        :data:`~walkstream.client.truth.compare.CAUSES`, -1 where the client shows the
        truth's object (:attr:`~walkstream.client.truth.compare.FrameError.cause`).
    coarse : (h, w) bool, optional
        Pixels where the client's picture shows an object drawn at a coarser LOD than LOD2.
    stand_in : (h, w) bool, optional
        Pixels an image-based stand-in drew (the ``impostor`` hook).
    wall : (h, w) bool, optional
        Pixels a virtual wall's texture drew (cause ``wall``).

    Returns
    -------
    ColourError
    """
    t = np.asarray(truth_rgb)
    c = np.asarray(client_rgb)
    if t.ndim != 3 or t.shape[2] != 3 or c.shape != t.shape or t.dtype != np.uint8 or c.dtype != np.uint8:
        raise InputError(f"compare_colour: expected two (h, w, 3) uint8 pictures, got {t.shape} {t.dtype}, {c.shape} {c.dtype}")
    shape = t.shape[:2]

    def mask(a: ArrayLike | None, name: str) -> NDArray[np.bool_]:
        if a is None:
            return np.zeros(shape, bool)
        m = np.asarray(a, bool)
        if m.shape != shape:
            raise InputError(f"compare_colour: {name} is {m.shape}, expected {shape}")
        return m

    cause_id = np.full(shape, -1, np.int64) if id_cause is None else np.asarray(id_cause, np.int64)
    if cause_id.shape != shape:
        raise InputError(f"compare_colour: id_cause is {cause_id.shape}, expected {shape}")
    coarse_m, stand_m, wall_m = mask(coarse, "coarse"), mask(stand_in, "stand_in"), mask(wall, "wall")
    pixels = int(t.shape[0] * t.shape[1])
    # only the pixels that differ at all are converted: most of a frame is the same
    diff = (t[..., 0] != c[..., 0]) | (t[..., 1] != c[..., 1]) | (t[..., 2] != c[..., 2])  # any() over axis 2 is slow
    de = np.zeros(shape, np.float32)
    lin_err = sq_err = 0.0
    by_cause = np.zeros(len(COLOUR_CAUSES), np.float64)
    if diff.any():
        td, cd = t[diff], c[diff]
        lin_px = np.abs(srgb_to_linear(td) - srgb_to_linear(cd)).sum(axis=1)
        lin_err = float(lin_px.sum())
        by_cause = np.bincount(_attribute(cause_id[diff], coarse_m[diff], stand_m[diff], wall_m[diff]),
                               weights=lin_px, minlength=len(COLOUR_CAUSES)).astype(np.float64)
        sq_err = float(np.square(td.astype(np.int32) - cd.astype(np.int32)).sum(dtype=np.int64))
        # flat-shaded pictures hold few colours: ΔE once per distinct pair of colours
        w = np.array([1 << 40, 1 << 32, 1 << 24], np.int64)
        key = td.astype(np.int64) @ w + cd.astype(np.int64) @ (w >> 24)
        pairs, first, inv = np.unique(key, return_index=True, return_inverse=True)
        d = delta_e_2000(srgb_to_lab(td[first]), srgb_to_lab(cd[first]))
        de[diff] = d[inv.reshape(-1)].astype(np.float32)
    vis = de > VISIBLE_DE
    cause = _attribute(cause_id[vis], coarse_m[vis], stand_m[vis], wall_m[vis])
    counts = np.bincount(cause, minlength=len(COLOUR_CAUSES)).astype(np.int64)
    mse = sq_err / max(3 * pixels, 1)
    return ColourError(
        pixels=pixels,
        mean_error=lin_err / max(3 * pixels, 1),
        delta_e_mean=float(de.sum(dtype=np.float64)) / max(pixels, 1),
        visible=int(vis.sum()),
        psnr_db=math.inf if mse == 0.0 else 10.0 * math.log10(255.0**2 / mse),
        causes=counts,
        delta_e=de,
        error_causes=by_cause / max(3 * pixels, 1),
    )


def _attribute(
    cause_id: NDArray[np.int64], coarse: NDArray[np.bool_], stand_in: NDArray[np.bool_], wall: NDArray[np.bool_]
) -> NDArray[np.int64]:
    """Each given pixel's index in :data:`COLOUR_CAUSES` (the order of the module docs)."""
    cause = np.where(stand_in, _IMPOSTOR, np.where(cause_id >= 0, cause_id, np.where(coarse, _LOD_COLOUR, _OTHER)))
    out: NDArray[np.int64] = np.where(wall, _WALL, cause).astype(np.int64)
    return out


def heat_map(delta_e: ArrayLike, top: float = 20.0) -> NDArray[np.uint8]:
    """A picture of ΔE00 per pixel: black for none, through the ``magma`` colours to white at ``top``.

    Pixels at or under :data:`VISIBLE_DE` stay in the darkest fifth of the scale,
    so what is visible stands out.

    Returns
    -------
    (h, w, 3) uint8
    """
    from matplotlib import colormaps

    d = np.clip(np.asarray(delta_e, np.float64) / float(top), 0.0, 1.0)
    rgba = colormaps["magma"](d)
    out: NDArray[np.uint8] = (255.0 * rgba[..., :3] + 0.5).astype(np.uint8)
    return out
