"""The textures of the rings a walker enters next (issue 28, outdoors): asked for where
the walker enters the next ring, whatever way it turns, and the zones it walks along
after; the rings planned by the bake's own planner (no GL, no replay)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from walkstream.client.stream.cellmap import nearest_point
from walkstream.client.walk.ringahead import TURNED_LAG_S, ring_textures_ahead, ring_zones_ahead
from walkstream.server.bake.ringwalls import plan_ring_walls
from walkstream.server.bake.viewcell import ViewCell
from walkstream.server.bake.wallplan import WallSettings
from walkstream.shared.walls import WallTable, ring_cell

HORIZONS = (0.5, 1.0, 1.5, 2.0, 3.0)


def _square(x0: float, y0: float, size: float = 10.0) -> NDArray[np.float64]:
    return np.array([[x0, y0], [x0 + size, y0], [x0 + size, y0 + size], [x0, y0 + size]], np.float64)


def _scene() -> tuple[list, WallTable, dict[int, list[int]], dict[int, NDArray[np.float64]]]:
    """Cell 0, cell 1 east of it and cell 3 north of it (a side street), a ring each."""
    outlines = {0: _square(0, 0), 1: _square(10, 0), 3: _square(0, 10)}
    cells = [ViewCell(0, "street", outlines[0], 1.0, 2.0, (1, 3)), ViewCell(1, "street", outlines[1], 1.0, 2.0, (0,)),
             ViewCell(3, "street", outlines[3], 1.0, 2.0, (0,))]
    boxes = {i: (x - 1, y - 1, 0.0, x + 1, y + 1, 8.0) for i, (x, y) in enumerate([(5, 5), (15, 5), (5, 15)])}
    boxes |= {10 + i: (x - 2, y - 2, 0.0, x + 2, y + 2, 12.0) for i, (x, y) in enumerate([(300, 0), (-300, 0), (0, 300), (0, -300)])}
    pvs = {c.id: np.array(sorted(boxes)) for c in cells}
    plan = plan_ring_walls(cells, pvs, boxes, WallSettings(keep=2, ring_min=6.0, region=0.0, error_deg=10.0))
    sides = plan.walls.sides
    rings: dict[int, list[int]] = {}
    for k, s in enumerate(sides):
        rings.setdefault(ring_cell(s.portal), []).append(k)
    return sides, WallTable(sides), rings, outlines


def _facing_east(sides: list, eye: NDArray[np.float64]):  # type: ignore[no-untyped-def]
    """A view looking along +x: the walls whose middle lies ahead of the (moved) eye."""
    def in_view(walls: list[int], moved: NDArray[np.float64]) -> NDArray[np.bool_]:
        x = eye[0] + moved[0]
        return np.array([(sides[k].p0[0] + sides[k].p1[0]) / 2.0 > x for k in walls], bool)
    return in_view


def test_the_entry_point_is_the_cells_point_nearest_the_walker() -> None:
    sq = _square(10, 0)
    assert nearest_point(sq, np.array([12.0, 3.0])).tolist() == [12.0, 3.0]  # inside: where it stands
    assert nearest_point(sq, np.array([4.0, 5.0])).tolist() == [10.0, 5.0]
    assert np.allclose(nearest_point(sq, np.array([25.0, 20.0])), [20.0, 10.0])


def test_the_next_rings_textures_are_wanted_where_the_walker_enters_it_and_along_after() -> None:
    sides, table, rings, outlines = _scene()
    eye = np.array([7.0, 5.0, 1.6])
    got: dict[int, float] = {}

    def want(tid: int, need: float) -> None:
        got[tid] = min(need, got.get(tid, np.inf))

    n = ring_textures_ahead(table, sides, rings, 0, eye, np.array([4.0, 0.0]), {0: 0.0, 1: 0.75, 3: 9.0},
                            outlines, HORIZONS, _facing_east(sides, eye), want)
    assert n == 1  # cell 3 is beyond the last horizon
    theirs = {t for k in rings[1] for t in sides[k].textures}
    mine = {t for k in rings[0] for t in sides[k].textures}
    assert got and set(got) <= theirs and not set(got) & mine
    # at the entry point (10, 5): every wall of the next ring facing it, those ahead at the
    # time the route reaches the cell, the one behind (the walker may turn to it) later
    at = np.array([[10.0, 5.0, 1.6]])
    zones, _d, weights = table.views(at)
    ahead = _facing_east(sides, eye)(rings[1], at[0] - eye)
    for j, k in enumerate(rings[1]):
        if weights[0, k] > 0.0:
            tid = sides[k].textures[int(zones[0, k])]
            assert got[tid] == (0.75 if ahead[j] else 0.75 + TURNED_LAG_S)
    # and on from there at the walker's velocity: the zones it walks along at later horizons
    later = np.array([[10.0 + 4.0 * (1.5 - 0.75), 5.0, 1.6]])  # (13, 5): a zone on from the entry
    zl, _d, wl = table.views(later)
    along = [sides[k].textures[int(zl[0, k])] for k in rings[1] if wl[0, k] > 0.0 and sides[k].p0[1] == sides[k].p1[1]]
    entry = {sides[k].textures[int(zones[0, k])] for k in rings[1]}
    assert along and set(along).isdisjoint(entry) and all(got.get(t) == 1.5 for t in along)


def test_a_side_street_ahead_is_looked_at_from_where_the_walker_turns_into_it() -> None:
    sides, table, rings, outlines = _scene()
    eye = np.array([5.0, 7.0, 1.6])  # walking east in cell 0; the route turns north into cell 3
    got: dict[int, float] = {}
    ring_textures_ahead(table, sides, rings, 0, eye, np.array([4.0, 0.0]), {3: 0.75}, outlines, HORIZONS,
                        _facing_east(sides, eye), lambda t, need: got.setdefault(t, need))
    # the zones at its entry (5, 10), not at the eye moved on east (8, 7), which is not in cell 3
    zones, _d, weights = table.views(np.array([[5.0, 10.0, 1.6]]))
    entry = {sides[k].textures[int(zones[0, k])] for k in rings[3] if weights[0, k] > 0.0}
    assert len(entry) == 4 and entry <= set(got)


def test_nothing_is_wanted_without_rings_ahead() -> None:
    sides, table, rings, outlines = _scene()
    eye = np.array([5.0, 5.0, 1.6])
    got: list[int] = []
    n = ring_textures_ahead(table, sides, rings, 0, eye, np.zeros(2), {0: 0.0, 7: 1.0}, outlines, HORIZONS,
                            _facing_east(sides, eye), lambda t, need: got.append(t))
    assert n == 0 and got == []


def test_the_current_rings_zones_ahead_include_the_walls_a_turn_shows_later() -> None:
    sides, table, rings, _outlines = _scene()
    eye = np.array([2.0, 5.0, 1.6])
    eyes = np.array([eye + np.array([2.0 * h, 0.0, 0.0]) for h in HORIZONS[:3]])  # walking east
    calls: list[tuple[int, float]] = []
    in_view = _facing_east(sides, eye)
    ring_zones_ahead(table, sides, rings[0], eye, eyes, HORIZONS, in_view, lambda t, need: calls.append((t, need)))
    zones, _d, weights = table.views(eyes)
    expected = set()
    for h, t in enumerate(HORIZONS[:3]):
        shown = in_view(rings[0], eyes[h] - eye)
        for j, k in enumerate(rings[0]):
            if weights[h, k] > 0.0:
                expected.add((sides[k].textures[int(zones[h, k])], t if shown[j] else t + TURNED_LAG_S))
    assert set(calls) == expected
    # the wall behind the walker (west) is asked for too, after a turn's lag
    west = [k for k in rings[0] if max(sides[k].p0[0], sides[k].p1[0]) < 0.0]
    assert west and any(t in sides[west[0]].textures and need > HORIZONS[0] for t, need in calls)
    ring_zones_ahead(table, sides, rings[0], eye, np.zeros((0, 3)), (), in_view, lambda t, need: calls.append((-1, 0.0)))
    assert (-1, 0.0) not in calls  # standing: no horizons, nothing ahead
