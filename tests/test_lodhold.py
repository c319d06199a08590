"""The LOD hold (client/walk/lodhold.py): a building at a steady pose does not flip its LOD with the budget."""

from __future__ import annotations

from collections import deque
from types import SimpleNamespace
from typing import Any

import numpy as np

from walkstream.client.draw.allocate import allocate_ach
from walkstream.client.walk.figures import WalkFrames
from walkstream.client.walk.lodhold import held_budget, lod_caps, note_lod_changes

# four buildings in descending ACH; the last a far one of a few pixels
ACH = np.array([0.5, 0.3, 0.15, 0.05])
TRI = np.array([[12, 240, 2000], [12, 200, 1500], [12, 160, 1200], [12, 90, 400]], np.int64)
AVAIL = np.ones((4, 3), bool)


def _walk(hold_s: float, frames: int = 50) -> tuple[WalkFrames, list[int], list[int]]:
    """A steady pose at 25 fps whose budget swings by 150 triangles every other frame
    (the facade bake's share on ``pda``): the objects' LOD changes, the triangles and
    the budgets of the frames."""
    geoms = [SimpleNamespace(id=i) for i in (7, 8, 9, 10)]
    w: Any = SimpleNamespace(config=SimpleNamespace(lod_hold_s=hold_s), lod_since={}, lod_budgets=deque(),
                             objects=SimpleNamespace(geoms=geoms))
    fr = WalkFrames()
    tris, budgets = [], []
    for k in range(frames):
        f: Any = SimpleNamespace(wt=0.04 * k, alloc=None)
        budget = 560 if k % 2 else 410
        f.alloc = allocate_ach(ACH, TRI, AVAIL, np.ones(4, bool), held_budget(w, f, budget), reserve_floor=True,
                               greedy=True,
                               cap=lod_caps(w, f))
        note_lod_changes(w, f)
        fr.note_lods(f.wt, np.array([g.id for g in geoms]), f.alloc.lod.astype(np.int64))
        tris.append(f.alloc.triangles)
        budgets.append(budget)
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
