"""A cell's PVS within a pixel budget per view (``walkstream bake --pvs-budget``).

A PVS that holds every object any sample point sees at any pixel holds, beside what
matters, many objects that cover a pixel or two from somewhere in the cell: far
buildings peeking over roofs, slivers beside nearer facades.  A PVS that leaves all of
them out misses what a walker sees where the one point that saw a building well
stood.  The budget decides by *views*: each sample point's six cube faces are one view
and, with ``--far-band``, each band point's band another, and an object may be left
out only while, in every view, the pixels of all the objects left out stay within
``budget`` of that view's object pixels.  The objects are tried least-seen first, by
their largest share of any one view, so an object seen well from one point and hardly
from the rest is kept, where a budget on the pixels pooled over the cell would drop it
(large in one view, it is small in the sum of many).

Every view's loss within the budget bounds what the cell's own samples lose: pooled
over the points (as ``bench visibility`` pools its reference's) and for the worst
single object, both at most ``budget``; and a view of the band is the client's pixel
size around the horizon, where the far field is.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from walkstream.server.bake.farband import merge_band_counts
from walkstream.server.bake.settings import BakeSettings
from walkstream.shared.arrays import I64

__all__ = ["View", "budget_drops", "pool_views", "within_budget"]

View = tuple[I64, I64]
"""One view's ``(ids, pixels)``: the ids it sees (ascending) and the pixels of each."""


def budget_drops(views: Sequence[View], budget: float) -> I64:
    """The objects a cell's PVS may leave out: the least-seen first, while every view's loss stays within ``budget``.

    Parameters
    ----------
    views:
        Per view, the ids it sees and their pixels (:data:`View`).
    budget:
        The share of a view's object pixels the objects left out may cover together
        (0: none left out).

    Returns
    -------
    (k,) int64
        The ids left out, ascending.

    >>> a = (np.array([1, 2, 3]), np.array([9_990, 6, 4]))
    >>> b = (np.array([1, 2]), np.array([100, 900]))
    >>> budget_drops([a, b], 0.001).tolist()  # 2 is 90 % of view b: kept; 3 is 0.04 % of a
    [3]
    """
    if budget <= 0.0 or not views:
        return np.zeros(0, np.int64)
    u = np.unique(np.concatenate([np.asarray(ids, np.int64) for ids, _ in views]))
    share = np.zeros((len(views), len(u)))
    for v, (ids, px) in enumerate(views):
        total = float(np.sum(px))
        if total > 0:
            share[v, np.searchsorted(u, ids)] = np.asarray(px, np.float64) / total
    order = np.argsort(share.max(axis=0), kind="stable")
    fits = np.all(np.cumsum(share[:, order], axis=1) <= budget, axis=0)
    n = len(u) if fits.all() else int(np.argmin(fits))
    return np.sort(u[order[:n]])


def pool_views(views: Sequence[View]) -> View:
    """Pixels per object summed over ``views``: what one render of all of them counts."""
    if not views:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    ids = np.concatenate([np.asarray(i, np.int64) for i, _ in views])
    px = np.concatenate([np.asarray(p, np.int64) for _, p in views])
    u, inv = np.unique(ids, return_inverse=True)
    return u, np.bincount(inv, weights=px, minlength=len(u)).astype(np.int64)


def within_budget(cube: Sequence[View], band: Sequence[View], settings: BakeSettings) -> View:
    """A cell's counts, as the bake pools them, less the objects :func:`budget_drops` leaves out.

    ``cube`` holds one view per sample point (its six faces), ``band`` one per band
    point (empty without ``--far-band``); the band's pixels are added scaled to the
    cube's pixel size (:func:`~.farband.merge_band_counts`).
    """
    ids, px = pool_views(cube)
    if band:
        ids, px = merge_band_counts(ids, px, *pool_views(band), settings)
    keep = ~np.isin(ids, budget_drops([*cube, *band], settings.pvs_budget))
    return ids[keep], px[keep]
