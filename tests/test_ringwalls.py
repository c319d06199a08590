"""Textured virtual walls outdoors (issue 28 item 2, a cell's far field): rings of walls
around a city's cells whose PVS is large, their textures, the cut PVS, the client's draw.
"""

from __future__ import annotations

import io
import math
import shutil
import sqlite3
from dataclasses import replace
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
from asgiclient import Http
from PIL import Image
from startparts import start_parts

from walkstream.client.config import ReplayConfig
from walkstream.client.net.link import LinkProfile
from walkstream.client.replay import ReplayResult, run_replay
from walkstream.client.truth.colour import COLOUR_CAUSES
from walkstream.server.bake import BakeSettings, bake
from walkstream.server.bake.impostorsettings import ImpostorSettings
from walkstream.server.bake.ringwalls import plan_ring_walls, ring_regions
from walkstream.server.bake.viewcell import ViewCell
from walkstream.server.bake.wallplan import WallSettings
from walkstream.server.service.main import create_app
from walkstream.server.sources.citygen import write_city
from walkstream.server.store import SceneReader
from walkstream.shared.walls import ring_cell, zone_count
from walkstream.shared.wire import MSGPACK

URL = "http://walkstream.test"
FAST = BakeSettings(resolution=32, sampling="corners")
# few textures (a wide error, large regions, coarse texels): the bake stays a few seconds
RINGS = WallSettings(keep=5, ring_min=10.0, region=80.0, error_deg=30.0, outdoor_texels_per_m=2.0, outdoor_max_side=64)


def _cell(cid: int, x0: float, y0: float, size: float = 10.0, neighbours: tuple[int, ...] = ()) -> ViewCell:
    poly = np.array([[x0, y0], [x0 + size, y0], [x0 + size, y0 + size], [x0, y0 + size]], np.float64)
    return ViewCell(cid, "street", poly, 1.0, 2.0, neighbours)


def _box(x: float, y: float, half: float = 2.0, top: float = 12.0) -> tuple[float, ...]:
    return (x - half, y - half, 0.0, x + half, y + half, top)


# ------------------------------------------------------------------ the plan (no GL)


def test_objects_wholly_beyond_the_ring_leave_the_geometry_pvs_and_crossing_ones_stay() -> None:
    cell = _cell(0, 0.0, 0.0)  # 10 m square: the viewer is within it
    boxes = {1: _box(5, 5), 2: _box(-4, 5), 3: _box(14, 5), 4: _box(5, 60), 5: _box(-70, 0), 6: _box(90, 90)}
    st = WallSettings(keep=3, ring_min=5.0, region=0.0)
    plan = plan_ring_walls([cell], {0: np.array([1, 2, 3, 4, 5, 6])}, boxes, st)
    r = plan.radius[0]
    # the three nearest reach the cell's square within 2 m; the fourth is 53 m out: the ring just inside it
    assert 5.0 <= r < 53.0
    assert plan.kept[0].tolist() == [1, 2, 3]
    assert plan.removed == 3
    sides = plan.walls.sides
    assert len(sides) == 4 and {s.portal for s in sides} == {0, 1, 2, 3} and {ring_cell(s.portal) for s in sides} == {0}
    alpha = math.radians(st.error_deg)
    for s in sides:
        assert s.zones == zone_count(s.length, r, alpha) == len(s.textures)
        # the wall stands r beyond the cell's square, the hidden space (outside) to its left
        mid = (np.asarray(s.p0) + np.asarray(s.p1)) / 2.0
        assert float((mid - np.array([5.0, 5.0])) @ s.normal) == pytest.approx(5.0 + r)
        # a viewer anywhere in the cell sees the texture in full (no geometry behind it to blend with)
        for eye in ([0.5, 0.5, 1.6], [9.5, 9.5, 1.6], [5.0, 5.0, 1.6]):
            assert s.view(eye).weight == 1.0
        # tall enough for the highest object behind it, from the ground
        assert s.z0 == 0.0 and s.z1 >= 12.0
    # the objects meeting the ring are holes in every texture of the ring, never painted on it
    holes = {j[4] for j in plan.walls.jobs}
    assert holes == {(1, 2, 3)}


def test_a_cell_whose_pvs_is_small_gets_no_ring() -> None:
    cell = _cell(0, 0.0, 0.0)
    boxes = {1: _box(5, 5), 2: _box(50, 5)}
    plan = plan_ring_walls([cell], {0: np.array([1, 2])}, boxes, WallSettings(keep=3))
    assert plan.kept == {} and plan.walls.sides == [] and plan.walls.jobs == []


def test_neighbouring_cells_share_one_ring_and_its_textures() -> None:
    cells = [_cell(0, 0.0, 0.0, neighbours=(1,)), _cell(1, 10.0, 0.0, neighbours=(0, 2)), _cell(2, 20.0, 0.0, neighbours=(1,))]
    assert [[c.id for c in r] for r in ring_regions(cells, 25.0)] == [[0, 1], [2]]
    assert [[c.id for c in r] for r in ring_regions(cells, 0.0)] == [[0], [1], [2]]
    boxes = {i: _box(5 + 10 * i, 5) for i in range(3)} | {10 + i: _box(200 + 30 * i, 5) for i in range(4)}
    pvs = {c.id: np.array([0, 1, 2, 10, 11, 12, 13]) for c in cells}
    plan = plan_ring_walls(cells, pvs, boxes, WallSettings(keep=3, ring_min=5.0, region=25.0))
    by_cell: dict[int, list[Any]] = {}
    for s in plan.walls.sides:
        by_cell.setdefault(ring_cell(s.portal), []).append(s)
    assert sorted(by_cell) == [0, 1, 2] and all(len(v) == 4 for v in by_cell.values())
    # cells 0 and 1: one region, the same walls and texture ids under their own portal ids
    assert [s.textures for s in by_cell[0]] == [s.textures for s in by_cell[1]]
    assert not {t for s in by_cell[2] for t in s.textures} & {t for s in by_cell[0] for t in s.textures}
    assert len(plan.walls.jobs) == sum(len(s.textures) for s in by_cell[0] + by_cell[2])
    assert {tuple(k.tolist()) for k in plan.kept.values()} == {(0, 1, 2)}


def test_a_region_grows_only_while_its_ring_at_the_least_distance_keeps_at_most_k() -> None:
    # four 10 m cells in a row, an object in each: a 100 m region would hold all four,
    # and its ring, at the least distance, would keep all four as geometry (K = 2)
    cells = [_cell(i, 10.0 * i, 0.0, neighbours=tuple(n for n in (i - 1, i + 1) if 0 <= n < 4)) for i in range(4)]
    boxes = {i: _box(5 + 10 * i, 5, half=1.0) for i in range(4)} | {10 + i: _box(200 + 30 * i, 5) for i in range(4)}
    pvs = {c.id: np.array(sorted(boxes)) for c in cells}
    st = WallSettings(keep=2, ring_min=3.0, region=100.0)
    assert [[c.id for c in r] for r in ring_regions(cells, st.region)] == [[0, 1, 2, 3]]
    plan = plan_ring_walls(cells, pvs, boxes, st)
    regions = {}
    for s in plan.walls.sides:
        regions.setdefault(s.textures, set()).add(ring_cell(s.portal))
    assert sorted(sorted(v) for v in regions.values()) == [[0, 1], [0, 1], [0, 1], [0, 1], [2, 3], [2, 3], [2, 3], [2, 3]]
    assert all(len(k) <= st.keep for k in plan.kept.values())


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--virtual-walls", "--wall-keep", "-1"], "--wall-keep"),
        (["--virtual-walls", "--wall-ring-min", "0"], "--wall-ring-min"),
        (["--virtual-walls", "--wall-region", "-5"], "--wall-region"),
        (["--wall-keep", "4"], "give --virtual-walls too"),
    ],
)
def test_bad_ring_flags_are_one_clear_line(
    flags: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from walkstream.cli import main

    assert main(["bake", str(tmp_path / "c.geojson"), "-o", str(tmp_path / "x.db"), *flags]) == 2
    err = capsys.readouterr().err
    assert err.startswith("walkstream: error:") and message in err and "Traceback" not in err
    assert not (tmp_path / "x.db").exists()


# ------------------------------------------------------------------ bake, serve, draw (GL)


def _solid(oid: int, box: tuple[float, ...]) -> tuple[int, np.ndarray, np.ndarray]:
    import trimesh

    lo, hi = np.asarray(box[:3]), np.asarray(box[3:])
    m = trimesh.creation.box(extents=hi - lo)
    m.apply_translation((lo + hi) / 2.0)
    tri = np.asarray(m.vertices, np.float64)[np.asarray(m.faces)]
    return oid, tri, np.zeros(len(tri), np.uint8)


@pytest.mark.gl
def test_the_far_object_is_painted_on_the_ring_and_a_crossing_one_is_a_hole(gl: object) -> None:
    from walkstream.server.bake.wallrender import WallRenderer

    cell = _cell(0, 0.0, 0.0)
    # 1 and 4 near (kept); 2 a long block crossing the north wall; 3 far behind it, beside 2
    boxes = {1: _box(5, 5, top=4.0), 2: (20.0, 14.0, 0.0, 24.0, 200.0, 15.0), 3: (-40.0, 100.0, 0.0, 0.0, 104.0, 30.0),
             4: _box(5, -3, top=4.0)}
    plan = plan_ring_walls([cell], {0: np.array([1, 2, 3, 4])}, boxes, WallSettings(keep=3, ring_min=5.0, region=0.0))
    assert plan.kept[0].tolist() == [1, 2, 4] and plan.radius[0] < 90.0
    north = max(plan.walls.sides, key=lambda s: s.p0[1] + s.p1[1])
    job = next(j for j in plan.walls.jobs if j[0] == north.textures[len(north.textures) // 2])
    assert job[4] == (1, 2, 4)  # the objects meeting the ring: holes, never painted
    ren = WallRenderer([_solid(i, boxes[i]) for i in (1, 2, 3, 4)], ctx=gl)
    try:
        img = ren.render(north, job[2], 256, job[4])
        painted = img[..., 3] > 0
        assert painted.any()  # the far object is on the texture
        solo = ren.render(north, job[2], 256, ())
    finally:
        ren.release()
    # where the crossing object stands in front of the far one, the texture is a hole (its
    # geometry behind the wall shows through); without it as a hole it would be painted there
    assert (solo[..., 3] > 0).sum() > painted.sum()


@pytest.fixture(scope="module")
def dbs(tmp_path_factory: pytest.TempPathFactory, gl_ctx: object) -> tuple[Path, Path, dict[str, Any]]:
    d = tmp_path_factory.mktemp("ringwalls")
    write_city(d / "city.geojson", 150, 2)  # 35 cells, 45 objects: both bakes in about 10 s
    # the rings baked together with impostors (small images): the walk draws both, and the facades
    summary = bake(d / "city.geojson", d / "walls.db", settings=FAST, walls=RINGS, name="walls",
                   impostors=ImpostorSettings(size=16, complex_triangles=400).check())
    bake(d / "city.geojson", d / "plain.db", settings=FAST, name="plain")
    return d / "walls.db", d / "plain.db", summary


def _replay(db: Path, **kw: Any) -> ReplayResult:
    app = create_app([db])
    try:
        cfg = ReplayConfig(link=LinkProfile(56_000.0, 56_000.0, 0.2), device="pda", duration_s=6.0,
                           size=(160, 120), **kw)
        return run_replay(httpx.ASGITransport(app=app), URL, cfg)
    finally:
        app.state.scenes.close()


@pytest.fixture(scope="module")
def plain_walk(dbs: tuple[Path, Path, dict[str, Any]]) -> dict[str, Any]:
    """The plain bake's walk (compared with the walls' in two tests: replayed once)."""
    return _replay(dbs[1], truth_every=25).summary


def _pvs(db: Path) -> dict[int, set[int]]:
    with SceneReader.open(db) as r:
        return {c.id: set(np.asarray(c.pvs).tolist()) for c in r.cells()}


@pytest.mark.gl
def test_a_city_bake_rings_its_cells_and_carries_the_far_field_on_the_textures(dbs: tuple[Path, Path, dict[str, Any]]) -> None:
    walls, plain, summary = dbs
    assert summary["ring_cells"] > 0 and summary["ring_removed"] > 0 and summary["wall_textures"] > 0
    assert summary["impostor_images"] > 0  # rings and impostors bake together
    cut, full = _pvs(walls), _pvs(plain)
    assert cut.keys() == full.keys()
    assert all(cut[c] <= full[c] for c in cut)  # only taken away
    assert sum(len(full[c]) - len(cut[c]) for c in cut) == summary["ring_removed"]
    with SceneReader.open(walls) as r:  # what a ring took is stored apart, with its share of the coverage
        far = {c: r.ring_far(c) for c in cut}
    assert sum(f is not None for f in far.values()) == summary["ring_cells"]
    for c, f in far.items():
        assert f is None or (set(f[0].tolist()) == full[c] - cut[c] and 0.0 <= f[2] <= 1.0)
    db = sqlite3.connect(walls)
    try:
        rows = db.execute("SELECT data FROM wall_textures").fetchall()
    finally:
        db.close()
    alpha = [np.asarray(Image.open(io.BytesIO(r[0])).convert("RGBA"))[..., 3] for r in rows]
    # what lies beyond the rings is painted on their textures (the far field), the rest transparent
    assert sum(int((a > 0).any()) for a in alpha) > len(alpha) // 4
    assert all(int((a == 0).any()) for a in alpha)


@pytest.mark.gl
def test_the_client_draws_its_cells_ring_and_fewer_objects_as_geometry(dbs: tuple[Path, Path, dict[str, Any]],
                                                                       plain_walk: dict[str, Any]) -> None:
    walls, _plain, _ = dbs
    w = _replay(walls, truth_every=25).summary
    p = plain_walk
    ws = w["walls"]
    assert ws["frames_with_walls"] > 0.5 and ws["textures_received"] > 0 and ws["texture_bytes"] > 0
    # the rings came as the walk came to their cells: the start bundle's, then by request
    assert ws["ring_requests"] >= 1 and 0 < ws["wall_sides"]
    assert w["facades"]["frames_with_facades"] > 0 and w["perfect_frame_ratio"] >= 0.99  # with the facades, on pda
    assert ws["geometry_objects_mean"] < p["visible_mean"]
    # the walker stands at its start for its first view and first textures, not for the later poses' parts
    assert w["start_hold_s"] <= p["start_hold_s"] + 0.25
    # the far field is on the walls: the truth's colour error stays that of a picture, not of holes
    assert w["truth"]["colour"]["mean_error"]["median"] < 0.1
    off = _replay(walls, virtual_walls=False).summary
    assert "walls" not in off  # no ring asked for, no texture on the link


@pytest.mark.gl
def test_a_ring_wall_whose_texture_never_arrives_shows_its_far_field_as_geometry_never_a_hole(
        dbs: tuple[Path, Path, dict[str, Any]], plain_walk: dict[str, Any], tmp_path: Path) -> None:
    walls, _plain, _ = dbs
    bare = tmp_path / "bare.db"  # the same bake, its textures gone: none ever arrives
    shutil.copy(walls, bare)
    db = sqlite3.connect(bare)
    try:
        db.execute("DELETE FROM wall_textures")
        db.commit()
    finally:
        db.close()
    b = _replay(bare, truth_every=25).summary
    p = plain_walk
    ws = b["walls"]
    assert ws.get("textures_received", 0) == 0 and ws["walls_mean"] == 0.0
    # every frame with a ring wall in view draws the far field as geometry: no hole, and whole
    assert ws["far_field_frames"] > 0.5 and ws["texture_missing_frames"] == 0.0
    assert b["visible_mean"] >= 0.95 * p["visible_mean"]  # the objects the plain bake's PVS draws
    assert b["perfect_frame_ratio"] >= p["perfect_frame_ratio"] - 0.02
    assert b["truth"]["colour"]["mean_error"]["median"] <= p["truth"]["colour"]["mean_error"]["median"] + 0.005
    db = sqlite3.connect(bare)  # a city baked with walls before the far field was stored: served as before
    try:
        db.execute("DROP TABLE ring_far")
        db.commit()
    finally:
        db.close()
    with SceneReader.open(bare) as r:
        assert all(r.ring_far(c.id) is None for c in r.cells())


def test_the_walls_route_sends_the_rings_of_the_cells_asked_and_the_start_bundle_its_first_ring(
        dbs: tuple[Path, Path, dict[str, Any]]) -> None:

    from walkstream.shared.walls import decode_walls

    walls, _plain, _ = dbs
    app = create_app([walls])
    c = Http(app)
    try:
        every = decode_walls(c.get("/v1/scenes/walls/walls", headers={"Accept": MSGPACK}).content, "all")
        ringed = sorted({ring_cell(s.portal) for s in every})
        with SceneReader.open(walls) as r:
            bare = sorted({int(x.id) for x in r.cells()} - set(ringed))
        ask = [ringed[0], ringed[-1], *bare[:1]]
        got = decode_walls(c.get("/v1/scenes/walls/walls", params={"cells": ",".join(map(str, ask))},
                                 headers={"Accept": MSGPACK}).content, "some")
        assert sorted(s.to_row() for s in got) == sorted(s.to_row() for s in every if ring_cell(s.portal) in ask)
        assert 0 < len(got) < len(every)
        for bad in ("x", "1,,2", "-3", ",".join(["1"] * 2) + "," + ",".join(str(i) for i in range(300))):
            r = c.get("/v1/scenes/walls/walls", params={"cells": bad}, headers={"Accept": MSGPACK})
            assert r.status_code == 422 and len(r.text.splitlines()) == 1
        # a city's start bundle with walls: the rings its first seconds pass, after the first view's objects
        start = {"path": "SE", "view": "160x120", "heads": "true"}
        parts = []
        for ask_walls in (True, False):
            got_b = c.get("/v1/scenes/walls/start", params={**start, **({"walls": "true"} if ask_walls else {})},
                          headers={"Accept": MSGPACK})
            assert got_b.status_code == 200
            names = start_parts(got_b.content, heads=True)
            parts.append(names)
    finally:
        c.close()
        app.state.scenes.close()
    on, off = parts
    names_on = [n for n, _ in on]
    assert "walls" not in [n for n, _ in off]  # not asked: as before
    assert names_on.index("objects") < names_on.index("walls") < names_on.index("walltex")
    first = dict(on)["walls"][0]
    assert first and len(first) < len(every)
    tex = [t for n, b in on if n == "walltex" for t in b]  # type: ignore[union-attr]
    assert tex and set(tex) <= {t for s in first for t in s.textures}
    # the first pose's parts, then the rings and the first moments' textures in a part of
    # their own (even when none): the walker stands at its start until that part's
    # textures are in (StartFeed.holding); the later poses' parts by the time the walk
    # needs them, the records of the cells it reaches after the first seconds last
    at = [i for i, n in enumerate(names_on) if n == "walltex"]
    assert at[0] == names_on.index("walls") + 1 and names_on.index("boxes") < at[0]
    assert all(n in ("walltex", "cell", "record", "index", "objects") for n in names_on[at[0] + 1:])
    assert len(tex) == len(set(tex))


def test_the_walker_stops_waiting_for_the_start_bundle_once_its_first_textures_are_in() -> None:
    import asyncio

    from walkstream.client.stream.cache import Cache
    from walkstream.client.stream.cellmap import CellMap
    from walkstream.client.stream.images import ImpostorImages
    from walkstream.client.stream.scheduler import RequestScheduler
    from walkstream.client.stream.startfeed import StartFeed
    from walkstream.client.stream.startwalls import StartWalls

    async def walk() -> None:
        feed = StartFeed(None, "params", CellMap())  # type: ignore[arg-type]
        feed.task = asyncio.create_task(asyncio.sleep(0))  # a bundle on the link
        assert feed.starting and feed.holding
        feed.textures_left()  # its first walltex part's textures are in: the later poses' parts follow
        assert feed.starting and not feed.holding  # still on the link, but the walk goes on
        await feed.task
        feed.task = None
        assert not feed.starting and not feed.holding
        # the textures the bundle announced are not asked for by the walls' lane meanwhile
        sched = RequestScheduler(3)
        lane = ImpostorImages(None, Cache(1 << 20), sched, kind="walltex")  # type: ignore[arg-type]
        start = StartWalls()
        start.expect([7, 8])
        start.attach(lane)
        lane.want({7: 0.0, 8: 0.0, 9: 0.0})
        assert [list(f.ids) for f in sched.flights(lane)] == [[9]]
        start.add_texture(7, np.zeros((1, 1, 4), np.uint8), 10)  # it came: held, not asked
        start.ended()  # the bundle ended without 8: the lane asks for it
        assert lane.held(7) and sorted(i for f in sched.flights(lane) for i in f.ids) == [8, 9]
        for f in sched.flights(lane):
            assert f.task is not None
            f.task.cancel()
        await asyncio.sleep(0)

    asyncio.run(walk())


def test_the_walls_list_sends_a_regions_ring_once_and_decodes_to_every_cells_walls() -> None:
    import msgpack

    from walkstream.shared.errors import CodecError
    from walkstream.shared.walls import decode_walls, walls_wire

    cells = [_cell(0, 0.0, 0.0, neighbours=(1,)), _cell(1, 10.0, 0.0, neighbours=(0,))]
    boxes = {0: _box(5, 5), 1: _box(15, 5)} | {10 + i: _box(200 + 30 * i, 5) for i in range(4)}
    plan = plan_ring_walls(cells, {c.id: np.array([0, 1, 10, 11, 12, 13]) for c in cells}, boxes,
                           WallSettings(keep=2, ring_min=5.0, region=25.0))
    rows = [s.to_row(compact=True) for s in plan.walls.sides]
    body = walls_wire(rows)
    assert len(rows) == 8 and len(body["sides"]) == 4 and len(body["same"]) == 4
    back = decode_walls(msgpack.packb(body), "walls")
    assert sorted(s.to_row(compact=True) for s in back) == sorted(rows)
    own = [r for r in rows if ring_cell(int(r[0])) == 0]
    assert walls_wire(own) == {"sides": own}  # nothing shared: as before
    with pytest.raises(CodecError, match="same"):
        decode_walls(msgpack.packb({"sides": own, "same": [[9, 5]]}), "walls")


def test_a_cell_record_carries_its_rings_far_field_and_streams_it_weighed_by_its_share() -> None:
    import msgpack

    from walkstream.shared.errors import CodecError
    from walkstream.shared.wire import CellRecord, cell_from_wire

    rec = CellRecord(id=3, kind="street", pvs=np.array([1, 4]), ach=np.array([0.75, 0.25]),
                     far=np.array([2, 9, 30]), far_ach=np.array([0.5, 0.25, 0.25]), far_share=0.4)
    back = cell_from_wire(msgpack.unpackb(msgpack.packb(rec.to_wire())), "cell 3")
    assert back.pvs.tolist() == [1, 4] and back.far is not None and back.far.tolist() == [2, 9, 30]
    ids, ach = back.streamed()
    assert ids.tolist() == [1, 4, 2, 9, 30]
    assert np.allclose(ach, [0.45, 0.15, 0.2, 0.1, 0.1], atol=1e-4)  # the whole cell's coverage again
    plain = CellRecord(id=3, kind="street", pvs=np.array([1, 4]), ach=np.array([0.75, 0.25]))
    assert "far" not in plain.to_wire() and plain.streamed()[0].tolist() == [1, 4]  # no ring: as before
    from walkstream.shared.codec import pack_ints

    bad = rec.to_wire() | {"fach": pack_ints([65535])}
    with pytest.raises(CodecError, match="3 far ids but 1 fach"):
        cell_from_wire(msgpack.unpackb(msgpack.packb(bad)), "cell 3")


def test_a_missing_ring_texture_brings_back_only_the_far_objects_behind_its_wall() -> None:
    from types import SimpleNamespace

    from walkstream.client.walk.objects import behind_walls

    def box(x: float, y: float) -> Any:
        return SimpleNamespace(bbox_min=np.array([x - 1.0, y - 1.0, 0.0]), bbox_max=np.array([x + 1.0, y + 1.0, 9.0]))

    # a ring's walls run clockwise, the hidden space to the left: north (-10, 10) -> (10, 10)
    north = ((-10.0, 10.0, 10.0, 10.0),)
    east = ((10.0, 10.0, 10.0, -10.0),)
    geoms = [box(0.0, 30.0), box(30.0, 0.0), box(30.0, 30.0), None]
    assert behind_walls(geoms, north).tolist() == [True, False, True, True]  # not built yet: must arrive
    assert behind_walls(geoms, east).tolist() == [False, True, True, True]
    assert behind_walls(geoms, north + east).tolist() == [True, True, True, True]
    assert behind_walls(geoms, ()).tolist() == [True] * 4
    # from the eye at the ring's middle, the corner box (30, 30) is behind both lines but
    # seen through the north wall's end only just; a box far to the east behind the
    # north wall's line is seen through the east wall alone: left to its texture
    eye = np.array([0.0, 0.0, 1.7])
    far_east = [box(60.0, 12.0), box(0.0, 30.0), box(8.0, 80.0)]
    assert behind_walls(far_east, north).tolist() == [True, True, True]  # the line alone keeps all three
    assert behind_walls(far_east, north, eye).tolist() == [False, True, True]
    assert behind_walls(far_east, east, eye).tolist() == [True, False, False]
    # the eye inside a box: that box spans every angle and stays
    assert behind_walls([box(0.0, 30.0)], north, np.array([0.0, 30.0, 1.7])).tolist() == [True]


def test_ring_textures_are_lossy_at_the_outdoor_quality_and_a_bad_quality_is_one_line() -> None:
    from walkstream.shared.errors import InputError

    st = WallSettings()
    assert st.outdoors().quality == st.outdoor_quality < st.quality
    assert st.record_outdoors()["quality"] == st.outdoor_quality
    assert st.outdoors().codec == st.record_outdoors()["codec"] == "webp" != st.codec  # indoors lossless
    lossless = st.with_texture(quality="lossless")
    assert lossless.outdoors().codec == lossless.record_outdoors()["codec"] == lossless.codec == "webp-lossless"
    lossy = lossless.with_texture(quality=60)
    assert (lossy.outdoors().codec, lossy.outdoors().quality, lossy.record_outdoors()["quality"]) == ("webp", 60, 60)
    for bad in (WallSettings(outdoor_quality=0), WallSettings(quality=101)):
        with pytest.raises(InputError, match="quality: expected 1 to 100"):
            bad.check()



def test_texture_fidelity_from_the_target_view_the_cap_and_the_codec_flags() -> None:
    from walkstream.server.bake.wallplan import texture_width

    fixed = WallSettings().outdoors()
    # the fixed density: 4 texels a metre, whatever the distance
    assert texture_width(30.0, 20.0, 10.0, 20.0, fixed) == texture_width(30.0, 20.0, 40.0, 20.0, fixed) == 120
    view = replace(WallSettings(view_height=120, outdoor_max_side=1024), outdoor_texels_per_m=4.0).outdoors()
    # a texel at most a pixel of a 120-pixel, 60-degree view at 10 m (10.4 px/m), the warp's
    # magnification there (20 / (10 + 5) = 1.33) on top: 30 m x 13.9 texels a metre
    assert texture_width(30.0, 20.0, 10.0, 20.0, view) == round(30.0 * 120 / (2 * 10.0 * np.tan(np.radians(30))) * 4 / 3)
    # twice as far: about half the texels; nearer than the sampling point only magnifies
    assert abs(texture_width(30.0, 20.0, 20.0, 20.0, view) - 30 * 5.196) <= 1
    # capped on both axes: a tall short wall's height stays within the cap
    capped = replace(view, max_side=64)
    w = texture_width(10.0, 40.0, 5.0, 20.0, capped)
    assert w == 16 and round(w * 40.0 / 10.0) == 64
    # the flags set indoors and outdoors alike; lossless is the lossless codec; records carry the view
    st = WallSettings(view_height=240).with_texture(texels=8.0, max_side=128, quality="lossless").check()
    assert (st.texels_per_m, st.outdoor_texels_per_m, st.max_side, st.outdoor_max_side) == (8.0, 8.0, 128, 128)
    assert st.codec == "webp-lossless" and st.record_outdoors()["view_height"] == 240
    assert "view_height" not in WallSettings().record_outdoors() and "quality" not in WallSettings().record()


def _solid_quad(x0: float, x1: float, y: float, image: int, rgb: tuple[int, int, int]) -> tuple[Any, ...]:
    """An opaque quad of one colour standing at ``y``, from ``x0`` to ``x1``, 0-6 m high."""
    corners = np.array([[x0, y, 0.0], [x1, y, 0.0], [x1, y, 6.0], [x0, y, 6.0]])
    rgba = np.zeros((8, 8, 4), np.uint8)
    rgba[..., :3], rgba[..., 3] = rgb, 255
    return corners, image, rgba, 1.0


@pytest.mark.gl
def test_a_ring_wall_and_an_impostor_side_by_side_are_each_under_their_own_cause(gl: object) -> None:
    from walkstream.client.truth.notes import FrameNote
    from walkstream.client.truth.picture import colour_error
    from walkstream.client.truth.render import TruthRenderer
    from walkstream.client.truth.standin import impostor_overlay
    from walkstream.shared.camera import look_at

    truth = TruthRenderer({}, (160, 120), ctx=gl)
    try:
        eye = np.array([0.0, 0.0, 3.0])
        view = look_at(eye, (0.0, 20.0, 3.0))
        imp = _solid_quad(-8.0, -1.0, 20.0, -1, (255, 0, 255))  # left: an impostor, magenta
        wall = _solid_quad(1.0, 8.0, 20.0, -2, (0, 255, 0))  # right: a ring wall, green
        front = _solid_quad(-3.0, -2.0, 12.0, -3, (0, 0, 255))  # a wall nearer, over the impostor's right edge
        note = FrameNote(frame=0, t=0.0, eye=eye, view=view, cell=None, pvs=None, received=np.zeros(0, np.int64),
                         built=np.zeros(0, np.int64), drawn=(), parts=(), waiting=(), fog=np.inf,
                         impostors=((7, imp),), wall_quads=(wall, front))
        truth.render(eye, view)
        sky = truth.colour()  # the truth: nothing there but sky and ground
        overlay = impostor_overlay(truth, truth.proj)
        err, pic = colour_error(truth, note, sky, np.full(sky.shape[:2], -1), truth.proj, overlay)
    finally:
        truth.release()
    assert pic.stand_in is not None and pic.wall is not None
    stand, walls = pic.stand_in, pic.wall
    assert not (stand & walls).any()
    mid = stand.shape[1] // 2
    # the impostor's pixels are left of the middle, the far wall's right of it
    assert stand.any() and stand[:, mid:].sum() == 0
    assert walls[:, mid + 5:].sum() > 100
    # the nearer wall over the impostor is the wall's, not the impostor's
    blue = (pic.rgb[..., 2] > 200) & (pic.rgb[..., 0] < 50)
    assert blue.any() and walls[blue].all() and not stand[blue].any()
    causes = dict(zip(COLOUR_CAUSES, err.causes.tolist(), strict=True))
    assert causes["impostor"] == int(stand.sum()) and causes["wall"] == int(walls.sum())


def _wrong_textures(db: Path) -> None:
    """Every wall texture of ``db`` painted one loud colour (its shape and alpha kept)."""
    con = sqlite3.connect(db)
    try:
        for tid, data in con.execute("SELECT id, data FROM wall_textures").fetchall():
            im = Image.open(io.BytesIO(data))
            fmt = im.format
            rgba = np.asarray(im.convert("RGBA")).copy()
            rgba[..., 0], rgba[..., 1], rgba[..., 2] = 255, 0, 255
            rgba[..., :3] = (rgba[..., :3].astype(np.uint16) * rgba[..., 3:4] // 255).astype(np.uint8)
            buf = io.BytesIO()
            Image.fromarray(rgba, "RGBA").save(buf, format=fmt, lossless=True) if fmt == "WEBP" else \
                Image.fromarray(rgba, "RGBA").save(buf, format=fmt)
            con.execute("UPDATE wall_textures SET data = ? WHERE id = ?", (buf.getvalue(), tid))
        con.commit()
    finally:
        con.close()


@pytest.mark.gl
def test_the_bench_counts_a_visibly_wrong_ring_wall_under_wall1(dbs: tuple[Path, Path, dict[str, Any]],
                                                                tmp_path: Path) -> None:
    from walkstream.benchmarks.walls import _visible_shares
    from walkstream.client.report.truth import write_truth_csv

    walls, _plain, _ = dbs
    wrong = tmp_path / "wrong.db"
    shutil.copy(walls, wrong)
    _wrong_textures(wrong)
    r = _replay(wrong, truth_every=25)
    assert r.truth is not None and r.summary["walls"]["textures_received"] > 0
    write_truth_csv(tmp_path / "truth.csv", r.truth.log)
    shares = _visible_shares(tmp_path)
    # the walls' magenta is theirs: wall1% falls below every frame (it read 100 % outdoors
    # whatever the walls showed, their pixels counted as the impostors')
    assert shares["frames_wall_visible_1pct"] is not None and shares["frames_wall_visible_1pct"] < 1.0
    assert r.summary["truth"]["colour"]["causes"]["wall"] > 0


def test_a_wall_texture_builds_each_building_as_the_client_does_so_its_door_is_on_the_same_side() -> None:
    """The village's building 23 (way/513995876): a rectangle whose two long sides are
    equally long to the millimetre; the grammar's door goes on the longest free frontage,
    and the centimetre the database stores moves it from the south side to the north.
    The bake's textures must show the door where the client's building (and the truth)
    has it."""
    from walkstream.server.bake.wallrender import wall_elements
    from walkstream.server.sources.scene import SourceScene
    from walkstream.shared.buildings import build_lod
    from walkstream.shared.codec.params import decode_building, encode_building
    from walkstream.shared.records import BuildingParams

    ring = np.array([[20.2338134, -27.48756555], [20.2810145, -33.55667563], [27.33462918, -33.50303865],
                     [27.2874206, -27.43392854]])
    b = BuildingParams(id=23, rings=(ring,), neighbour_heights=(np.array([0.0, 0.0, 6.4, 0.0]),), floors=6,
                       floor_height=3.2, style=1224950823)

    def door_y(tri: np.ndarray, mats: np.ndarray) -> float:
        return float(tri[mats == 2].reshape(-1, 3)[:, 1].mean())

    def mesh_door_y(m: Any) -> float:
        idx = np.asarray(m.indices, np.int64).reshape(-1, 3)
        return door_y(np.asarray(m.positions, np.float64)[idx], np.asarray(m.materials)[idx[:, 0]])

    client = mesh_door_y(build_lod(decode_building(encode_building(b)), 2))
    assert client > -28.0 and mesh_door_y(build_lod(b, 2)) < -33.0  # the premise: the rounding moves the door
    (_, tri, mats), = wall_elements(SourceScene("door", "local", (0.0, 0.0), (b,), ()))
    assert door_y(tri, mats) == pytest.approx(client, abs=0.01)
