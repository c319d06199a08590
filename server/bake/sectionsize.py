"""The redundancy ``R`` of sections, derived from the scene's own field (the default of ``--redundancy``).

``R`` counts objects, and the number of objects a section can afford depends on the
city: on the demo city R 96 wins the bytes figure, on West Oakland (126 objects) R 64
already makes the whole extract one section, on a clip of Kouvola R 64 wins and R 32
loses (docs/benchmarks.md).  The smallest R that won was 0.53 to 1.2 times the street
cells' mean PVS and 0.7 to 2 times a field point's mean visible set: no count and no
fixed multiple says how coarse the partition gets.  What does agree is the sections'
*size*: where sections won with the smallest R, they
averaged 2,160 to 2,350 m² of the walkable cover (demo R 96, West Oakland R 32), and
where they lost they were at most 1,210 m² (demo R 64, by 5 % on one walk; the clip's
R 32: 117 m²).  That is geometry, not object counts: a walker enters a section per
so many metres, and the prefetch asks for the records of the sections within so many
metres, so the records and index tiles a walk moves (most of a fine partition's
bytes) fall with the sections' area whatever the city's objects.

So the default ``R`` is the smallest that grows sections of :data:`SECTION_AREA` square
metres on average over the cover (``ceil(cover area / SECTION_AREA)`` sections at
most), found on the field itself by growing the sections for a few ``R``: a bracket
from the field's mean visible-set size, doubling or halving, then bisection to within
a sixteenth.  Where no ``R`` reaches that count (pieces of the cover that no section
may join), the coarsest partition's count is the goal.  The growth is a few seconds
against the field's minutes to hours, and the sections of the chosen ``R`` are kept.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from walkstream.server.bake.field import FieldLattice, PointSets
from walkstream.server.bake.sections import Section, grow_sections

__all__ = ["SECTION_AREA", "sections_for_area"]

SECTION_AREA = 2400.0
"""Square metres of walkable cover per section the default ``R`` aims at (see the module docstring)."""

_TOLERANCE = 16
"""The bisection stops when the bracket is within ``hi / _TOLERANCE`` objects (or 1)."""


def sections_for_area(
    lattice: FieldLattice,
    sets: PointSets,
    *,
    min_size: float,
    area: float = SECTION_AREA,
    say: Callable[[str], None] | None = None,
) -> tuple[int, list[Section]]:
    """The smallest redundancy whose sections average at least ``area`` m², and those sections.

    Parameters
    ----------
    lattice, sets:
        The field points (``n``) and their visible sets.
    min_size:
        ``M`` of :func:`~.sections.grow_sections`.
    area:
        Square metres of cover per section aimed at (> 0).
    say:
        Told each ``R`` tried and the sections it grew.

    Returns
    -------
    (int, list[Section])
        ``R`` and the sections grown with it.
    """
    if not (math.isfinite(area) and area > 0):
        raise ValueError(f"section area: expected a positive number of square metres, got {area}")
    n = len(lattice)
    if n == 0:
        return 0, []
    grown: dict[int, list[Section]] = {}

    def count(r: int) -> int:
        if r not in grown:
            grown[r] = grow_sections(lattice, sets, redundancy=r, min_size=min_size)
            if say is not None:
                say(f"R {r}: {len(grown[r])} sections")
        return len(grown[r])

    # R beyond the objects the field sees changes nothing: the coarsest partition
    r_max = max(1, int(np.unique(sets.ids).size))
    target = max(1, math.ceil(n * lattice.spacing**2 / area), count(r_max))
    # bracket lo < R <= hi: count(lo) > target >= count(hi), from the mean visible set
    r = min(r_max, max(1, round(float(sets.sizes().mean()))))
    lo, hi = -1, r_max
    if count(r) <= target:
        hi = r
        while hi > 0:
            r = hi // 2
            if count(r) <= target:
                hi = r
            else:
                lo = r
                break
    else:
        lo = r
        while 2 * lo < hi:
            r = 2 * lo
            if count(r) <= target:
                hi = r
                break
            lo = r
    while hi - lo > max(1, hi // _TOLERANCE):
        mid = (lo + hi) // 2
        if count(mid) <= target:
            hi = mid
        else:
            lo = mid
    return hi, grown[hi]
