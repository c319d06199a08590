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
viewer-scale visible pixels (S-CIELAB)
    The per-pixel measure above compares pixel with pixel, so it counts aliasing
    of pixel-wide detail (a window that falls on a pixel centre in one picture and
    between two in the other) at full weight.  Beside it -- never in its place --
    the spatial extension of CIELAB of Zhang and Wandell ("A spatial extension of
    CIELAB for digital color image reproduction", SID Symposium 1996; J. SID 5(1),
    1997): both pictures go to CIE XYZ (D65), to the opponent space of Poirson and
    Wandell (:data:`XYZ_TO_OPPONENT`: luminance, red-green, blue-yellow), each
    channel is filtered with the eye's spatial sensitivity for that channel
    (:data:`SCIELAB_KERNELS`: a sum of Gaussians ``w exp(-r² / s²)``, ``s`` in degrees
    of visual angle, each Gaussian normalised to sum 1, as in the paper's table),
    then back to XYZ and CIELAB, and CIEDE2000 per pixel of the filtered pictures
    (CIEDE2000 with S-CIELAB as Johnson and Fairchild, "A top down description of
    S-CIELAB and CIEDE2000", Color Res. Appl. 28(6), 2003).  A pixel is visibly
    wrong at the viewer's scale when that ΔE00 exceeds :data:`SCIELAB_VISIBLE_DE`
    (2.3, the same threshold: S-CIELAB is built so that its ΔE reads as CIELAB's
    on uniform areas, where the filters pass everything).  The filters' widths in
    pixels come from the display's pixels per degree: :func:`pixels_per_degree` of
    the view's height and vertical field of view (the picture seen under the angle
    it was drawn for), or a viewer's own figure.  At 160 x 120 and 60° that is 1.8
    pixels a degree, where every filter is under a pixel wide and the measure
    stays close to the per-pixel one: a pixel there is 0.55° across, which an eye
    resolves.  Causes: each pixel over the threshold is given the cause of the
    nearest differing pixel (the filter spreads an error over its neighbours).
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
    "SCIELAB_VISIBLE_DE",
    "SCIELAB_KERNELS",
    "XYZ_TO_OPPONENT",
    "pixels_per_degree",
    "scielab_xyz",
    "scielab_delta_e",
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

#: ΔE00 of the S-CIELAB-filtered pictures above which a pixel counts as visibly wrong
#: at the viewer's scale (see the module docs).
SCIELAB_VISIBLE_DE = 2.3

#: CIE XYZ to the opponent channels (luminance, red-green, blue-yellow) of Poirson and
#: Wandell, as S-CIELAB uses them (Zhang and Wandell 1997).
XYZ_TO_OPPONENT = np.array(
    [[0.2787336, 0.7218031, -0.1065520], [-0.4487736, 0.2898056, 0.0771569], [0.0859513, -0.5899859, 0.5011089]]
)

#: S-CIELAB's spatial filters (Zhang and Wandell 1997, table 1): per opponent channel
#: the ``(weight, spread)`` of each Gaussian ``exp(-r² / spread²)``, spread in degrees of
#: visual angle; each channel's weights sum to 1, so a uniform area passes unchanged.
SCIELAB_KERNELS: tuple[tuple[tuple[float, float], ...], ...] = (
    ((1.00327, 0.0500), (0.114416, 0.2250), (-0.117686, 7.0000)),
    ((0.616725, 0.0685), (0.383275, 0.8260)),
    ((0.567885, 0.0920), (0.432115, 0.6451)),
)

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
    return _xyz_to_lab(srgb_to_linear(rgb) @ _RGB_TO_XYZ.T)


def _xyz_to_lab(xyz_abs: NDArray[np.float64]) -> NDArray[np.float64]:
    """CIELAB of ``(..., 3)`` CIE XYZ on the scale where the D65 white's Y is 1."""
    xyz = xyz_abs / _WHITE
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


def pixels_per_degree(height_px: int, fov_y_deg: float) -> float:
    """Pixels per degree of visual angle at the centre of a view seen under its own angle.

    Parameters
    ----------
    height_px : int
        The view's height in pixels.
    fov_y_deg : float
        Its vertical field of view, degrees (square pixels: the width and the
        horizontal field of view give the same figure).

    Returns
    -------
    float
        The focal length in pixels times pi / 180: 1.81 at 120 pixels and 60°.
    """
    if height_px <= 0 or not 0.0 < fov_y_deg < 180.0:
        raise InputError(f"pixels_per_degree: expected a positive height and a field of view in (0, 180), "
                         f"got {height_px}, {fov_y_deg}")
    return float(height_px / 2.0 / math.tan(math.radians(fov_y_deg) / 2.0) * math.pi / 180.0)


def scielab_xyz(rgb: ArrayLike, ppd: float) -> NDArray[np.float64]:
    """An sRGB picture as the eye sees it at ``ppd`` pixels a degree: S-CIELAB's filtered CIE XYZ.

    Parameters
    ----------
    rgb : (h, w, 3) uint8
        sRGB code values.
    ppd : float
        The display's pixels per degree of visual angle (:func:`pixels_per_degree`).

    Returns
    -------
    (h, w, 3) float64
        CIE XYZ (the D65 white's Y is 1) of the picture filtered in the opponent
        channels by :data:`SCIELAB_KERNELS` (edges mirrored).
    """
    from scipy.ndimage import gaussian_filter

    a = np.asarray(rgb)
    if a.ndim != 3 or a.shape[2] != 3 or a.dtype != np.uint8:
        raise InputError(f"scielab_xyz: expected an (h, w, 3) uint8 picture, got {a.shape} {a.dtype}")
    if not ppd > 0.0:
        raise InputError(f"scielab_xyz: pixels per degree must be positive, got {ppd}")
    opp = srgb_to_linear(a) @ (XYZ_TO_OPPONENT @ _RGB_TO_XYZ).T
    out = np.empty_like(opp)
    for ch, kernels in enumerate(SCIELAB_KERNELS):
        plane = opp[..., ch]
        # exp(-r² / s²) is a Gaussian of standard deviation s / sqrt(2)
        out[..., ch] = sum(w * gaussian_filter(plane, s * ppd / math.sqrt(2.0), mode="reflect") for w, s in kernels)
    xyz: NDArray[np.float64] = out @ np.linalg.inv(XYZ_TO_OPPONENT).T
    return xyz


def scielab_delta_e(truth_rgb: ArrayLike, client_rgb: ArrayLike, ppd: float) -> NDArray[np.float64]:
    """ΔE00 per pixel between two sRGB pictures after S-CIELAB's spatial filters.

    Parameters
    ----------
    truth_rgb, client_rgb : (h, w, 3) uint8
        Two pictures of one camera.
    ppd : float
        The display's pixels per degree.

    Returns
    -------
    (h, w) float64
        Zero everywhere for identical pictures.
    """
    t = np.asarray(truth_rgb)
    c = np.asarray(client_rgb)
    if t.shape != c.shape:
        raise InputError(f"scielab_delta_e: expected two pictures of one shape, got {t.shape}, {c.shape}")
    if np.array_equal(t, c):
        return np.zeros(t.shape[:2], np.float64)
    return delta_e_2000(_xyz_to_lab(scielab_xyz(t, ppd)), _xyz_to_lab(scielab_xyz(c, ppd)))


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
    ppd : float or None
        The display's pixels per degree the viewer-scale figures were measured at
        (None: not measured, and the ``scielab`` figures are zero).
    scielab_delta_e_mean : float
        Mean ΔE00 of the S-CIELAB-filtered pictures over the frame's pixels.
    scielab_visible : int
        Pixels over :data:`SCIELAB_VISIBLE_DE` after S-CIELAB's filters.
    scielab_causes : (len(COLOUR_CAUSES),) int64
        ``scielab_visible`` per cause (the cause of each one's nearest differing pixel).
    scielab_delta_e : (h, w) float32 or None
        The filtered ΔE00 per pixel.
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
    ppd: float | None = None
    scielab_delta_e_mean: float = 0.0
    scielab_visible: int = 0
    scielab_causes: NDArray[np.int64] | None = None
    scielab_delta_e: NDArray[np.float32] | None = None

    @property
    def visible_share(self) -> float:
        """Visible pixels as a share of the frame."""
        return self.visible / max(self.pixels, 1)

    @property
    def scielab_visible_share(self) -> float:
        """Pixels visibly wrong at the viewer's scale (S-CIELAB) as a share of the frame."""
        return self.scielab_visible / max(self.pixels, 1)

    @property
    def scielab_cause_shares(self) -> NDArray[np.float64]:
        """``scielab_causes`` as shares of the frame (zeros when not measured)."""
        if self.scielab_causes is None:
            return np.zeros(len(COLOUR_CAUSES))
        out: NDArray[np.float64] = self.scielab_causes / max(self.pixels, 1)
        return out

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
    ppd: float | None = None,
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
    ppd : float, optional
        The display's pixels per degree: with it the viewer-scale (S-CIELAB) figures
        are measured too, beside the per-pixel ones.

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
    s_de: NDArray[np.float32] | None = None
    s_counts: NDArray[np.int64] | None = None
    if ppd is not None:
        s_de = np.zeros(shape, np.float32)
        s_counts = np.zeros(len(COLOUR_CAUSES), np.int64)
        if diff.any():
            from scipy.ndimage import distance_transform_edt

            s_de = scielab_delta_e(t, c, ppd).astype(np.float32)
            s_vis = s_de > SCIELAB_VISIBLE_DE
            if s_vis.any():
                # the filter spreads a pixel's error over its neighbours: the nearest differing pixel's cause
                near = distance_transform_edt(~diff, return_distances=False, return_indices=True)
                ny, nx = near[0][s_vis], near[1][s_vis]
                s_cause = _attribute(cause_id[ny, nx], coarse_m[ny, nx], stand_m[ny, nx], wall_m[ny, nx])
                s_counts = np.bincount(s_cause, minlength=len(COLOUR_CAUSES)).astype(np.int64)
    return ColourError(
        pixels=pixels,
        mean_error=lin_err / max(3 * pixels, 1),
        delta_e_mean=float(de.sum(dtype=np.float64)) / max(pixels, 1),
        visible=int(vis.sum()),
        psnr_db=math.inf if mse == 0.0 else 10.0 * math.log10(255.0**2 / mse),
        causes=counts,
        delta_e=de,
        error_causes=by_cause / max(3 * pixels, 1),
        ppd=ppd,
        scielab_delta_e_mean=0.0 if s_de is None else float(s_de.sum(dtype=np.float64)) / max(pixels, 1),
        scielab_visible=0 if s_counts is None else int(s_counts.sum()),
        scielab_causes=s_counts,
        scielab_delta_e=s_de,
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
