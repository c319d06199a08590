"""The ground truth of a replay frame (issue 12): comparison, causes, a planted miss, no side effects."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
from scenes import build_city_db

import walkstream.client.rewrite.geometry as geometry
from walkstream.cli import main
from walkstream.client.config import ReplayConfig
from walkstream.client.draw.frames import FrameRenderer
from walkstream.client.net.link import LinkProfile
from walkstream.client.replay import ReplayResult, run_replay
from walkstream.client.report import write_report
from walkstream.client.truth.compare import CAUSES, compare_frame, missing_mask
from walkstream.client.truth.render import TruthRenderer
from walkstream.server.bake.walks import default_paths
from walkstream.server.service.main import create_app
from walkstream.server.sources.citygen import generate_city
from walkstream.server.sources.geojson import load_geojson_dict
from walkstream.server.store import SceneReader, write_path
from walkstream.shared.buildings import build_lods
from walkstream.shared.camera import camera, perspective
from walkstream.shared.errors import InputError
from walkstream.shared.streets import build_street

URL = "http://walkstream.test"
EVERY = 10


# --------------------------------------------------------------------------- comparison


def test_pvs_misses_over_a_hundredth_percent_count_after_the_first_perfect_frame() -> None:
    """Only the ``pvs`` column counts, only from the first perfect frame on, over 1e-4 strictly."""
    from walkstream.client.report.truth import PVS_OVER_SHARE, TruthLog, summarise_truth

    k = CAUSES.index("pvs")
    miss = np.zeros((5, len(CAUSES)))
    miss[0, k] = 0.5  # before the first perfect frame: not counted
    miss[1, k] = PVS_OVER_SHARE  # exactly at the bound: not over it
    miss[2, k] = 2 * PVS_OVER_SHARE  # over it
    miss[3, CAUSES.index("not_received")] = 0.5  # the link's miss, not the PVS's
    log = TruthLog(np.arange(5), np.arange(5.0), np.zeros(5), miss)
    s = summarise_truth(log, 1.0)
    assert s["pvs_over_hundredth_percent_ratio"] == pytest.approx(1 / 4)
    assert s["missing"]["pvs"]["mean"] == pytest.approx((0.5 + 3 * PVS_OVER_SHARE) / 5)
    assert summarise_truth(log, None)["pvs_over_hundredth_percent_ratio"] is None


def _frames() -> tuple[np.ndarray, np.ndarray]:
    """A 2 x 6 truth: objects 0..5 one per column on row 0, nothing on row 1."""
    t = np.zeros((2, 6), np.uint32)
    t[0] = np.arange(6) + 1
    return t, np.zeros((2, 6, 3), np.uint8)


def test_each_cause_in_order() -> None:
    t, rgb = _frames()
    c = np.zeros_like(t)
    c[0, 5] = 6  # object 5 is shown: not missing
    c[0, 4] = 8  # object 4 hidden behind object 7, drawn at LOD0 (a coarse front)
    err = compare_frame(
        t, rgb, c, rgb,
        pvs=[1, 2, 3, 4, 5, 6, 7],  # 0 is not in it
        received=[2, 3, 4, 5, 6, 7],  # 1 is not received
        built=[3, 4, 5, 6, 7],  # 2 is not built
        drawn={3: 1, 4: 2, 5: 2, 7: 0},  # 3 at LOD1, 6 not drawn
    )
    # 0 pvs, 1 not_received, 2 not_built, 3 lod (itself coarse), 4 lod (coarse front)
    assert err.missing.tolist() == [1, 1, 1, 2, 0, 0]
    assert err.cause[0].tolist() == [0, 1, 2, 3, 3, -1]
    assert err.cause[1].tolist() == [-1] * 6 and err.pixels == 12 and err.missed == 5
    # culled: in the PVS, received, built, not drawn and not beyond any fog
    t2 = np.array([[7, 7]], np.uint32)
    z = np.zeros((1, 2, 3), np.uint8)
    got = compare_frame(t2, z, np.zeros_like(t2), z, pvs=[6], received=[6], built=[6], drawn={})
    assert got.missing.tolist() == [0, 0, 0, 0, 2, 0]
    fog = compare_frame(t2, z, np.zeros_like(t2), z, pvs=[6], received=[6], built=[6], drawn={}, fogged=[6])
    assert fog.missing.tolist() == [0, 0, 0, 0, 0, 2] and fog.missed == 0
    # without a cell record (pvs None) everything shown is outside the PVS
    none = compare_frame(t2, z, np.zeros_like(t2), z, pvs=None, received=[6], built=[6], drawn={})
    assert none.missing[0] == 2


def test_colour_differences_count_beyond_the_tolerance() -> None:
    t, rgb = _frames()
    other = rgb.copy()
    other[0, 0] = 2  # within the tolerance
    other[1, 0] = 3  # beyond it
    err = compare_frame(t, rgb, t, other, pvs=range(6), received=range(6), built=range(6), drawn=dict.fromkeys(range(6), 2))
    assert err.differing == 1 and err.missed == 0
    with pytest.raises(InputError, match="one size"):
        compare_frame(t, rgb, t[:1], rgb, pvs=None, received=(), built=(), drawn={})
    mask = missing_mask(np.full((2, 6, 3), 200, np.uint8), np.array([[0, -1, 3, -1, -1, -1]] * 2))
    assert mask.shape == (2, 6, 3) and tuple(mask[0, 0]) != tuple(mask[0, 1])


# --------------------------------------------------------------------------- renderers


def test_truth_and_the_client_id_pass_agree(gl: Any) -> None:
    """Every object at LOD2 through both renderers: the same ids and the same colours."""
    scene = load_geojson_dict(generate_city(120, 3))
    lod2 = {b.id: build_lods(b)[2] for b in scene.buildings} | {s.id: build_street(s) for s in scene.streets}
    eye = np.array([*scene.streets[0].ring.mean(axis=0), 1.7])
    view = camera(eye, 0.7)
    with TruthRenderer(lod2, (160, 120), ctx=gl) as tr, FrameRenderer((160, 120), ctx=gl) as fr:
        t_rgb, t_ids = tr.colour_frame(eye, view)
        keys = [(i, 2) for i in sorted(lod2, reverse=True)]
        for i, m in lod2.items():
            fr.upload((i, 2), m)
        fr.draw(sorted(keys), view)
        c_rgb = fr.snapshot()
        c_ids = fr.draw_ids(keys, view)  # any order: the id pass draws in ascending ids
    assert len(np.unique(t_ids)) > 5
    np.testing.assert_array_equal(t_ids, c_ids)
    assert int(np.abs(t_rgb.astype(int) - c_rgb.astype(int)).max()) <= 2
    # the view distance leaves out what is farther
    with TruthRenderer(lod2, (160, 120), view_distance=1.0, ctx=gl) as near:
        _, ids = near.colour_frame(eye, view)
        assert set(np.unique(ids).tolist()) <= {0, *[int(i) + 1 for i in near.within(eye)]}


# --------------------------------------------------------------------------- replays


def _walkable(db: Path) -> Path:
    with SceneReader.open(db) as r:
        cells = list(r.cells())
    for p in default_paths(cells):
        write_path(db, p.name, p.to_msgpack())
    return db


@pytest.fixture(scope="module")
def every_db(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A small city whose every cell sees every object (no visibility misses at all)."""
    return _walkable(build_city_db(tmp_path_factory.mktemp("truth") / "city.db", name="city", size=150.0, k=100_000).path)


def _replay(db: Path, **kw: Any) -> ReplayResult:
    app = create_app([db])
    try:
        cfg = ReplayConfig(link=LinkProfile(56_000.0, 56_000.0, 0.2), device="desktop2003", duration_s=8.0, **kw)
        return run_replay(httpx.ASGITransport(app=app), URL, cfg)
    finally:
        app.state.scenes.close()


@pytest.fixture(scope="module")
def runs(every_db: Path, gl_ctx: Any) -> tuple[ReplayResult, ReplayResult]:
    """The same walk without and with the truth; rebuilds charged a fixed CPU time.

    Rewrites are charged the CPU time they really took, which differs from run to run
    by itself; a fixed charge makes two walks comparable figure by figure.
    """
    mp = pytest.MonkeyPatch()
    ticks = iter(range(10**9))
    mp.setattr(geometry.time, "thread_time", lambda: 0.002 * next(ticks))
    try:
        plain = _replay(every_db)
        ticks = iter(range(10**9))
        truth = _replay(every_db, truth_every=EVERY)
    finally:
        mp.undo()
    return plain, truth


def test_the_truth_changes_no_other_figure(runs: tuple[ReplayResult, ReplayResult]) -> None:
    plain, with_truth = runs
    a, b = dict(plain.summary), dict(with_truth.summary)
    assert "truth" not in a
    t = b.pop("truth")
    assert a == b
    np.testing.assert_array_equal(plain.log.frame_time, with_truth.log.frame_time)
    # the truth object exactly as specified
    assert set(t) == {
        "frames", "differing_pixels_mean", "over_half_percent_ratio", "pvs_over_hundredth_percent_ratio",
        "missing", "colour", "below_horizon",
    }
    assert set(t["missing"]) == set(CAUSES)
    assert all(set(v) == {"mean", "p95", "max"} for v in t["missing"].values())
    assert t["frames"] == len(range(0, a["frames"], EVERY))
    # every object is in every PVS: nothing is missing for visibility, nothing culled
    assert t["pvs_over_hundredth_percent_ratio"] == 0.0
    assert t["missing"]["pvs"]["max"] == 0.0 and t["missing"]["culled"]["max"] == 0.0
    assert t["missing"]["fog"]["max"] == 0.0
    # the start-up frames miss what has not arrived yet
    assert t["missing"]["not_received"]["max"] > 0.5
    assert 0.0 <= t["differing_pixels_mean"] <= 1.0
    # the ground plane: below the horizon no sky, whatever shows no object
    below = t["below_horizon"]
    assert below["sky"]["max"] < 0.01 and below["no_object"]["max"] >= below["sky"]["max"]


def test_a_planted_miss_is_found_with_its_pixels(
    runs: tuple[ReplayResult, ReplayResult], every_db: Path, tmp_path: Path, gl: Any
) -> None:
    """Leave one building out of one cell's PVS: its pixels, and only those, are cause (a)."""
    _, base = runs
    assert base.truth is not None and base.truth.frames
    first = base.summary["time_to_first_perfect_frame_s"]
    with SceneReader.open(every_db) as r:
        kinds = {i: o.kind for i, o in r.object_info(r.object_ids().tolist()).items()}
    # the biggest building of a compared frame after the first perfect one, and its cell
    best = max(
        (
            (n, f.cell, i)
            for f in base.truth.frames
            if f.t >= first and f.cell is not None
            for i, n in f.shown.items()
            if kinds[i] == "building"
        ),
    )
    _, cell, obj = best
    planted = _walkable(build_city_db(tmp_path / "city.db", name="city", size=150.0, k=100_000, drop={cell: {obj}}).path)
    got = _replay(planted, truth_every=EVERY)
    assert got.truth is not None
    frames = [f for f in got.truth.frames if f.cell == cell and f.t >= got.summary["time_to_first_perfect_frame_s"]]
    assert frames and any(f.shown.get(obj, 0) > 100 for f in frames)
    lod2 = _lod2(planted)
    for f in frames:
        pvs_px = int(f.missing_px[CAUSES.index("pvs")])
        # exactly the building's pixels in the truth, all of them attributed to it
        assert pvs_px == f.shown.get(obj, 0) == f.missing.get(obj, 0)
        assert f.missing_px[CAUSES.index("culled")] == 0
        # counted again through the client's own renderer: every object at LOD2
        with FrameRenderer((640, 480), ctx=gl) as fr:
            for i, m in lod2.items():
                fr.upload((i, 2), m)
            ids = fr.draw_ids([(i, 2) for i in lod2], f.view, PROJ)
        assert int((ids == obj + 1).sum()) == pvs_px
    # other cells are untouched
    assert all(f.missing_px[0] == 0 for f in got.truth.frames if f.cell != cell and f.cell is not None)


PROJ = np.asarray(perspective(60.0, 640 / 480, 0.5, 2000.0))
"""The replay's camera projection (640 x 480, 60 degrees)."""


def _lod2(db: Path) -> dict[int, Any]:
    with SceneReader.open(db) as r:
        info = r.object_info(r.object_ids().tolist())
        out = {}
        for i, o in info.items():
            out[i] = build_lods(r.building(i))[2] if o.kind == "building" else build_street(r.street(i))
    return out


def test_report_shows_the_truth(runs: tuple[ReplayResult, ReplayResult], tmp_path: Path) -> None:
    _, res = runs
    index = write_report(tmp_path, res.summary, res.log, res.bytes_log, truth=res.truth)
    report = json.loads((tmp_path / "report.json").read_text())
    assert res.truth is not None and report["truth"]["frames"] == len(res.truth.log)
    for name in ("error.png", "truth.csv", "truth/worst_client.png", "truth/worst_truth.png", "truth/worst_missing.png",
                 "truth/worst_colour.png", "truth/worst_colour_client.png", "truth/worst_colour_de.png"):
        assert (tmp_path / name).read_bytes()[:4] in (b"\x89PNG", b"fram"), name
    page = index.read_text()
    assert "error.png" in page and "worst_missing.png" in page and "Ground truth" in page
    assert "worst_colour.png" in page and "dE00" in page
    colour = report["truth"]["colour"]
    assert colour["frames"] == len(res.truth.log) and colour["metric"] == "CIEDE2000"
    for key in ("mean_error", "visible_pixels", "psnr_db", "delta_e_mean", "causes"):
        assert all(v is not None for v in colour[key].values()), key
    # the right object at LOD2 is never the wrong colour (a box's facade picture whose edge
    # covers a pixel the box's id does not is the box's: lod_colour)
    assert colour["causes"]["other"] == 0.0
    assert "truth_samples" not in colour and "picture_samples" not in colour  # point-sampled, as always
    # the viewer-scale (S-CIELAB) figures are asked for (--viewer-ppd): none without it
    assert res.truth.log.colour is not None and res.truth.log.colour.visible_scielab is None
    for key in ("viewer_ppd", "visible_scielab_pixels", "delta_e_scielab_mean", "causes_scielab",
                "frames_over_visible_scielab_ratio"):
        assert key not in colour, key
    assert "visible_scielab" not in colour["per_frame"] and "reached_scielab" not in report["truth"].get("impostor", {})
    assert not (tmp_path / "truth/worst_colour_de_scielab.png").exists() and "S-CIELAB" not in page
    assert "scielab" not in (tmp_path / "truth.csv").read_text().splitlines()[0]


def test_cli_truth_every(every_db: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], gl_ctx: Any) -> None:
    out = tmp_path / "rep"
    assert main(["replay", str(every_db), "--device", "desktop2003", "--duration", "3s", "--truth-every", "25",
                 "--viewer-ppd", "24", "--truth-samples", "2", "--report", str(out)]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["truth"]["frames"] == len(range(0, report["frames"], 25))
    # asked for: the viewer-scale (S-CIELAB) figures beside the per-pixel ones
    colour = report["truth"]["colour"]
    assert colour["viewer_ppd"] == 24.0
    # asked for: the full scene anti-aliased (2 x 2), the client's picture as drawn
    assert colour["truth_samples"] == "2x2" and colour["picture_samples"] == "1"
    for key in ("visible_scielab_pixels", "delta_e_scielab_mean", "causes_scielab"):
        assert all(v is not None for v in colour[key].values()), key
    assert colour["frames_over_visible_scielab_ratio"] is not None and "visible_scielab" in colour["per_frame"]
    assert (out / "truth/worst_colour_de_scielab.png").read_bytes()[:4] == b"\x89PNG"
    assert "S-CIELAB" in (out / "index.html").read_text()
    assert "visible_scielab" in (out / "truth.csv").read_text().splitlines()[0]
    assert (out / "error.png").exists()
    with pytest.raises(InputError, match="truth-every"):
        ReplayConfig(link=LinkProfile(1.0, 1.0, 0.1), truth_every=-1)


def test_bench_stream_truth_every(every_db: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], gl_ctx: Any) -> None:
    """``bench stream --truth-every`` prints a second table, one line per scenario, from each walk's truth."""
    out = tmp_path / "bench"
    argv = ["bench", "stream", str(every_db), "--only", "SM 56k", "--duration", "3s", "--truth-every", "25", "--out", str(out)]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "culled% max" in text and "compared" in text and "PSNR med" in text  # and the colour table
    rows = json.loads((out / "bench_stream.json").read_text())
    assert [r["scenario"] for r in rows] == ["SM 56k prefetch"]
    t = rows[0]["truth"]
    assert t["frames"] == len(range(0, rows[0]["frames"], 25)) > 0
    assert t["missing"]["culled"]["max"] == 0.0
    line = next(ln for ln in text.splitlines() if ln.startswith("SM 56k prefetch") and ln.split()[3] == str(t["frames"]))
    assert line
    assert (out / "01-sm-56k-prefetch" / "error.png").exists()


def test_truth_too_big_for_one_buffer_is_a_clear_error(monkeypatch: pytest.MonkeyPatch) -> None:
    """A scene too large for one GL buffer fails with a RenderError naming the size, before any GL call."""
    import walkstream.client.truth.render as render
    from walkstream.shared.errors import RenderError

    scene = load_geojson_dict(generate_city(120, 3))
    lod2 = {b.id: build_lods(b)[2] for b in scene.buildings}
    monkeypatch.setattr(render, "MAX_BUFFER_BYTES", 1024)
    with pytest.raises(RenderError, match=r"objects at LOD2 need a .* GiB buffer"):
        TruthRenderer(lod2, (64, 48))


def test_the_ground_plane_changes_colours_below_the_horizon_and_no_id(gl: Any) -> None:
    """Both renderers draw the ground plane (shared/ground.py): the same colours, the ids
    of frames without it, no sky below the horizon, the sky above it."""
    from walkstream.client.draw.meshes import BACKGROUND_RGB
    from walkstream.client.truth.horizon import below_horizon, horizon_shares
    from walkstream.shared.ground import GROUND_Z

    scene = load_geojson_dict(generate_city(120, 3))
    lod2 = {b.id: build_lods(b)[2] for b in scene.buildings[:4]} | {s.id: build_street(s) for s in scene.streets[:3]}
    eye = np.array([*scene.streets[0].ring.mean(axis=0), 1.7])
    view = camera(eye, 0.7)
    keys = [(i, 2) for i in sorted(lod2)]
    with TruthRenderer(lod2, (160, 120), ctx=gl) as bare, TruthRenderer(lod2, (160, 120), ground_z=GROUND_Z, ctx=gl) as tr:
        bare_rgb, bare_ids = bare.colour_frame(eye, view)
        t_rgb, t_ids = tr.colour_frame(eye, view)
        with FrameRenderer((160, 120), ctx=gl) as fr:
            fr.ground_z = GROUND_Z
            for i, m in lod2.items():
                fr.upload((i, 2), m)
            fr.draw(keys, view)
            c_rgb = fr.snapshot()
            c_ids = fr.draw_ids(keys, view)
    np.testing.assert_array_equal(t_ids, bare_ids)  # the plane is key 0: no pixel's id changes
    np.testing.assert_array_equal(t_ids, c_ids)
    assert int(np.abs(t_rgb.astype(int) - c_rgb.astype(int)).max()) <= 2
    sky = np.all(np.abs(c_rgb.astype(int) - BACKGROUND_RGB) <= 2, axis=2)
    # the camera looks level: the horizon is the middle row; below it the ground or an object
    assert not sky[61:].any() and sky[:59][c_ids[:59] == 0].all()
    ground = (c_ids == 0) & ~sky
    assert ground[61:].sum() > 100  # the few objects leave ground in view
    # the figures below the horizon: without the plane whatever shows no object is sky
    below = below_horizon(view, tr.proj, (160, 120))
    assert below[61:].all() and not below[:59].any()
    sky_share, bare_share = horizon_shares(bare_rgb, bare_ids, below)
    assert sky_share == bare_share > 0.05
    assert horizon_shares(c_rgb, c_ids, below) == (0.0, bare_share)


def test_bench_streams_truth_table_prints_the_pvs_figures() -> None:
    """``bench stream --truth-every``: the share of frames over 0.01 % and the mean, per row."""
    from walkstream.benchmarks.stream import format_truth_table
    from walkstream.client.report.truth import TruthLog, summarise_truth

    k = CAUSES.index("pvs")
    miss = np.zeros((4, len(CAUSES)))
    miss[1:3, k] = 3e-4  # two of the four frames from the first perfect one
    truth = summarise_truth(TruthLog(np.arange(4), np.arange(4.0), np.zeros(4), miss), 0.0)
    table = format_truth_table([{"scenario": "kouvola SE 56k", "truth": truth}])
    head, _, line = table.splitlines()
    assert "pvs>0.01%" in head and "pvs% mean" in head
    cols = line.split()
    assert cols[:3] == ["kouvola", "SE", "56k"]
    assert "50.00" in cols and "0.0150" in cols  # 2 of 4 frames; mean 1.5e-4 as a percentage
    # a report without the figure (an older report.json) prints n/a, not a KeyError
    del truth["pvs_over_hundredth_percent_ratio"]
    assert "n/a" in format_truth_table([{"scenario": "old", "truth": truth}])
