"""Interiors II: portal culling with visible screen areas (shared/portals.py).

The conservative test renders the whole building with object ids and no culling
(:class:`~walkstream.client.truth.render.TruthRenderer`, 160 x 120) and checks that
no part showing in it was culled, at frames through every door, opening and stair of
a generated office, FZK-Haus and duplex: the eye on the portal plane (1 cm either
side, and on it), looking through it and obliquely, looking along the wall that holds
the door, and climbing and descending the stairs.  A second test plants the paper's
bug (portal vertices projected as they are, behind the eye too) and shows the check
catches it.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from portalscene import EYE, SIZE, PortalScene, walk_every_door

from walkstream.cli import main
from walkstream.server.bake import bake
from walkstream.server.sources.interiorgen import InteriorPlan, write_interior
from walkstream.shared.camera import camera, perspective
from walkstream.shared.partcull import cull_parts
from walkstream.shared.portalgraph import PortalGraph
from walkstream.shared.portals import cull_portals, frustum_cells
from walkstream.shared.roomview import cell_of
from walkstream.shared.roomwire import ContentsRef, PortalRef, RoomRecord, Topology
from walkstream.shared.screenrects import box_rects

# --------------------------------------------------------------------------- a tiny hand-made interior


def _box_cell(cid: int, x0: float, x1: float, portals: tuple[PortalRef, ...]) -> RoomRecord:
    planes = np.array([[-1, 0, 0, x0], [1, 0, 0, -x1], [0, -1, 0, -2], [0, 1, 0, -2], [0, 0, -1, 0], [0, 0, 1, -3]], float)
    return RoomRecord(
        id=cid, kind="room", name=f"c{cid}", room=None, storey=0,
        outline=np.array([[x0, -2], [x1, -2], [x1, 2], [x0, 2]], float), zmin=0.0, zmax=3.0,
        planes=planes, portals=portals, neighbours=tuple(sorted({p.cell for p in portals})),
        contents=ContentsRef(0, 0, 0, 0, 0, 0.0),
    )


def _door(pid: int, x: float, to: int, y0: float = -0.5, y1: float = 0.5) -> PortalRef:
    return PortalRef(pid, "door", np.array([[x, y0, 0], [x, y1, 0], [x, y1, 2], [x, y0, 2]], float), to)


def _corridor(n: int, doors_per_wall: int = 1) -> Topology:
    """``n`` cells of 4 x 4 m in a row along x, joined by ``doors_per_wall`` doors."""
    cells = []
    for i in range(n):
        refs: list[PortalRef] = []
        for k in range(doors_per_wall):
            y0 = -1.8 + 3.6 * k / doors_per_wall if doors_per_wall > 1 else -0.5
            y1 = y0 + 3.6 / doors_per_wall - 0.1 if doors_per_wall > 1 else 0.5
            if i > 0:
                refs.append(_door(100 * i + k, 4.0 * i, i - 1, y0, y1))
            if i < n - 1:
                refs.append(_door(100 * (i + 1) + k, 4.0 * (i + 1), i + 1, y0, y1))
        cells.append(_box_cell(i, 4.0 * i, 4.0 * (i + 1), tuple(refs)))
    return Topology((), tuple(cells), (), ())


def _cam(eye: tuple[float, float, float], yaw: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    e = np.array(eye, float)
    return e, camera(e, yaw).astype(np.float64), perspective(60.0, SIZE[0] / SIZE[1], 0.1, 100.0).astype(np.float64)


def test_vsa_is_the_portal_rectangle_rounded_outward() -> None:
    g = PortalGraph.from_topology(_corridor(2))
    e, view, proj = _cam((2.0, 0.0, 1.0), 0.0)
    pc = cull_portals(g, 0, e, view, proj, SIZE)
    assert pc.order == [0, 1]
    rect = np.array(pc.vsas[1][0])
    # the door x = 4, y in [-0.5, 0.5], z in [0, 2] seen from 2 m: project its corners
    vp = proj @ view
    c = np.array([[4, -0.5, 0, 1], [4, 0.5, 0, 1], [4, 0.5, 2, 1], [4, -0.5, 2, 1]], float) @ vp.T
    px = (c[:, :2] / c[:, 3:] + 1) * 0.5 * np.array(SIZE)
    want = np.floor([px[:, 0].min(), px[:, 1].min(), px[:, 0].max(), px[:, 1].max()]).astype(int)
    want = np.maximum(np.minimum(want, [SIZE[0] - 1, SIZE[1] - 1] * 2), 0)
    assert rect.tolist() == want.tolist()
    # looking away, the door is behind the eye: culled
    e, view, proj = _cam((2.0, 0.0, 1.0), math.pi)
    assert cull_portals(g, 0, e, view, proj, SIZE).order == [0]


def test_a_door_beside_the_eye_is_clipped_not_flipped() -> None:
    """The eye 30 cm before the door plane, looking along it: two door corners are
    behind the eye.  Clipped, the door's rectangle is the screen's half on the door's
    side; the paper's projection flips those corners and loses the door."""
    g = PortalGraph.from_topology(_corridor(2))
    e, view, proj = _cam((3.7, -0.3, 1.0), math.pi / 2 - 0.2)  # looking north, a little east
    pc = cull_portals(g, 0, e, view, proj, SIZE)
    assert 1 in pc.order
    naive = cull_portals(g, 0, e, view, proj, SIZE, naive=True)
    assert 1 not in naive.order or not np.array_equal(naive.vsas[1], pc.vsas[1])


def test_eye_on_the_portal_plane_passes_the_parent_vsa_through() -> None:
    g = PortalGraph.from_topology(_corridor(3))
    for dx in (-0.01, -0.003, 0.0, 0.003, 0.01):
        for yaw in (0.0, 0.7, -0.7, math.pi / 2 - 0.1):
            e, view, proj = _cam((4.0 + dx, 0.0, 1.0), yaw)
            pc = cull_portals(g, 0, e, view, proj, SIZE)
            assert 1 in pc.order and [list(v) for v in pc.vsas[1]] == [[0, 0, SIZE[0] - 1, SIZE[1] - 1]], (dx, yaw)


def test_many_paths_do_not_grow_exponentially_and_depth_and_fog_stop() -> None:
    # 12 cells, 4 doors per wall: 4**11 paths to the last cell
    g = PortalGraph.from_topology(_corridor(12, doors_per_wall=4))
    e, view, proj = _cam((0.5, 0.0, 1.5), 0.0)
    pc = cull_portals(g, 0, e, view, proj, SIZE)
    assert pc.order == list(range(12)) and len(set(pc.order)) == 12
    assert pc.tested < 12 * 8 * 4  # each cell looked through a few times at most
    assert all(len(v) <= 4 for v in pc.vsas.values())
    assert cull_portals(g, 0, e, view, proj, SIZE, max_depth=3).order == [0, 1, 2, 3]
    # fog: the door at x = 8 is 7.5 m away, the one at x = 12 11.5 m
    assert cull_portals(g, 0, e, view, proj, SIZE, fog_m=10.0).order == [0, 1, 2]
    assert frustum_cells(g, 0, e, proj @ view, fog_m=10.0) == [0, 1, 2]


def test_box_rects_clip_boxes_that_hold_the_eye() -> None:
    e, view, proj = _cam((0.0, 0.0, 1.0), 0.0)
    rect, front = box_rects([[-1, -1, 0]], [[1, 1, 2]], view, proj, SIZE)
    assert front[0] and rect[0, 0] < 0 and rect[0, 2] >= SIZE[0] - 1
    _, front = box_rects([[-3, -1, 0]], [[-2, 1, 2]], view, proj, SIZE)  # behind the eye
    assert not front[0]


# --------------------------------------------------------------------------- conservative, on real scenes


def test_generated_office_every_door_zero_missed_pixels_and_the_papers_bug_is_caught(
    office_db: Path, gl_ctx: Any
) -> None:
    scene = PortalScene(office_db, gl_ctx)
    try:
        good = walk_every_door(scene)
        assert good["frames"] >= 100
        assert good["missed"] == 0 and good["leaks"] == 0 and good["pinholes"] == 0, good
        assert scene.triangle_culled > 0  # the parts' triangles were tested, and some dropped
        bad = walk_every_door(scene, naive=True)
        assert bad["frames"] == good["frames"]
        assert bad["bad_frames"] >= 0.1 * bad["frames"] and bad["missed"] > 10_000, bad
    finally:
        scene.release()


def test_fzk_haus_every_door_zero_missed_pixels(fzk_db: tuple[Path, dict[str, Any]], gl_ctx: Any) -> None:
    scene = PortalScene(fzk_db[0], gl_ctx)
    try:
        got = walk_every_door(scene)
        assert got["frames"] >= 50 and got["missed"] == 0, got
        assert got["leaks"] == 0 and got["pinholes"] <= 3, got
    finally:
        scene.release()


def test_duplex_every_door_zero_missed_pixels(duplex_db: tuple[Path, dict[str, Any]], gl_ctx: Any) -> None:
    scene = PortalScene(duplex_db[0], gl_ctx)
    try:
        got = walk_every_door(scene)
        # duplex's IFC spaces stop short of their walls and its door openings have no
        # reveals: from an eye inside a door hole, rays run inside the wall to faces no
        # cell holds (``leaks``, the source's partition, counted apart); nothing else
        assert got["frames"] >= 200 and got["missed"] == 0, got
        assert got["leaks"] < 0.02 * got["frames"] * SIZE[0] * SIZE[1], got
    finally:
        scene.release()


def test_duplex_bedroom_door_seen_at_the_frames_edge_is_not_culled(
    duplex_db: tuple[Path, dict[str, Any]], gl_ctx: Any
) -> None:
    """A replay's pose on the duplex's upper hallway: the right edge of the frame looks
    through the bedroom door's doorway cell past the end of its bedroom-side portal,
    which stopped 37 mm short of the opening (a face split by a vertex, its short
    piece dropped); 85 pixels of the bedroom were culled."""
    scene = PortalScene(duplex_db[0], gl_ctx)
    try:
        got = scene.frame(np.array([-3.076, -0.908, 4.70]), math.radians(-15.25))
        assert got is not None
        chk, _start, _view = got
        assert chk.missed_pixels - chk.pinholes == 0, sorted(chk.missed)
    finally:
        scene.release()


def test_portal_culling_draws_fewer_triangles_than_frustum_alone(office_db: Path, gl_ctx: Any) -> None:
    scene = PortalScene(office_db, gl_ctx)
    try:
        tris = {"portals": 0, "frustum": 0, "none": 0}
        for k, (eye, yaw, pitch) in enumerate(scene.poses()):
            hit = np.flatnonzero(cell_of(scene.planes, eye))
            if k % 5 or not len(hit):
                continue
            start = int(scene.ids[hit[0]])
            view = camera(eye, yaw, pitch).astype(np.float64)
            pc = cull_portals(scene.graph, start, eye, view, scene.proj, SIZE)
            cells = frustum_cells(scene.graph, start, eye, scene.proj @ view)
            assert set(pc.order) <= set(cells)
            for mode in tris:
                keep = cull_parts(mode, pc.order if mode == "portals" else cells, scene.boxes, eye, view,
                                  scene.proj, SIZE, vsas=pc.vsas)
                tris[mode] += sum(scene.meshes[c].parts[i].triangles for c, m in keep.items() for i in np.flatnonzero(m))
        assert tris["portals"] < 0.8 * tris["frustum"] < tris["none"], tris
    finally:
        scene.release()


def test_replay_culling_switch_on_an_interior(office_db: Path, tmp_path: Path) -> None:
    import json

    got = {}
    for mode in ("portals", "frustum"):
        rep = tmp_path / mode
        plots = mode == "portals"  # the other without its plots: --no-plots
        assert main(["replay", str(office_db), "--path", "tour", "--duration", "8", "--culling", mode,
                     "--truth-every", "40", "--size", "160x120", "--report", str(rep),
                     *([] if plots else ["--no-plots"])]) == 0
        s = json.loads((rep / "report.json").read_text())
        s = s.get("summary", s)
        assert s["culling"] == mode and s["culling_ms_median"] > 0
        # the culling's CPU time split: the walk and the triangle test are parts of it, frame
        # by frame; the triangle test is made after the portal walk only
        assert 0 < s["culling_walk_ms_median"] <= s["culling_ms_median"] <= s["culling_ms_p99"]
        assert s["culling_triangles_ms_median"] <= s["culling_ms_median"]
        assert (s["culling_triangles_ms_median"] > 0) == (mode == "portals")
        # the ground truth on an interior: no part culled shows (late cells are not culled)
        assert s["truth"]["frames"] >= 4 and s["truth"]["culled_pixels"] == 0, s["truth"]
        # the colour truth agrees: what the frame waited for, or kept at the same depth, is not culled
        assert s["truth"]["colour"]["causes"]["culled"] == 0, s["truth"]["colour"]["causes"]
        assert set(s["truth"]) == {"frames", "culled_pixels", "culled_frames", "pinholes", "refused_poses",
                                   "fog_hidden_pct", "tightness_mean", "tightness_p95", "colour"}
        page = (rep / "index.html").read_text()
        assert s["truth"]["colour"]["frames"] >= 4 and (rep / "truth.csv").exists()
        if plots:  # the colour error against the full scene without fog, and its plot
            assert "error.png" in page
            assert (rep / "interior.png").read_bytes()[:4] == b"\x89PNG" and "interior.png" in page
            assert (rep / "culled.png").read_bytes()[:4] == b"\x89PNG" and "culled.png" in page
        else:  # the same figures, no plot drawn, and the page says so
            assert not list(rep.glob("*.png")) and "--no-plots" in page and "culled_pixels" in page
        got[mode] = s["triangles_mean"]
    assert got["portals"] < got["frustum"]


def test_bench_portals_figures(office_db: Path, gl_ctx: Any) -> None:
    from walkstream.benchmarks.portals import hall_figures, portal_figures, portals_tables

    fig = portal_figures(office_db, frames=8, step_s=10.0, size=(160, 120), truth_frames=4)
    m = fig["modes"]
    assert fig["frames"] == 8 and fig["missed_pixels"] == 0
    assert m["portals"]["tris"]["mean"] <= m["frustum"]["tris"]["mean"] <= m["none"]["tris"]["mean"]
    assert m["none"]["cells"]["mean"] == fig["cells"] + 1  # every cell, the outside too
    assert fig["tightness"]["portals"]["mean"] <= fig["tightness"]["frustum"]["mean"]
    assert all(v["gl_ms"]["median"] > 0 and v["pda_ms"]["median"] > 0 for v in m.values())
    halls = hall_figures((3, 6), repeats=2)
    assert [h["visible"] for h in halls][0] == 9 and halls[1]["visible"] > 20
    assert "Table 1" in portals_tables([fig], halls)


def test_fog_fades_surfaces_into_the_background(gl_ctx: Any) -> None:
    from walkstream.client.draw.frames import FrameRenderer
    from walkstream.client.draw.meshes import BACKGROUND_RGB
    from walkstream.shared.records import Mesh

    # a wall 10 m ahead, facing the eye
    pos = np.array([[10, -5, -5], [10, 5, -5], [10, 5, 5], [10, -5, 5]], np.float32)
    wall = Mesh(pos, np.tile(np.float32([-1, 0, 0]), (4, 1)), np.array([[0, 2, 1], [0, 3, 2]], np.uint32),
                np.zeros(4, np.uint8))
    r = FrameRenderer(size=(64, 48), near=0.1, far=100.0, ctx=gl_ctx)
    try:
        r.upload("wall", wall)
        view = camera(np.zeros(3), 0.0)
        centre = []
        for fog in (0.0, 100.0, 11.0, 9.0):
            r.fog_m = fog
            r.draw(["wall"], view)
            centre.append(r.snapshot()[24, 32].astype(int))
        bg = np.array(BACKGROUND_RGB)
        assert np.abs(centre[0] - bg).sum() > 30  # no fog: the wall
        assert np.array_equal(centre[1], centre[0])  # fog far beyond: unchanged
        assert 0 < np.abs(centre[2] - bg).sum() < np.abs(centre[0] - bg).sum()  # fading
        assert np.abs(centre[3] - bg).sum() <= 3  # beyond the fog: the background
    finally:
        r.release()


def test_the_walk_stops_at_the_fog_not_at_a_depth_the_fog_still_shows() -> None:
    """A corridor of 12 segments, 4 m each: at the client's and the server's default fog
    (40 m) every segment whose door is within the fog is seen, however many doors on."""
    from walkstream.client.stream.rooms import RoomStreamConfig
    from walkstream.shared.roomview import RoomView

    g = PortalGraph.from_topology(_corridor(12))
    e, view, proj = _cam((0.5, 0.0, 1.5), 0.0)
    for fog, depth in ((RoomView().fog_m, RoomView().max_depth),
                       (RoomStreamConfig().fog_m, RoomStreamConfig().max_depth)):
        pc = cull_portals(g, 0, e, view, proj, SIZE, fog_m=fog, max_depth=depth)
        # the door at x = 40 is 39.5 m away (within the fog), the one at x = 44 43.5 m
        assert pc.order == list(range(11)), pc.order
        assert frustum_cells(g, 0, e, proj @ view, fog_m=fog, max_depth=depth) == list(range(11))


def test_a_gl_replay_with_its_frame_schedule_repeats_exactly(office_db: Path, tmp_path: Path) -> None:
    """The gl device times frames on llvmpipe; given the first run's frame times, a
    second run walks the same frames and its ground truth compares the same poses."""
    import json

    runs = {}
    for name, extra in (("first", []), ("again", ["--frame-times", str(tmp_path / "first")])):
        rep = tmp_path / name
        assert main(["replay", str(office_db), "--path", "tour", "--duration", "3", "--device", "gl",
                     "--truth-every", "25", "--size", "96x72", "--report", str(rep), *extra]) == 0
        s = json.loads((rep / "report.json").read_text())
        runs[name] = ((rep / "frames.csv").read_text(), s.get("summary", s)["truth"])
    assert runs["first"] == runs["again"]
    assert main(["replay", str(office_db), "--frame-times", str(tmp_path / "nowhere"),
                 "--report", str(tmp_path / "x")]) == 2


# --------------------------------------------------------------------------- a property: any generated interior


@st.composite
def _plans(draw: st.DrawFn) -> InteriorPlan:
    storeys = draw(st.integers(1, 2))
    width = draw(st.floats(13.0, 15.0)) if storeys > 1 else draw(st.floats(8.0, 14.0))
    lo = draw(st.floats(2.6, 4.0))
    return InteriorPlan(storeys=storeys, length=draw(st.floats(12.0, 16.0)), width=width,
                        seed=draw(st.integers(0, 10**6)), room_width=(lo, lo + draw(st.floats(0.0, 2.0))),
                        doors_per_segment=draw(st.integers(1, 2)), furniture=draw(st.sampled_from([0.0, 1.0])))


@settings(max_examples=2, deadline=None, derandomize=True)
@given(plan=_plans(), data=st.data())
def test_any_generated_interior_culls_no_pixel_the_truth_shows(
    plan: InteriorPlan, data: st.DataObject, gl_ctx: Any, tmp_path_factory: pytest.TempPathFactory
) -> None:
    """Generated interiors (seed, storeys, size, rooms, doors, furniture) and poses: every
    door and stair as the walk-every-door test takes them (eyes on the portal planes),
    and eyes anywhere in random cells, looking anywhere; no culled pixel (pinholes apart)."""
    d = tmp_path_factory.mktemp("prop")
    write_interior(d / "gen.json", plan)
    bake(d / "gen.json", d / "gen.db")
    _ = gl_ctx.error  # the shared context: an error an earlier test left pending is not this scene's
    scene = PortalScene(d / "gen.db", gl_ctx)
    try:
        got = walk_every_door(scene)
        assert got["frames"] >= 8 and got["missed"] == 0 and got["leaks"] == 0, (plan, got)
        cells = [c for c in scene.topology.cells if c.kind == "room" and len(c.planes)]
        for _ in range(12):
            c = data.draw(st.sampled_from(cells))
            lo, hi = c.outline.min(axis=0), c.outline.max(axis=0)
            u = np.array([data.draw(st.floats(0.05, 0.95)), data.draw(st.floats(0.05, 0.95))])
            eye = np.array([*(lo + u * (hi - lo)), c.zmin + EYE])
            yaw, pitch = data.draw(st.floats(-math.pi, math.pi)), data.draw(st.floats(-0.5, 0.5))
            res = scene.frame(eye, yaw, pitch)
            if res is None:
                continue  # a concave room's box corner lies in no cell
            chk, start, view = res
            real = chk.missed_pixels - chk.pinholes
            assert real == 0 or scene.leaks(chk, eye, view, start) >= 0.75 * min(24, chk.missed_pixels), \
                (plan, eye.tolist(), yaw, pitch, real)
    finally:
        scene.release()


def test_bench_portals_seed_rows_are_parsed_and_tabled() -> None:
    from walkstream.benchmarks.portals import seed_table
    from walkstream.cli import build_parser

    args = build_parser().parse_args(["bench", "portals", "--presets", "--seeds", "11", "13", "--seed-duration", "20s"])
    assert args.seeds == [11, 13] and args.seed_duration == "20s" and args.presets == []
    assert build_parser().parse_args(["bench", "portals"]).seeds == []  # none unless asked
    with pytest.raises(SystemExit):
        build_parser().parse_args(["bench", "portals", "--seeds", "eleven"])
    row = {"seed": 11, "duration": "20s", "perfect_frame_ratio": 0.99637, "time_to_first_perfect_frame_s": 4.0877,
           "culled_pixels": 0, "truth_frames": 12, "tightness_p95": 3.907, "bytes_received": 79662,
           "start_contents_cells": 39, "culling_ms_median": 2.5, "late_cells": 2, "cpu_ms_per_frame": 11.04}
    table = seed_table([row, {**row, "seed": 13, "culled_pixels": None, "tightness_p95": None}]).splitlines()
    assert table[0].split()[:4] == ["seed", "walked", "perfect%", "1st"] and table[0].split()[-2:] == ["cpu", "ms/fr"]
    assert table[1].split() == ["11", "20s", "99.64", "4.09", "0", "12", "3.91", "79.7", "39", "2.50", "2", "11.0"]
    assert table[2].split()[4] == "-" and table[2].split()[6] == "-"  # no truth: said so, not zero


def test_bench_portals_whole_tours_say_how_far_they_walked(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    from walkstream.benchmarks.portals import WHOLE_TOUR, seed_rows, seed_table
    from walkstream.cli import build_parser

    args = build_parser().parse_args(["bench", "portals", "--presets", "--seeds", "3", "--seed-duration", "whole"])
    assert args.seed_duration == WHOLE_TOUR
    # a bad duration is named in one line before anything is generated or baked
    assert main(["bench", "portals", "--presets", "--no-gl", "--seeds", "3", "--seed-duration", "soon"]) == 2
    assert "'soon'" in capsys.readouterr().err
    assert args.seed_truth_every == 50  # the truth as before unless asked
    assert main(["bench", "portals", "--presets", "--no-gl", "--seeds", "3", "--seed-truth-every", "-1"]) == 2
    assert "--seed-truth-every -1" in capsys.readouterr().err
    row = {"seed": 3, "duration": WHOLE_TOUR, "perfect_frame_ratio": 1.0, "time_to_first_perfect_frame_s": 2.37,
           "culled_pixels": 0, "truth_frames": 600, "tightness_p95": 2.5, "bytes_received": 990000,
           "start_contents_cells": 30, "culling_ms_median": 3.0, "late_cells": 0, "walked_s": 1328.4}
    assert seed_table([row]).splitlines()[1].split()[:2] == ["3", "1328s"]  # the tour's length, not "whole"
    assert seed_table([{**row, "walked_s": None}]).splitlines()[1].split()[1] == "whole"
    seen: list[dict[str, object]] = []

    def replay(db: str, options: dict[str, object], title: str) -> object:
        seen.append(options)
        return type("R", (), {"summary": {"duration_s": 12.0, "frames": 300 if options.get("duration") else 0}})()

    (tmp_path / "seed3.db").touch()  # baked already: the rows only replay
    rows_whole = seed_rows([3], replay, tmp_path, duration="whole", truth_every=0)
    rows = seed_rows([3], replay, tmp_path, duration="20s", truth_every=50)
    assert "duration" not in seen[0] and seen[1]["duration"] == "20s"  # whole: no limit on the replay
    assert seen[0]["truth_every"] == 0 and seen[1]["truth_every"] == 50
    assert rows[0]["walked_s"] == 12.0
    assert rows[0]["cpu_ms_per_frame"] >= 0.0  # the replay's CPU time over the frames it walked
    assert rows_whole[0]["cpu_ms_per_frame"] is None  # no frame walked: not a figure
