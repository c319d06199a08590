"""Whole-pixel rectangles hold the pixels whose centres a projection may cover, no more."""

from __future__ import annotations

import numpy as np
import pytest

from walkstream.shared import screenrects
from walkstream.shared.camera import camera, perspective
from walkstream.shared.partcull import cull_boxes
from walkstream.shared.screenrects import BOX_EDGES, CENTRE_MARGIN_PX, TOUCH_MARGIN_PX, ndc_pixels

SIZE = (10, 10)


def _rect(x0: float, x1: float) -> list[int]:
    """The rectangle of a span ``x0 .. x1`` in pixel coordinates (and the same in y)."""
    lo = np.array([[x0, x0]]) / 5.0 - 1.0
    hi = np.array([[x1, x1]]) / 5.0 - 1.0
    return ndc_pixels(lo, hi, SIZE)[0].tolist()


def test_a_span_holds_the_pixels_whose_centres_it_covers() -> None:
    assert _rect(3.2, 3.8) == [3, 3, 3, 3]  # the centre 3.5 only
    assert _rect(3.2, 6.9) == [3, 3, 6, 6]  # centres 3.5 .. 6.5; 7.5 is beyond 6.9
    assert _rect(-4.0, 20.0) == [-4, -4, 19, 19]  # unclamped, as before


def test_a_sliver_between_two_centres_is_empty() -> None:
    x0, x1 = _rect(3.7, 4.3)[0::2]  # touches pixels 3 and 4, covers neither centre
    assert x0 > x1
    # within the margin of a centre: kept (float32 transforms, sub-pixel snapping)
    x0, x1 = _rect(3.5 + 0.9 * CENTRE_MARGIN_PX, 4.3)[0::2]
    assert (x0, x1) == (3, 3)


def test_a_box_between_pixel_centres_is_culled_and_a_box_over_one_is_kept() -> None:
    eye = np.array([0.0, 0.0, 1.6])
    view = camera(eye, 0.0, 0.0).astype(np.float64)
    proj = perspective(60.0, 160 / 120, 0.1, 100.0).astype(np.float64)
    whole = np.array([[0, 0, 159, 119]])
    # 1 mm at 10 m straight ahead: it projects onto the corner of four pixels
    tiny = cull_boxes([[10.0, -0.0005, 1.5995]], [[10.001, 0.0005, 1.6005]], whole, eye, view, proj, (160, 120))
    assert not tiny[0]
    # 20 cm there covers centres
    small = cull_boxes([[10.0, -0.1, 1.5]], [[10.001, 0.1, 1.7]], whole, eye, view, proj, (160, 120))
    assert small[0]


def test_a_few_clipped_sets_in_plain_floats_give_numpys_rectangles(monkeypatch: pytest.MonkeyPatch) -> None:
    """A frame clips a handful of sets in plain Python floats and many with numpy: the
    same rectangles to the pixel, portals (4 vertices) and boxes (8), at both margins."""
    proj = perspective(60.0, 4 / 3, 0.1, 100.0).astype(np.float64)
    rng = np.random.default_rng(0)
    quad = np.stack([np.arange(4), (np.arange(4) + 1) % 4], axis=1)
    for k, edges in ((4, quad), (8, BOX_EDGES)):
        for _ in range(150):
            m = int(rng.integers(1, 12))
            v = rng.normal(0.0, 1.0, (3, k, m))
            v[2] = rng.uniform(-2.0, 0.5, (k, m))  # most sets straddle the clip plane
            margin = float(rng.choice([CENTRE_MARGIN_PX, TOUCH_MARGIN_PX]))
            monkeypatch.setattr(screenrects, "_FEW", 0)
            many = screenrects._clipped(v, -v[2], edges, proj, (640, 480), 0.03, margin)
            monkeypatch.setattr(screenrects, "_FEW", 100)
            few = screenrects._clipped(v, -v[2], edges, proj, (640, 480), 0.03, margin)
            assert np.array_equal(many[0], few[0]) and np.array_equal(many[1], few[1])


def test_a_crossing_sets_unclipped_rectangle_holds_its_clipped_one() -> None:
    """:func:`~walkstream.shared.screenrects.crossing_rects` (no clipping) holds the exact
    clipped rectangle of every box and portal that crosses the clip plane, and is not
    everything: sets beside or behind the eye fall wholly off the viewport."""
    proj = perspective(60.0, 4 / 3, 0.1, 100.0).astype(np.float64)
    view = camera(np.array([0.0, 0.0, 1.6]), 0.3, -0.1).astype(np.float64)
    size = (640, 480)
    rng = np.random.default_rng(5)
    quad = np.stack([np.arange(4), (np.arange(4) + 1) % 4], axis=1)
    off = 0
    for k, edges in ((4, quad), (8, BOX_EDGES)):
        pts = rng.normal(0.0, 1.0, (3, k, 600)) + np.array([0.0, 0.0, 1.6])[:, None, None]
        pts += rng.normal(0.0, 1.5, (3, 1, 600))  # sets scattered around the eye
        exact, front, near, _far = screenrects.rects_ckm(pts, edges, view, proj, size, 0.03)
        loose, front2, _n, _f = screenrects.rects_ckm(pts, edges, view, proj, size, 0.03, clip_rest=False)
        cross = front & (near < 0.03)
        assert cross.sum() > 100 and np.array_equal(front, front2)
        assert np.array_equal(exact[:, ~cross], loose[:, ~cross])
        e, lo = exact[:, cross], loose[:, cross]
        shows = (e[0] <= e[2]) & (e[1] <= e[3])  # an exact rectangle with no pixel centre needs no holding
        assert np.all((lo[:2, shows] <= e[:2, shows]) & (lo[2:, shows] >= e[2:, shows]))
        off += int(np.sum((lo[2] < 0) | (lo[0] >= size[0]) | (lo[3] < 0) | (lo[1] >= size[1])))
    assert off > 20
