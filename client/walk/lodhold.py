"""Part of the frame step ``allocate``: the LOD hold, so that a building's LOD does not flip frame to frame.

The greedy ACH allocation (:func:`~walkstream.client.draw.allocate.allocate_ach`) hands
what the budget leaves after the objects of most ACH to the ones after them: far
buildings of a few pixels.  The objects' share of the budget swings by a few hundred
triangles frame to frame on ``pda`` (the facade bake's triangles and the impostors'
quads come off it first, on some frames and not others), and that slack moved such a
building between LOD 0 and 1 every few frames, each change a pop of its own (issue 27:
about 0.044 of the switching pixels' colour).  Two rules, both ``config.lod_hold_s``
long (0: neither; :func:`hold_seconds`):

- the allocation gets the least of the objects' share over the last ``hold_s``
  (:func:`held_budget`): it falls at once with the budget and rises only when the rise
  has lasted, and it is never more than the frame's own share;
- an object whose LOD changed less than ``hold_s`` ago may only go down (:func:`lod_caps`,
  :func:`note_lod_changes`): the ACH order changing (a new cell's ACH, an object coming
  into view) moves an object once a hold at most, never over the budget.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from walkstream.client.walk.state import Frame, WalkState

__all__ = ["HOLD_S", "held_budget", "hold_seconds", "lod_caps", "note_lod_changes"]

HOLD_S = 1.0
"""The hold on a simulated device unless ``--lod-hold`` says otherwise."""


def hold_seconds(w: WalkState) -> float:
    """The walk's hold: ``config.lod_hold_s``, or where that is None :data:`HOLD_S` on a
    simulated device and 0 on ``gl`` (its budget follows the real frame time, and holding
    the low water of a facade bake's frame there kept LOD2 from the look-alike boxes)."""
    hold = w.config.lod_hold_s
    if hold is not None:
        return float(hold)
    return HOLD_S if getattr(w.device, "simulated", False) else 0.0


def held_budget(w: WalkState, f: Frame, budget: int) -> int:
    """The objects' ``budget`` the allocation gets: the least of it over the last
    ``config.lod_hold_s`` of walk time (``budget`` itself with the hold off).  The
    frame's own share swings by the facade bake's and the impostors' quads frame to
    frame; the low water of the last second does not, so what it leaves the far
    buildings stays put, and it is never more than the frame's own."""
    hold = hold_seconds(w)
    if hold <= 0:
        return budget
    lows = w.lod_budgets
    while lows and lows[0][0] <= f.wt - hold:
        lows.popleft()
    while lows and lows[-1][1] >= budget:  # the least of the window at lows[0]: a rising
        lows.pop()  # budget leaves nothing behind it that could be the least later
    lows.append((f.wt, budget))
    return int(lows[0][1])


def lod_caps(w: WalkState, f: Frame) -> NDArray[np.int64] | None:
    """``(k,)`` the highest LOD each of the walk's objects (``w.objects.geoms``) may take
    this frame: its LOD where that changed less than ``config.lod_hold_s`` before the
    frame's walk time, else 2; None with the hold off (0) or nothing held."""
    hold = hold_seconds(w)
    if hold <= 0 or not w.lod_since:
        return None
    since = w.lod_since
    caps = np.full(len(w.objects.geoms), 2, np.int64)
    for k, g in enumerate(w.objects.geoms):
        held = since.get(g.id)
        if held is not None and f.wt - held[1] < hold:
            caps[k] = held[0]
    return caps


def note_lod_changes(w: WalkState, f: Frame) -> None:
    """Note each drawn object's LOD and, where it changed (or first drawn), the frame's
    walk time (``w.lod_since``), after the allocation and its blend hold."""
    if hold_seconds(w) <= 0 or f.alloc is None:
        return
    since = w.lod_since
    for g, lod in zip(w.objects.geoms, f.alloc.lod.tolist(), strict=False):
        if lod < 0:
            continue
        was = since.get(g.id)
        if was is None:
            since[g.id] = (lod, -np.inf)  # first drawn: nothing to hold it against
        elif was[0] != lod:
            since[g.id] = (lod, f.wt)
