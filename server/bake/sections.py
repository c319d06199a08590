"""Sections (Brosnan et al., section 4): axis-aligned rectangles grown over the dense visibility field.

Given every field point's visible set (:mod:`.field`), sections are grown as the
paper does:

1. a seed point ``p`` (unassigned points in turn, the one seeing most first) and
   the set ``s`` of field points whose visible sets are subsets of ``p``'s;
2. the *inner rectangle*: the largest lattice rectangle holding ``p`` whose field
   points all lie in ``s`` (no gaps); its visible set is ``p``'s;
3. expanded one row or column at a time on the side that adds the fewest objects,
   while the objects added beyond ``p``'s set stay within the redundancy ``R``
   (a section's *redundancy*: what it holds that its seed does not see); a side whose
   row holds no unassigned field point is not taken (sections overlap only where
   they add points, and a row of building alone never joins two streets);
4. accepted when its area reaches the minimum size ``M`` (square metres), its
   field points then assigned; a second, *relaxed* pass grows sections from the
   points left without the minimum, until every field point lies in a section.

Lattice point ``(i, j)`` owns the ``spacing`` square around it, so a section of
points ``i0..i1 x j0..j1`` is the rectangle from ``i0 - 1/2`` to ``i1 + 1/2``
spacings: sections that share an edge meet exactly, and every field point's
square (all the free space) is covered.  A section's PVS is the union of the
visible sets of every field point inside it, its ACH their pixel counts summed.

The visible sets are kept as bit rows over the objects the field sees, so a subset
test, a union and the objects a row adds are numpy operations over bytes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from walkstream.server.bake.field import FieldLattice, PointSets
from walkstream.server.bake.visibility import pvs_from_counts
from walkstream.shared.arrays import F64, I64
from walkstream.shared.errors import InputError

__all__ = ["INNER_WINDOW_M", "Section", "grow_sections", "section_pvs", "section_stats"]

INNER_WINDOW_M = 120.0
"""The inner rectangle is looked for within this many metres of its seed."""

_POPCOUNT = np.array([bin(i).count("1") for i in range(256)], np.int64)


@dataclass(frozen=True, slots=True)
class Section:
    """One section: lattice rectangle ``i0..i1`` (columns) by ``j0..j1`` (rows), inclusive.

    ``seed`` is the field point it grew from, ``inner`` its inner rectangle
    ``(i0, j0, i1, j1)``, ``redundancy`` the objects it holds that the seed does not
    see, ``relaxed`` whether the second pass made it (below the minimum size).
    """

    i0: int
    j0: int
    i1: int
    j1: int
    seed: int
    inner: tuple[int, int, int, int]
    redundancy: int
    relaxed: bool

    def outline(self, lattice: FieldLattice) -> F64:
        """The rectangle, counter-clockwise, scene-local metres (turned with the lattice)."""
        s, (x0, y0) = lattice.spacing, lattice.origin
        xa, xb = x0 + (self.i0 - 0.5) * s, x0 + (self.i1 + 0.5) * s
        ya, yb = y0 + (self.j0 - 0.5) * s, y0 + (self.j1 + 0.5) * s
        return lattice.to_scene(np.array([[xa, ya], [xb, ya], [xb, yb], [xa, yb]]))

    @property
    def points(self) -> int:
        """Lattice positions it covers (field points or not)."""
        return (self.i1 - self.i0 + 1) * (self.j1 - self.j0 + 1)


def _bits(sets: PointSets) -> NDArray[np.uint8]:
    """``(n, bytes)`` each point's visible set as a bit row over the objects the field sees."""
    objs = np.unique(sets.ids)
    col = np.searchsorted(objs, sets.ids)
    row = np.repeat(np.arange(len(sets)), sets.sizes())
    out = np.zeros((len(sets), max(1, (len(objs) + 7) // 8)), np.uint8)
    np.bitwise_or.at(out, (row, col >> 3), (1 << (col & 7)).astype(np.uint8))
    return out


def _count(bits: NDArray[np.uint8]) -> int:
    return int(_POPCOUNT[bits].sum())


def _inner(mask: NDArray[np.bool_], r: int, c: int) -> tuple[int, int, int, int]:
    """The largest all-true rectangle of ``mask`` holding ``(r, c)``: ``(c0, r0, c1, r1)``."""
    rows = mask.shape[0]
    lo = np.zeros(rows, np.int64)
    hi = np.zeros(rows, np.int64)
    top = bot = r
    while top - 1 >= 0 and mask[top - 1, c]:
        top -= 1
    while bot + 1 < rows and mask[bot + 1, c]:
        bot += 1
    for k in range(top, bot + 1):
        row = mask[k]
        left = np.flatnonzero(~row[:c])
        right = np.flatnonzero(~row[c + 1 :])
        lo[k] = left[-1] + 1 if len(left) else 0
        hi[k] = c + right[0] if len(right) else len(row) - 1
    best = (0, (c, r, c, r))
    for r0 in range(r, top - 1, -1):
        left, right = np.maximum.accumulate(lo[r0 : bot + 1]), np.minimum.accumulate(hi[r0 : bot + 1])
        # rows r0..r1 with r1 >= r: offsets from r - r0 on
        k0 = r - r0
        width = right[k0:] - left[k0:] + 1
        area = width * (np.arange(k0, bot - r0 + 1) + 1)
        k = int(np.argmax(area))
        if area[k] > best[0]:
            best = (int(area[k]), (int(left[k0 + k]), r0, int(right[k0 + k]), r0 + k0 + k))
    return best[1]


def grow_sections(
    lattice: FieldLattice, sets: PointSets, *, redundancy: int, min_size: float
) -> list[Section]:
    """Grow sections until every field point lies in one (see the module docstring).

    Parameters
    ----------
    lattice, sets:
        The field points and their visible sets.
    redundancy:
        ``R``: objects a section may hold beyond what its seed sees.
    min_size:
        ``M``: smallest area (square metres) the first pass accepts.

    Returns
    -------
    list[Section]
        In the order they were grown.
    """
    if redundancy < 0:
        raise InputError(f"--redundancy: expected >= 0 objects, got {redundancy}")
    if min_size < 0:
        raise InputError(f"--min-size: expected >= 0 square metres, got {min_size}")
    n = len(lattice)
    if n == 0:
        return []
    bits = _bits(sets)
    grid = lattice.grid()
    ny, nx = grid.shape
    pos_r, pos_c = np.divmod(lattice.index, nx)
    assigned = np.zeros(n, bool)
    order = np.lexsort((np.arange(n), -sets.sizes()))
    win = max(1, int(INNER_WINDOW_M / lattice.spacing))
    area_of_point = lattice.spacing**2
    out: list[Section] = []
    for relaxed in (False, True):
        for p in order.tolist():
            if assigned[p]:
                continue
            sec = _grow(p, bits, grid, pos_r, pos_c, assigned, win, int(redundancy), relaxed)
            if not relaxed and sec.points * area_of_point < min_size:
                continue
            inside = grid[sec.j0 : sec.j1 + 1, sec.i0 : sec.i1 + 1]
            assigned[inside[inside >= 0]] = True
            out.append(sec)
    return out


def _grow(
    p: int,
    bits: NDArray[np.uint8],
    grid: I64,
    pos_r: I64,
    pos_c: I64,
    assigned: NDArray[np.bool_],
    win: int,
    redundancy: int,
    relaxed: bool,
) -> Section:
    ny, nx = grid.shape
    r, c = int(pos_r[p]), int(pos_c[p])
    ra, rb, ca, cb = max(0, r - win), min(ny, r + win + 1), max(0, c - win), min(nx, c + win + 1)
    g = grid[ra:rb, ca:cb]
    mask = g >= 0
    pts = g[mask]
    # the subset rule: nothing a point sees is missing from the seed's set
    mask[mask] = ~np.any(bits[pts] & ~bits[p], axis=1)
    c0, r0, c1, r1 = _inner(mask, r - ra, c - ca)
    i0, j0, i1, j1 = c0 + ca, r0 + ra, c1 + ca, r1 + ra
    inner = (i0, j0, i1, j1)
    union = bits[p].copy()
    added = 0
    while True:
        best: tuple[int, int, int] | None = None
        for side in range(4):
            if side == 0:
                if i0 == 0:
                    continue
                strip = grid[j0 : j1 + 1, i0 - 1]
            elif side == 1:
                if i1 == nx - 1:
                    continue
                strip = grid[j0 : j1 + 1, i1 + 1]
            elif side == 2:
                if j0 == 0:
                    continue
                strip = grid[j0 - 1, i0 : i1 + 1]
            else:
                if j1 == ny - 1:
                    continue
                strip = grid[j1 + 1, i0 : i1 + 1]
            q = strip[strip >= 0]
            fresh = int((~assigned[q]).sum())
            if fresh == 0:
                continue
            new = _count(np.bitwise_or.reduce(bits[q], axis=0) & ~union)
            if added + new > redundancy:
                continue
            key = (new, -fresh, side)
            if best is None or key < best:
                best = key
        if best is None:
            break
        new, _, side = best
        if side == 0:
            i0 -= 1
            q = grid[j0 : j1 + 1, i0]
        elif side == 1:
            i1 += 1
            q = grid[j0 : j1 + 1, i1]
        elif side == 2:
            j0 -= 1
            q = grid[j0, i0 : i1 + 1]
        else:
            j1 += 1
            q = grid[j1, i0 : i1 + 1]
        q = q[q >= 0]
        union |= np.bitwise_or.reduce(bits[q], axis=0)
        added += new
    return Section(i0, j0, i1, j1, p, inner, added, relaxed)


def section_points(section: Section, grid: I64) -> I64:
    """The field points inside ``section`` (``grid``: :meth:`FieldLattice.grid`)."""
    inside = grid[section.j0 : section.j1 + 1, section.i0 : section.i1 + 1]
    out: I64 = inside[inside >= 0]
    return out


def section_pvs(section: Section, grid: I64, sets: PointSets, *, threshold: int = 0) -> tuple[I64, F64]:
    """A section's PVS (the union of its field points' sets) and ACH (their pixels summed)."""
    pts = section_points(section, grid)
    if len(pts) == 0:
        return np.zeros(0, np.int64), np.zeros(0)
    return pvs_from_counts(*sets.union(pts), threshold=threshold)


def section_stats(sections: list[Section], grid: I64, sets: PointSets, pvs_sizes: I64) -> dict[str, float]:
    """Figures of a partition into sections: how many, mean PVS, redundancy, overlap.

    ``redundancy_mean`` is, over every (section, field point inside it) pair, the
    objects the section holds that the point does not see (what a walker standing
    there is sent in vain); ``cover_mean`` the sections each field point lies in.
    """
    sizes = sets.sizes()
    red, cover = [], np.zeros(len(sets), np.int64)
    for sec, m in zip(sections, pvs_sizes.tolist(), strict=True):
        pts = section_points(sec, grid)
        red.append(m - sizes[pts])
        cover[pts] += 1
    r = np.concatenate(red) if red else np.zeros(0)
    return {
        "sections": len(sections),
        "sections_relaxed": sum(1 for s in sections if s.relaxed),
        "section_pvs_mean": float(np.mean(pvs_sizes)) if len(pvs_sizes) else 0.0,
        "section_redundancy_mean": float(r.mean()) if len(r) else 0.0,
        "section_redundancy_max": int(max((s.redundancy for s in sections), default=0)),
        "section_cover_mean": float(cover.mean()) if len(cover) else 0.0,
    }
