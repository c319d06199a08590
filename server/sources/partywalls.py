"""Party walls: find the footprint edges that two buildings share.

Adjacent buildings in a city block stand wall to wall.  The grammar must know, for
every footprint edge, how tall the building behind it is (a party wall has no
openings up to the neighbour's height).  Real and generated footprints rarely have
matching vertices on a shared wall: a short house next to a long one shares only
part of the long one's edge.  :func:`find_party_walls` therefore first splits such
edges at the neighbour's vertices, so that every resulting edge is either shared
over (nearly) its whole length or not at all, then gives each edge the height of
the neighbour behind it.

The work is vectorised over all edges of all buildings: one shapely ``STRtree``
bulk query over the edges' bounding boxes proposes candidate edge pairs, numpy
filters them.  4,000 buildings take a fraction of a second.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import shapely

from walkstream.shared.arrays import F64
from walkstream.shared.errors import InputError

__all__ = ["find_party_walls", "split_shared_edges", "MAX_ANGLE_DEG"]


#: Two edges can only be a party wall when their directions differ by at most this
#: many degrees (parallel or anti-parallel).  Without it, two short edges crossing
#: each other at a steep angle would pass the distance test.
MAX_ANGLE_DEG = 10.0


def find_party_walls(
    footprints: Sequence[Sequence[F64]],
    heights: Sequence[float],
    tol: float = 0.1,
) -> tuple[list[list[F64]], list[list[F64]]]:
    """Split partly shared edges and find the neighbour height behind every edge.

    Two edges of different buildings *share* a stretch (form a party wall) when

    - their directions are parallel or anti-parallel within :data:`MAX_ANGLE_DEG`,
    - their common stretch, measured along the first edge, is longer than ``tol``,
    - and both ends of that common stretch of the second edge lie within ``tol``
      metres of the first edge's line (so a gap of up to ``tol`` between the two
      walls still counts as shared).

    Every vertex of the second edge that lies within ``tol`` of the first edge's
    line, strictly inside the first edge and at least ``tol`` from its ends, becomes
    a new vertex of the first edge (placed on the edge, so the edge stays straight).
    Split points closer than ``tol`` to a previous split point on the same edge are
    dropped, so no new vertex is ever closer than ``tol`` to another.  An edge of the
    split rings then gets the height of every neighbour whose common stretch covers
    the edge's midpoint (the maximum when there are several), else 0.

    Parameters
    ----------
    footprints:
        ``footprints[b]`` is the list of rings of building ``b``; each ring is an
        ``(n, 2) float64`` array of metres without a repeated closing vertex.  Ring 0
        is the exterior (counter-clockwise), the others are holes (clockwise).  The
        orientation is not needed here and is kept as given.
    heights:
        ``(B,)`` height in metres of each building.
    tol:
        Distance tolerance in metres (> 0), see above.

    Returns
    -------
    split_rings:
        Per building, per ring, an ``(m, 2) float64`` array with ``m >= n``: the input
        vertices in their order (unchanged) plus the inserted split vertices.
    neighbour_heights:
        Per building, per ring, an ``(m,) float64`` array: for edge ``i`` (vertex ``i``
        to ``(i + 1) % m``) the height of the neighbour behind it, 0 for a free edge.

    Raises
    ------
    InputError
        If ``heights`` does not have one value per footprint, ``tol`` is not a
        positive finite number, or a ring is not an ``(n, 2)`` array.
    """
    if not (math.isfinite(tol) and tol > 0):
        raise InputError(f"find_party_walls: tol must be a positive number of metres, got {tol!r}")
    if len(heights) != len(footprints):
        raise InputError(
            f"find_party_walls: expected one height per footprint ({len(footprints)}), "
            f"got {len(heights)}"
        )
    rings: list[F64] = []
    ring_bld: list[int] = []
    for b, fp in enumerate(footprints):
        for k, r in enumerate(fp):
            arr = np.asarray(r, dtype=np.float64)
            if arr.ndim != 2 or arr.shape[1] != 2:
                raise InputError(
                    f"find_party_walls: footprints[{b}][{k}] must be an (n, 2) array, "
                    f"got shape {arr.shape}"
                )
            rings.append(arr)
            ring_bld.append(b)
    if sum(len(r) for r in rings) == 0:
        return (
            [[r.copy() for r in fp] for fp in _regroup(rings, ring_bld, len(footprints))],
            [[np.zeros(len(r)) for r in fp] for fp in _regroup(rings, ring_bld, len(footprints))],
        )

    # --- Flatten every edge of every ring into one set of arrays. -------------------
    counts = np.array([len(r) for r in rings], dtype=np.int64)
    n_rings = len(rings)
    a = np.concatenate(rings)  # (E, 2) edge start points
    n_edges = len(a)
    ring_of_edge = np.repeat(np.arange(n_rings), counts)
    ring_start = np.cumsum(counts) - counts
    edge_ids = np.arange(n_edges)
    is_last = edge_ids - ring_start[ring_of_edge] + 1 == counts[ring_of_edge]
    nxt = np.where(is_last, ring_start[ring_of_edge], edge_ids + 1)
    b_pts = a[nxt]  # (E, 2) edge end points
    bld = np.asarray(ring_bld, dtype=np.int64)[ring_of_edge]
    h_bld = np.asarray(heights, dtype=np.float64)

    d = b_pts - a
    length = np.hypot(d[:, 0], d[:, 1])
    safe = np.where(length > 0, length, 1.0)
    # Zero-length edges get a zero direction so "start + 0 * u" stays exact, not NaN.
    u = np.where((length > 0)[:, None], d / safe[:, None], 0.0)

    # --- Candidate pairs: edge boxes grown by tol, one bulk STRtree query. ----------
    lo = np.minimum(a, b_pts) - tol
    hi = np.maximum(a, b_pts) + tol
    boxes = shapely.box(lo[:, 0], lo[:, 1], hi[:, 0], hi[:, 1])
    tree = shapely.STRtree(boxes)
    ei, fi = tree.query(boxes)
    keep = (bld[ei] != bld[fi]) & (length[ei] > 0) & (length[fi] > 0)
    ei, fi = ei[keep], fi[keep]

    # --- Exact test in edge e's frame: t along e, offset across it. -----------------
    ue = u[ei]
    le = length[ei]
    c = a[fi] - a[ei]
    dd = b_pts[fi] - a[ei]
    tc = c[:, 0] * ue[:, 0] + c[:, 1] * ue[:, 1]
    td = dd[:, 0] * ue[:, 0] + dd[:, 1] * ue[:, 1]
    oc = ue[:, 0] * c[:, 1] - ue[:, 1] * c[:, 0]
    od = ue[:, 0] * dd[:, 1] - ue[:, 1] * dd[:, 0]
    sin_angle = np.abs(ue[:, 0] * u[fi, 1] - ue[:, 1] * u[fi, 0])
    o0 = np.maximum(np.minimum(tc, td), 0.0)
    o1 = np.minimum(np.maximum(tc, td), le)
    ok = (o1 - o0 > tol) & (sin_angle <= math.sin(math.radians(MAX_ANGLE_DEG)))
    # The offset of edge f from e's line is linear in t; evaluate it at both ends of
    # the common stretch (td != tc wherever o1 - o0 > tol).
    span = np.where(ok, td - tc, 1.0)
    off0 = oc + (o0 - tc) / span * (od - oc)
    off1 = oc + (o1 - tc) / span * (od - oc)
    ok &= (np.abs(off0) <= tol) & (np.abs(off1) <= tol)
    ei, fi, tc, td, oc, od, le = ei[ok], fi[ok], tc[ok], td[ok], oc[ok], od[ok], le[ok]
    s0, s1 = o0[ok], o1[ok]

    # --- Split points: f's vertices on e's line, inside e, >= tol from its ends. ----
    split_e_parts = []
    split_t_parts = []
    for t, off in ((tc, oc), (td, od)):
        m = (np.abs(off) <= tol) & (t >= tol) & (t <= le - tol)
        split_e_parts.append(ei[m])
        split_t_parts.append(t[m])
    split_e = np.concatenate(split_e_parts)
    split_t = np.concatenate(split_t_parts)
    order = np.lexsort((split_t, split_e))
    split_e, split_t = split_e[order], split_t[order]
    # Neighbours that share a corner give the same point several times: keep the
    # first of every run of points closer than tol to each other on the same edge.
    first_of_edge = np.ones(len(split_e), dtype=bool)
    first_of_edge[1:] = split_e[1:] != split_e[:-1]
    far = np.ones(len(split_e), dtype=bool)
    far[1:] = np.diff(split_t) >= tol
    take = first_of_edge | far
    split_e, split_t = split_e[take], split_t[take]

    # --- New vertex list: original starts (t = 0) and split points, sorted. ---------
    all_e = np.concatenate([edge_ids, split_e])
    all_t = np.concatenate([np.zeros(n_edges), split_t])
    order = np.lexsort((all_t, all_e))
    ve, vt = all_e[order], all_t[order]
    pts = a[ve] + vt[:, None] * u[ve]  # exact for originals: t = 0 and u finite
    same_next = np.zeros(len(ve), dtype=bool)
    same_next[:-1] = ve[1:] == ve[:-1]
    t_end = np.where(same_next, np.roll(vt, -1), length[ve])
    t_mid = 0.5 * (vt + t_end)

    # --- Heights: every shared stretch lifts the sub-edges whose midpoint it covers.
    nh = np.zeros(len(ve))
    n_sub = np.bincount(ve, minlength=n_edges)
    first_sub = np.cumsum(n_sub) - n_sub
    rep = n_sub[ei]
    total = int(rep.sum())
    if total:
        within = np.arange(total) - np.repeat(np.cumsum(rep) - rep, rep)
        idx = np.repeat(first_sub[ei], rep) + within
        tm = t_mid[idx]
        cover = (tm >= np.repeat(s0, rep)) & (tm <= np.repeat(s1, rep))
        np.maximum.at(nh, idx[cover], np.repeat(h_bld[bld[fi]], rep)[cover])

    # --- Back to per-ring, per-building lists. ---------------------------------------
    new_counts = np.bincount(ring_of_edge[ve], minlength=n_rings)
    cuts = np.cumsum(new_counts)[:-1]
    out_rings = np.split(pts, cuts)
    out_heights = np.split(nh, cuts)
    return (
        _regroup(out_rings, ring_bld, len(footprints)),
        _regroup(out_heights, ring_bld, len(footprints)),
    )


def split_shared_edges(footprints: Sequence[Sequence[F64]], tol: float = 0.1) -> list[list[F64]]:
    """The footprints with a vertex wherever a neighbour's corner lies on an edge.

    The splitting of :func:`find_party_walls` without the heights: a generator that
    rounds its output (to 1 cm) calls this first, so that buildings standing wall to
    wall keep identical vertices along the wall and rounding cannot make them overlap.
    The neighbour heights are left to whoever loads the footprints.
    """
    rings, _ = find_party_walls(footprints, [0.0] * len(footprints), tol)
    return rings


def _regroup(items: Sequence[F64], ring_bld: Sequence[int], n_buildings: int) -> list[list[F64]]:
    """Group per-ring arrays (in building order) back into one list per building."""
    out: list[list[F64]] = [[] for _ in range(n_buildings)]
    for item, b in zip(items, ring_bld, strict=True):
        out[b].append(item)
    return out
