"""The ``outside`` cell's long facades cut into columns, so that each of its parts has a small box.

The outside cell holds whatever lies outside every room and doorway: the outer faces of
the outer walls, their window reveals, roofs, the middle of thick walls
(:mod:`~.roomcontents`).  Grouped by element alone, one part is a storey's whole facade:
on the generated offices an outer wall 60 m long with a hole for every window, about
220 triangles in one part whose box spans the building.  The client culls a part by its
box against the screen rectangles a portal walk leaves for the cell
(:func:`~walkstream.shared.partcull.cull_parts`); a window's rectangle meets the
projection of such a box from anywhere in the building (a long slab seen obliquely has
a screen box covering half the view), so every window drew every storey's facades,
which the rooms' own outer walls hide: on seed 3's tour up to 1,457 of a frame's 1,904
triangles, none of them seen.

Cut into columns of :data:`OUTSIDE_TILE_M` (triangles clipped exactly at vertical planes,
grouped by column, element and material; a group no longer than :data:`LONG_TILES`
columns stays whole), a window's rectangle meets only the pieces of
the facade around it.  The cut is in the bake and not at decoding
(:mod:`~walkstream.shared.codec.cellpieces`), because the facade's triangles themselves
run the building's length (the strip above the windows is two triangles): a box is only
small once the triangles are clipped.  The picture is unchanged (the pieces cover the
same surface, flat faces cut along lines); the culling stays conservative (every piece
is still the outside cell's, culled by its own box).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.server.bake.roomcontents import Part, weld
from walkstream.server.bake.roomgeom import clip_polygons, fan_triangles
from walkstream.shared.arrays import F64

__all__ = ["OUTSIDE_TILE_M", "LONG_TILES", "tile_triangles", "outside_parts"]

#: Pitch of the outside cell's columns, metres: two offices along a facade (3.6 to 6 m on
#: the generated offices), so that a window's rectangle takes the facade around its room,
#: not the building's.  On the first 30 s of seeds 3 and 13 pose by pose, 4 m and 8 m
#: columns drew the same triangles (within 0.3 %), and the outside cell's blob grew
#: from 3.6 kB to 7.0-7.2 kB at 4 m and 5.9-6.0 kB at 8 m: each column is a part of its
#: own, and a part costs bytes.
OUTSIDE_TILE_M = 8.0

#: A group of the outside cell (one element's triangles of one material) is cut only when
#: it is longer than this many columns across (24 m): cutting the 12-18 m groups of
#: FZK-Haus and the duplex (roofs, slabs, a wall) at 6 m drew no fewer triangles (-0.6 %,
#: -0.2 % a frame) and cost bytes (+0.4 and +0.7 kB; FZK-Haus's first perfect frame
#: 3.40 -> 3.56 s, its tightness p95 2.98 -> 3.03).
LONG_TILES = 3.0


def tile_triangles(
    tris: F64, tile: float | ArrayLike = OUTSIDE_TILE_M, axes: tuple[int, ...] = (0, 1), origin: ArrayLike = (0.0, 0.0, 0.0)
) -> tuple[F64, NDArray[np.int64], NDArray[np.int64]]:
    """Clip a triangle soup at the planes of a grid of pitch ``tile`` from ``origin``
    across ``axes`` (by default x and y: columns, a facade cut by vertical lines).

    Parameters
    ----------
    tris : (t, 3, 3) float64
        Triangles.
    tile : float or (3,) float
        The grid's pitch, metres (> 0), or one per axis.
    axes : tuple of int
        The axes cut (0, 1, 2: x, y, z); the others are not.
    origin : (3,) float
        A corner of the grid.

    Returns
    -------
    pieces : (m, 3, 3) float64
        The triangles, those crossing a plane clipped into one convex piece per cube
        they cross and fanned (winding kept; slivers of no area dropped).
    source : (m,) int64
        The triangle of ``tris`` each piece comes from.
    cube : (m, 3) int64
        The tile each piece lies in (its centroid's ``floor((centroid - origin) / tile)``
        on the axes cut, 0 on the others).
    """
    pitch = np.broadcast_to(np.asarray(tile, np.float64), (3,))
    if not np.all(pitch[list(axes)] > 0):
        raise ValueError(f"tile must be > 0, got {np.asarray(tile).tolist()}")
    org = np.asarray(origin, np.float64).reshape(3)
    tris = np.asarray(tris, np.float64).reshape(-1, 3, 3) - org
    poly = tris.copy()
    count = np.full(len(tris), 3, np.int64)
    src = np.arange(len(tris))
    for axis in axes:
        if len(poly) == 0:
            break
        tile_a = float(pitch[axis])
        lo_k = np.floor(np.min(np.where(np.arange(poly.shape[1])[None, :, None] < count[:, None, None],
                                        poly, np.inf)[..., axis], axis=1) / tile_a).astype(np.int64)
        hi_k = np.floor(np.max(np.where(np.arange(poly.shape[1])[None, :, None] < count[:, None, None],
                                        poly, -np.inf)[..., axis], axis=1) / tile_a).astype(np.int64)
        # a vertex exactly on a plane is in no danger: the piece beyond it has no area
        span = hi_k - lo_k
        keep_p, keep_c, keep_s = [poly[span == 0]], [count[span == 0]], [src[span == 0]]
        cross = np.flatnonzero(span > 0)
        if len(cross):
            # one copy of a crossing polygon per cube it may reach along this axis
            reps = span[cross] + 1
            rows = np.repeat(cross, reps)
            k = np.concatenate([np.arange(r) for r in reps.tolist()]) + np.repeat(lo_k[cross], reps)
            p, c = poly[rows], count[rows]
            normal = np.zeros(3)
            normal[axis] = 1.0
            below = np.concatenate([np.tile(normal, (len(k), 1)), -(k[:, None] + 1.0) * tile_a], axis=1)
            above = np.concatenate([np.tile(-normal, (len(k), 1)), k[:, None] * tile_a], axis=1)
            p, c = _clip_each(p, c, below)
            p, c = _clip_each(p, c, above)
            ok = c >= 3
            width = max(poly.shape[1], p.shape[1])
            keep_p.append(_pad(p[ok], width))
            keep_c.append(c[ok])
            keep_s.append(src[rows][ok])
            keep_p[0] = _pad(keep_p[0], width)
        poly = np.concatenate(keep_p)
        count = np.concatenate(keep_c)
        src = np.concatenate(keep_s)
    tri, which = fan_triangles(poly, count)
    cube = np.floor(tri.mean(axis=1) / np.where(pitch > 0, pitch, 1.0)).astype(np.int64)
    cube[:, [a for a in range(3) if a not in axes]] = 0
    return tri + org, src[which], cube


def outside_parts(
    soup: F64, elem: NDArray[np.int64], mat: NDArray[np.int64], tile: float = OUTSIDE_TILE_M
) -> list[Part]:
    """The outside cell's parts: its triangles grouped by element and material, a group
    longer than :data:`LONG_TILES` tiles across (x or y) cut into columns of ``tile``
    metres (:func:`tile_triangles`), one part per column.

    A shorter group stays whole: a window, a beam or a door crossing a grid line would
    only be cut in two, each half drawn with the other (on the duplex, cutting every
    group added 16 % triangles to the outside cell and drew more a frame).

    Parameters
    ----------
    soup : (t, 3, 3) float64
        The outside cell's triangles.
    elem, mat : (t,) int
        Element id and material of each.
    tile : float
        The columns' pitch, metres; 0: every group whole.

    Returns
    -------
    list of Part
        By element and material (ascending), then by column.
    """
    out: list[Part] = []
    if len(soup) == 0:
        return out
    key = np.asarray(elem, np.int64) * 256 + np.asarray(mat, np.int64)
    for k in np.unique(key).tolist():
        sel = np.flatnonzero(key == k)
        tri = soup[sel]
        span = tri.reshape(-1, 3).max(axis=0) - tri.reshape(-1, 3).min(axis=0)
        if tile > 0 and float(span[:2].max()) > LONG_TILES * tile:
            # one grid for the building (from the scene's origin): the cuts fall on the
            # same lines in every storey and element, which the codec's position
            # deltas compress better than columns of each group's own (6.3 against
            # 6.7 kB for seed 13's outside cell)
            pieces, _, cube = tile_triangles(tri, tile)
            _, group = np.unique(cube, axis=0, return_inverse=True)
            group = group.reshape(-1)
            groups = [pieces[group == g] for g in range(int(group.max()) + 1)] if len(group) else []
        else:
            groups = [tri]
        for g in groups:
            v, t = weld(g)
            out.append((int(k) // 256, int(k) % 256, v, t))
    return out


def _pad(poly: F64, width: int) -> F64:
    """``(n, k, 3)`` polygons padded (with their last row) to ``width`` vertices."""
    if poly.shape[1] >= width:
        return poly
    if len(poly) == 0:
        return np.zeros((0, width, 3))
    return np.concatenate([poly, np.repeat(poly[:, -1:], width - poly.shape[1], axis=1)], axis=1)


def _clip_each(poly: F64, count: NDArray[np.int64], planes: F64) -> tuple[F64, NDArray[np.int64]]:
    """:func:`~.roomgeom.clip_polygons` with a plane of its own per polygon (``planes`` ``(n, 4)``)."""
    if len(poly) == 0:
        return poly, count
    # group by plane (few distinct planes: one per grid line crossed)
    keys, inverse = np.unique(planes, axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    outs: list[tuple[NDArray[np.int64], F64, NDArray[np.int64]]] = []
    for g in range(len(keys)):
        sel = np.flatnonzero(inverse == g)
        p, c = clip_polygons(poly[sel], count[sel], keys[g])
        outs.append((sel, p, c))
    width = max(max(p.shape[1] for _, p, _ in outs), 3)
    res_p = np.zeros((len(poly), width, 3))
    res_c = np.zeros(len(poly), np.int64)
    for sel, p, c in outs:
        res_p[sel] = _pad(p, width)
        res_c[sel] = c
    return res_p, res_c
