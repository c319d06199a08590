"""Impostors drawn by the client (issue 27 item 3): fetched through the one scheduler, chosen,
counted by the budget, drawn as premultiplied textured quads; a scene without impostors unchanged.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest

from walkstream.client.config import ReplayConfig
from walkstream.client.net.link import LinkProfile
from walkstream.client.replay import ReplayResult, run_replay
from walkstream.client.stream.images import AHEAD_LEAD_S, IMAGE_LEAD_S, ImpostorImages, offered_need
from walkstream.client.stream.scheduler import RequestScheduler
from walkstream.client.truth.standin import stand_in_ids
from walkstream.client.walk.impostors import quad_corners
from walkstream.server.bake import BakeSettings, ImpostorSettings, bake
from walkstream.server.service.main import create_app
from walkstream.server.sources.citygen import write_city
from walkstream.shared.camera import look_at, perspective
from walkstream.shared.impostors import bin_direction

URL = "http://walkstream.test"
FAST = BakeSettings(resolution=32, sampling="corners")
# perspective images: this module's walks bake, serve and draw them (an orthographic bake
# is served and drawn in tests/test_impostors.py and tests/test_ringwalls.py)
SMALL = ImpostorSettings(distance=50.0, error_deg=4.0, size=16, projection="perspective")


@pytest.fixture(scope="module")
def dbs(tmp_path_factory: pytest.TempPathFactory, gl_ctx: object) -> tuple[Path, Path]:
    d = tmp_path_factory.mktemp("impdraw")
    write_city(d / "city.geojson", 150, 2)
    bake(d / "city.geojson", d / "imp.db", settings=FAST, impostors=SMALL, name="imp")
    bake(d / "city.geojson", d / "plain.db", settings=FAST, name="plain")
    return d / "imp.db", d / "plain.db"


def _replay(db: Path, **kw: Any) -> ReplayResult:
    app = create_app([db])
    try:
        cfg = ReplayConfig(link=LinkProfile(56_000.0, 56_000.0, 0.2), device="pda", duration_s=6.0, **kw)
        return run_replay(httpx.ASGITransport(app=app), URL, cfg)
    finally:
        app.state.scenes.close()


@pytest.fixture(scope="module")
def both_ways(dbs: tuple[Path, Path]) -> tuple[dict[str, Any], dict[str, Any]]:
    """One walk on the impostor bake with impostors and geometry only, every 25th frame
    compared with the truth (160 x 120): the summaries, shared by the tests that read them."""
    imp = _replay(dbs[0], truth_every=25, size=(160, 120)).summary
    geo = _replay(dbs[0], truth_every=25, size=(160, 120), impostors=False).summary
    return imp, geo


@pytest.mark.gl
def test_far_buildings_are_drawn_as_impostors_and_cost_two_triangles(
    both_ways: tuple[dict[str, Any], dict[str, Any]],
) -> None:
    imp, geo = both_ways
    f = imp["impostors"]
    assert f["images_received"] > 0 and f["image_bytes"] > 0 and f["impostors_mean"] > 0
    assert 0 < f["texture_bytes_max"] <= 8 << 20
    assert "impostors" not in geo  # geometry only: no image asked for
    assert imp["triangles_mean"] < geo["triangles_mean"]


@pytest.mark.gl
def test_a_perspective_bake_serves_its_cells_with_the_projection(dbs: tuple[Path, Path]) -> None:
    from asgiclient import Http

    from walkstream.shared.wire import MSGPACK, decode_cell

    app = create_app([dbs[0]])
    http = Http(app)
    try:
        listed = [imp for cid in range(40)
                  if (resp := http.get(f"/v1/scenes/imp/cells/{cid}", headers={"Accept": MSGPACK})).status_code == 200
                  and (imp := decode_cell(resp.content, "cell").impostors) is not None]
    finally:
        http.close()
        app.state.scenes.close()
    assert listed and all(imp.perspective for imp in listed)
    row = listed[0].rows[0]
    assert listed[0].eye(row) > row.radius  # the client places the quad from the same eye as the bake


@pytest.mark.gl
def test_a_texture_budget_smaller_than_one_image_draws_geometry(dbs: tuple[Path, Path]) -> None:
    s = _replay(dbs[0], texture_budget_bytes=1).summary
    assert s["impostors"]["images_received"] > 0 and s["impostors"].get("impostors_mean", 0) == 0


@pytest.mark.gl
def test_a_scene_without_impostors_asks_for_no_image(dbs: tuple[Path, Path]) -> None:
    a, b = _replay(dbs[1]).summary, _replay(dbs[1], impostors=False).summary
    a.pop("rewrite_cpu_s"), b.pop("rewrite_cpu_s")  # real CPU seconds
    assert "impostors" not in a and a == b


class _Lane:
    def offer(self) -> None:
        return None

    def in_flight(self) -> int:
        return 0

    def outstanding_bytes(self) -> float:
        return 0.0


class _Cache:
    def has(self, kind: str, oid: int) -> bool:
        return False


def test_an_image_is_offered_before_what_is_needed_now() -> None:
    sched = RequestScheduler()
    sched.join(_Lane())  # type: ignore[arg-type]
    lane = ImpostorImages(None, _Cache(), sched)  # type: ignore[arg-type]
    lane.refused = True  # join without dispatching
    lane.want({7: 0.0})
    assert lane not in sched.lanes
    lane.refused = False
    lane.wanted = {7: 0.0, 9: 3.0}
    o = lane.offer()
    assert o is not None and o.need_s == IMAGE_LEAD_S < 0.0


def test_the_images_of_the_cells_ahead_are_offered_in_order_of_need() -> None:
    sched = RequestScheduler()
    lane = ImpostorImages(None, _Cache(), sched)  # type: ignore[arg-type]
    # only a cell ahead's images are wanted: offered a lead before that cell's need,
    # so after what is due now and before the parameters due at the same time
    lane.wanted = {9: 3.0, 11: 5.0}
    o = lane.offer()
    assert o is not None and o.need_s == pytest.approx(3.0 - AHEAD_LEAD_S)
    assert 0.0 < o.need_s < 3.0
    # a cell ahead needed in a moment still waits for what is needed now
    assert 0.0 < offered_need(0.01) < offered_need(0.5) < 0.5
    assert offered_need(0.0) == IMAGE_LEAD_S < 0.0


@pytest.mark.gl
def test_quad_is_upright_and_premultiplied_without_dark_fringe(gl: object) -> None:
    from walkstream.client.draw.frames import FrameRenderer

    # image: top half red, bottom half blue; its right column half-covered white (premultiplied)
    img = np.zeros((8, 8, 4), np.uint8)
    img[:4, :, :] = (255, 0, 0, 255)
    img[4:, :, :] = (0, 0, 255, 255)
    img[:, 7, :] = (128, 128, 128, 128)
    box = (-1.0, -1.0, 0.0, 1.0, 1.0, 2.0)
    corners = quad_corners(box, 2, 16, 8)
    r = FrameRenderer(size=(64, 64), fov_deg=40.0, ctx=gl)  # type: ignore[arg-type]
    try:
        r.impostors = [(corners, 1, img, 1.0)]
        eye = np.array([0.0, 0.0, 1.0]) + 20.0 * bin_direction(2, 16, 8)  # the image's own direction
        view = look_at(eye, np.array([0.0, 0.0, 1.0]))
        r.draw([], view, perspective(40.0, 1.0, 0.5, 100.0))
        px = r.snapshot().astype(int)
    finally:
        r.release()
    rows = np.where((px[..., 0] > 200) & (px[..., 2] < 50))[0]
    rows_b = np.where((px[..., 2] > 200) & (px[..., 0] < 50))[0]
    assert len(rows) and len(rows_b) and rows.max() < rows_b.min()  # red above blue: row 0 is the top
    # the half-covered white texels over the light background stay light (a straight-alpha
    # blend of premultiplied texels would darken them to about 3/4 of the background)
    bg = px[0, 0, :3].sum()
    grey = (px[..., 0] < 150) & (px[..., 2] < 150) | (np.abs(px[..., 0] - px[..., 2]) < 20)
    assert grey.any() and px[..., :3].sum(axis=2)[grey].min() >= 0.9 * bg


@pytest.mark.gl
def test_the_truth_paints_impostors_under_their_own_cause(both_ways: tuple[dict[str, Any], dict[str, Any]]) -> None:
    with_imp, without = (s["truth"]["colour"]["causes"] for s in both_ways)
    assert with_imp["impostor"] > 0.0 and without["impostor"] == 0.0


def test_a_building_drawn_as_its_image_is_shown_where_the_image_painted() -> None:
    truth = np.array([[3, 3, 5], [3, 0, 5]], np.uint32)  # ids + 1: buildings 2 and 4
    client = np.zeros_like(truth)
    painted = np.array([[True, False, True], [True, True, True]])
    got = stand_in_ids(client, truth, painted, [2])  # building 2 drawn as an impostor, 4 not
    assert got.tolist() == [[3, 0, 0], [3, 0, 0]]


@pytest.mark.gl
def test_bench_impostors_replays_one_walk_both_ways(dbs: tuple[Path, Path], tmp_path: Path) -> None:
    from walkstream.benchmarks.impostors import (
        bake_label,
        format_impostor_table,
        run_impostor_bench,
    )
    from walkstream.cmd_replay import replayer

    # one bake's two rows (their reports without plots: drawing them was most of this
    # test's time); a sweep is the same loop over more databases, and the label of a bake
    # without impostors is read from its settings record as here
    # with plain boxes (--facades both's second half: the replay's --facades off)
    rows = run_impostor_bench([str(dbs[0])], replayer(plots=False), out=tmp_path, duration="2s",
                              truth_every=25, size="80x60", facades=(False,))
    assert [r["with_impostors"] for r in rows] == [True, False]
    assert [r["with_facades"] for r in rows] == [False, False] and all(not r.get("facades") for r in rows)
    assert [r["bake"] for r in rows] == ["imp D50 A4 S16 persp"] * 2
    assert bake_label(str(dbs[1])) == "plain (no impostors)"
    assert rows[0]["impostors"]["image_bytes"] > 0 and "impostors" not in rows[1]
    assert all(r["frame_time_median_ms"] > 0 for r in rows)
    c = rows[0]["truth"]["colour"]
    assert sum(c["error_causes"].values()) == pytest.approx(c["mean_error"]["mean"])
    table = format_impostor_table(rows)
    assert "SE impostors" in table and "SE geometry" in table and "e:boxes" in table and " pop" in table
    assert "pop" not in rows[1]["truth"]  # geometry only: nothing switches
    assert (tmp_path / "bench_impostors.json").is_file() and (tmp_path / "bench_impostors.png").stat().st_size > 0
