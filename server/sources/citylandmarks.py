"""Where the generated city's landmarks stand: a few towers and spires in backyards.

A few blocks of the generated city (one per 16 ha, at most 4, none below 400 m: 3 in
the 700 m demo) get a tall, detailed building standing free in the middle of their
backyard, alternately a tower and a spire (:mod:`walkstream.shared.landmarks` says
how the grammar builds their crowns).  A landmark stands free, so no party wall
touches it and its footprint stays an exact square.  The choice draws from its own
random stream next to the city's seed, so every other building of the city is the
same with or without landmarks; :mod:`~walkstream.server.sources.citygen` puts the
chosen ones in its building list.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from walkstream.shared.arrays import F64

__all__ = ["LANDMARK_FLOOR_HEIGHT", "LandmarkPick", "choose_landmarks", "landmark_count", "landmark_site"]

LANDMARK_AREA = 160000.0
"""One landmark per this many square metres of city."""
LANDMARK_MAX = 4
LANDMARK_SIDE = (14.0, 24.0)
"""Metres, the square footprint's side: the largest that fits, not under the first."""
LANDMARK_STREAM = 27
"""The landmarks' own random stream next to the city's seed."""
LANDMARK_FLOOR_HEIGHT = 3.4
TOWER_FLOORS = (26, 34)
"""[lo, hi) floors of a tower."""
SPIRE_FLOORS = (14, 18)
"""[lo, hi) floors of a spire."""


@dataclass(frozen=True, slots=True)
class LandmarkPick:
    """One landmark: in backyard ``yard`` (an index), its footprint ``site`` ``(4, 2)``
    (counter-clockwise), ``use`` ``"tower"`` or ``"spire"``, its floors and style."""

    yard: int
    site: F64
    use: str
    floors: int
    style: int


def landmark_count(size: float) -> int:
    """How many landmarks a city of ``size`` metres gets: 3 in the 700 m demo, none below 400 m."""
    return min(LANDMARK_MAX, int(size * size // LANDMARK_AREA))


def landmark_site(yard: F64) -> F64 | None:
    """The largest square (side at most 24 m) centred in a backyard quad ``(4, 2)`` with
    3 m of yard around it, aligned with the yard's first edge; None if it would be
    under 14 m."""
    d = yard[1] - yard[0]
    u = d / np.linalg.norm(d)
    v = np.array([-u[1], u[0]])
    c = yard.mean(axis=0)
    e = np.roll(yard, -1, axis=0) - yard
    e = e / np.linalg.norm(e, axis=1, keepdims=True)
    signs = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])  # CCW
    for half in np.arange(LANDMARK_SIDE[1] / 2.0, LANDMARK_SIDE[0] / 2.0 - 1e-9, -0.5):
        sq = c + signs[:, :1] * half * u + signs[:, 1:] * half * v
        rel = sq[:, None] - yard[None]  # (corner, edge, 2)
        # each corner at least 3 m to the left of every yard edge (inside, with room)
        if bool(np.all(e[None, :, 0] * rel[..., 1] - e[None, :, 1] * rel[..., 0] >= 3.0)):
            return sq
    return None


def choose_landmarks(size: float, seed: int, yards: list[F64], styles: int) -> list[LandmarkPick]:
    """The landmarks of a city of ``size`` metres and ``seed``: yards tried in a random
    order until :func:`landmark_count` have a site; alternately a tower and a spire.

    Parameters
    ----------
    yards: each perimeter block's backyard quad ``(4, 2)``.
    styles: how many facade styles there are (a landmark's style is drawn below it).
    """
    rng = np.random.default_rng([seed, LANDMARK_STREAM])
    want = landmark_count(size)
    chosen: list[tuple[int, F64]] = []
    for k in rng.permutation(len(yards)).tolist():
        if len(chosen) == want:
            break
        site = landmark_site(yards[k])
        if site is not None:
            chosen.append((k, site))
    out = []
    for n, (k, site) in enumerate(chosen):
        use = ("tower", "spire")[n % 2]
        floors = int(rng.integers(*(TOWER_FLOORS if use == "tower" else SPIRE_FLOORS)))
        out.append(LandmarkPick(k, site, use, floors, int(rng.integers(styles))))
    return out
