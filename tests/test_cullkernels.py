"""The compiled box test (shared/cullkernels.py) makes numpy's figures exactly.

:func:`~walkstream.shared.cullkernels.box_kernel` repeats, box by box, the IEEE
operations of :func:`~walkstream.shared.screenrects.box_rects_ckm` (the two corners'
sums; a box across the clip plane gets :func:`~walkstream.shared.screenrects.crossing_rects`'
superset) and of :func:`~walkstream.shared.portals.box_distance` (the fog), in the same
order: its rectangles, depths, fog test and verdicts must be those of the numpy
functions, bit for bit, on random boxes and poses (boxes flat, behind the eye, across
the clip plane, beyond the fog).  The walk's kernel is checked against the reference walk
in tests/test_portalwalk.py.
"""

from __future__ import annotations

import math

import numpy as np

from walkstream.shared.camera import camera, perspective
from walkstream.shared.cullkernels import box_kernel
from walkstream.shared.partcull import near_far
from walkstream.shared.portals import box_distance
from walkstream.shared.screenrects import box_rects_ckm, camera_rows

SIZE = (320, 240)
PROJ = perspective(60.0, SIZE[0] / SIZE[1], 0.1, 30.0).astype(np.float64)


def test_box_kernel_makes_numpys_rectangles_depths_and_verdicts() -> None:
    rng = np.random.default_rng(11)
    n = 600
    lo = rng.uniform(-8.0, 8.0, (n, 3))
    hi = lo + rng.uniform(0.0, 3.0, (n, 3))
    hi[:50, 0] = lo[:50, 0]  # flat boxes (a portal, a floor slab seen edge-on)
    lohi = np.ascontiguousarray(np.stack([lo.T, hi.T], axis=1))
    # two cells: the first half of the boxes seen through two VSAs, the rest through one
    cells_first, cells_count = np.array([0, n // 2]), np.array([n // 2, n - n // 2])
    vsas = np.array([[0, 0, 100, 80], [150, 60, 319, 239], [40, 30, 260, 200]], np.int64)
    vsa_first, vsa_count = np.array([0, 2]), np.array([2, 1])
    owner = np.repeat([0, 1], cells_count)
    near_plane, far_plane = near_far(PROJ)  # type: ignore[misc]
    crossed = behind = fogged = kept = 0
    for i in range(12):
        eye = rng.uniform(-3.0, 3.0, 3)
        view = camera(eye, float(rng.uniform(-math.pi, math.pi)), float(rng.uniform(-0.6, 0.6))).astype(np.float64)
        fog = math.inf if i % 2 else 7.0
        rows, shift = camera_rows(view, PROJ)
        keep, projected, rect, near, far = box_kernel(
            lo, hi, cells_first, cells_count, vsas, vsa_first, vsa_count, eye, fog, rows, shift, SIZE[0], SIZE[1],
            0.125, 0.03, True, near_plane, far_plane, True)
        want_rect, front, want_near, want_far = box_rects_ckm(lohi, view, PROJ, SIZE, 0.03, clip_rest=False)
        within = box_distance(lo, hi, eye) <= fog
        assert np.array_equal(projected, within), i
        p = np.flatnonzero(within)
        assert np.array_equal(rect[:, p], want_rect[:, p]), i
        assert np.array_equal(near[p], want_near[p]) and np.array_equal(far[p], want_far[p]), i
        meet = np.zeros(n, bool)
        for c in (0, 1):
            for v in vsas[vsa_first[c]: vsa_first[c] + vsa_count[c]]:
                meet |= (owner == c) & (np.maximum(want_rect[0], v[0]) <= np.minimum(want_rect[2], v[2])) & (
                    np.maximum(want_rect[1], v[1]) <= np.minimum(want_rect[3], v[3]))
        want = within & front & meet & (want_far >= near_plane) & (want_near <= far_plane)
        assert np.array_equal(keep, want), i
        crossed += int((within & (want_near < 0.03) & (want_far >= 0.03)).sum())
        behind += int((within & ~front).sum())
        fogged += int((~within).sum())
        kept += int(want.sum())
    assert crossed > 20 and behind > 100 and fogged > 100 and kept > 100  # every case was compared
