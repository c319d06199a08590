"""The frame loop's time per phase in a report: ``phases.csv`` and ``phases.png``.

The phases are :data:`~walkstream.client.draw.phases.PHASES` (measured by
:class:`~walkstream.client.draw.phases.FramePhases` in the replay's loop); the
figures of ``report.json`` come from :meth:`~walkstream.client.draw.phases.FramePhases.summary`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from walkstream.client.draw.phases import PHASES
from walkstream.client.report.files import atomic_open
from walkstream.client.report.plots import grid_figure, save_figure
from walkstream.shared.errors import InputError

__all__ = ["write_phases_csv", "plot_phases"]

# Okabe-Ito colours and their darker kin, one per phase ("other" grey).
_COLOURS = (
    "#56B4E9", "#2A7AB0", "#009E73", "#F0E442", "#CC79A7", "#0072B2", "#D55E00", "#E69F00", "#8C510A",
    "#000000", "#999999",
)


def _check(t: NDArray[np.float64], phases: NDArray[np.float64]) -> None:
    if phases.ndim != 2 or phases.shape != (len(t), len(PHASES)):
        raise InputError(
            f"frame phases: expected ({len(t)}, {len(PHASES)}) seconds, got shape {phases.shape}"
        )


def write_phases_csv(path: Path, t: NDArray[np.float64], phases: NDArray[np.float64]) -> Path:
    """``phases.csv``: one row per frame, its time and milliseconds per phase.

    Parameters
    ----------
    t : (n,) float
        Frame times of the log, seconds.
    phases : (n, len(PHASES)) float
        Seconds per phase.
    """
    _check(t, phases)
    rows = np.column_stack([t, 1000.0 * phases])
    with atomic_open(path) as f:
        f.write("t_s," + ",".join(f"{p}_ms" for p in PHASES) + "\n")
        np.savetxt(f, rows, fmt="%.4f", delimiter=",")
    return path


def plot_phases(
    path: Path, t: NDArray[np.float64], phases: NDArray[np.float64], title: str
) -> Path:
    """``phases.png``: per frame, stacked milliseconds per phase (top), medians (bottom).

    Parameters
    ----------
    t : (n,) float
        Frame times relative to the walk's start, seconds.
    phases : (n, len(PHASES)) float
        Seconds per phase.
    """
    _check(t, phases)
    fig, (ax, bx) = grid_figure(2, height=3.0, sharex=False)
    ms = 1000.0 * phases
    if len(t):
        # mean per time bin (at most 400), stacked: the plot stays readable at any length
        nb = min(len(t), 400)
        edges = np.linspace(float(t[0]), float(t[-1]) + 1e-9, nb + 1)
        idx = np.clip(np.digitize(t, edges) - 1, 0, nb - 1)
        n = np.bincount(idx, minlength=nb)
        keep = n > 0
        means = [
            np.bincount(idx, ms[:, k], minlength=nb)[keep] / n[keep] for k in range(len(PHASES))
        ]
        centres = ((edges[:-1] + edges[1:]) / 2.0)[keep]
        ax.stackplot(centres, means, labels=list(PHASES), colors=list(_COLOURS), linewidth=0)
        top = float(np.percentile(np.sum(means, axis=0), 99))
        ax.set_ylim(0.0, 1.15 * top if top > 0 else 1.0)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("ms per frame (stacked)")
    ax.legend(loc="upper right", fontsize=8, ncol=4)
    med = np.median(ms, axis=0) if len(ms) else np.zeros(len(PHASES))
    bx.barh(list(PHASES)[::-1], med[::-1], color=list(_COLOURS)[::-1])
    for y, v in enumerate(med[::-1]):
        bx.annotate(f"{v:.2f} ms", (v, y), xytext=(3, -3), textcoords="offset points", fontsize=8)
    bx.set_xlabel("median ms per frame")
    fig.suptitle(title)
    return save_figure(fig, path)
