"""Tests for server.sources.partywalls.find_party_walls."""

from __future__ import annotations

import time

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from walkstream.server.sources.partywalls import find_party_walls
from walkstream.shared.errors import InputError


def box(x0: float, y0: float, x1: float, y1: float) -> np.ndarray:
    """Counter-clockwise axis-aligned box, (4, 2) float64."""
    return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], dtype=np.float64)


def test_full_shared_edge_gets_neighbour_height_on_that_edge_only() -> None:
    rings, hts = find_party_walls([[box(0, 0, 10, 10)], [box(10, 0, 20, 10)]], [12.0, 7.0])
    np.testing.assert_array_equal(rings[0][0], box(0, 0, 10, 10))
    np.testing.assert_array_equal(rings[1][0], box(10, 0, 20, 10))
    # Edge 1 of A is x=10 going up; edge 3 of B is x=10 going down.
    np.testing.assert_array_equal(hts[0][0], [0, 7, 0, 0])
    np.testing.assert_array_equal(hts[1][0], [0, 0, 0, 12])
    assert all(r.dtype == np.float64 for b in rings for r in b)


def test_half_shared_edge_is_split_and_only_shared_half_gets_height() -> None:
    rings, hts = find_party_walls([[box(0, 0, 10, 10)], [box(10, 0, 20, 5)]], [12.0, 7.0])
    np.testing.assert_array_equal(rings[0][0], [[0, 0], [10, 0], [10, 5], [10, 10], [0, 10]])
    np.testing.assert_array_equal(hts[0][0], [0, 7, 0, 0, 0])
    # B's edge is covered completely by A: no split, full height.
    np.testing.assert_array_equal(rings[1][0], box(10, 0, 20, 5))
    np.testing.assert_array_equal(hts[1][0], [0, 0, 0, 12])


def test_edge_in_the_middle_of_a_longer_edge_splits_it_twice() -> None:
    rings, hts = find_party_walls([[box(0, 0, 10, 30)], [box(10, 10, 20, 20)]], [9.0, 15.0])
    np.testing.assert_array_equal(
        rings[0][0], [[0, 0], [10, 0], [10, 10], [10, 20], [10, 30], [0, 30]]
    )
    np.testing.assert_array_equal(hts[0][0], [0, 0, 15, 0, 0, 0])
    np.testing.assert_array_equal(hts[1][0], [0, 0, 0, 9])


@pytest.mark.parametrize(
    ("gap", "shared"), [(0.0, True), (0.05, True), (0.099, True), (0.5, False)]
)
def test_tolerance_on_the_gap_between_walls(gap: float, shared: bool) -> None:
    _, hts = find_party_walls([[box(0, 0, 10, 10)], [box(10 + gap, 0, 20, 10)]], [12.0, 7.0])
    assert hts[0][0][1] == (7.0 if shared else 0.0)
    assert hts[1][0][3] == (12.0 if shared else 0.0)


def test_custom_tolerance() -> None:
    fps = [[box(0, 0, 10, 10)], [box(10.5, 0, 20, 10)]]
    assert find_party_walls(fps, [12.0, 7.0], tol=1.0)[1][0][0][1] == 7.0
    assert find_party_walls(fps, [12.0, 7.0], tol=0.1)[1][0][0][1] == 0.0


def test_no_split_vertex_closer_than_tol_to_an_existing_vertex() -> None:
    # B ends 0.05 m short of A's corner: no new vertex, but A's edge is still shared.
    rings, hts = find_party_walls([[box(0, 0, 10, 10)], [box(10, 0, 20, 9.95)]], [12.0, 7.0])
    assert len(rings[0][0]) == 4
    np.testing.assert_array_equal(hts[0][0], [0, 7, 0, 0])


def test_neighbours_sharing_a_corner_give_one_split_vertex() -> None:
    # A long building with two short ones behind it whose corners meet at x = 5.
    fps = [[box(0, 0, 10, 10)], [box(0, 10, 5, 20)], [box(5, 10, 10, 20)]]
    rings, hts = find_party_walls(fps, [10.0, 6.0, 8.0])
    np.testing.assert_array_equal(rings[0][0], [[0, 0], [10, 0], [10, 10], [5, 10], [0, 10]])
    np.testing.assert_array_equal(hts[0][0], [0, 0, 8, 6, 0])
    np.testing.assert_array_equal(hts[1][0], [10, 8, 0, 0])
    np.testing.assert_array_equal(hts[2][0], [10, 0, 0, 6])


def test_max_height_when_several_neighbours_cover_an_edge() -> None:
    fps = [[box(0, 0, 10, 10)], [box(10, 0, 20, 10)], [box(10, 0, 15, 10)]]
    _, hts = find_party_walls(fps, [5.0, 7.0, 11.0])
    assert hts[0][0][1] == 11.0


def test_parallel_overlapping_edges_count_too() -> None:
    # B overlaps A with its bottom edge running the same way along A's bottom edge.
    rings, hts = find_party_walls([[box(0, 0, 10, 10)], [box(0, 0, 5, 5)]], [12.0, 7.0])
    np.testing.assert_array_equal(rings[0][0][:3], [[0, 0], [5, 0], [10, 0]])
    np.testing.assert_array_equal(hts[0][0][:2], [7, 0])


def test_steeply_crossing_short_edges_are_not_party_walls() -> None:
    # A's bottom edge (0.18 m) and B's edge cross at 45 degrees, both within tol of
    # each other's line over more than tol: the angle test must reject them.
    a = np.array([[0.0, 0.0], [0.18, 0.0], [0.09, 1.0]])
    b = np.array([[0.18, 0.09], [0.0, -0.09], [1.0, -1.0]])
    _, hts = find_party_walls([[a], [b]], [10.0, 10.0])
    assert not np.any(hts[0][0]) and not np.any(hts[1][0])


def test_perpendicular_touching_wall_is_not_shared() -> None:
    _, hts = find_party_walls([[box(0, 0, 10, 10)], [box(10, 4.95, 20, 5.05)]], [12.0, 7.0])
    # B's short left edge (0.1 m) is not longer than tol: nothing shared.
    assert not np.any(hts[0][0]) and not np.any(hts[1][0])


def test_building_in_a_courtyard_shares_the_hole_edges() -> None:
    hole = box(10, 10, 20, 20)[::-1].copy()  # clockwise: top, right, bottom, left edge
    outer = [box(0, 0, 30, 30), hole]
    inner = [box(10, 10, 20, 15)]
    rings, hts = find_party_walls([outer, inner], [20.0, 6.0])
    assert len(rings[0]) == 2
    np.testing.assert_array_equal(rings[0][0], box(0, 0, 30, 30))
    assert not np.any(hts[0][0])
    h_ring, h_hts = rings[0][1], hts[0][1]
    # Two hole edges are split at y = 15; covered stretches carry 6 m.
    assert len(h_ring) == 6
    mids = 0.5 * (h_ring + np.roll(h_ring, -1, axis=0))
    for mid, h in zip(mids, h_hts, strict=True):
        expected = 6.0 if mid[1] <= 15 else 0.0
        assert h == expected, (mid, h)
    np.testing.assert_array_equal(hts[1][0], [20, 20, 0, 20])


def test_empty_and_bad_input() -> None:
    assert find_party_walls([], []) == ([], [])
    with pytest.raises(InputError, match="one height per footprint"):
        find_party_walls([[box(0, 0, 1, 1)]], [])
    with pytest.raises(InputError, match="tol"):
        find_party_walls([[box(0, 0, 1, 1)]], [1.0], tol=0.0)
    with pytest.raises(InputError, match=r"\(n, 2\)"):
        find_party_walls([[np.zeros((4, 3))]], [1.0])


def test_four_thousand_buildings_are_fast() -> None:
    rng = np.random.default_rng(1)
    fps, hts = [], []
    for row in range(80):
        x = 0.0
        for _ in range(50):
            w, d = rng.uniform(6, 15), rng.uniform(8, 14)
            fps.append([box(x, row * 40.0, x + w, row * 40.0 + d)])
            hts.append(float(rng.uniform(8, 25)))
            x += w
    find_party_walls(fps[:10], hts[:10])  # warm up imports and caches
    best = np.inf
    for _ in range(2):
        t0 = time.perf_counter()
        rings, nh = find_party_walls(fps, hts)
        best = min(best, time.perf_counter() - t0)
    assert best < 2.0, f"4,000 buildings took {best:.2f} s"
    # Every house except the row ends has two party walls.
    shared = sum(int(np.count_nonzero(h[0])) for h in nh)
    assert shared == 80 * (2 * 50 - 2)


# Widths on a 0.5 m grid so break points either coincide or are further apart than tol.
_widths = st.lists(st.integers(min_value=1, max_value=24), min_size=1, max_size=6)


@settings(max_examples=60, deadline=None)
@given(
    front=_widths,
    back=_widths,
    shift=st.integers(min_value=-10, max_value=10),
    seed=st.integers(min_value=0, max_value=2**32 - 1),
)
def test_rows_of_houses_match_a_geometric_oracle(
    front: list[int], back: list[int], shift: int, seed: int
) -> None:
    """Two rows of houses back to back: every edge is shared all along or not at all,
    carries the max height of the buildings whose outline it lies on, and keeps the
    original vertices in order."""
    fps = []
    for widths, y0, y1, x in ((front, 0.0, 10.0, 0.0), (back, 10.0, 18.0, shift * 0.5)):
        for w in widths:
            fps.append([box(x, y0, x + w * 0.5, y1)])
            x += w * 0.5
    heights = list(np.random.default_rng(seed).uniform(3.0, 30.0, len(fps)))
    polys = [shapely.Polygon(f[0]) for f in fps]
    rings, nh = find_party_walls(fps, heights)
    for b, (ring, h) in enumerate(zip((r[0] for r in rings), (x[0] for x in nh), strict=True)):
        # Original vertices kept, in order, as a subsequence.
        orig = fps[b][0]
        pos = [int(np.flatnonzero((ring == v).all(axis=1))[0]) for v in orig]
        assert pos == sorted(pos)
        nxt = np.roll(ring, -1, axis=0)
        for i in range(len(ring)):
            exp = []
            for f in (0.25, 0.5, 0.75):
                p = shapely.Point(ring[i] + f * (nxt[i] - ring[i]))
                on = [
                    heights[o]
                    for o in range(len(fps))
                    if o != b and polys[o].boundary.distance(p) < 1e-9
                ]
                exp.append(max(on, default=0.0))
            assert exp[0] == exp[1] == exp[2], f"edge {i} of building {b} is only partly shared"
            assert h[i] == pytest.approx(exp[1]), (b, i)
