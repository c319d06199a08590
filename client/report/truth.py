"""The ground-truth figures of a replay: one row per compared frame, and the ``truth`` summary.

``walkstream replay --truth-every N`` compares every N-th frame with a ground truth
(:mod:`walkstream.client.truth`).  Each compared frame gives one row of a
:class:`TruthLog`; :func:`summarise_truth` reduces it to the ``truth`` object of
``report.json``.  The definitions, used by the report and the benchmarks alike:

``frames``
    How many frames were compared.
``differing_pixels_mean``
    Mean over the compared frames of the share of the frame's pixels whose colour
    differs from the truth (0..1).
``missing``
    Per cause (``pvs``, ``not_received``, ``not_built``, ``lod``, ``culled``, ``fog``;
    :data:`~walkstream.client.truth.compare.CAUSES`) the ``mean``, ``p95`` and ``max``
    over the compared frames of the share of the frame's pixels where the truth shows
    an object that the client's frame does not, attributed to that cause (0..1).
``over_half_percent_ratio``
    Among the compared frames from the first perfect frame on (the frame whose ``t``
    is at least the first perfect frame's), the share whose missing pixels -- every
    cause but ``fog``, which hides objects on purpose -- exceed 0.5 % of the frame;
    ``None`` when no compared frame comes after a perfect one.
``pvs_over_hundredth_percent_ratio``
    Among the same frames, the share whose PVS-caused missing pixels (cause ``pvs``:
    the object is not in the PVS of the viewer's cell, whatever the link did) exceed
    :data:`PVS_OVER_SHARE` (0.01 %) of the frame: the misses of the visibility bake a
    viewer could see; ``None`` as above.  The mean of the same share over every
    compared frame is ``missing.pvs.mean``.
``colour``
    The colour error of the client's picture against the full scene (a city walk's
    frames): :func:`~walkstream.client.report.colour.summarise_colour`.
``below_horizon``
    A city's compared frames only (added by the recorder,
    :mod:`walkstream.client.truth.horizon`): per share of the client's frame's pixels
    below the horizon -- ``sky`` (in the background colour) and ``no_object`` (no
    object shows: the ground plane, or the sky where there is no plane) -- the
    ``mean``, ``p95`` and ``max`` over the compared frames (0..1).
"""

from __future__ import annotations

import csv
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from walkstream.client.report.colour import ColourLog, summarise_colour
from walkstream.client.report.files import atomic_open
from walkstream.client.truth.colour import COLOUR_CAUSES
from walkstream.client.truth.compare import CAUSES, MISS_CAUSES
from walkstream.shared.arrays import F64, I64
from walkstream.shared.errors import InputError

__all__ = [
    "OVER_SHARE",
    "PVS_OVER_SHARE",
    "TruthLog",
    "summarise_truth",
    "write_truth_csv",
    "read_truth_csv",
]

#: a compared frame is "bad" when its missing pixels exceed this share of the frame
OVER_SHARE = 0.005
#: a compared frame's PVS misses are "visible" when its ``pvs`` pixels exceed this share
PVS_OVER_SHARE = 1e-4


@dataclass(frozen=True, slots=True, eq=False)
class TruthLog:
    """One row per compared frame (read-only arrays of equal length).

    Attributes
    ----------
    frame : (n,) int64
        Index of the frame in the replay's frame log.
    t : (n,) float64
        Its ``t`` (the frame log's clock).
    differing : (n,) float64
        Share of its pixels whose colour differs from the truth.
    missing : (n, 6) float64
        Share of its pixels missing, per cause in :data:`CAUSES` order.
    colour : ColourLog, optional
        The same frames' colour error (a city walk's; None where there is none).
    """

    frame: I64
    t: F64
    differing: F64
    missing: F64
    colour: ColourLog | None = None

    def __post_init__(self) -> None:
        n = len(np.asarray(self.frame))
        cols = {
            "frame": np.array(self.frame, np.int64).reshape(-1),
            "t": np.array(self.t, np.float64).reshape(-1),
            "differing": np.array(self.differing, np.float64).reshape(-1),
            "missing": np.array(self.missing, np.float64).reshape(-1, len(CAUSES)),
        }
        for name, a in cols.items():
            if len(a) != n:
                raise InputError(f"TruthLog column {name!r} has {len(a)} rows, expected {n}")
            a.flags.writeable = False
            object.__setattr__(self, name, a)
        if self.colour is not None and len(self.colour) != n:
            raise InputError(f"TruthLog colour has {len(self.colour)} rows, expected {n}")

    def __len__(self) -> int:
        return len(self.frame)

    @property
    def missed(self) -> F64:
        """(n,) share of each frame's pixels missing for a cause that counts (all but fog)."""
        out: F64 = self.missing[:, : len(MISS_CAUSES)].sum(axis=1)
        return out

    @classmethod
    def empty(cls) -> TruthLog:
        """No compared frame."""
        return cls(np.zeros(0, np.int64), np.zeros(0), np.zeros(0), np.zeros((0, len(CAUSES))))


def _stats(a: ArrayLike) -> dict[str, float | None]:
    v = np.asarray(a, np.float64)
    if v.size == 0:
        return {"mean": None, "p95": None, "max": None}
    return {
        "mean": float(v.mean()),
        "p95": float(np.percentile(v, 95)),
        "max": float(v.max()),
    }


def summarise_truth(log: TruthLog, t_first_perfect: float | None) -> dict[str, Any]:
    """The ``truth`` object of ``report.json`` (see the module docs for each figure).

    Parameters
    ----------
    log : TruthLog
        The compared frames.
    t_first_perfect : float or None
        ``t`` of the replay's first perfect frame (``None``: there was none).
    """
    after = (
        np.zeros(len(log), bool) if t_first_perfect is None else log.t >= float(t_first_perfect)
    )
    over = log.missed[after] > OVER_SHARE
    pvs_over = log.missing[after, CAUSES.index("pvs")] > PVS_OVER_SHARE
    out: dict[str, Any] = {
        "frames": len(log),
        "differing_pixels_mean": float(log.differing.mean()) if len(log) else None,
        "over_half_percent_ratio": float(over.mean()) if over.size else None,
        "pvs_over_hundredth_percent_ratio": float(pvs_over.mean()) if pvs_over.size else None,
        "missing": {c: _stats(log.missing[:, k]) for k, c in enumerate(CAUSES)},
    }
    if log.colour is not None:
        out["colour"] = summarise_colour(log.colour)
    return out


_COLOUR_COLUMNS = ["mean_error", "delta_e_mean", "visible", "psnr_db", *(f"colour_{c}" for c in COLOUR_CAUSES)]
_SCIELAB_COLUMNS = ["delta_e_scielab_mean", "visible_scielab", *(f"scielab_{c}" for c in COLOUR_CAUSES)]


def write_truth_csv(path: str | os.PathLike[str], log: TruthLog) -> Path:
    """One row per compared frame: ``frame, t, differing`` and one column per cause (shares);
    with colour figures also ``mean_error, delta_e_mean, visible, psnr_db`` and one
    ``colour_<cause>`` column per colour cause; with the viewer-scale (S-CIELAB) figures
    then ``delta_e_scielab_mean, visible_scielab`` and one ``scielab_<cause>`` column
    per colour cause."""
    p = Path(path)
    c = log.colour
    with atomic_open(p) as f:
        w = csv.writer(f, lineterminator="\n")
        scielab = c is not None and c.visible_scielab is not None
        w.writerow(["frame", "t", "differing", *CAUSES, *(_COLOUR_COLUMNS if c is not None else []),
                    *(_SCIELAB_COLUMNS if scielab else [])])
        for i in range(len(log)):
            extra = [] if c is None else [
                c.mean_error[i], c.delta_e_mean[i], c.visible[i], c.psnr_db[i], *c.causes[i]
            ]
            if c is not None and c.visible_scielab is not None:
                assert c.delta_e_scielab_mean is not None and c.causes_scielab is not None
                extra += [c.delta_e_scielab_mean[i], c.visible_scielab[i], *c.causes_scielab[i]]
            w.writerow(
                [int(log.frame[i]), repr(float(log.t[i])), repr(float(log.differing[i]))]
                + [repr(float(v)) for v in log.missing[i]]
                + [repr(float(v)) for v in extra]
            )
    return p


def read_truth_csv(path: str | os.PathLike[str]) -> TruthLog:
    """Read a file written by :func:`write_truth_csv`."""
    p = Path(path)
    with p.open(encoding="utf-8", newline="") as f:
        rows = list(csv.reader(f))
    head = ["frame", "t", "differing", *CAUSES]
    if not rows or rows[0] not in (head, head + _COLOUR_COLUMNS, head + _COLOUR_COLUMNS + _SCIELAB_COLUMNS):
        raise InputError(f"{p}: not a truth.csv (expected the header frame, t, differing, causes[, colour figures])")
    with_colour = len(rows[0]) > len(head)
    with_scielab = len(rows[0]) > len(head) + len(_COLOUR_COLUMNS)
    try:
        body = [[float(v) for v in r] for r in rows[1:]]
    except ValueError as exc:
        raise InputError(f"{p}: {exc}") from exc
    if not body:
        e = TruthLog.empty()
        return TruthLog(e.frame, e.t, e.differing, e.missing, ColourLog.empty()) if with_colour else e
    a = np.array(body, np.float64)
    k = len(head)
    s = k + len(_COLOUR_COLUMNS)
    colour = None if not with_colour else ColourLog(
        a[:, 0].astype(np.int64), a[:, 1], a[:, k], a[:, k + 1], a[:, k + 2], a[:, k + 3], a[:, k + 4 : s],
        delta_e_scielab_mean=a[:, s] if with_scielab else None,
        visible_scielab=a[:, s + 1] if with_scielab else None,
        causes_scielab=a[:, s + 2 :] if with_scielab else None,
    )
    return TruthLog(a[:, 0].astype(np.int64), a[:, 1], a[:, 2], a[:, 3:k], colour)
