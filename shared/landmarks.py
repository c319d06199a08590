"""Landmarks: the few tall, detailed buildings of a city (a tower, a spire).

A landmark is an ordinary :class:`~walkstream.shared.records.BuildingParams` with a
non-zero ``kind``; the building grammar (``shared/grammars/building.lsys``) reads the
kind as its global ``K`` and builds the crown (setback stages and a mast for a tower,
a tapering stepped spire for a spire) from the footprint and three numbers the host
gives it: ``K``, ``LMIN`` (the shortest edge of the exterior ring, so the crown fits
a square or rectangular footprint) and ``T`` (the height of the crown's top).  Only
these parameters travel; no landmark geometry is ever sent.

``T`` is computed here and nowhere else, so the grammar, the scene's object boxes and
the truth's bounds agree on how high a landmark reaches.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from walkstream.shared.errors import InputError

__all__ = ["LANDMARK_KINDS", "PLAIN", "TOWER", "SPIRE", "landmark_kind", "crown_top", "shortest_edge"]

#: an ordinary building
PLAIN = 0
#: a tall building with three setback stages and a mast
TOWER = 1
#: a church-like base with a tapering stepped spire
SPIRE = 2
#: the kinds by name (the ``landmark`` property of a footprint file)
LANDMARK_KINDS = {"tower": TOWER, "spire": SPIRE}

# how far a crown reaches above the eaves, in multiples of the footprint's short side
_CROWN = {PLAIN: 0.0, TOWER: 1.5, SPIRE: 3.0}


def landmark_kind(value: Any) -> int:
    """The kind number of a ``landmark`` property: ``"tower"``, ``"spire"`` or empty.

    Raises
    ------
    InputError
        The value names no landmark kind.
    """
    if value is None or value == "":
        return PLAIN
    if isinstance(value, str) and value in LANDMARK_KINDS:
        return LANDMARK_KINDS[value]
    raise InputError(f"landmark: expected one of {sorted(LANDMARK_KINDS)}, got {value!r}")


def shortest_edge(exterior: np.ndarray) -> float:
    """Length in metres of the shortest edge of a ring ``(n, 2)`` (closing edge included)."""
    d = np.roll(exterior, -1, axis=0) - exterior
    return float(np.hypot(d[:, 0], d[:, 1]).min())


def crown_top(kind: int, height: float, lmin: float) -> float:
    """Height in metres of the top of a building of ``kind``: its eaves for a plain one.

    Parameters
    ----------
    kind: :data:`PLAIN`, :data:`TOWER` or :data:`SPIRE`.
    height: eaves height (floors times floor height), metres.
    lmin: the footprint's shortest exterior edge, metres.
    """
    if kind not in _CROWN:
        raise InputError(f"building kind: expected one of {sorted(_CROWN)}, got {kind!r}")
    return float(height) + _CROWN[kind] * float(lmin)
