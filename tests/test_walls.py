"""Textured virtual walls (issue 28): the error metric and zones, placement, the bake, the store, the service.

The traps: an object crossing a virtual wall (geometry, never on the texture), the
viewer on a zone border and on a wall, a viewer above the eye-height range, a scene
with no open space (no walls), a database baked without walls (served, 404 for
walls), a bake killed among its textures (resumed to the same version).
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Iterator
from pathlib import Path

import httpx
import msgpack
import numpy as np
import pytest
from asgiclient import Http
from openhall import open_hall
from startparts import start_parts

from walkstream.server.bake import bake
from walkstream.server.bake.rooms import room_layout
from walkstream.server.bake.wallplan import WallSettings, plan_walls
from walkstream.server.service.main import create_app
from walkstream.server.sources.interiorfile import load_interior, load_interior_dict
from walkstream.server.sources.interiorgen import InteriorPlan, generate_interior
from walkstream.server.store import SceneReader, SceneWriter
from walkstream.shared.codec.cellbatch import check_contents_part
from walkstream.shared.codec.cellmesh import decode_cell_mesh
from walkstream.shared.codec.image import decode_image
from walkstream.shared.errors import InputError
from walkstream.shared.walls import (
    EYE_HEIGHT,
    WallSide,
    WallTable,
    angular_error,
    decode_walls,
    wall_distance,
    zone_count,
)
from walkstream.shared.wire import MSGPACK

A = math.radians(10.0)
SMALL = WallSettings(texels_per_m=8.0, codec="webp-lossless")  # lossless: the stored texture is the render


def _side(length: float = 8.0, x_t: float = 8.0 / 3.0, zones: int | None = None) -> WallSide:
    n = zone_count(length, x_t, A) if zones is None else zones
    # the wall along x from (0, 0) to (length, 0); the hidden space at y > 0, the viewer at y < 0
    return WallSide(1, 0, (0.0, 0.0), (length, 0.0), 0.0, 4.0, 0.0, x_t, 0.5, 6.0, A, n)


# ------------------------------------------------------------------ the error metric


def test_zone_width_and_wall_distance_are_the_papers_equations() -> None:
    # the paper's laboratory: six zones per wall at 10 degrees
    assert zone_count(8.0, 4.0, A) == math.ceil(8.0 / (2 * 4.0 * math.tan(A)))
    x_t = wall_distance(0.5, A)
    assert math.isclose(x_t, 0.5 / math.tan(A))
    assert zone_count(1.0, x_t, A) == 1 and zone_count(1.01, x_t, A) == 2
    with pytest.raises(InputError):
        zone_count(8.0, 0.0, A)


def test_the_error_stays_under_a_at_the_zones_worst_corner() -> None:
    s = _side()
    w = s.length / s.zones
    assert w / 2 <= s.x_t * math.tan(A) + 1e-9
    origin, normal = np.zeros(3), np.array([0.0, 1.0, 0.0])
    for k in range(s.zones):
        b = s.sample_point(k)
        assert math.isclose(b[2], EYE_HEIGHT)
        lo, hi = s.zone_span(k)
        for corner in (lo, hi):
            viewer = np.array([corner, -s.x_t, EYE_HEIGHT])
            # points behind the wall, straight behind the sampling point, nearer and farther
            errs = [angular_error(b, viewer, [b[0], depth, EYE_HEIGHT], origin, normal) for depth in (0.1, 5, 50, 5000)]
            assert max(errs) <= A + 1e-6
            assert errs == sorted(errs)  # the far point is the worst, not the near one
            assert errs[-1] > 0.95 * math.atan((w / 2) / s.x_t)
    # at the sampling point itself: exact
    b = s.sample_point(0)
    assert angular_error(b, b, [3.0, 20.0, 0.5], origin, normal) < 1e-9
    # nearer than x_T the bound no longer holds: why the wall opens there
    near = np.array([0.0, -0.5, EYE_HEIGHT])
    assert angular_error(s.sample_point(0), near, [s.sample_point(0)[0], 5000, EYE_HEIGHT], origin, normal) > A


def test_viewer_on_a_zone_border_on_the_wall_and_above_the_eye_range() -> None:
    s = _side()
    w = s.length / s.zones
    mid = -(s.x_t + s.blend + 1.0)
    # on a border: the higher zone, the same weight on both sides of it
    on = s.view([w, mid, EYE_HEIGHT])
    assert on.zone == 1 and on.weight == 1.0
    assert s.view([w - 1e-9, mid, EYE_HEIGHT]).zone == 0
    # clamped at the ends
    assert s.view([-3.0, mid, EYE_HEIGHT]).zone == 0 and s.view([99.0, mid, EYE_HEIGHT]).zone == s.zones - 1
    # on the wall, behind it and nearer than x_T: no texture (the next cell is drawn)
    for y in (0.0, 1.0, -0.99 * s.x_t):
        assert s.view([2.0, y, EYE_HEIGHT]).weight == 0.0
    # the blend zone: half way, half the texture
    assert math.isclose(s.view([2.0, -(s.x_t + s.blend / 2), EYE_HEIGHT]).weight, 0.5)
    # a gallery 3 m over the eye height at 4 m: beyond the bound, geometry
    assert s.view([2.0, -4.0, EYE_HEIGHT + 3.0]).weight == 0.0
    # within the vertical bound, texture
    far = -(s.x_t + s.blend + 0.5)
    assert s.view([2.0, far, EYE_HEIGHT + 0.9 * abs(far) * math.tan(A)]).weight == 1.0


def test_a_side_row_round_trips_and_bad_rows_are_refused() -> None:
    s = WallSide(3, 1, (1.0, 2.0), (5.0, 2.0), 0.0, 4.0, 0.0, 2.0, 0.5, 6.0, A, 2, (7, 8))
    assert WallSide.from_row(s.to_row()) == s
    with pytest.raises(InputError, match="wall"):
        WallSide.from_row([1, 2, 3])
    # the wire's compact form: ids that follow one another by the first alone
    assert s.to_row(compact=True) == [*s.to_row()[:-2], 7]
    assert WallSide.from_row(s.to_row(compact=True)) == s
    odd = WallSide(3, 1, (1.0, 2.0), (5.0, 2.0), 0.0, 4.0, 0.0, 2.0, 0.5, 6.0, A, 3, (7, 9, 8))
    assert odd.to_row(compact=True) == odd.to_row() and WallSide.from_row(odd.to_row(compact=True)) == odd
    with pytest.raises(InputError, match="bad wall row"):
        WallSide.from_row(odd.to_row()[:-1])  # one texture short


# ------------------------------------------------------------------ placement


def test_a_scene_with_no_open_space_gets_no_walls() -> None:
    doc = generate_interior(InteriorPlan(storeys=1, length=20, width=14, seed=2))
    layout = room_layout(load_interior_dict(doc), 8.0)
    assert not any(p.kind == "wall" for p in layout.portals)
    assert len(layout.cells) == len(room_layout(load_interior_dict(doc)).cells)


def test_an_open_hall_is_cut_into_a_grid_of_cells_joined_by_walls() -> None:
    scene = load_interior_dict(open_hall(24.0, 16.0, spacing=3.0))
    layout = room_layout(scene, 8.0)
    rooms = [c for c in layout.cells if c.kind == "room"]
    assert len(rooms) == 6  # 3 x 2 squares of 8 m
    walls = [p for p in layout.portals if p.kind == "wall"]
    assert len(walls) == 7  # 2 x 2 across x, 3 x 1 across y
    assert all(abs(c.polygon.area - 64.0) < 1.0 for c in rooms)
    plan = plan_walls(scene, layout, SMALL)
    assert len(plan.sides) == 14
    for s in plan.sides:
        assert s.zones == zone_count(s.length, s.x_t, A) and len(s.textures) == s.zones
        # the sampling points stand in the viewer's cell, in front of the wall
        cell = next(c for c in rooms if c.id == (layout.portals[s.portal].a if s.side == 0 else layout.portals[s.portal].b))
        for k in range(s.zones):
            p = s.sample_point(k)
            assert cell.holds(p[:2], p[2])
    ids = [t for s in plan.sides for t in s.textures]
    assert ids == list(range(len(plan.jobs)))


def _two_rooms(width: float, depth: float) -> dict:
    """The open hall ``width`` x ``depth`` drawn as two rooms touching along x = width / 2
    with no wall between them (the production hall's bays are drawn so)."""
    doc = open_hall(width, depth, spacing=3.0)
    (x0, y0), (x1, y1) = doc["rooms"][0]["outline"][0], doc["rooms"][0]["outline"][2]
    xm = (x0 + x1) / 2.0
    doc["rooms"] = [{"id": "west", "name": "west", "storey": 0, "outline": [[x0, y0], [xm, y0], [xm, y1], [x0, y1]]},
                    {"id": "east", "name": "east", "storey": 0, "outline": [[xm, y0], [x1, y0], [x1, y1], [xm, y1]]}]
    return doc


def _across(layout: object) -> list[str]:
    """Kinds of the portals on the line where the rooms ``west`` and ``east`` touch."""
    cells = {c.id: c.room for c in layout.cells}  # type: ignore[attr-defined]
    return sorted(p.kind for p in layout.portals  # type: ignore[attr-defined]
                  if {cells[p.a], cells[p.b]} == {"west", "east"})


def test_rooms_of_one_open_space_are_split_where_they_touch_too() -> None:
    # two rooms of 12 x 16 m touching with no wall: one open space of 384 m2 (over
    # 2 S2), so the stretch between them is a wall as the grid lines inside each are
    doc = _two_rooms(24.0, 16.0)
    layout = room_layout(load_interior_dict(doc), 8.0)
    assert _across(layout) == ["wall", "wall"]  # the border, two cells tall on each side
    assert not any(p.kind == "opening" for p in layout.portals)
    assert any("open stretches" in n for n in layout.notes)
    # without --virtual-walls the same stretch is an open portal, as before
    assert _across(room_layout(load_interior_dict(doc))) == ["opening"]
    # a small open space (two rooms of 6 x 8 m, 96 m2 together) stays open
    assert _across(room_layout(load_interior_dict(_two_rooms(12.0, 8.0)), 8.0)) == ["opening"]


def test_the_production_halls_bays_are_walled_on_every_side() -> None:
    from walkstream.server.sources.hallgen import HallPlan, generate_hall

    doc = generate_hall(HallPlan(columns=3, rows=2, side_depth=0.0, equipment=0.0))
    layout = room_layout(load_interior_dict(doc), 8.0)
    kinds = {p.kind for p in layout.portals}
    assert "opening" not in kinds and "wall" in kinds
    # every room cell's every neighbour in the hall is behind a wall (or a door)
    rooms = {c.id for c in layout.cells if c.kind == "room"}
    assert all(p.kind in ("wall", "door") for p in layout.portals if p.a in rooms and p.b in rooms)


def test_the_wall_table_gives_every_sides_view() -> None:
    rng = np.random.default_rng(3)
    sides = [WallSide(i, 0, tuple(rng.uniform(-5, 5, 2)), tuple(rng.uniform(-5, 5, 2)), 0.0, 3.0, 0.0,  # type: ignore[arg-type]
                      1.5, 0.3 if i % 5 else 0.0, 4.0, A, int(rng.integers(1, 9))) for i in range(25)]
    eyes = np.c_[rng.uniform(-10, 10, (150, 2)), rng.uniform(0, 4, 150)]
    zones, dist, weights = WallTable(sides).views(eyes)
    for m, e in enumerate(eyes):
        for n, s in enumerate(sides):
            v = s.view(e)
            assert (v.zone, round(v.weight, 12), round(v.distance, 9)) == (
                zones[m, n], round(float(weights[m, n]), 12), round(float(dist[m, n]), 9))
    assert WallTable([]).views(eyes)[2].shape == (150, 0)


# ------------------------------------------------------------------ the bake

CROSS = (8.0, 4.0)  # a shelf centred on the wall at x = 8 (local frame: the hall's corner at 0, 0)


@pytest.fixture(scope="module")
def hall(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("walls")
    src = d / "hall.json"
    src.write_text(json.dumps(open_hall(24.0, 16.0, spacing=3.0, crossing=[CROSS])))
    return src


@pytest.fixture(scope="module")
def baked(hall: Path, gl_ctx: object) -> tuple[Path, dict]:
    out = hall.parent / "walls.db"
    return out, bake(hall, out, walls=SMALL, name="walls")


@pytest.fixture(scope="module")
def deep(hall: Path, gl_ctx: object) -> tuple[Path, dict]:
    """The hall baked with ``--wall-depth 8``: each texture's depth grid after it."""
    out = hall.parent / "deep.db"
    return out, bake(hall, out, walls=dataclasses.replace(SMALL, depth_grid=8), name="deep")


@pytest.fixture(scope="module")
def plain(hall: Path, gl_ctx: object) -> tuple[Path, dict]:
    out = hall.parent / "plain.db"
    return out, bake(hall, out, name="plain")


@pytest.mark.gl
def test_bake_stores_sides_and_textures(baked: tuple[Path, dict]) -> None:
    path, summary = baked
    assert "walls" in summary["features"] and summary["wall_sides"] == 14
    with SceneReader.open(path) as r:
        assert r.has_walls() and r.meta.settings["walls"]["error_deg"] == 10.0
        sides = [WallSide.from_row(row) for row in r.wall_sides()]
        info = r.wall_texture_info()
        assert sorted(t for s in sides for t in s.textures) == sorted(info)
        assert summary["wall_textures"] == len(info)
        for s in sides[:2]:
            for zone, tid in enumerate(s.textures):
                portal, side, z, width, height, _n = info[tid]
                assert (portal, side, z) == (s.portal, s.side, zone)
                img = decode_image(r.wall_textures([tid])[tid][1], "texture")
                assert img.shape == (height, width, 4)
                # an enclosed hall: nearly every texel shows something (the door shows the outside)
                assert (img[..., 3] == 255).mean() > 0.9


@pytest.mark.gl
def test_an_object_crossing_a_wall_is_whole_geometry_and_not_on_the_texture(
    hall: Path, baked: tuple[Path, dict], gl_ctx: object
) -> None:
    from walkstream.server.bake.wallrender import WallRenderer

    path, summary = baked
    assert summary["wall_crossing"] >= 1
    scene = load_interior(hall)
    shelf = next(e for e in scene.elements if e.key == "x0")
    layout = room_layout(scene, SMALL.pitch)
    plan = plan_walls(scene, layout, SMALL)
    crossed = [pid for pid, ids in plan.crossing.items() if shelf.id in ids]
    assert len(crossed) == 1
    wall = layout.portals[crossed[0]]
    with SceneReader.open(path) as r:
        for cid in (wall.a, wall.b):
            mesh = decode_cell_mesh(r.contents(cid), f"cell {cid}")
            pts = np.vstack([p.positions for p in mesh.parts if p.element == shelf.id])
            # whole in both cells, not clipped at the wall (to the codec's millimetre grid)
            assert np.allclose(pts.min(axis=0), shelf.vertices.min(axis=0), atol=2e-3)
            assert np.allclose(pts.max(axis=0), shelf.vertices.max(axis=0), atol=2e-3)
        side = next(s for s in plan.sides if s.portal == wall.id)
        zone = side.view([*_centre(shelf), 0.0]).zone
        stored = decode_image(r.wall_textures([side.textures[zone]])[side.textures[zone]][1], "texture")
    job = plan.jobs[side.textures[zone]]
    ren = WallRenderer(scene, ctx=gl_ctx)
    try:
        without = ren.render(side, zone, job[3], job[4])
        with_it = ren.render(side, zone, job[3], ())
    finally:
        ren.release()
    assert np.array_equal(stored, without)
    assert np.abs(with_it.astype(int) - without.astype(int)).max() > 40  # the shelf would show
    # where the shelf is, the texture is a transparent hole: its geometry shows through the quad
    assert (without[..., 3] == 0).sum() > 20 and with_it[..., 3].min() == 255


def _centre(e: object) -> tuple[float, float]:
    """An element's box centre on the floor plan."""
    v = e.vertices  # type: ignore[attr-defined]
    c = (v.min(axis=0) + v.max(axis=0)) / 2
    return float(c[0]), float(c[1])


@pytest.mark.gl
def test_a_bake_with_wall_depth_stores_each_textures_grid_after_its_image(
    baked: tuple[Path, dict], deep: tuple[Path, dict]
) -> None:
    from walkstream.shared.content.walltex import decode_walltex
    from walkstream.shared.walldepth import split_depth

    with SceneReader.open(deep[0]) as r, SceneReader.open(baked[0]) as old:
        assert r.meta.settings["walls"]["depth_grid"] == 8 and "depth_grid" not in old.meta.settings["walls"]
        assert r.wall_sides() == old.wall_sides() and r.wall_texture_info().keys() == old.wall_texture_info().keys()
        ids = sorted(r.wall_texture_info())
        blobs, flat = r.wall_textures(ids), old.wall_textures(ids)
    for tid in ids:
        image, inv = split_depth(blobs[tid][1])
        # the image byte for byte as without depths, then the 9 x 9 grid (the hall is
        # enclosed: every vertex sees something, within the hall's 24 m)
        assert image == flat[tid][1] and split_depth(flat[tid][1]) == (flat[tid][1], None)
        assert inv is not None and inv.shape == (9, 9) and 0.0 < inv.min() and inv.max() <= 1.0
        img = decode_walltex(blobs[tid][1])
        assert np.array_equal(img, decode_image(image, "t")) and np.array_equal(img.depth, inv)
        # a decoder that does not know the trailer still reads the image (WebP's own length)
        assert np.array_equal(decode_image(blobs[tid][1], "t"), img)
    extra = sum(len(blobs[t][1]) - len(flat[t][1]) for t in ids) / len(ids)
    assert 20 < extra < 90  # bytes a texture: 81 depths, row differences deflated


@pytest.mark.gl
def test_a_bake_without_walls_is_unchanged(plain: tuple[Path, dict]) -> None:
    path, summary = plain
    assert not any(k.startswith("wall") for k in summary) and "walls" not in summary["features"]
    with SceneReader.open(path) as r:
        assert not r.has_walls() and r.wall_sides() == [] and r.wall_textures([0]) == {}
        assert "walls" not in r.meta.settings
        assert all(p.kind != "wall" for p in r.portals())


@pytest.mark.gl
def test_a_bake_killed_among_its_textures_resumes(
    hall: Path, baked: tuple[Path, dict], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    out = tmp_path / "killed.db"
    real = SceneWriter.add_wall_texture
    calls = {"n": 0}

    def dying(self: SceneWriter, *args: object, **kw: object) -> None:
        if calls["n"] == 40:
            raise KeyboardInterrupt
        calls["n"] += 1
        real(self, *args, **kw)  # type: ignore[arg-type]

    monkeypatch.setattr(SceneWriter, "add_wall_texture", dying)
    with pytest.raises(KeyboardInterrupt):
        bake(hall, out, walls=SMALL, name="walls")
    monkeypatch.setattr(SceneWriter, "add_wall_texture", real)
    summary = bake(hall, out, walls=SMALL, name="walls")
    assert summary["wall_resumed"] == 40
    assert summary["version"] == baked[1]["version"]


def test_walls_refuse_a_city_and_bad_settings(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="--wall-error"):
        bake(tmp_path / "x.json", tmp_path / "x.db", walls=WallSettings(error_deg=90.0))
    with pytest.raises(InputError, match="--virtual-walls"):
        bake(tmp_path / "x.geojson", tmp_path / "x.db", interior=tmp_path / "y.json", walls=WallSettings())


# ------------------------------------------------------------------ the service


@pytest.fixture(scope="module")
def http(baked: tuple[Path, dict], plain: tuple[Path, dict], deep: tuple[Path, dict]) -> Iterator[Http]:
    app = create_app([baked[0], plain[0], deep[0]])
    c = Http(app)
    yield c
    c.close()
    app.state.scenes.close()


@pytest.mark.gl
def test_walls_and_textures_are_served_immutable_and_in_batches(http: Http, baked: tuple[Path, dict]) -> None:
    got = http.get("/v1/scenes/walls/walls", headers={"Accept": MSGPACK})
    assert got.status_code == 200
    sides = decode_walls(got.content, "walls")
    assert len(sides) == 14
    again = http.get("/v1/scenes/walls/walls", headers={"Accept": MSGPACK, "If-None-Match": got.headers["etag"]})
    assert again.status_code == 304
    assert http.get("/v1/scenes/walls/walls", headers={"Accept": "application/json"}).json()["sides"][0][0] == sides[0].portal
    # the sides as stored, on the wire compact (ids by the first) and gzip-compressed when asked
    with SceneReader.open(baked[0]) as r:
        assert [s.to_row() for s in sides] == r.wall_sides()
    plain = http.get("/v1/scenes/walls/walls", headers={"Accept": MSGPACK, "Accept-Encoding": "identity"})
    packed = http.get("/v1/scenes/walls/walls", headers={"Accept": MSGPACK, "Accept-Encoding": "gzip"})
    assert "content-encoding" not in plain.headers and packed.headers["content-encoding"] == "gzip"
    assert packed.headers["etag"] != plain.headers["etag"] and "Accept-Encoding" in packed.headers["vary"]
    assert decode_walls(packed.content, "walls") == sides == decode_walls(plain.content, "walls")
    assert int(packed.headers["content-length"]) < len(plain.content) / 2
    assert http.get("/v1/scenes/walls/walls", headers={"Accept": MSGPACK, "Accept-Encoding": "gzip",
                                                        "If-None-Match": packed.headers["etag"]}).status_code == 304
    tid = sides[0].textures[0]
    one = http.get(f"/v1/scenes/walls/walls/textures/{tid}")
    assert one.status_code == 200 and one.headers["content-type"] == "image/webp"
    assert "immutable" in one.headers.get("cache-control", "")
    assert http.get(f"/v1/scenes/walls/walls/textures/{tid}",
                    headers={"If-None-Match": one.headers["etag"]}).status_code == 304
    ids = list(sides[1].textures)
    batch = http.post("/v1/scenes/walls/walls/textures", json={"ids": ids})
    assert batch.status_code == 200
    unpacker = msgpack.Unpacker(raw=False)
    unpacker.feed(batch.content)
    parts = [check_contents_part(p, "part") for p in unpacker]
    assert [p[0] for p in parts] == ids
    with SceneReader.open(baked[0]) as r:
        stored = r.wall_textures(ids)
    assert all(body == stored[i][1] for i, _etag, body in parts)
    assert http.get("/v1/scenes/walls/walls/textures/99999").status_code == 404
    assert http.post("/v1/scenes/walls/walls/textures", json={"ids": [tid, tid]}).status_code == 422


@pytest.mark.gl
def test_a_textures_depth_grid_travels_with_it(http: Http) -> None:
    from walkstream.shared.content.walltex import decode_walltex

    tid = decode_walls(http.get("/v1/scenes/deep/walls", headers={"Accept": MSGPACK}).content, "w")[0].textures[0]
    one, flat = http.get(f"/v1/scenes/deep/walls/textures/{tid}"), http.get(f"/v1/scenes/walls/walls/textures/{tid}")
    assert one.status_code == 200 and one.headers["etag"] != flat.headers["etag"]
    assert one.content.startswith(flat.content) and decode_walltex(one.content).depth.shape == (9, 9)
    assert getattr(decode_walltex(flat.content), "depth", None) is None
    assert http.get(f"/v1/scenes/deep/walls/textures/{tid}", headers={"If-None-Match": one.headers["etag"]}).status_code == 304
    batch = http.post("/v1/scenes/deep/walls/textures", json={"ids": [tid]})
    unpacker = msgpack.Unpacker(raw=False)
    unpacker.feed(batch.content)
    assert [check_contents_part(p, "part")[2] for p in unpacker] == [one.content]


@pytest.mark.gl
def test_a_scene_without_walls_serves_as_before_and_404s_walls(http: Http) -> None:
    assert http.get("/v1/scenes/plain/topology").status_code == 200
    for resp in (http.get("/v1/scenes/plain/walls"), http.get("/v1/scenes/plain/walls/textures/0"),
                 http.post("/v1/scenes/plain/walls/textures", json={"ids": [0]})):
        assert resp.status_code == 404
        assert "without --virtual-walls" in resp.json()["error"]


# ------------------------------------------------------------------ the client


@pytest.fixture(scope="module")
def walked(baked: tuple[Path, dict], tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The hall with walls and a walk across it, from one end to the other and back along the far side."""
    import shutil

    from walkstream.server.paths.record import record_walk

    db = tmp_path_factory.mktemp("walked") / "walls.db"
    shutil.copy(baked[0], db)
    record_walk(db, "cross", (-10.0, -6.0, EYE_HEIGHT), (-10.0, 6.0, EYE_HEIGHT),
                via=[(10.0, -6.0, EYE_HEIGHT), (10.0, 6.0, EYE_HEIGHT)])
    return db


def _replay(db: Path, **kw: object) -> object:
    from walkstream.client.config import ReplayConfig
    from walkstream.client.net.link import LinkProfile
    from walkstream.client.replay import run_replay

    app = create_app([db])
    try:
        kw = {"duration_s": 14.0, **kw}
        cfg = ReplayConfig(link=LinkProfile(56_000.0, 56_000.0, 0.2), device="pda", path="cross",
                           fog_budget=False, **kw)  # type: ignore[arg-type]
        return run_replay(httpx.ASGITransport(app=app), "http://walkstream.test", cfg)
    finally:
        app.state.scenes.close()


@pytest.fixture(scope="module")
def replays(walked: Path) -> tuple[object, object]:
    """The walk with walls (the truth on a few frames) and with ``virtual_walls`` off."""
    return _replay(walked, truth_every=120), _replay(walked, virtual_walls=False)


@pytest.mark.gl
def test_a_replay_draws_walls_and_culls_what_is_behind_them(replays: tuple[object, object]) -> None:
    on, off = replays
    s, g = on.summary, off.summary  # type: ignore[attr-defined]
    w = s["walls"]
    assert w["wall_sides"] == 14 and w["textures_received"] > 0 and w["texture_bytes"] > 0
    assert w["walls_closed_mean"] > 0 and w["frames_with_walls"] > 0.5
    assert "walls" not in g  # --no-walls: no texture asked for, every portal open
    assert s["visible_cells_mean"] < g["visible_cells_mean"]
    assert s["triangles_mean"] < g["triangles_mean"]
    # only the textures of the walls on the cells due now, in view, are asked for (every
    # wall faces the viewer from somewhere: asking for all filled the link), so the
    # walk keeps its perfect frames at 56 kbit/s
    assert s["perfect_frame_ratio"] >= 0.995 and s["bytes_received"] > g["bytes_received"]
    assert w["textures_received"] < 0.5 * w["textures_per_wall"] * w["wall_sides"] / 2
    # the truth: what lies behind a closed wall shows on its texture, not as a culled pixel
    t = s["truth"]
    assert t["frames"] >= 2 and t["culled_pixels"] == 0 and t["wall_pixels"] > 0


@pytest.mark.gl
def test_a_wall_whose_texture_has_not_arrived_is_geometry_never_a_hole(replays: tuple[object, object]) -> None:
    on, off = replays
    a, b = on.interior, off.interior  # type: ignore[attr-defined]
    assert a is not None and b is not None
    # the first frame: no texture is in yet (one round trip at 56 kbit/s), so no wall is
    # closed and the walk sees the cells behind them as geometry, as without walls
    assert a["cells"][0] == b["cells"][0] and a["triangles"][0] == b["triangles"][0]
    # later, with textures in, fewer cells
    assert a["cells"].mean() < b["cells"].mean()



@pytest.mark.gl
def test_the_walls_walks_only_imperfect_frames_are_its_start(replays: tuple[object, object]) -> None:
    on, _off = replays
    s, log = on.summary, on.log  # type: ignore[attr-defined]
    perfect = (log.cell >= 0) & (np.minimum(log.download_quality, log.rewrite_quality) >= 1.0 - 1e-9)
    first = int(np.argmax(perfect))
    assert perfect.any() and s["time_to_first_perfect_frame_s"] is not None
    # frame by frame: once the first view is in, no frame misses a cell or a texture's
    # geometry (a wall whose texture is late leaves its portal open and the cells behind
    # it count); the frames before it are the walker standing while its first view comes
    assert perfect[first:].all() and s["perfect_frame_ratio"] == 1.0
    assert s["late_cells"]["cells"] == 0 and sum(s["late_cells"]["cell_frames_by_cause"].values()) == 0
    assert s["perfect_frames"] == len(log.t) - first


def _bundle(app: object, walls: bool) -> list[tuple[str, object]]:
    """The start bundle of the walk ``cross`` for a 160x120 view: each part's name and
    body (for ``walltex`` and ``contents`` the ids listed)."""
    c = Http(app)
    try:
        got = c.get("/v1/scenes/walls/start", params={"path": "cross", "view": "160x120",
                                                      **({"walls": "true"} if walls else {})},
                    headers={"Accept": MSGPACK})
    finally:
        c.close()
    assert got.status_code == 200
    return start_parts(got.content)


@pytest.mark.gl
def test_the_start_bundle_brings_the_first_views_wall_textures_and_walks_it_closed(walked: Path) -> None:
    app = create_app([walked])
    try:
        on, off = _bundle(app, True), _bundle(app, False)
    finally:
        app.state.scenes.close()  # type: ignore[attr-defined]
    names = [n for n, _ in on]
    assert names.index("walls") < names.index("walltex") < names.index("contents")
    assert "walls" not in [n for n, _ in off]  # not asked: the bundle as before
    ids = dict(on)["walltex"]
    sides = dict(on)["walls"][0]
    assert ids and set(ids) <= {t for s in sides for t in s.textures}  # type: ignore[arg-type]
    # the first view walked with those walls closed needs no cell the open walk does not
    first_on, first_off = dict(on)["contents"], dict(off)["contents"]
    assert set(first_on) <= set(first_off) and len(first_on) <= len(first_off)  # type: ignore[arg-type]


@pytest.mark.gl
def test_a_walk_started_with_its_wall_textures_closes_its_first_walls(walked: Path) -> None:
    with_tex = _replay(walked, kind="interior", start_walls=True, duration_s=4.0)
    without = _replay(walked, kind="interior", start_walls=False, duration_s=4.0)
    a, b = with_tex.interior, without.interior  # type: ignore[attr-defined]
    s, g = with_tex.summary, without.summary  # type: ignore[attr-defined]
    # the textures came in the bundle: the first frame shows walls closed, and fewer
    # cells; a texture still missing on the other walk left its walls open
    assert s["walls"]["textures_received"] > 0
    assert a["cells"][0] < b["cells"][0]
    assert s["perfect_frame_ratio"] >= 0.995
    assert s["time_to_first_perfect_frame_s"] <= g["time_to_first_perfect_frame_s"]


def test_a_walltex_part_lists_distinct_textures_and_a_short_bundle_says_so() -> None:
    from walkstream.client.net.startitems import StartDecoder
    from walkstream.shared.errors import CodecError
    from walkstream.shared.startwire import decode_start_part

    assert decode_start_part({"part": "walltex", "etag": None, "textures": [3, 5]}, "b") == ("walltex", None, [3, 5])
    for bad in ([3, 3], [-1], "x", list(range(65))):
        with pytest.raises(CodecError, match="walltex part without its textures"):
            decode_start_part({"part": "walltex", "etag": None, "textures": bad}, "b")
    dec = StartDecoder("params", False)
    assert dec({"part": "walltex", "etag": None, "textures": [7]}, 10) == ("walltex", [7])
    assert dec.short() == "1 wall textures"
    with pytest.raises(CodecError, match="texture 8 where 7 was announced"):
        dec({"cell": 8, "etag": "e", "body": b""}, 10)


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--virtual-walls", "--wall-error", "0"], "--wall-error"),
        (["--virtual-walls", "--wall-pitch", "1"], "--wall-pitch"),
        (["--wall-error", "10"], "give --virtual-walls too"),
        (["--virtual-walls", "--wall-depth", "5"], "--wall-depth: expected one of 0, 4, 8, 16, got 5"),
        (["--wall-depth", "8"], "give --virtual-walls too"),
        (["--virtual-walls", "--wall-view", "-1"], "--wall-view: expected 0"),
        (["--virtual-walls", "--wall-texels", "0"], "--wall-texels: expected 0.1 to 256"),
        (["--virtual-walls", "--wall-max-side", "2048"], "--wall-max-side: expected 8 to 1024"),
        (["--virtual-walls", "--wall-quality", "best"], "--wall-quality: expected 1 to 100 or lossless, got 'best'"),
        (["--wall-quality", "lossless"], "give --virtual-walls too"),
    ],
)
def test_bad_wall_flags_are_one_clear_line(
    flags: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from walkstream.cli import main

    assert main(["bake", str(tmp_path / "h.json"), "-o", str(tmp_path / "x.db"), *flags]) == 2
    err = capsys.readouterr().err
    assert err.startswith("walkstream: error:") and message in err and "Traceback" not in err
    assert not (tmp_path / "x.db").exists()


def test_wall_textures_ahead_go_a_few_at_a_time_so_one_needed_now_is_not_queued() -> None:
    import asyncio

    from walkstream.client.stream.cache import Cache
    from walkstream.client.stream.images import MAX_REQUESTS, WALL_BATCH, ImpostorImages
    from walkstream.client.stream.scheduler import RequestScheduler

    async def started(wanted: dict[int, float]) -> list[list[int]]:
        sched = RequestScheduler(3)
        lane = ImpostorImages(None, Cache(1 << 20), sched, kind="walltex")  # type: ignore[arg-type]
        sched.join(lane)
        lane.wanted = dict(wanted)
        sched.dispatch()
        out = [list(f.ids) for f in sched.flights(lane)]
        for f in sched.flights(lane):
            assert f.task is not None
            f.task.cancel()
        await asyncio.sleep(0)
        return out

    # textures the eye will see ahead (0.5 s on): a few to a request, soonest first, so
    # a wall that comes into view meanwhile (a turn) waits for at most a few of them,
    # not for two requests of 16 (2 s of a 56 kbit/s link)
    ahead = asyncio.run(started({10 + k: 0.5 + 0.05 * k for k in range(8)}))
    assert 1 <= WALL_BATCH <= 2 and len(ahead) == MAX_REQUESTS
    assert [i for ids in ahead for i in ids] == list(range(10, 10 + MAX_REQUESTS * WALL_BATCH))
    # textures needed now (the first frame, a cell entered): all in one request
    now = asyncio.run(started({20 + k: 0.0 for k in range(5)}))
    assert now[0] == [20, 21, 22, 23, 24]


class _Prefetch:
    """Another lane on the link (the rooms' contents): requests by need, one slot each."""

    def __init__(self, needs: list[float]) -> None:
        self.needs, self.flying = sorted(needs), 0

    def offer(self) -> object:
        from walkstream.client.stream.scheduler import Offer

        if not self.needs:
            return None

        def start() -> None:
            self.needs.pop(0)
            self.flying += 1

        return Offer(self.needs[0], start)

    def in_flight(self) -> int:
        return self.flying

    def outstanding_bytes(self) -> float:
        return 0.0


def test_a_texture_needed_now_takes_the_slot_kept_beyond_the_links_and_the_far_prefetch_waits() -> None:
    import asyncio

    from walkstream.client.stream.cache import Cache
    from walkstream.client.stream.images import MAX_REQUESTS, ImpostorImages
    from walkstream.client.stream.scheduler import HOLD_S, RequestScheduler

    async def run() -> None:
        sched = RequestScheduler(3)
        lane = ImpostorImages(None, Cache(1 << 20), sched, kind="walltex")  # type: ignore[arg-type]
        sched.join(lane)
        rooms = _Prefetch([0.4, 1.5, 2.0])
        sched.join(rooms)  # type: ignore[arg-type]
        lane.wanted = {10 + k: 0.5 + 0.1 * k for k in range(6)}  # textures ahead
        sched.dispatch()
        assert sched.in_flight() == 3 and len(sched.flights(lane)) == MAX_REQUESTS  # every slot taken
        # the walker turns: two walls' textures needed now go at once, in the slot kept
        # beyond the link's (and the lane's own) limit, not behind the textures ahead
        lane.wanted |= {30: 0.0, 31: 0.0}
        assert sched.dispatch() == 1
        urgent = [f for f in sched.flights(lane) if f.urgent]
        assert len(urgent) == 1 and urgent[0].ids == [30, 31] and sched.in_flight() == 4
        # one urgent request at a time; while it flies what is needed later than HOLD_S waits
        lane.wanted |= {32: 0.0}
        rooms.flying -= 1  # a prefetch landed: its slot stays free for the urgent request's sake
        assert HOLD_S < 1.5 and sched.dispatch() == 0 and rooms.needs == [1.5, 2.0]
        rooms.needs.insert(0, 0.0)  # contents needed now still go
        assert sched.dispatch() == 1 and rooms.needs == [1.5, 2.0]
        for f in sched.flights(lane):
            assert f.task is not None
            f.task.cancel()
        await asyncio.sleep(0)

    asyncio.run(run())
