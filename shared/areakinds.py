"""The kinds of typed area (:mod:`walkstream.shared.areas`), the order they lie in and their heights.

Plain data with no import of the records, so that
:class:`~walkstream.shared.records.AreaParams` can check a kind.
"""

from __future__ import annotations

__all__ = ["AREA_KINDS", "AREA_MATERIALS", "AREA_Z_LOWEST", "AREA_Z_STEP", "area_z"]

#: The kinds of area, lowest first (the order they lie in).
AREA_KINDS: tuple[str, ...] = (
    "built",
    "farmland",
    "grass",
    "wood",
    "sport",
    "sand",
    "parking",
    "pedestrian",
    "water",
)

#: Palette id of each kind (:data:`~walkstream.shared.palette.MATERIALS`, ``area_<kind>``).
AREA_MATERIALS: dict[str, int] = {k: 21 + i for i, k in enumerate(AREA_KINDS)}

#: Height of the lowest kind, metres (below the datum: under buildings and streets).
AREA_Z_LOWEST = -0.10
#: Height between two kinds, metres: 1 cm, as far apart as 24-bit depth keeps them
#: a few hundred metres away with the street's 0.5 m near plane.
AREA_Z_STEP = 0.01


def area_z(kind: str) -> float:
    """Height of an area of ``kind``, metres (why: :mod:`walkstream.shared.areas`)."""
    return AREA_Z_LOWEST + AREA_Z_STEP * AREA_KINDS.index(kind)
