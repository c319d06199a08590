"""Per-frame level-of-detail selection: ACH budget sharing and distance LODs (after culling).

Everything here is pure numpy and runs every frame over the current cell's PVS (tens
to a few hundred objects), so the hot loops stay on plain Python floats.

ACH allocation (Marvie et al. 2003, section 4)
    The cell's PVS is frustum-culled by bounding box; the ACH of the visible objects
    that have any geometry is normalised to sum to 1 over them; in descending ACH
    (ties by index) object ``i`` is offered

        ``N_i = N_rem * ACH_i / sum(ACH_k for the objects not yet served)``

    and takes the best (highest) available LOD whose triangle count fits ``N_i``, but
    never less than its lowest available LOD, so nothing visible disappears.  Then
    ``N_rem = max(0, N_rem - triangles used)``: an object that fits in less than its
    share leaves the rest to the objects after it.  Nothing is reserved for the
    objects still to come, so a frame can exceed its budget by at most the lowest
    LODs of the objects served after the budget ran out (a few dozen triangles each
    with the building grammar), even when all lowest LODs together would fit.  The paper writes
    ``N_i = ACH_i * N_rem``; dividing by the ACH still unserved is what makes the
    shares of a budget that is never overrun add up to the whole budget.

Distance selection
    The usual rule the paper compares against: LOD2 nearer than ``d1``, LOD1 nearer
    than ``d2``, LOD0 beyond.  :func:`distance_thresholds_for_budget` picks the
    thresholds that spend a given triangle budget, so both rules can be compared at
    equal frame time.

An :class:`Allocation` records the chosen LOD per object (``-1``: not drawn)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.shared.errors import InputError

__all__ = [
    "NOT_DRAWN",
    "Allocation",
    "allocate_ach",
    "allocate_distance",
    "distance_thresholds_for_budget",
]

#: LOD value of an object that is not drawn (culled, or no geometry available).
NOT_DRAWN = -1

_N_LODS = 3


@dataclass(frozen=True, slots=True)
class Allocation:
    """The LOD chosen for each object of one frame.

    Attributes
    ----------
    lod : (k,) int8
        0, 1 or 2; ``-1`` (:data:`NOT_DRAWN`) for an object that is culled or has no
        geometry available.
    triangles : int
        Total triangles of the chosen LODs.
    floor_limited : bool
        The lowest available LODs of the visible drawable objects alone exceed the
        budget (the frame cannot be made cheaper by choosing LODs).  Always False for
        distance selection without a budget.
    all_max : bool
        Every drawn object is at its highest available LOD (LOD2 once all geometry is
        built): a bigger budget would not change the frame.  True for a frame that
        draws nothing.
    """

    lod: NDArray[np.int8]
    triangles: int
    floor_limited: bool
    all_max: bool

    @property
    def drawn(self) -> NDArray[np.int64]:
        """Indices of the drawn objects, ascending."""
        return np.flatnonzero(self.lod >= 0)


# --------------------------------------------------------------------------- checks


def _inputs(
    k_name: str,
    first: ArrayLike,
    tri: ArrayLike,
    available: ArrayLike,
    visible: ArrayLike,
    what: str,
) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.bool_], NDArray[np.bool_]]:
    """Validate and convert the per-object arrays shared by both allocators."""
    a = np.asarray(first, dtype=np.float64).reshape(-1)
    k = len(a)
    t = np.asarray(tri)
    if t.size == 0 and k == 0:
        t = np.zeros((0, _N_LODS), np.int64)
    if t.shape != (k, _N_LODS):
        raise InputError(f"{what}: tri: expected shape ({k}, 3), got {t.shape}")
    if not np.issubdtype(t.dtype, np.integer):
        if not np.all(np.isfinite(t)) or np.any(t != np.round(t)):
            raise InputError(f"{what}: tri: expected whole triangle counts")
    t = t.astype(np.int64)
    if np.any(t < 0):
        raise InputError(f"{what}: tri: triangle counts must be >= 0")
    av = np.asarray(available, dtype=bool)
    if av.shape != (k, _N_LODS):
        raise InputError(f"{what}: available: expected shape ({k}, 3), got {av.shape}")
    vis = np.asarray(visible, dtype=bool).reshape(-1)
    if vis.shape != (k,):
        raise InputError(f"{what}: visible: expected {k} values, got {vis.shape[0]}")
    if not np.all(np.isfinite(a)) or np.any(a < 0):
        raise InputError(f"{what}: {k_name}: expected finite values >= 0")
    return a, t, av, vis


def _budget(budget: float, what: str) -> float:
    b = float(budget)
    if not (math.isfinite(b) and b >= 0):
        raise InputError(f"{what}: budget: expected a finite number >= 0, got {budget!r}")
    return b


def _lowest_available(av: NDArray[np.bool_]) -> NDArray[np.int64]:
    """Index of the lowest available LOD per row (rows with none give 0: mask them out)."""
    return np.argmax(av, axis=1).astype(np.int64)


def _highest_available(av: NDArray[np.bool_]) -> NDArray[np.int64]:
    """Index of the highest available LOD per row (rows with none give 2: mask them out)."""
    return (_N_LODS - 1 - np.argmax(av[:, ::-1], axis=1)).astype(np.int64)


def _finish(
    lod: NDArray[np.int8],
    t: NDArray[np.int64],
    av: NDArray[np.bool_],
    drawable: NDArray[np.bool_],
    budget: float | None,
) -> Allocation:
    idx = np.flatnonzero(drawable)
    chosen = lod[idx].astype(np.int64)
    triangles = int(t[idx, chosen].sum())
    floor = int(t[idx, _lowest_available(av[idx])].sum())
    all_max = bool(np.all(chosen == _highest_available(av[idx])))
    floor_limited = budget is not None and floor > budget
    return Allocation(lod, triangles, bool(floor_limited), all_max)


# --------------------------------------------------------------------------- ACH


def allocate_ach(
    ach: ArrayLike,
    tri: ArrayLike,
    available: ArrayLike,
    visible: ArrayLike,
    budget: float,
    *,
    reserve_floor: bool = False,
    greedy: bool = False,
    cap: ArrayLike | None = None,
) -> Allocation:
    """Share a triangle budget among the visible objects by their ACH.

    Parameters
    ----------
    ach : (k,) float
        Average coverage hint of each object (any non-negative scale: it is
        normalised over the visible drawable objects here).
    tri : (k, 3) int
        Triangle count of LOD 0, 1 and 2 of each object.
    available : (k, 3) bool
        Whether each LOD's geometry is built and uploaded; unavailable LODs are
        never chosen, and an object with none is not drawn.
    visible : (k,) bool
        Result of :func:`frustum_cull` (False: not drawn).
    budget : float
        Triangles for the frame (>= 0).
    reserve_floor : bool
        The paper's rule as written (False) can overshoot the budget: objects served
        first take LOD1/LOD2 shares and the later ones still get their LOD0.  With
        True, the lowest LOD of every visible object is set aside first and the same
        rule shares what is left (the *upgrades*: a LOD costs its triangles minus
        the object's lowest LOD), so the frame stays within the budget whenever the
        lowest LODs fit.  The replay uses True.
    greedy : bool
        Instead of the shares: in descending ACH each object takes the best LOD whose
        upgrade still fits what is left.  On a weak device every share falls under each
        object's next LOD, so the shares leave the first objects at their lowest LOD and
        hand the accumulated rest to the last, least-covering ones; greedy gives it to
        the objects that cover the most of the view (never over the budget).  The
        replay uses True.
    cap : (k,) int, optional
        The highest LOD each object may take this frame (its lowest available one is
        still taken where that is above): the replay's LOD hold
        (:func:`~walkstream.client.walk.lodhold.lod_caps`).  None: no cap.

    Returns
    -------
    Allocation

    Notes
    -----
    See the module docstring for the rule.  Objects with zero ACH get a zero share
    and therefore their lowest available LOD.  ``floor_limited`` is set when the
    lowest available LODs alone exceed ``budget``; the allocation then necessarily
    exceeds the budget.  Otherwise it can exceed it only by the lowest LODs of
    objects served after the budget ran out (see the module docstring).
    """
    what = "allocate_ach"
    a, t, av, vis = _inputs("ach", ach, tri, available, visible, what)
    b = _budget(budget, what)
    k = len(a)
    lod = np.full(k, NOT_DRAWN, np.int8)
    drawable = vis & av.any(axis=1)
    idx = np.flatnonzero(drawable)
    if len(idx) == 0:
        return _finish(lod, t, av, drawable, b)
    w = a[idx]
    total = float(w.sum())
    w = w / total if total > 0 else np.zeros_like(w)
    # descending ACH, ties by index (lexsort: last key is primary)
    order = np.lexsort((idx, -w))
    ws = w[order]
    # ACH of the objects not yet served, from a suffix sum rather than by subtracting
    # as we go, which would drift and could reach a tiny negative number.
    rest = np.cumsum(ws[::-1])[::-1].tolist()
    ids = idx[order]
    # cost of each LOD, infinite where not available, and the fallback (lowest) LOD
    cost = np.where(av[ids], t[ids], np.inf)
    low = _lowest_available(av[ids])
    if cap is not None:
        c = np.asarray(cap, np.int64).reshape(-1)
        if c.shape != (k,):
            raise InputError(f"{what}: cap: expected {k} values, got {c.shape[0]}")
        above = np.arange(_N_LODS)[None, :] > np.maximum(c[ids], low)[:, None]
        cost = np.where(above, np.inf, cost)  # a LOD over the cap is as if not built
    if reserve_floor:
        floor = cost[np.arange(len(ids)), low]
        cost = cost - floor[:, None]  # what moving up from the lowest LOD costs
        b = max(0.0, b - float(floor.sum()))
    if greedy:
        lod[ids] = _greedy(low.astype(np.int64), cost, ws, b)
        return _finish(lod, t, av, drawable, _budget(budget, what))
    c0, c1, c2 = (cost[:, level].tolist() for level in range(3))
    low_l = low.tolist()
    chosen_l = [0] * len(ids)
    n_rem = b
    served = 0
    for j, (wi, ri) in enumerate(zip(ws.tolist(), rest, strict=True)):
        if n_rem <= 0 or wi <= 0:
            break  # every later share is 0: done below, all at once
        share = n_rem if wi >= ri else n_rem * wi / ri  # the last one gets all that is left
        # a relative slack so that a share computed as, say, 299.99999999999994 still
        # fits a 300-triangle LOD it was meant to fit
        limit = share * (1.0 + 1e-12) + 1e-9
        if c2[j] <= limit:
            level, used = 2, c2[j]
        elif c1[j] <= limit:
            level, used = 1, c1[j]
        elif c0[j] <= limit:
            level, used = 0, c0[j]
        else:  # nothing fits: the lowest available LOD, so it stays visible
            level = low_l[j]
            used = (c0[j], c1[j], c2[j])[level]
        chosen_l[j] = level
        n_rem = n_rem - used if used < n_rem else 0.0
        served = j + 1
    chosen = np.asarray(chosen_l, dtype=np.int64)
    if served < len(ids):
        # shares of 0: the best LOD that costs nothing (rare), else the lowest available
        tail = cost[served:]
        free = tail <= 1e-9
        best_free = 2 - np.argmax(free[:, ::-1], axis=1)
        chosen[served:] = np.where(free.any(axis=1), best_free, low[served:])
    lod[ids] = chosen
    return _finish(lod, t, av, drawable, _budget(budget, what))


def _greedy(
    chosen: NDArray[np.int64], cost: NDArray[np.float64], ws: NDArray[np.float64], rest: float
) -> NDArray[np.int64]:
    """``chosen`` (objects in descending ACH ``ws``) with ``rest`` triangles spent on upgrades:
    each object with some ACH, in order, moves to its best LOD whose extra cost still fits."""
    out = chosen.copy()
    rows = cost.tolist()
    # no early stop once the budget is spent: a later object's upgrade that costs
    # nothing (LODs of equal triangles) is still taken, else such an object flips
    # between its LODs with the budget's slack frame to frame
    for j in np.flatnonzero(ws > 0).tolist():
        now = rows[j][out[j]]
        for level in (2, 1):
            extra = rows[j][level] - now
            if level > out[j] and extra <= rest + 1e-9:
                out[j] = level
                rest -= extra
                break
    return out


# --------------------------------------------------------------------------- distance


def _distance_lods(
    d: NDArray[np.float64], av: NDArray[np.bool_], d1: float, d2: float
) -> NDArray[np.int64]:
    """Wanted LOD per object by distance, moved to an available one (rows with none: any)."""
    want = np.where(d < d1, 2, np.where(d < d2, 1, 0)).astype(np.int64)
    return _nearest_available(want, av)


def _nearest_available(want: NDArray[np.int64], av: NDArray[np.bool_]) -> NDArray[np.int64]:
    """The highest available LOD not above ``want``, else the lowest available above it."""
    levels = np.arange(_N_LODS)
    below = av & (levels[None, :] <= want[:, None])
    has_below = below.any(axis=1)
    best_below = _N_LODS - 1 - np.argmax(below[:, ::-1], axis=1)
    above_first = np.argmax(av & (levels[None, :] > want[:, None]), axis=1)
    return np.where(has_below, best_below, above_first).astype(np.int64)


def allocate_distance(
    distance: ArrayLike,
    tri: ArrayLike,
    available: ArrayLike,
    visible: ArrayLike,
    thresholds: tuple[float, float],
    budget: float | None = None,
) -> Allocation:
    """The usual distance-based LOD selection, for comparison with :func:`allocate_ach`.

    Parameters
    ----------
    distance : (k,) float
        Distance from the eye to each object (the paper: to its centre), metres.
    tri, available, visible
        As for :func:`allocate_ach`.
    thresholds : (d1, d2)
        LOD2 for ``distance < d1``, LOD1 for ``d1 <= distance < d2``, LOD0 beyond
        (``0 <= d1 <= d2``).  When the wanted LOD is not available the highest
        available one below it is taken, else the lowest available above it.
    budget : float, optional
        Only to set ``floor_limited`` comparably with ACH allocation; it does not
        change the selection.

    Returns
    -------
    Allocation
    """
    what = "allocate_distance"
    d, t, av, vis = _inputs("distance", distance, tri, available, visible, what)
    d1, d2 = (float(v) for v in thresholds)
    if not (0.0 <= d1 <= d2) or math.isnan(d2):
        raise InputError(f"{what}: thresholds: expected 0 <= d1 <= d2, got {thresholds!r}")
    b = None if budget is None else _budget(budget, what)
    lod = np.full(len(d), NOT_DRAWN, np.int8)
    drawable = vis & av.any(axis=1)
    if drawable.any():
        lod[drawable] = _distance_lods(d[drawable], av[drawable], d1, d2)
    return _finish(lod, t, av, drawable, b)


def _cut_points(u: NDArray[np.float64]) -> NDArray[np.float64]:
    """Thresholds below, between and beyond sorted distinct distances ``u``.

    ``c[j]`` has exactly the ``j`` smallest distances below it (``d < c[j]``); cuts
    sit halfway between distances so that a small move does not flip a LOD.
    """
    below = u[0] / 2.0  # 0 when an object sits at the eye: then nothing is below
    beyond = u[-1] * 1.5 + 1.0
    return np.concatenate([[below], (u[:-1] + u[1:]) / 2.0, [beyond]])


def _best_fit(totals: NDArray[np.float64], budget: float) -> int:
    """Flat index of the largest total within budget, else of the smallest total."""
    flat = totals.reshape(-1)
    fits = flat <= budget
    if fits.any():
        return int(np.argmax(np.where(fits, flat, -np.inf)))
    return int(np.argmin(flat))


def distance_thresholds_for_budget(
    distance: ArrayLike,
    tri: ArrayLike,
    available: ArrayLike,
    visible: ArrayLike,
    budget: float,
    ratio: float | None = 2.0,
) -> tuple[float, float]:
    """Distance thresholds ``(d1, d2)`` whose selection best spends ``budget``.

    The total triangle count of :func:`allocate_distance` only changes where ``d1``
    or ``d2`` passes an object's distance.  Every such step is tried and the
    thresholds whose total comes closest to the budget without exceeding it are
    returned (placed halfway between object distances, so that a small move does
    not flip a LOD).  When even all-LOD0 exceeds the budget, the cheapest selection
    is returned.

    Parameters
    ----------
    distance, tri, available, visible
        As for :func:`allocate_distance`.
    budget : float
        Triangles to spend (>= 0).
    ratio : float or None
        ``d2 = ratio * d1`` (>= 1), the usual fixed proportion: one free parameter.
        ``None`` searches ``d1 <= d2`` independently, which gets closer to the budget
        (every pair is tried: O(k^2) for k objects).

    Returns
    -------
    (d1, d2) : (float, float)
    """
    what = "distance_thresholds_for_budget"
    d, t, av, vis = _inputs("distance", distance, tri, available, visible, what)
    b = _budget(budget, what)
    r = None if ratio is None else float(ratio)
    if r is not None and not (math.isfinite(r) and r >= 1.0):
        raise InputError(f"{what}: ratio: expected a finite number >= 1 or None, got {ratio!r}")
    drawable = vis & av.any(axis=1)
    d, t, av = d[drawable], t[drawable], av[drawable]
    if len(d) == 0:
        return 0.0, 0.0
    rows = np.arange(len(d))
    tri_at = [t[rows, _nearest_available(np.full(len(d), w, np.int64), av)] for w in range(3)]
    base = int(tri_at[0].sum())
    gain01 = tri_at[1] - tri_at[0]  # once d < d2
    gain12 = tri_at[2] - tri_at[1]  # once d < d1

    if r is None:
        u, inv = np.unique(d, return_inverse=True)
        cuts = _cut_points(u)
        # a[j]: gain of the objects with d < cuts[j], i.e. of the j nearest distances
        a01 = np.concatenate([[0], np.cumsum(np.bincount(inv, gain01, len(u)))]).round()
        a12 = np.concatenate([[0], np.cumsum(np.bincount(inv, gain12, len(u)))]).round()
        totals = base + a12[:, None] + a01[None, :]  # [j1, j2]
        j1s, j2s = np.indices(totals.shape)
        # d1 <= d2 only: elsewhere a total the thresholds cannot give
        totals = np.where(j1s <= j2s, totals, np.inf)
        j1, j2 = np.unravel_index(_best_fit(totals, b), totals.shape)
        return float(cuts[j1]), float(cuts[j2])

    # d1 alone: LOD0 -> LOD1 once d1 > d / ratio, LOD1 -> LOD2 once d1 > d
    pos = np.concatenate([d / r, d])
    gain = np.concatenate([gain01, gain12])
    u, inv = np.unique(pos, return_inverse=True)
    cuts = _cut_points(u)
    totals = base + np.concatenate([[0], np.cumsum(np.bincount(inv, gain, len(u)))]).round()
    j = _best_fit(totals, b)
    d1 = float(cuts[j])
    return d1, d1 * r
