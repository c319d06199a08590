"""Facade textures on boxes (issue 27): a building left at its LOD0 box carries images of
its LOD2 facades, baked by the client, drawn as quads over the box, charged to the frame,
painted into the colour truth's picture of the client's frame."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest

from walkstream.client.config import ReplayConfig
from walkstream.client.draw.facades import FacadeBaker, facade_image_id, texture_size, wall_faces
from walkstream.client.net.link import LinkProfile
from walkstream.client.replay import run_replay
from walkstream.client.truth.render import TruthRenderer, form_key
from walkstream.server.service.main import create_app
from walkstream.shared.buildings import build_lods
from walkstream.shared.camera import look_at
from walkstream.shared.errors import InputError
from walkstream.shared.records import BuildingParams, Mesh

URL = "http://walkstream.test"


def _building() -> tuple[Mesh, Mesh, Mesh]:
    ring = np.array([[0.0, 0.0], [20.0, 0.0], [20.0, 12.0], [0.0, 12.0]])
    return build_lods(BuildingParams(id=1, rings=(ring,), neighbour_heights=(np.zeros(4),), floors=5,
                                     floor_height=3.0, style=1))


def test_the_wall_faces_of_a_box_are_its_four_walls() -> None:
    l0, _, l2 = _building()
    top = float(l2.positions[:, 2].max())
    faces = wall_faces(l0, top)
    assert sorted(round(f.width, 2) for f in faces) == [12.6, 12.6, 20.6, 20.6]  # grown 0.3 m each side
    for f in faces:
        assert abs(f.normal[2]) < 1e-9 and abs(np.linalg.norm(f.normal) - 1) < 1e-9
        assert abs(f.right @ f.normal) < 1e-9
        c = f.corners()
        assert np.isclose(c[2, 2], top) and np.isclose(c[0, 2], -0.3)  # up to LOD2's parapet
        # the face lies on the box's wall: 0 or 20 (x), 0 or 12 (y)
        d = float(c[0, :2] @ f.normal[:2])
        assert np.isclose(abs(d), 0.0) or np.isclose(abs(d), 20.0) or np.isclose(abs(d), 12.0)
    assert texture_size(faces[0], 8.0, 256) == (165, 128)
    assert texture_size(faces[0], 100.0, 256) == (256, 256)


def test_image_ids_are_negative_and_distinct() -> None:
    ids = {facade_image_id(o, k) for o in range(50) for k in range(10)}
    assert len(ids) == 500 and max(ids) < 0


def test_facade_ids_never_meet_a_wall_texture_or_an_impostor_image() -> None:
    # a wall texture t is drawn as -1 - t: building 2's face 3 was -1 - 131 before, the key
    # of wall texture 131 too, so one frame showing both drew one image in both places
    from walkstream.client.draw.quads import FACADE_IDS

    facades = {facade_image_id(o, k) for o in range(200) for k in range(64)}
    walls = {-1 - t for t in range(200 * 64 + 1)}
    assert not facades & walls
    assert max(facades) <= -FACADE_IDS < min(walls)


def test_bad_facade_settings_are_refused() -> None:
    link = LinkProfile(56_000.0, 56_000.0, 0.2)
    with pytest.raises(InputError, match="--facade-texels"):
        ReplayConfig(link, facade_texels_per_m=0.0)
    with pytest.raises(InputError, match="--facade-bake-share"):
        ReplayConfig(link, facade_bake_share=0.0)
    with pytest.raises(InputError, match="--facade-budget"):
        ReplayConfig(link, facade_budget_bytes=-1)
    with pytest.raises(InputError, match="--facade-filter 'mipmap'"):
        ReplayConfig(link, facade_filter="mipmap")


@pytest.mark.gl
@pytest.mark.parametrize("how", ["point", "anisotropic"])
def test_a_facade_seen_obliquely_is_read_as_its_filter_says(gl: Any, how: str) -> None:
    """Windows a texel wide, black on white, on a face seen along the street at 80 degrees:
    read point-sampled each pixel is a window or a wall (what one sample of LOD2 shows),
    read anisotropically each is the mean under its footprint (what an anti-aliased
    drawing of LOD2 shows); a wrong filter, or mipmaps with none built, fails one side."""
    from walkstream.client.draw.facades import facade_image_id
    from walkstream.client.draw.frames import FrameRenderer
    from walkstream.shared.camera import perspective

    img = np.full((64, 256, 4), 255, np.uint8)
    img[:, 1::2, :3] = 0  # a column of windows every other texel
    # a 40 m x 10 m face in the plane y = 0 facing -y, seen from 3 m in front at 80 degrees
    corners = np.array([[0.0, 0.0, 0.0], [40.0, 0.0, 0.0], [40.0, 0.0, 10.0], [0.0, 0.0, 10.0]])
    eye = np.array([-2.0, -3.0, 5.0])
    r = FrameRenderer(size=(64, 64), fov_deg=40.0, ctx=gl, facade_filter=how)
    try:
        r.impostors = [(corners, facade_image_id(1, 0), img, 1.0)]
        r.draw([], look_at(eye, eye + np.array([np.sin(np.radians(80)), np.cos(np.radians(80)), 0.0])),
               perspective(40.0, 1.0, 0.5, 100.0))
        px = r.snapshot()[:, :, :3].astype(float).mean(axis=2)
        held = r._quads.texture_bytes if r._quads is not None else 0
    finally:
        r.release()
    # the face's far part, where a pixel spans several windows (the sky, 239, is to its right)
    far = px[16:48, 12:32]
    if how == "point":
        assert ((far < 40) | (far > 250)).mean() > 0.9  # black or white, as the texel under each centre
        assert held == img.nbytes
    else:
        assert np.abs(far - 127.5).max() < 25  # grey, the windows averaged with their wall
        assert held == img.nbytes * 4 // 3  # the mipmaps counted


@pytest.mark.gl
def test_a_textured_box_is_closer_to_lod2_than_the_plain_box(gl: Any) -> None:
    l0, _, l2 = _building()
    truth = TruthRenderer({1: l2}, (160, 120), forms={(1, 0): l0}, ctx=gl)
    baker = FacadeBaker(gl)
    try:
        s = baker.bake(1, l0, l2)
        eye = np.array([-8.0, -22.0, 1.7])  # the south and west faces, obliquely
        view = look_at(eye, (10.0, 6.0, 7.0))
        ids, _ = truth.render(eye, view)
        full = truth.colour().astype(np.float64)
        truth.render(eye, view, truth.flags([form_key(1, 0)]))
        box = truth.colour().astype(np.float64)
        quads = s.quads(eye)
        assert len(quads) == 2  # the two faces turned to the eye, not the two behind
        textured = truth.paint_quads(quads, view).astype(np.float64)
        on = ids >= 0
        err_box = float(np.abs(box - full)[on].mean())
        err_tex = float(np.abs(textured - full)[on].mean())
        assert err_tex < 0.5 * err_box, (err_tex, err_box)
    finally:
        baker.release()
        truth.release()


@pytest.mark.gl
def test_a_facade_image_is_premultiplied_and_empty_where_lod2_is_not(gl: Any) -> None:
    l0, _, l2 = _building()
    baker = FacadeBaker(gl, texels_per_m=4.0)
    try:
        s = baker.bake(1, l0, l2)
    finally:
        baker.release()
    assert len(s.images) == 4 and s.nbytes == sum(im.rgba.nbytes for im in s.images)
    assert s.bake_triangles == sum(im.bake_triangles for im in s.images) > 0
    for im in s.images:
        a = im.rgba
        assert (a[..., :3] <= a[..., 3:4]).all()  # premultiplied: no colour without cover
        assert a[-1, :, 3].max() == 0  # the bottom margin is below the ground: nothing there
        assert (a[a.shape[0] // 2, a.shape[1] // 4 : -a.shape[1] // 4, 3] == 255).all()  # the wall itself


@pytest.mark.gl
def test_a_facade_texel_holds_one_point_of_the_surface_not_a_mix(gl: Any) -> None:
    """Point sampling (the default): a texel is covered or not, and its colour is one the
    surface has; averaging 2x2 samples (``samples=2``) mixes a window with its wall."""
    l0, _, l2 = _building()
    with pytest.raises(InputError, match="samples per texel"):
        FacadeBaker(gl, samples=3)
    made = {}
    for n in (1, 2):
        baker = FacadeBaker(gl, samples=n)
        try:
            made[n] = [baker.bake(1, l0, l2).images for _ in range(2)]
        finally:
            baker.release()
    for a, b in zip(*made[1], strict=True):
        assert np.array_equal(a.rgba, b.rgba)  # the same bytes however often it is baked
    point = np.concatenate([im.rgba.reshape(-1, 4) for im in made[1][0]])
    area = np.concatenate([im.rgba.reshape(-1, 4) for im in made[2][0]])
    assert set(np.unique(point[:, 3]).tolist()) <= {0, 255}
    assert ((area[:, 3] > 0) & (area[:, 3] < 255)).any()  # soft edges where samples were averaged
    # the colours of the opaque texels: the surface's few lit colours, not the mixes between them
    colours = {tuple(c) for c in point[point[:, 3] == 255, :3].tolist()}
    mixes = {tuple(c) for c in area[area[:, 3] == 255, :3].tolist()}
    assert len(colours) < len(mixes) / 2, (len(colours), len(mixes))


@pytest.fixture(scope="module")
def city(small_city_db: Path) -> Path:
    """The small city every walk here replays (read only)."""
    return small_city_db


def _replay(db: Path, duration: float = 8.0, **kw: Any) -> dict[str, Any]:
    app = create_app([db])
    try:
        cfg = ReplayConfig(link=LinkProfile(56_000.0, 56_000.0, 0.2), device="pda", duration_s=duration, **kw)
        return run_replay(httpx.ASGITransport(app=app), URL, cfg).summary
    finally:
        app.state.scenes.close()


@pytest.mark.gl
def test_a_walk_on_pda_draws_boxes_with_facades_and_pays_for_them(city: Path, gl_ctx: object) -> None:
    fac = _replay(city, truth_every=40, size=(160, 120))
    box = _replay(city, truth_every=40, size=(160, 120), facades=False)
    f = fac["facades"]
    assert f["buildings_baked"] > 0 and f["facades_mean"] > 0 and f["facade_quads_mean"] > 0
    assert f["bake_triangles"] > 0 and 0 < f["texture_bytes_max"] <= 8 << 20
    assert "error" not in f and "facades" not in box
    # objects drawn as geometry count no quad: the facades' quads stay out of the count
    geo = fac["geometry_objects_mean"], box["geometry_objects_mean"]
    assert 0 < geo[0] < geo[1] + f["facade_quads_mean"] / 2, (geo, f["facade_quads_mean"])
    err = fac["truth"]["colour"]["error_causes"]["lod_colour"], box["truth"]["colour"]["error_causes"]["lod_colour"]
    assert err[0] < err[1], err  # the boxes' own error falls


@pytest.mark.gl
def test_a_facade_budget_smaller_than_one_building_draws_plain_boxes(city: Path, gl_ctx: object) -> None:
    f = _replay(city, 4.0, facade_budget_bytes=1)["facades"]
    assert f["buildings_baked"] > 0 and f["facades_mean"] == 0 and f["dropped"] > 0


@pytest.mark.gl
def test_the_truth_paints_facades_into_the_boxes_picture_not_as_stand_ins(gl: Any) -> None:
    from walkstream.client.truth.notes import FrameNote
    from walkstream.client.truth.standin import impostor_overlay

    l0, _, l2 = _building()
    truth = TruthRenderer({1: l2}, (160, 120), forms={(1, 0): l0}, ctx=gl)
    baker = FacadeBaker(gl)
    try:
        s = baker.bake(1, l0, l2)
        eye = np.array([10.0, -25.0, 1.7])
        view = look_at(eye, (10.0, 6.0, 7.0))
        note = FrameNote(frame=0, t=0.0, eye=eye, view=view, cell=None, pvs=None, received=np.zeros(0, np.int64),
                         built=np.zeros(0, np.int64), drawn=((1, 0, l0),), parts=(), waiting=(), fog=np.inf,
                         facades=tuple(s.quads(eye)))
        keys, _ = truth.render(eye, view, truth.flags([form_key(1, 0)]))
        rgb = truth.colour()
        plain = rgb.copy()
        painted, wall = impostor_overlay(truth, truth.proj)(note, rgb, keys)
        assert not painted.any() and not wall.any()  # no stand-in: the pixels stay the box's
        assert np.any(rgb != plain, axis=2).mean() > 0.05  # the windows are on the box now
    finally:
        baker.release()
        truth.release()
