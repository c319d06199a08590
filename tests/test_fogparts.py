"""The fog chosen by the triangle budget indoors and the parts it cuts (``client/walk/allocate.py``)."""

from __future__ import annotations

import numpy as np

from walkstream.client.walk.allocate import fog_for_budget, kept_distances
from walkstream.shared.portals import box_distance


def _scene(rng: np.random.Generator) -> tuple[dict[int, np.ndarray], dict[int, tuple[np.ndarray, np.ndarray]],
                                              dict[int, np.ndarray]]:
    masks, boxes, tris = {}, {}, {}
    for cid in (7, 3, 11, 5):  # not in id order: the cells' order is the masks'
        n = int(rng.integers(0, 40))
        lo = rng.uniform(-30.0, 30.0, (n, 3))
        boxes[cid] = (lo, lo + rng.uniform(0.0, 3.0, (n, 3)))
        masks[cid] = rng.random(n) < 0.6
        tris[cid] = rng.integers(1, 400, n)
    return masks, boxes, tris


def test_the_fog_is_chosen_on_the_kept_parts_and_cuts_them_as_their_full_distances_do() -> None:
    rng = np.random.default_rng(24)
    eye = np.array([1.0, -2.0, 1.6])
    cut = 0
    for budget in (0, 500, 2000, 8000, 10**6):
        masks, boxes, tris = _scene(rng)
        kept = kept_distances(masks, boxes, eye)
        assert list(kept) == [c for c in masks if masks[c].any()]
        for cid, (idx, d) in kept.items():
            assert idx.tolist() == np.flatnonzero(masks[cid]).tolist()
            assert np.array_equal(d, box_distance(*boxes[cid], eye)[idx])  # each box's own distance
        fog = fog_for_budget(masks, boxes, {}, eye, budget, 40.0, tris, kept=kept)
        assert fog == fog_for_budget(masks, boxes, {}, eye, budget, 40.0, tris)
        assert 2.0 <= fog <= 40.0
        # what the frame draws: the kept parts within the fog, by their full arrays' distances
        want = {c: m & (box_distance(*boxes[c], eye) <= fog) for c, m in masks.items()}
        for cid, (idx, d) in kept.items():
            masks[cid][idx[d > fog]] = False
        assert all(np.array_equal(masks[c], want[c]) for c in masks)
        drawn = sum(int(tris[c][masks[c]].sum()) for c in masks)
        assert drawn <= budget or fog == 2.0 or fog == 40.0
        cut += fog < 40.0
    assert cut >= 2  # the budget moved the fog on some of them
    assert kept_distances({1: np.zeros(3, bool)}, {1: (np.zeros((3, 3)), np.ones((3, 3)))}, eye) == {}
