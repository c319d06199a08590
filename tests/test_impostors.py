"""Impostors (issue 27): the error bound and its bins, the bake's plan, the images, the stored tables, the service.

The traps: an object straddling the distance D, a building seen from both sides of a
cell, an image shared by two cells, premultiplied alpha at the silhouette (no dark
fringes), a database baked without impostors (served to a client asking for them),
a bake killed among its images; the client's choice: the blend at the exact switch
distance, a texture budget smaller than the images of one cell.
"""

from __future__ import annotations

import io
import math
from collections.abc import Iterator
from pathlib import Path

import msgpack
import numpy as np
import pytest
from asgiclient import Http

from walkstream.client.draw.impostors import (
    BLEND_SHARE,
    ImpostorChoice,
    choose_impostors,
    fit_textures,
    impostor_alpha,
)
from walkstream.server.bake import BakeSettings, ImpostorSettings, bake
from walkstream.server.bake.impostorplan import plan_impostors
from walkstream.server.bake.viewcell import ViewCell
from walkstream.server.service.main import create_app
from walkstream.server.sources.citygen import write_city
from walkstream.server.store import SceneReader, SceneWriter
from walkstream.shared.codec.cellbatch import check_contents_part
from walkstream.shared.codec.image import decode_image, encode_image
from walkstream.shared.errors import CodecError, InputError
from walkstream.shared.impostors import (
    allowed_angle,
    angular_error,
    bin_direction,
    bin_of,
    directions,
    level_for,
    level_step,
)
from walkstream.shared.impostorwire import ImpostorRow
from walkstream.shared.wire import MSGPACK, CellRecord, decode_cell

BOUND = math.radians(2.0)


def _cell(cid: int, x0: float, y0: float, x1: float, y1: float) -> ViewCell:
    poly = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], np.float64)
    return ViewCell(cid, "street", poly, 1.5, 1.9, ())


def _box(cx: float, cy: float, half: float = 5.0, h: float = 20.0) -> tuple[float, ...]:
    return (cx - half, cy - half, 0.0, cx + half, cy + half, h)


# ------------------------------------------------------------------ the bound


def test_levels_keep_the_error_bound() -> None:
    r = np.array([5.0, 15.0, 30.0, 15.0])
    d = np.array([50.0, 200.0, 400.0, 1000.0])
    lv = level_for(r, d, BOUND)
    assert (lv >= 0).all()
    # the half-diagonal of a bin at that level is within the allowed angle...
    half = np.array([level_step(int(v)) for v in lv]) / math.sqrt(2.0)
    assert (half <= allowed_angle(r, d, BOUND) + 1e-12).all()
    # ...so the error at that angle is within the bound, and the next coarser level is not
    assert (angular_error(r, d, half) <= BOUND + 1e-12).all()
    coarser = lv > 0
    half_c = np.array([level_step(int(v) - 1) for v in lv[coarser]]) / math.sqrt(2.0)
    assert (half_c > allowed_angle(r[coarser], d[coarser], BOUND)).all()


def test_too_near_for_any_level() -> None:
    assert level_for(30.0, 1.0, BOUND) == -1


# ------------------------------------------------------------------ the plan


def test_an_object_straddling_d_is_not_far() -> None:
    d = 100.0
    cell = _cell(0, 0.0, 0.0, 20.0, 20.0)
    # box from x = 119 to 139: its near side is 99 m from the cell, its centre 109 m
    straddling, beyond = 1, 2
    boxes = {straddling: (119.0, 5.0, 0.0, 139.0, 15.0, 20.0), beyond: (121.0, 40.0, 0.0, 141.0, 50.0, 20.0)}
    plan = plan_impostors([cell], {0: np.array([1, 2])}, boxes, {1: 100, 2: 100},
                          ImpostorSettings(distance=d, error_deg=2.0))
    assert [c.object for c in plan.cells[0]] == [beyond]
    assert plan.far == 1


def test_a_building_seen_from_both_sides_of_a_long_cell() -> None:
    """A 600 m cell passing a building 220 m off its middle: the directions to the
    cell span about 110 degrees, so several images; every point of the cell finds its
    direction's bin listed, and that bin's image keeps the error bound."""
    cell = _cell(0, -300.0, -5.0, 300.0, 5.0)
    oid = 7
    boxes = {oid: _box(0.0, 225.0)}
    st = ImpostorSettings(distance=200.0, error_deg=2.0)
    plan = plan_impostors([cell], {0: np.array([oid])}, boxes, {oid: 100}, st)
    (imp,) = plan.cells[0]
    assert imp.n_az > 1
    centre = np.array([0.0, 225.0, 10.0])
    radius = float(np.linalg.norm(np.array(boxes[oid][3:]) - np.array(boxes[oid][:3]))) / 2.0
    n_az = round(2 * math.pi / level_step(imp.level))
    rng = np.random.default_rng(3)
    pts = np.column_stack([rng.uniform(-300, 300, 400), rng.uniform(-5, 5, 400), rng.uniform(1.5, 1.9, 400)])
    az, el = directions(pts, centre)
    ia, ie = bin_of(imp.level, az, el)
    for a, e, p in zip(ia.tolist(), ie.tolist(), pts, strict=True):
        i, j = (a - imp.az0) % n_az, e - imp.el0
        assert 0 <= i < imp.n_az and 0 <= j < imp.n_el, "a direction of the cell has no image"
        v = (p - centre) / np.linalg.norm(p - centre)
        theta = math.acos(float(np.clip(v @ bin_direction(imp.level, a, e), -1, 1)))
        assert angular_error(radius, np.linalg.norm(p - centre), theta) <= math.radians(st.error_deg) + 1e-9
    # both sides: the first and last bins face the building's west and east
    assert len({int(x) for x in ia}) == imp.n_az


def test_an_image_shared_by_two_cells() -> None:
    cells = [_cell(0, 0.0, 0.0, 20.0, 10.0), _cell(1, 20.0, 0.0, 40.0, 10.0)]
    boxes = {3: _box(30.0, 400.0)}
    plan = plan_impostors(cells, {0: np.array([3]), 1: np.array([3])}, boxes, {3: 100}, ImpostorSettings())
    a, b = plan.cells[0][0].images, plan.cells[1][0].images
    assert set(a) & set(b)
    assert len(plan.jobs) < len(a) + len(b) or len(plan.jobs) == len(set(a) | set(b))
    assert sorted(j[0] for j in plan.jobs) == list(range(1, len(plan.jobs) + 1))


def test_complex_buildings_are_impostors_where_the_bound_allows() -> None:
    cell = _cell(0, 0.0, 0.0, 20.0, 20.0)
    boxes = {1: _box(10.0, 80.0), 2: _box(10.0, 16.0 + 12.0)}  # 60 m off; the other next to the cell
    plan = plan_impostors([cell], {0: np.array([1, 2])}, boxes, {1: 50_000, 2: 50_000},
                          ImpostorSettings(distance=500.0, complex_triangles=10_000))
    assert [c.object for c in plan.cells[0]] == [1]
    assert plan.complex == 2 and plan.too_near == 1


def test_settings_are_checked() -> None:
    for bad in (dict(distance=0.0), dict(error_deg=0.0), dict(size=100), dict(complex_triangles=0),
                dict(codec="png"), dict(sampling="blur")):
        with pytest.raises(InputError):
            ImpostorSettings(**bad).check()  # type: ignore[arg-type]


# ------------------------------------------------------------------ images


def test_codec_round_trip_and_bounds() -> None:
    img = np.zeros((16, 16, 4), np.uint8)
    img[4:12, 4:12] = (120, 60, 30, 255)
    img[4:12, 3] = (60, 30, 15, 128)  # a half-covered column, premultiplied
    for codec in ("webp-lossless", "webp"):
        back = decode_image(encode_image(img, codec), "test image")
        assert back.shape == img.shape
        assert np.abs(back.astype(int) - img.astype(int)).max() <= (1 if codec == "webp-lossless" else 40)
    with pytest.raises(CodecError):
        decode_image(b"not an image", "test image")


@pytest.mark.gl
def test_premultiplied_silhouette_has_no_dark_fringe(gl: object) -> None:
    """Composited over white, a silhouette texel lies between the object's colours and
    white; straight alpha filtered with the transparent black would darken it."""
    from walkstream.server.bake.impostorrender import ImpostorRenderer
    from walkstream.shared.records import Mesh

    # one flat quad facing the sun (south), 10 m square, a wall's colour: bright, its
    # edge texels partly covered
    p = np.array([[-5, 0, 0], [5, 0, 0], [5, 0, 10], [-5, 0, 10]], np.float32)
    m = Mesh(p, np.tile([0.0, -1.0, 0.0], (4, 1)), np.array([[0, 1, 2], [0, 2, 3]]), np.zeros(4, np.uint8))
    r = ImpostorRenderer([m], [1], [(-5.0, -0.5, 0.0, 5.0, 0.5, 10.0)], ctx=gl)
    try:
        u = np.array([0.2, -1.0, 0.13])
        # area sampling: the silhouette's texels partly covered (point sampling has none)
        img = decode_image(encode_image(r.render(1, u / np.linalg.norm(u), 32, "area")), "image")
        # images drawn as tiles of one framebuffer are those drawn one by one
        views = [(1, bin_direction(2, a, 15)) for a in (10, 12, 14)]
        tiled = r.render_many(views, 16, "area")
        assert all(np.array_equal(t, r.render(o, d, 16, "area")) for t, (o, d) in zip(tiled, views, strict=True))
        assert len({t.tobytes() for t in tiled}) == 3
    finally:
        r.release()
    a = img[..., 3].astype(np.float64) / 255.0
    solid, edge = a == 1.0, (a > 0.05) & (a < 0.95)
    assert solid.sum() > 50 and edge.sum() > 10
    over_white = img[..., :3].astype(np.float64) + 255.0 * (1.0 - a[..., None])
    lo = img[solid][:, :3].min(axis=0).astype(np.float64)
    assert (over_white[edge] >= lo - 2.0).all(), "a silhouette texel is darker than the object: a dark fringe"
    # the trap it guards: the same texels taken as straight alpha are darker
    naive = img[..., :3] * a[..., None] + 255.0 * (1.0 - a[..., None])
    assert (naive[edge] < lo - 2.0).any()


# ------------------------------------------------------------------ the bake

FAST = BakeSettings(resolution=32, sampling="corners")
SMALL = ImpostorSettings(distance=50.0, error_deg=4.0, size=16)


@pytest.fixture(scope="module")
def city(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("impostors") / "city.geojson"
    write_city(path, 150, 2)
    return path


@pytest.fixture(scope="module")
def baked(city: Path, gl_ctx: object) -> tuple[Path, dict]:
    out = city.parent / "imp.db"
    return out, bake(city, out, settings=FAST, impostors=SMALL, name="imp")


@pytest.mark.gl
def test_bake_stores_images_and_cell_lists(baked: tuple[Path, dict]) -> None:
    path, summary = baked
    assert summary["impostor_images"] > 0 and summary["impostor_pairs"] > 0
    assert "impostors" in summary["features"]
    with SceneReader.open(path) as r:
        assert r.has_impostors()
        info = r.impostor_info()
        listed = set()
        for c in r.cells():
            for row in r.cell_impostors(c.id):
                obj, level, az0, n_az, el0, n_el, *images = row
                assert len(images) == n_az * n_el and 0 <= level
                listed.update(images)
                assert all(info[i][0] == obj for i in images)
        assert listed == set(info)
        some = sorted(info)[:5]
        for media, data in r.impostor_images(some).values():
            assert media == "image/webp"
            img = decode_image(data, "stored image")
            assert img.shape[0] == img.shape[1] <= SMALL.size and img[..., 3].max() == 255


@pytest.mark.gl
def test_a_bake_without_impostors_is_unchanged(city: Path, baked: tuple[Path, dict], tmp_path: Path) -> None:
    plain = tmp_path / "plain.db"
    summary = bake(city, plain, settings=FAST)
    assert not any(k.startswith("impostor") for k in summary)
    assert "impostors" not in summary["features"]
    with SceneReader.open(plain) as r:
        assert not r.has_impostors()
        assert r.impostor_images([1, 2]) == {} and r.cell_impostors(0) == [] and r.impostor_info() == {}
        assert "impostors" not in r.meta.settings


@pytest.mark.gl
def test_a_bake_killed_among_its_images_resumes(
    city: Path, baked: tuple[Path, dict], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    out = tmp_path / "killed.db"
    real = SceneWriter.add_impostor
    calls = {"n": 0}

    def dying(self: SceneWriter, *args: object, **kw: object) -> None:
        if calls["n"] == 3:
            raise KeyboardInterrupt
        calls["n"] += 1
        real(self, *args, **kw)  # type: ignore[arg-type]

    monkeypatch.setattr(SceneWriter, "add_impostor", dying)
    with pytest.raises(KeyboardInterrupt):
        bake(city, out, settings=FAST, impostors=SMALL, name="imp")
    monkeypatch.setattr(SceneWriter, "add_impostor", real)
    summary = bake(city, out, settings=FAST, impostors=SMALL, name="imp")
    assert summary["impostor_resumed"] == 3
    assert summary["version"] == baked[1]["version"]


def test_impostors_refuse_an_interior(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="--impostors"):
        bake(tmp_path / "x.geojson", tmp_path / "x.db", interior=tmp_path / "y.json", impostors=ImpostorSettings())


# ------------------------------------------------------------------ the service


@pytest.fixture(scope="module")
def plain(city: Path, gl_ctx: object) -> Path:
    out = city.parent / "plain.db"
    bake(city, out, settings=FAST, name="plain")
    return out


@pytest.fixture(scope="module")
def http(baked: tuple[Path, dict], plain: Path) -> Iterator[Http]:
    app = create_app([baked[0], plain])
    c = Http(app)
    yield c
    c.close()
    app.state.scenes.close()


@pytest.mark.gl
def test_a_scene_without_impostors_serves_its_cells_as_before_and_404s_images(
    http: Http, plain: Path
) -> None:
    with SceneReader.open(plain) as r:
        c = r.cell(0)
        before = msgpack.packb(CellRecord(id=c.id, kind=c.kind, pvs=c.pvs, ach=c.ach).to_wire(), use_bin_type=True)
    got = http.get("/v1/scenes/plain/cells/0", headers={"Accept": MSGPACK})
    assert got.status_code == 200 and got.content == before and b"imp" not in got.content
    for resp in (http.get("/v1/scenes/plain/impostors/1"), http.post("/v1/scenes/plain/impostors", json={"ids": [1]})):
        assert resp.status_code == 404
        assert "without --impostors" in resp.json()["error"]


@pytest.mark.gl
def test_images_are_listed_by_cells_and_served_immutable_in_batches(http: Http) -> None:
    rows = []
    for cid in range(40):
        resp = http.get(f"/v1/scenes/imp/cells/{cid}", headers={"Accept": MSGPACK})
        if resp.status_code != 200:
            break
        imp = decode_cell(resp.content, "cell").impostors
        if imp is not None:
            assert imp.d == SMALL.distance and abs(imp.bound - math.radians(SMALL.error_deg)) < 1e-6
            assert not imp.perspective  # an orthographic bake: served as before
            rows += imp.rows
    assert rows, "no cell lists an impostor"
    row = rows[0]
    assert row.radius > 0 and len(row.images) == row.n_az * row.n_el
    assert row.image_for(row.az0, row.el0) == row.images[0]
    image = row.images[0]
    one = http.get(f"/v1/scenes/imp/impostors/{image}")
    assert one.status_code == 200 and one.headers["content-type"] == "image/webp"
    assert "immutable" in one.headers["cache-control"]
    assert decode_image(one.content, "image").shape[2] == 4
    again = http.get(f"/v1/scenes/imp/impostors/{image}", headers={"If-None-Match": one.headers["etag"]})
    assert again.status_code == 304
    ids = sorted({i for r in rows for i in r.images})[:3]
    batch = http.post("/v1/scenes/imp/impostors", json={"ids": ids})
    assert batch.status_code == 200
    parts = [check_contents_part(p, "part") for p in msgpack.Unpacker(io.BytesIO(batch.content), raw=False)]
    assert [p[0] for p in parts] == ids
    first = http.get(f"/v1/scenes/imp/impostors/{ids[0]}")
    assert parts[0][1] == first.headers["etag"] and parts[0][2] == first.content
    assert http.get("/v1/scenes/imp/impostors/999999").status_code == 404
    assert http.post("/v1/scenes/imp/impostors", json={"ids": [ids[0], ids[0]]}).status_code == 422


# ------------------------------------------------------------------ the client's choice


def _row(images: tuple[int, ...] = (5,), box: tuple[float, ...] = (295.0, -5.0, 0.0, 305.0, 5.0, 20.0)) -> ImpostorRow:
    centre = np.array([(box[0] + box[3]) / 2, (box[1] + box[4]) / 2, (box[2] + box[5]) / 2])
    az, el = directions(np.array([0.0, 0.0, 1.7]), centre)
    ia, ie = bin_of(0, az, el)
    return ImpostorRow(9, 0, int(ia), len(images), int(ie), 1, box, images)


def test_the_blend_at_the_exact_switch_distance() -> None:
    d, bound = 250.0, math.radians(2.0)
    blend = BLEND_SHARE * d  # the blend's length scales with D
    assert impostor_alpha(d + blend / 2, 0.0, d, bound) == pytest.approx(impostor_alpha(d / 10 + blend / 20, 0.0, d / 10, bound))
    alpha = impostor_alpha([d - 1.0, d, d + blend / 2, d + blend, d + 100.0], 0.0, d, bound)
    assert alpha[0] == 0.0 and alpha[1] == 0.0, "at D and nearer: geometry only"
    assert 0.0 < alpha[2] < 1.0 and alpha[3] == 1.0 and alpha[4] == 1.0
    eps = 1e-6  # continuous at the switch: no pop
    assert impostor_alpha(d + eps, 0.0, d, bound) < 1e-9
    steps = impostor_alpha(np.linspace(d, d + blend, 201), 0.0, d, bound)
    assert (np.diff(steps) >= 0).all() and np.abs(np.diff(steps)).max() < 0.02
    # the error bound: full opacity well inside it, none at it, continuous between
    errs = impostor_alpha(d + 100.0, [0.5 * bound, 0.75 * bound, 0.9 * bound, bound, 1.1 * bound], d, bound)
    assert errs[0] == 1.0 and errs[1] == 1.0 and 0.0 < errs[2] < 1.0 and errs[3] == 0.0 and errs[4] == 0.0


def test_choice_picks_the_bin_of_the_viewers_direction() -> None:
    row = _row()
    (c,) = choose_impostors([row], (0.0, 0.0, 1.7), 250.0, math.radians(4.0))
    assert c.image == 5 and c.alpha > 0.0 and abs(c.distance - 295.0) < 1e-9
    # a viewer whose direction falls in a bin the cell does not list: geometry
    (c,) = choose_impostors([row], (300.0, 400.0, 1.7), 250.0, math.radians(4.0))
    assert c.image is None and c.alpha == 0.0


def test_a_texture_budget_smaller_than_one_cells_images() -> None:
    choices = [ImpostorChoice(k, 100 + k, 1.0, 300.0 + 10.0 * k, 0.0) for k in range(6)]
    sizes = {100 + k: 4 * 64 * 64 for k in range(6)}
    fitted = fit_textures(choices, sizes, budget=3 * 4 * 64 * 64 + 10)
    assert [c.image for c in fitted] == [100, 101, 102, None, None, None], "the farthest dropped first"
    assert all(c.alpha == 0.0 for c in fitted[3:])
    # a budget under one image: every building is geometry, none is lost
    assert [c.image for c in fit_textures(choices, sizes, budget=100)] == [None] * 6
    # an image two buildings share counts once
    shared = [ImpostorChoice(1, 7, 1.0, 300.0, 0.0), ImpostorChoice(2, 7, 1.0, 310.0, 0.0)]
    assert [c.image for c in fit_textures(shared, {7: 1000}, budget=1000)] == [7, 7]


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--impostors", "--impostor-size", "100"], "--impostor-size"),
        (["--impostors", "--impostor-error", "0"], "--impostor-error"),
        (["--impostor-distance", "100"], "give --impostors too"),
        (["--impostor-sampling", "point"], "give --impostors too"),
        (["--impostor-projection", "perspective"], "give --impostors too"),
    ],
)
def test_bad_impostor_flags_are_one_clear_line(
    flags: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from walkstream.cli import main

    assert main(["bake", str(tmp_path / "c.geojson"), "-o", str(tmp_path / "x.db"), *flags]) == 2
    err = capsys.readouterr().err
    assert err.startswith("walkstream: error:") and message in err and "Traceback" not in err
