"""The colour figures of a replay's compared frames: one row per frame, and the ``truth.colour`` summary.

Each frame compared with the ground truth (``--truth-every N``) on a city walk gives
one row of a :class:`ColourLog` (:mod:`walkstream.client.truth.colour` defines the
figures); :func:`summarise_colour` reduces it to the ``colour`` object inside the
``truth`` object of ``report.json``.  Every figure is over *all* compared frames, so
that two runs of one walk with the same ``--truth-every`` are measured on the same
frames (the start-up frames, before anything has arrived, count too):

``metric``, ``visible_threshold``
    ``"CIEDE2000"`` and the ΔE00 above which a pixel is visibly wrong (2.3).
``mean_error``
    ``median``, ``p95``, ``max``, ``mean`` over the frames of the mean absolute
    linear-RGB error per pixel and channel, a share of full scale (0..1).
``delta_e_mean``
    ``median``, ``p95``, ``max`` of the frames' mean ΔE00 per pixel.
``visible_pixels``
    ``median``, ``p95``, ``max``, ``mean`` of the share of a frame's pixels over the
    visible threshold.
``frames_over_visible_ratio``
    The share of frames whose visible pixels exceed 0.5 % of the frame
    (:data:`~walkstream.client.report.truth.OVER_SHARE`).
``viewer_ppd``, ``visible_scielab_threshold``, ``delta_e_scielab_mean``, ``visible_scielab_pixels``, ``frames_over_visible_scielab_ratio``, ``causes_scielab``
    The same figures at the viewer's scale (S-CIELAB, the module docs of
    :mod:`walkstream.client.truth.colour`), beside the per-pixel ones above, never in
    their place: the display's pixels per degree they were measured at, the
    threshold, the frames' mean filtered ΔE00, their share of pixels over it, the
    share of frames over 0.5 % of them, and per cause the mean share.  Absent when
    not measured (a log read back from an older ``truth.csv``).
``psnr_db``
    ``median``, ``p5`` (the worst twentieth) and ``min`` of the frames' PSNR, dB;
    identical pictures count as :data:`~walkstream.client.truth.colour.PSNR_CAP_DB`.
``causes``
    Per cause of :data:`~walkstream.client.truth.colour.COLOUR_CAUSES` the mean share
    of a frame's pixels visibly wrong for it.
``error_causes``
    Per cause the mean over the frames of its part of the mean linear-RGB error
    (:attr:`~walkstream.client.truth.colour.ColourError.error_causes`; they sum to
    ``mean_error.mean``): where the error comes from, weighted by how wrong each
    pixel is.  Absent when the log was read back from a ``truth.csv``.
``impostor``
    The impostors' own error frame by frame (the figure "mean colour error from
    impostors at most 1 % of full scale, pixels over the visible threshold at most
    0.5 % of the frame on 99 % of compared frames"): ``error`` (``median``, ``p99``,
    ``max`` over the frames of the ``impostor`` cause's part of the frame's mean
    linear-RGB error; absent without ``error_causes``), ``visible`` (the same of the
    share of the frame's pixels visibly wrong where an impostor stands in),
    ``frames_within_ratio`` (the share of frames within both limits,
    :data:`IMPOSTOR_ERROR_MAX` and :data:`COLOUR_OVER_SHARE`) and ``reached`` (that
    share at least 99 %); with the viewer-scale figures also ``visible_scielab``,
    ``frames_within_scielab_ratio`` and ``reached_scielab``, the same figure with the
    pixels counted at the viewer's scale (the error limit unchanged).
``per_frame``
    The rows, as columns: ``frame``, ``t``, ``mean_error``, ``delta_e_mean``,
    ``visible`` and ``psnr_db`` (capped) per compared frame, and ``visible_scielab``
    when measured (``truth.csv`` has the causes too).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from walkstream.client.truth.colour import (
    COLOUR_CAUSES,
    PSNR_CAP_DB,
    SCIELAB_VISIBLE_DE,
    VISIBLE_DE,
)
from walkstream.shared.arrays import F64, I64
from walkstream.shared.errors import InputError

__all__ = ["COLOUR_OVER_SHARE", "IMPOSTOR_ERROR_MAX", "IMPOSTOR_FRAMES_WITHIN", "ColourLog", "summarise_colour"]

#: a compared frame is over the visible threshold when more than this share of its pixels are
COLOUR_OVER_SHARE = 0.005

#: the most a frame's mean linear-RGB error from impostors may be (share of full scale)
IMPOSTOR_ERROR_MAX = 0.01

#: the share of compared frames that must keep the impostors' error within its limits
IMPOSTOR_FRAMES_WITHIN = 0.99


@dataclass(frozen=True, slots=True, eq=False)
class ColourLog:
    """One row per compared frame (read-only arrays of equal length).

    Attributes
    ----------
    frame : (n,) int64
    t : (n,) float64
    mean_error : (n,) float64
        Mean absolute linear-RGB error per pixel and channel, 0..1.
    delta_e_mean : (n,) float64
        Mean ΔE00 per pixel.
    visible : (n,) float64
        Share of the pixels with ΔE00 over the visible threshold.
    psnr_db : (n,) float64
        PSNR, dB (``inf``: identical pictures).
    causes : (n, len(COLOUR_CAUSES)) float64
        Share of the pixels visibly wrong, per cause.
    error_causes : (n, len(COLOUR_CAUSES)) float64 or None
        The frame's mean error split by cause (None: not measured).
    delta_e_scielab_mean : (n,) float64 or None
        Mean ΔE00 per pixel of the S-CIELAB-filtered pictures (None: not measured).
    visible_scielab : (n,) float64 or None
        Share of the pixels over the visible threshold at the viewer's scale.
    causes_scielab : (n, len(COLOUR_CAUSES)) float64 or None
        ``visible_scielab`` per cause.
    viewer_ppd : float or None
        The display's pixels per degree of the viewer-scale figures.
    """

    frame: I64
    t: F64
    mean_error: F64
    delta_e_mean: F64
    visible: F64
    psnr_db: F64
    causes: F64
    error_causes: F64 | None = None
    delta_e_scielab_mean: F64 | None = None
    visible_scielab: F64 | None = None
    causes_scielab: F64 | None = None
    viewer_ppd: float | None = None

    def __post_init__(self) -> None:
        n = len(np.asarray(self.frame))
        cols = {
            "frame": np.array(self.frame, np.int64).reshape(-1),
            "t": np.array(self.t, np.float64).reshape(-1),
            "mean_error": np.array(self.mean_error, np.float64).reshape(-1),
            "delta_e_mean": np.array(self.delta_e_mean, np.float64).reshape(-1),
            "visible": np.array(self.visible, np.float64).reshape(-1),
            "psnr_db": np.array(self.psnr_db, np.float64).reshape(-1),
            "causes": np.array(self.causes, np.float64).reshape(-1, len(COLOUR_CAUSES)),
        }
        if self.error_causes is not None:
            cols["error_causes"] = np.array(self.error_causes, np.float64).reshape(-1, len(COLOUR_CAUSES))
        scielab = (self.delta_e_scielab_mean, self.visible_scielab, self.causes_scielab)
        if any(v is not None for v in scielab) and not all(v is not None for v in scielab):
            raise InputError("ColourLog: the viewer-scale columns come together (delta_e_scielab_mean, visible_scielab, "
                             "causes_scielab)")
        if self.visible_scielab is not None:
            cols["delta_e_scielab_mean"] = np.array(self.delta_e_scielab_mean, np.float64).reshape(-1)
            cols["visible_scielab"] = np.array(self.visible_scielab, np.float64).reshape(-1)
            cols["causes_scielab"] = np.array(self.causes_scielab, np.float64).reshape(-1, len(COLOUR_CAUSES))
        for name, a in cols.items():
            if len(a) != n:
                raise InputError(f"ColourLog column {name!r} has {len(a)} rows, expected {n}")
            a.flags.writeable = False
            object.__setattr__(self, name, a)

    def __len__(self) -> int:
        return len(self.frame)

    @classmethod
    def empty(cls) -> ColourLog:
        """No compared frame."""
        z = np.zeros(0)
        return cls(np.zeros(0, np.int64), z, z, z, z, z, np.zeros((0, len(COLOUR_CAUSES))))


def _stats(a: ArrayLike, keys: tuple[str, ...]) -> dict[str, float | None]:
    v = np.asarray(a, np.float64)
    if v.size == 0:
        return dict.fromkeys(keys)
    table = {
        "median": lambda: np.median(v),
        "mean": lambda: v.mean(),
        "p95": lambda: np.percentile(v, 95),
        "p5": lambda: np.percentile(v, 5),
        "p99": lambda: np.percentile(v, 99),
        "max": lambda: v.max(),
        "min": lambda: v.min(),
    }
    return {k: float(table[k]()) for k in keys}


def _impostor_figures(log: ColourLog) -> dict[str, Any]:
    """The ``impostor`` object of ``truth.colour`` (see the module docs)."""
    k = COLOUR_CAUSES.index("impostor")
    keys = ("median", "p99", "max")
    vis = np.asarray(log.causes, np.float64).reshape(-1, len(COLOUR_CAUSES))[:, k]
    ok = vis <= COLOUR_OVER_SHARE
    out: dict[str, Any] = {"visible": _stats(vis, keys)}
    if log.error_causes is not None:
        err = np.asarray(log.error_causes, np.float64).reshape(-1, len(COLOUR_CAUSES))[:, k]
        out["error"] = _stats(err, keys)
        ok &= err <= IMPOSTOR_ERROR_MAX
    within = float(ok.mean()) if ok.size else None
    out["frames_within_ratio"] = within
    out["reached"] = None if within is None else within >= IMPOSTOR_FRAMES_WITHIN
    if log.causes_scielab is not None:
        s_vis = np.asarray(log.causes_scielab, np.float64).reshape(-1, len(COLOUR_CAUSES))[:, k]
        s_ok = s_vis <= COLOUR_OVER_SHARE
        if log.error_causes is not None:
            s_ok &= err <= IMPOSTOR_ERROR_MAX
        s_within = float(s_ok.mean()) if s_ok.size else None
        out["visible_scielab"] = _stats(s_vis, keys)
        out["frames_within_scielab_ratio"] = s_within
        out["reached_scielab"] = None if s_within is None else s_within >= IMPOSTOR_FRAMES_WITHIN
    return out


def _scielab_figures(log: ColourLog) -> dict[str, Any]:
    """The viewer-scale keys of ``truth.colour`` (none when not measured; see the module docs)."""
    if log.visible_scielab is None or log.delta_e_scielab_mean is None or log.causes_scielab is None:
        return {}
    n = len(log)
    return {
        "viewer_ppd": log.viewer_ppd,
        "visible_scielab_threshold": SCIELAB_VISIBLE_DE,
        "delta_e_scielab_mean": _stats(log.delta_e_scielab_mean, ("median", "p95", "max")),
        "visible_scielab_pixels": _stats(log.visible_scielab, ("median", "p95", "max", "mean")),
        "frames_over_visible_scielab_ratio": float((log.visible_scielab > COLOUR_OVER_SHARE).mean()) if n else None,
        "causes_scielab": {c: (float(log.causes_scielab[:, k].mean()) if n else None) for k, c in enumerate(COLOUR_CAUSES)},
    }


def summarise_colour(log: ColourLog) -> dict[str, Any]:
    """The ``colour`` object inside ``truth`` of ``report.json`` (see the module docs)."""
    n = len(log)
    return {
        "metric": "CIEDE2000",
        "visible_threshold": VISIBLE_DE,
        "frames": n,
        "mean_error": _stats(log.mean_error, ("median", "p95", "max", "mean")),
        "delta_e_mean": _stats(log.delta_e_mean, ("median", "p95", "max")),
        "visible_pixels": _stats(log.visible, ("median", "p95", "max", "mean")),
        "frames_over_visible_ratio": float((log.visible > COLOUR_OVER_SHARE).mean()) if n else None,
        **_scielab_figures(log),
        "psnr_db": _stats(np.minimum(log.psnr_db, PSNR_CAP_DB), ("median", "p5", "min")),
        "causes": {c: (float(log.causes[:, k].mean()) if n else None) for k, c in enumerate(COLOUR_CAUSES)},
        **({} if log.error_causes is None else {"error_causes": {
            c: (float(log.error_causes[:, k].mean()) if n else None) for k, c in enumerate(COLOUR_CAUSES)}}),
        "impostor": _impostor_figures(log),
        "per_frame": {
            "frame": log.frame.tolist(),
            "t": [round(float(v), 4) for v in log.t],
            "mean_error": [round(float(v), 6) for v in log.mean_error],
            "delta_e_mean": [round(float(v), 4) for v in log.delta_e_mean],
            "visible": [round(float(v), 6) for v in log.visible],
            "psnr_db": [round(float(v), 3) for v in np.minimum(log.psnr_db, PSNR_CAP_DB)],
            **({} if log.visible_scielab is None else {
                "visible_scielab": [round(float(v), 6) for v in log.visible_scielab]}),
        },
    }
