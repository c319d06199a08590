"""The LOD hold (client/walk/lodhold.py): a building at a steady pose does not flip its LOD with the budget,
and the hold holds nothing when the budget does not bind."""

from __future__ import annotations

from collections import deque
from types import SimpleNamespace
from typing import Any

import numpy as np

from walkstream.client.draw.allocate import allocate_ach
from walkstream.client.walk.figures import WalkFrames
from walkstream.client.walk.lodhold import (
    best_triangles,
    held_budget,
    held_share,
    lod_caps,
    note_lod_changes,
)

# four buildings in descending ACH; the last a far one of a few pixels
ACH = np.array([0.5, 0.3, 0.15, 0.05])
TRI = np.array([[12, 240, 2000], [12, 200, 1500], [12, 160, 1200], [12, 90, 400]], np.int64)
AVAIL = np.ones((4, 3), bool)


def _hold_walk(hold_s: float) -> Any:
    """A walk's state for the hold over the four buildings above."""
    geoms = [SimpleNamespace(id=i) for i in (7, 8, 9, 10)]
    return SimpleNamespace(config=SimpleNamespace(lod_hold_s=hold_s), lod_since={}, lod_budgets=deque(),
                           objects=SimpleNamespace(geoms=geoms))


def _frame(w: Any, k: int, budget: int, own: int) -> Any:
    """Frame ``k`` at 25 fps allocated as the walk does (:func:`held_share`): the
    controller's ``budget``, of which the draws before the objects left ``own``."""
    f: Any = SimpleNamespace(wt=0.04 * k, alloc=None, budget=budget)
    share, caps = held_share(w, f, own, TRI, AVAIL, np.ones(4, bool))
    f.alloc = allocate_ach(ACH, TRI, AVAIL, np.ones(4, bool), share, reserve_floor=True, greedy=True, cap=caps)
    note_lod_changes(w, f)
    return f


def _walk(hold_s: float, frames: int = 50) -> tuple[WalkFrames, list[int], list[int]]:
    """A steady pose at 25 fps whose objects' share swings by 150 triangles every other
    frame (the facade bake's share on ``pda``) under a steady budget: the objects' LOD
    changes, the triangles and the objects' shares of the frames."""
    w = _hold_walk(hold_s)
    fr = WalkFrames()
    tris, budgets = [], []
    for k in range(frames):
        own = 560 if k % 2 else 410
        f = _frame(w, k, 600, own)
        fr.note_lods(f.wt, np.array([g.id for g in w.objects.geoms]), f.alloc.lod.astype(np.int64))
        tris.append(f.alloc.triangles)
        budgets.append(own)
    return fr, tris, budgets


def test_a_building_at_a_steady_pose_does_not_flip_with_the_budget() -> None:
    free, _, _ = _walk(0.0)
    assert free.lod_flips >= 40  # without the hold the far building flips every frame
    held, tris, budgets = _walk(1.0)
    assert held.lod_changes <= 2  # down once, up again after the hold at most
    assert all(t <= b for t, b in zip(tris, budgets, strict=True))  # never over the budget
    figs = held.lod_figures()
    assert figs["lod_changes_per_object_s"] < free.lod_figures()["lod_changes_per_object_s"] / 10


def test_a_cap_keeps_an_object_at_or_below_it_but_never_below_its_lowest() -> None:
    a = allocate_ach(ACH, TRI, AVAIL, np.ones(4, bool), 10_000, reserve_floor=True, greedy=True,
                     cap=np.array([2, 1, 0, -1]))
    assert a.lod.tolist() == [2, 1, 0, 0]


def test_an_upgrade_that_costs_nothing_is_taken_after_the_budget_ran_out() -> None:
    tri = np.array([[12, 240, 2000], [2, 2, 2]], np.int64)
    a = allocate_ach([0.9, 0.1], tri, np.ones((2, 3), bool), np.ones(2, bool), 300, reserve_floor=True, greedy=True)
    assert a.lod.tolist() == [1, 2]


def test_the_held_budget_falls_at_once_and_rises_after_the_hold() -> None:
    w: Any = SimpleNamespace(config=SimpleNamespace(lod_hold_s=1.0), lod_budgets=deque())
    got = [held_budget(w, SimpleNamespace(wt=0.04 * k), b) for k, b in enumerate([500, 400, 600] + [600] * 30)]
    assert got[:3] == [500, 400, 400]
    assert got[24] == 400 and got[28] == 600  # the 400 of 0.04 s leaves the 1 s window at about 1.04 s


def test_a_slack_budget_rises_to_the_best_lods_at_once_despite_the_hold() -> None:
    best = best_triangles(TRI, AVAIL, np.ones(4, bool))
    assert best == 5100
    w = _hold_walk(1.0)
    # everything fits, then one frame the budget binds (a dip of the controller's budget,
    # then a facade bake's), then everything fits again
    steps = [(6000, 6000)] * 5 + [(3000, 3000)] + [(6000, 6000)] * 5 + [(6000, 3000)] + [(6000, 6000)] * 5
    lods = [_frame(w, k, b, own).alloc.lod.tolist() for k, (b, own) in enumerate(steps)]
    assert lods[5] != [2, 2, 2, 2] and lods[11] != [2, 2, 2, 2]  # the dips bind
    assert all(lods[k] == [2, 2, 2, 2] for k in (6, 7, 12, 13))  # and the next frame rises at once
    assert held_budget(w, SimpleNamespace(wt=0.04 * len(steps)), 0) == -3000  # the bake's cut is still held


def test_a_binding_budget_holds_the_cut_not_the_controllers_climb() -> None:
    w = _hold_walk(1.0)
    # the controller climbs from its low start, everything short of the best LODs:
    # the objects get each frame's own share at once (not the climb's foot for a second)
    climb = [_frame(w, k, b, b - 10).alloc.triangles for k, b in enumerate([500, 1000, 2000, 4000])]
    assert climb[-1] > 2000
    # a cut of 190 (a facade bake) on one frame is held for the hold's second
    f = _frame(w, 4, 4000, 3810)
    after = [_frame(w, k, 4000, 3990) for k in range(5, 10)]
    assert all(g.alloc.triangles <= 3810 for g in [f, *after])


def test_a_fall_holds_a_rise_back_but_a_rise_may_rise_on() -> None:
    w = _hold_walk(1.0)
    for k, lods in enumerate([[0, 0, 0, 0], [1, 2, 0, 0]]):  # first drawn, then two rise
        note_lod_changes(w, SimpleNamespace(wt=0.04 * k, alloc=SimpleNamespace(lod=np.array(lods, np.int8))))
    assert lod_caps(w, SimpleNamespace(wt=0.08)).tolist() == [2, 2, 2, 2]  # a rise is no flip: free
    note_lod_changes(w, SimpleNamespace(wt=0.08, alloc=SimpleNamespace(lod=np.array([1, 1, 0, 0], np.int8))))
    assert lod_caps(w, SimpleNamespace(wt=0.12)).tolist() == [2, 1, 2, 2]  # the fall: no rise back
    assert lod_caps(w, SimpleNamespace(wt=1.12)).tolist() == [2, 2, 2, 2]  # until the hold is over
