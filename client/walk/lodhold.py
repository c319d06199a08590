"""Part of the frame step ``allocate``: the LOD hold, so that a building's LOD does not flip frame to frame.

The greedy ACH allocation (:func:`~walkstream.client.draw.allocate.allocate_ach`) hands
what the budget leaves after the objects of most ACH to the ones after them: far
buildings of a few pixels.  The objects' share of the budget swings by a few hundred
triangles frame to frame on ``pda`` (the facade bake's triangles and the impostors'
quads come off it first, on some frames and not others), and that slack moved such a
building between LOD 0 and 1 every few frames, each change a pop of its own (issue 27:
about 0.044 of the switching pixels' colour).  Two rules, both ``config.lod_hold_s``
long (0: neither; :func:`hold_seconds`), and both only while the budget binds
(:func:`held_share`):

- the allocation gets the frame's budget less the most that was drawn before the
  objects (the facade bake, the impostors' and facades' quads, the rooms) over the last
  ``hold_s`` (:func:`held_budget` of that cut): the swing those draws give the objects'
  share is held, the budget controller's own moves pass at once, and it is never more
  than the frame's own share;
- an object whose LOD fell less than ``hold_s`` ago may not rise (:func:`lod_caps`,
  :func:`note_lod_changes`): the ACH order changing (a new cell's ACH, an object coming
  into view) and the controller's budget falling move an object down and back once a
  hold at most, never over the budget; an object that rose may rise on (no flip).

A frame whose own share draws every visible object at its best LOD gets that share and
no caps, so the objects rise at once.  Why both limits: on ``desktop2003`` (the demo's
device) the budget moves about 8 % around what the view's best LODs need; the first
rule as it was (the low water of the whole share) kept the objects below LOD 2 for a
second after each dip even on frames where everything fit, and at the walk's start it
held the controller's climb to its level at the climb's foot, where the controller,
seeing the same triangle count frame after frame, could not learn what a triangle
costs and crept up for 3 s instead of 10 frames, and the second rule as it was (no
rise for a hold after any change) stopped each object at the LOD it first rose to
(issue 27: all-LOD 2 frames 67 -> 30 %, pixels visibly wrong 0.10 -> 0.57 % of the
frame on the demo's SE, 40 s at 320 x 240, against no hold).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from walkstream.client.walk.state import Frame, WalkState

__all__ = ["HOLD_S", "best_triangles", "held_budget", "held_share", "hold_seconds", "lod_caps", "note_lod_changes"]

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
    """The least of ``budget`` over the last ``config.lod_hold_s`` of walk time
    (``budget`` itself with the hold off): it falls at once and rises only when the rise
    has lasted.  :func:`held_share` takes it of the objects' share less the frame's
    budget (minus what was drawn before the objects), so the most of that cut."""
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


def best_triangles(tri: NDArray[np.int64], avail: NDArray[np.bool_], seen: NDArray[np.bool_]) -> int:
    """The triangles of every seen object (``seen`` ``(k,)``) that has some LOD
    (``avail`` ``(k, 3)``) at its highest available one (``tri`` ``(k, 3)``): what the
    allocation draws when the budget cuts nothing."""
    drawable = seen & avail.any(axis=1)
    if not drawable.any():
        return 0
    best = avail.shape[1] - 1 - np.argmax(avail[drawable, ::-1], axis=1)
    return int(tri[drawable][np.arange(len(best)), best].sum())


def held_share(
    w: WalkState, f: Frame, own: int, tri: NDArray[np.int64], avail: NDArray[np.bool_], seen: NDArray[np.bool_],
) -> tuple[int, NDArray[np.int64] | None]:
    """The objects' budget and LOD caps the allocation gets this frame, from the frame's
    budget ``f.budget`` and the objects' own share of it ``own`` (what the facade bake,
    the quads and the rooms left): ``(own, None)`` when ``own`` draws every seen object
    at its best LOD (:func:`best_triangles`), else ``f.budget`` less the most those draws
    took over the hold (:func:`held_budget`; never above ``own``) and :func:`lod_caps`.

    Why the test tells a binding budget from a slack one: with ``own`` at or above the
    best LODs' triangles the allocation cuts nothing, so a swing above that line changes
    no LOD and there is nothing to hold; a hold from an earlier dip would only keep
    objects below the LOD they fit now.  Below the line the swing decides which objects
    drop, and the hold keeps that choice steady.  The cut is noted on every frame, so a
    dip that follows a slack frame still meets it.  Why the cut and not the whole share:
    the share's swing frame to frame is the cut's (the facade bake on some frames and not
    others); the controller's budget moves slowly, and holding it held back its own
    climb (the module docstring)."""
    cut = held_budget(w, f, own - f.budget)  # minus the most drawn before the objects
    if own >= best_triangles(tri, avail, seen):
        return own, None
    return max(0, min(own, f.budget + cut)), lod_caps(w, f)


def lod_caps(w: WalkState, f: Frame) -> NDArray[np.int64] | None:
    """``(k,)`` the highest LOD each of the walk's objects (``w.objects.geoms``) may take
    this frame: its LOD where that fell less than ``config.lod_hold_s`` before the
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
    """Note each drawn object's LOD and, where it fell, the frame's walk time
    (``w.lod_since``; first drawn or risen: ``-inf``, nothing to hold), after the
    allocation and its blend hold."""
    if hold_seconds(w) <= 0 or f.alloc is None:
        return
    since = w.lod_since
    for g, lod in zip(w.objects.geoms, f.alloc.lod.tolist(), strict=False):
        if lod < 0:
            continue
        was = since.get(g.id)
        if was is None:
            since[g.id] = (lod, -np.inf)  # first drawn: nothing to hold it against
        elif lod < was[0]:
            since[g.id] = (lod, f.wt)  # a fall: no rise back for the hold
        elif lod > was[0]:
            since[g.id] = (lod, -np.inf)  # a rise: a further rise is no flip (the climb at the start)
