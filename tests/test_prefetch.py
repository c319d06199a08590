"""Prefetch at speed (issue 16): the cell graph prediction, the plan, and its traps.

The prediction and the plan are tested on a synthetic crossroads; the traps end to
end, as replays on a small generated town over a GPRS-class link.

The synthetic crossroads: a crossroad cell ``X`` with two street cells on each arm
(``W1 W2`` west, ``E1 E2`` east, ``N1 N2`` north, ``S1`` south) and a dead end
``S1`` (no second cell south), 10 m wide streets, 20 m cells.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
from scenes import add_default_paths, build_city_db

from walkstream.client.config import ReplayConfig
from walkstream.client.net.link import LinkProfile
from walkstream.client.replay import ReplayResult, run_replay
from walkstream.client.report.metrics import link_utilisation
from walkstream.client.stream.cellmap import CellMap
from walkstream.client.stream.plan import plan_needs, tile_key, tile_of_key, wanted_objects
from walkstream.client.stream.predict import MotionPredictor
from walkstream.client.stream.route import horizon_m, predict_route, turn_cost_m
from walkstream.server.service.main import create_app
from walkstream.server.store import write_path
from walkstream.shared.cells import TileGrid
from walkstream.shared.paths import RecordedPath
from walkstream.shared.wire import CellRecord


def _box(x0: float, y0: float, x1: float, y1: float) -> np.ndarray:
    return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], dtype=np.float64)


CELLS = {
    "X": _box(-5, -5, 5, 5),
    "E1": _box(5, -5, 25, 5),
    "E2": _box(25, -5, 45, 5),
    "W1": _box(-25, -5, -5, 5),
    "W2": _box(-45, -5, -25, 5),
    "N1": _box(-5, 5, 5, 25),
    "N2": _box(-5, 25, 5, 45),
    "S1": _box(-5, -25, 5, -5),
}
LINKS = [
    ("X", "E1"),
    ("E1", "E2"),
    ("X", "W1"),
    ("W1", "W2"),
    ("X", "N1"),
    ("N1", "N2"),
    ("X", "S1"),
]
ID = {name: k for k, name in enumerate(CELLS)}
NAME = {k: name for name, k in ID.items()}


def _map() -> CellMap:
    nbs: dict[str, list[int]] = {n: [] for n in CELLS}
    for a, b in LINKS:
        nbs[a].append(ID[b])
        nbs[b].append(ID[a])
    m = CellMap()
    m.add_cells([ID[n] for n in CELLS], list(CELLS.values()), [nbs[n] for n in CELLS], tile=None)
    return m


def _order(route_steps: object) -> list[str]:
    return [NAME[s.cell] for s in route_steps]  # type: ignore[attr-defined]


def test_route_goes_straight_on_first_then_turns_and_back_last() -> None:
    m = _map()
    r = predict_route(m, ID["W1"], [-15.0, 0.0], [1.0, 0.0], 500.0, turn_cost_m(14.0))
    order = _order(r.steps)
    assert order[:3] == ["W1", "X", "E1"]  # the street ahead, across the junction
    assert order[-1] == "W2"  # turning round at speed comes last
    cost = r.cost()
    # a turn at the junction costs about half a U-turn more than going straight on
    for turn in ("N1", "S1"):
        assert cost[ID[turn]] - cost[ID["E1"]] == pytest.approx(turn_cost_m(14.0) / 3, rel=0.3)
    assert cost[ID["N2"]] > cost[ID["E2"]]
    # a walker turns more easily than a car
    walk = predict_route(m, ID["W1"], [-15.0, 0.0], [1.0, 0.0], 500.0, turn_cost_m(1.4)).cost()
    assert walk[ID["W2"]] < cost[ID["W2"]] and walk[ID["N1"]] < cost[ID["N1"]]
    # the horizon cuts: only what is within it
    near = predict_route(m, ID["W1"], [-15.0, 0.0], [1.0, 0.0], 30.0, turn_cost_m(14.0))
    assert _order(near.steps) == ["W1", "X", "E1"] and not near.frontier


def test_a_dead_end_turns_the_prediction_round() -> None:
    m = _map()
    # in the dead end S1, heading south at 14 m/s: the only way on is back north
    r = predict_route(m, ID["S1"], [0.0, -20.0], [0.0, -1.0], 500.0, turn_cost_m(14.0))
    order = _order(r.steps)
    assert order[0] == "S1" and order[1] == "X" and set(order) == set(CELLS)
    assert r.cost()[ID["X"]] >= turn_cost_m(14.0) * 0.9  # the U-turn is paid for, once


def test_the_horizon_grows_with_speed() -> None:
    assert horizon_m(0.0, 5.0, 60.0) == 60.0
    assert horizon_m(14.0, 5.0, 60.0) == 70.0 > horizon_m(4.0, 5.0, 60.0)


def test_a_u_turn_at_speed_is_followed_within_a_second() -> None:
    """Driving west at 50 km/h towards the junction, then turning round on the spot:
    within a second the soonest cell is the one the car now drives towards."""
    m = _map()
    p = MotionPredictor()
    t, x = 0.0, 22.0
    m.current = ID["E1"]
    for _ in range(25):  # 1 s westwards
        p.observe(t, [x, 0.0])
        t, x = t + 0.04, x - 0.56
    soonest: list[str] = []
    for _ in range(25):  # turned round: eastwards, away from the junction, still in E1
        p.observe(t, [x, 0.0])
        m.update([x, 0.0])
        needs = plan_needs(
            m,
            None,
            [x, 0.0],
            p.velocity(),
            p.heading(),
            reach_m=60.0,
            reach_records_m=80.0,
            turn_m=turn_cost_m(p.speed()),
            min_speed=1.5,
        )
        soonest.append(NAME[min((tt, c) for c, tt in needs.need.items() if c != m.current)[1]])
        t, x = t + 0.04, x + 0.56
    assert soonest[0] == "X"  # the old way, just after the turn
    recovered = next(k for k in range(len(soonest)) if set(soonest[k:]) == {"E2"})
    assert 0 < recovered * 0.04 <= 1.0


def test_slowing_down_at_a_junction_keeps_straight_on_wanted() -> None:
    """A car slows from 50 km/h to a crawl at the crossroad, then goes straight on:
    the street ahead stays wanted all along, so nothing is missing when it goes."""
    m = _map()
    p = MotionPredictor()
    t, x = 0.0, -44.0
    for speed in np.concatenate(
        [
            np.full(40, 14.0),
            np.linspace(14.0, 0.5, 60),
            np.full(30, 0.5),
            np.linspace(0.5, 14.0, 40),
        ]
    ):
        p.observe(t, [x, 0.0])
        cur, _ = m.update([x, 0.0])
        needs = plan_needs(
            m,
            None,
            [x, 0.0],
            p.velocity(),
            p.heading(),
            reach_m=horizon_m(p.speed(), 5.0, 60.0),
            reach_records_m=horizon_m(p.speed(), 5.0, 60.0) + 20,
            turn_m=turn_cost_m(p.speed()),
            min_speed=1.5,
        )
        if x > -25.0:
            assert ID["E1"] in needs.need and ID["E1"] in needs.records, (t, x)
        if x > -5.0:
            assert ID["E2"] in needs.need, (t, x)
        t += 0.04
        x = min(40.0, x + float(speed) * 0.04)


def test_a_record_round_the_corner_is_due_by_distance_not_turn_cost() -> None:
    """A car 5 m before the junction: the side streets are less likely than the street
    ahead (their objects later), but whoever turns is in them after the same few metres,
    so their records are due as soon as the one ahead."""
    m = _map()
    m.current = ID["W1"]
    v = np.array([14.0, 0.0])
    needs = plan_needs(
        m, None, [-10.0, 0.0], v, v, reach_m=60.0, reach_records_m=80.0,
        turn_m=turn_cost_m(14.0), min_speed=1.5,
    )
    for side in ("N1", "S1"):
        assert needs.need[ID[side]] > needs.need[ID["E1"]]  # objects: by cost
        # records: by distance (5 m to the junction, 7 m across it to the side portal)
        assert needs.records[ID[side]] == pytest.approx((5.0 + 50.0**0.5) / 14.0)
        assert needs.records[ID[side]] < needs.need[ID[side]]
        assert needs.records[ID[side]] <= needs.records[ID["E1"]]
    assert needs.records[ID["E1"]] == pytest.approx(needs.need[ID["E1"]])  # straight on: the same


def test_a_record_beyond_the_objects_reach_is_due_by_its_cost() -> None:
    """Where a cell's objects are not wanted yet (its cost beyond the objects' reach),
    its record is needed no sooner than they: due by cost, so the side streets a car
    passes at a junction do not hold up the records of the street it goes on along."""
    m = _map()
    m.current = ID["W1"]
    v = np.array([14.0, 0.0])
    needs = plan_needs(
        m, None, [-10.0, 0.0], v, v, reach_m=20.0, reach_records_m=80.0,
        turn_m=turn_cost_m(14.0), min_speed=1.5,
    )
    cost = predict_route(m, ID["W1"], [-10.0, 0.0], v, 80.0, turn_cost_m(14.0)).cost()
    assert cost[ID["E1"]] <= 20.0 and ID["E1"] in needs.need  # ahead: objects wanted
    assert needs.records[ID["E1"]] == pytest.approx(needs.need[ID["E1"]])
    for side in ("N1", "S1"):
        assert cost[ID[side]] > 20.0 and ID[side] not in needs.need  # objects not wanted yet
        assert needs.records[ID[side]] == pytest.approx(cost[ID[side]] / 14.0)  # by cost
        assert needs.records[ID[side]] > needs.records[ID["E1"]]  # after the street ahead


def test_a_route_leaving_the_cells_keeps_the_last_cell_and_asks_for_tiles() -> None:
    m = _map()
    grid = TileGrid((-45.0, -25.0), 50.0, (2, 2), 1.0)
    for x in np.arange(-40.0, -90.0, -1.0):  # west, out of W2 and the scene
        cur, found = m.update([x, 0.0])
        needs = plan_needs(
            m,
            grid,
            [x, 0.0],
            [-5.0, 0.0],
            [-1.0, 0.0],
            reach_m=60.0,
            reach_records_m=80.0,
            turn_m=turn_cost_m(5.0),
            min_speed=1.5,
        )
        assert cur == ID["W2"]  # the last cell it was in
        assert found == (x >= -45.0)
        assert needs.need.get(ID["W2"]) == 0.0
        if not found:
            assert needs.tiles  # it looks around for cells it may enter
            assert ID["E2"] not in needs.need  # nothing ahead of it: it left the cells
    # and coming back in, the tracking picks up at once
    assert m.update([-30.0, 0.0]) == (ID["W2"], True)
    assert m.update([-20.0, 0.0]) == (ID["W1"], True)


def test_wanted_objects_soonest_first_then_by_ach() -> None:
    cells = {
        1: CellRecord(1, "street", np.array([10, 11, 12]), np.array([0.2, 0.5, 0.3])),
        2: CellRecord(2, "street", np.array([11, 13]), np.array([0.9, 0.1])),
    }
    w = wanted_objects({1: 0.0, 2: 3.0, 5: 1.0}, cells, lambda oid: oid == 12)
    assert sorted(w, key=w.__getitem__) == [11, 10, 13]
    assert w[11] == (0.0, -0.5) and 12 not in w


def test_tile_keys_round_trip() -> None:
    for t in [(0, 0), (3, 65535), (70, 2), None]:
        assert tile_of_key(tile_key(t)) == t


def test_link_utilisation_counts_bytes_within_the_intervals() -> None:
    log = ([0.5, 1.5, 2.5, 3.5], [1000, 2000, 3000, 4000])
    assert link_utilisation(log, 8000.0, [[0.0, 4.0]]) == pytest.approx(1.0)
    assert link_utilisation(log, 8000.0, [[1.0, 2.0], [1.5, 3.0]]) == pytest.approx(1.0)
    assert link_utilisation(log, 16000.0, [[0.0, 4.0]]) == pytest.approx(0.5)
    assert link_utilisation(log, 8000.0, []) is None
    assert link_utilisation(log, 0.0, [[0.0, 1.0]]) is None


# ----------------------------------------------------------------- whole replays


def _timed(
    name: str, legs: list[tuple[tuple[float, float], float]], start: tuple[float, float]
) -> RecordedPath:
    """A path through ``start`` then each ``(point, speed m/s)`` leg's end point."""
    pts = [np.asarray(start, dtype=np.float64)]
    t = [0.0]
    for end, speed in legs:
        e = np.asarray(end, dtype=np.float64)
        t.append(t[-1] + float(np.hypot(*(e - pts[-1]))) / speed)
        pts.append(e)
    xy = np.array(pts)
    d = np.diff(xy, axis=0)
    yaw = np.arctan2(d[:, 1], d[:, 0])
    return RecordedPath(
        name,
        t=np.array(t),
        xyz=np.column_stack([xy, np.full(len(xy), 1.2)]),
        yaw=np.append(yaw, yaw[-1]),
        pitch=np.zeros(len(xy)),
        speed_kmh=50.0,
    )


@pytest.fixture(scope="module")
def town(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 300 m generated town with made-up PVS lists, the default paths and the traps'.

    Its ``drive`` starts at about (-82, -130) going north along x = -77 through
    crossroads at y = -77 and y = -10; the town ends at x = -150.
    """
    db = tmp_path_factory.mktemp("prefetch") / "town.db"
    build_city_db(db, name="town", size=300.0, k=30)
    add_default_paths(db)
    start = (-82.1, -130.1)
    paths = [
        # 50 km/h north, turned round on the spot before the crossroad, 50 km/h back
        _timed("uturn", [((-77.4, -85.0), 14.0), (start, 14.0)], start),
        # 50 km/h north, slowing to a crawl across the crossroad, then straight on
        _timed(
            "slow", [((-77.4, -90.0), 14.0), ((-77.2, -66.0), 1.0), ((-76.2, -10.0), 14.0)], start
        ),
        # walking north, then west out of every cell, 50 m past the town's edge, and back
        _timed(
            "leave",
            [((-77.3, -76.5), 2.0), ((-200.0, -78.0), 4.0), ((-77.3, -76.5), 4.0)],
            start,
        ),
    ]
    for p in paths:
        write_path(db, p.name, p.to_msgpack())
    return db


GPRS = LinkProfile(40_000.0, 40_000.0, 0.5)


def _replay(db: Path, **kw: Any) -> ReplayResult:
    cfg = ReplayConfig(**{"link": GPRS, "device": "desktop2003", **kw})
    app = create_app([db])
    try:
        return run_replay(httpx.ASGITransport(app=app), "http://walkstream.test", cfg)
    finally:
        app.state.scenes.close()


@pytest.mark.parametrize("path", ["uturn", "slow", "drive"])
def test_a_car_on_gprs_sees_a_complete_picture(town: Path, path: str) -> None:
    """50 km/h on a 5 kB/s, 500 ms link: a U-turn at speed, a crawl across a junction
    and on straight, the default drive (45 s of it) -- every frame perfect after the first."""
    s = _replay(town, path=path, duration_s=45.0).summary
    assert s["time_to_first_perfect_frame_s"] is not None
    assert s["time_to_first_perfect_frame_s"] < 3.0
    assert s["perfect_frame_ratio"] >= 0.99, s["perfect_frame_ratio"]
    assert s["overfetch_ratio"] <= 0.5
    assert s["locate_requests"] == 0  # the index tracks the viewer
    assert 0.0 < s["link_utilisation"] <= s["link_utilisation_busy"] <= 1.05


def test_a_route_leaving_the_cells_keeps_going(town: Path) -> None:
    r = _replay(town, path="leave")
    s, log = r.summary, r.log
    assert s["frames"] > 0 and s["perfect_frame_ratio"] > 0.95
    first = int(np.flatnonzero(log.cell >= 0)[0])
    assert (log.cell[first:] >= 0).all()  # outside every cell: the last cell is kept
    assert s["locate_requests"] == 0  # no storm of requests while outside
    assert s["index_requests"] <= 12
    # back in the cells at the end, the tracking and the frames are right again
    assert log.download_quality[-25:].min() == 1.0 and log.rewrite_quality[-25:].min() == 1.0


def test_a_cell_index_larger_than_the_cache_budget(town: Path) -> None:
    """A cache that cannot hold the index (nor anything much): tiles are evicted and
    fetched again when the route needs them, the viewer is tracked all along."""
    big = _replay(town, path="drive", duration_s=30.0).summary
    index_bytes = big["index_bytes"]
    assert index_bytes > 2000
    r = _replay(town, path="drive", duration_s=30.0, cache_bytes=index_bytes // 4)
    s, log = r.summary, r.log
    assert s["cache_over_budget_events"] > 0  # only what the frame needs, pinned
    assert s["index_requests"] > big["index_requests"]  # evicted, and fetched again
    assert s["index_requests"] < 10 * big["index_requests"]  # but no storm
    first = int(np.flatnonzero(log.cell >= 0)[0])
    assert (log.cell[first:] >= 0).all()
    assert s["perfect_frame_ratio"] > 0.5 and s["frames"] == big["frames"]


def test_the_start_bundle_saves_round_trips_and_gzip_saves_bytes(town: Path) -> None:
    """On a 500 ms link the bundle brings the first frame sooner with fewer requests;
    without gzip the same walk costs more bytes."""
    kw: dict[str, Any] = {"path": "drive", "duration_s": 8.0}
    both = _replay(town, **kw).summary
    plain = _replay(town, start_bundle=False, **kw).summary
    assert both["start_bundle"] and not plain["start_bundle"]
    assert both["time_to_first_perfect_frame_s"] is not None
    assert plain["time_to_first_perfect_frame_s"] is not None
    assert both["time_to_first_perfect_frame_s"] + 0.5 <= plain["time_to_first_perfect_frame_s"]
    raw = _replay(town, gzip=False, **kw).summary
    assert raw["bytes_received"] > 1.1 * both["bytes_received"]
