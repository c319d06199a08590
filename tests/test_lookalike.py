"""A building at LOD2 drawn as its box with facade pictures where the two look alike on the screen."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest

from walkstream.client.config import ReplayConfig
from walkstream.client.draw.facades import BACK_M, FRONT_M, FacadeBaker
from walkstream.client.draw.lookalike import (
    GRAZING_COS,
    PARALLAX_PX,
    buildings_alike,
    facade_screen_error,
    face_geometry,
    looks_alike,
    texel_distance,
)
from walkstream.client.net.link import LinkProfile
from walkstream.client.replay import run_replay
from walkstream.client.truth.render import TruthRenderer, form_key
from walkstream.server.service.main import create_app
from walkstream.shared.buildings import build_lods
from walkstream.shared.camera import look_at
from walkstream.shared.errors import InputError
from walkstream.shared.records import BuildingParams, Mesh

URL = "http://walkstream.test"
FOCAL = 208.0  # 240 pixels high, 60° field of view


def _face(relief: float, texel: float = 0.125) -> tuple[Any, ...]:
    """One 20 x 15 m face on the plane y = 0 turned to -y."""
    return (np.array([[0.0, 0.0, 0.0]]), np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, -1.0, 0.0]]),
            np.array([[20.0, 15.0]]), np.array([texel]), np.array([relief]))


def test_parallax_is_nil_head_on_and_grows_near_and_grazing() -> None:
    g = _face(0.3)
    far_head_on = np.array([10.0, -200.0, 7.5])
    p, t, c = facade_screen_error(g, far_head_on, FOCAL)
    assert p < PARALLAX_PX and t < 1.0 and c > 0.99 and looks_alike(g, far_head_on, FOCAL)
    # the same distance at a grazing angle: the corner nearest the eye sees the relief move,
    # and the windows shrink across the view below a pixel: not alike, whatever the parallax
    graze = np.array([200.0, -20.0, 1.7])
    p2, _, c2 = facade_screen_error(g, graze, FOCAL)
    assert p2 > p and p2 < PARALLAX_PX and c2 < GRAZING_COS and not looks_alike(g, graze, FOCAL)
    near = np.array([10.0, -15.0, 1.7])
    pn, tn, _ = facade_screen_error(g, near, FOCAL)
    assert pn > PARALLAX_PX and not looks_alike(g, near, FOCAL)
    # by the formula: the nearest point at 15 m, the grid's far corners at a slant
    assert pn <= 0.3 * FOCAL / 15.0 + 1e-9


def test_a_face_turned_away_is_not_seen_and_a_too_coarse_texel_refuses() -> None:
    g = _face(0.3)
    behind = np.array([10.0, 30.0, 1.7])
    assert facade_screen_error(g, behind, FOCAL) == (0.0, 0.0, 1.0)
    coarse = _face(0.0, texel=1.0)  # a metre a texel: within a pixel beyond 208 m only
    assert not looks_alike(coarse, np.array([10.0, -150.0, 7.5]), FOCAL)
    assert looks_alike(coarse, np.array([10.0, -260.0, 7.5]), FOCAL)
    assert texel_distance(1.0, FOCAL) == pytest.approx(208.0)
    assert not looks_alike(_face(math.inf), np.array([10.0, -5000.0, 7.5]), FOCAL)


def _building() -> tuple[Mesh, Mesh, Mesh]:
    ring = np.array([[0.0, 0.0], [20.0, 0.0], [20.0, 12.0], [0.0, 12.0]])
    return build_lods(BuildingParams(id=1, rings=(ring,), neighbour_heights=(np.zeros(4),), floors=5,
                                     floor_height=3.0, style=1))


@pytest.mark.gl
def test_where_the_test_says_alike_the_pictured_box_matches_lod2(gl: Any) -> None:
    l0, _, l2 = _building()
    size = (320, 240)
    truth = TruthRenderer({1: l2}, size, forms={(1, 0): l0}, ctx=gl)
    baker = FacadeBaker(gl)
    try:
        s = baker.bake(1, l0, l2)
        reliefs = [im.relief for im in s.images]
        assert all(0.0 < r <= max(FRONT_M, BACK_M) for r in reliefs), reliefs  # windows are recessed
        g = face_geometry(s.images)
        focal = float(truth.proj[1, 1]) * size[1] / 2.0
        errs = {}
        for name, eye in (("far", np.array([10.0, -150.0, 1.7])), ("near", np.array([-6.0, -14.0, 1.7]))):
            view = look_at(eye, (10.0, 6.0, 7.0))
            ids, _ = truth.render(eye, view)
            full = truth.colour().astype(np.float64)
            truth.render(eye, view, truth.flags([form_key(1, 0)]))
            textured = truth.paint_quads(s.quads(eye), view).astype(np.float64)
            on = ids >= 0
            errs[name] = (float(np.abs(textured - full)[on].mean()), looks_alike(g, eye, focal))
        assert errs["far"][1] and not errs["near"][1], errs
        assert errs["far"][0] < errs["near"][0], errs  # what the test lets through is the closer
    finally:
        baker.release()
        truth.release()


@pytest.fixture(scope="module")
def city(small_city_db: Path) -> Path:
    """The small city every walk here replays (read only)."""
    return small_city_db


def _replay(db: Path, **kw: Any) -> dict[str, Any]:
    app = create_app([db])
    try:
        # a fixed schedule well within the frame period: the budget draws LOD2, whatever the load
        cfg = ReplayConfig(link=LinkProfile(56_000.0, 56_000.0, 0.2), device="gl", clock="sim", duration_s=8.0,
                           size=(160, 120), facades=True, frame_times=(0.02,) * 400, **kw)
        return run_replay(httpx.ASGITransport(app=app), URL, cfg).summary
    finally:
        app.state.scenes.close()


@pytest.mark.gl
def test_on_gl_the_lookalike_boxes_save_triangles(city: Path, gl_ctx: object) -> None:
    on = _replay(city, facade_grazing_deg=90.0)  # no grazing limit: the small city's streets are narrow
    off = _replay(city, facade_lookalike=False)
    assert on["facades"]["lookalike_mean"] > 0 and off["facades"]["lookalike_mean"] == 0
    assert on["triangles_mean"] < off["triangles_mean"]


@pytest.mark.gl
def test_under_the_real_clock_the_pictures_are_baked_in_the_frames_slack(city: Path, gl_ctx: object) -> None:
    # 2 fps: half a second of slack a frame, whatever the machine's load
    app = create_app([city])
    try:
        cfg = ReplayConfig(link=LinkProfile(56_000.0, 56_000.0, 0.2), device="gl", clock="real", duration_s=4.0,
                           size=(160, 120), fps=2.0, facades=True)
        f = run_replay(httpx.ASGITransport(app=app), URL, cfg).summary["facades"]
    finally:
        app.state.scenes.close()
    assert f["slack_triangles"] > 0 and f["slack_triangles"] == f["bake_triangles"]
    assert f["bake_triangles_max"] == 0  # no frame paid for a bake in its own time
    assert f["buildings_baked"] > 0


def test_a_bad_grazing_angle_is_refused() -> None:
    link = LinkProfile(56_000.0, 56_000.0, 0.2)
    with pytest.raises(InputError, match="--facade-grazing"):
        ReplayConfig(link, facade_grazing_deg=95.0)
    for bad in (0.0, -1.0, math.nan, 9.0):
        with pytest.raises(InputError, match="--facade-parallax"):
            ReplayConfig(link, facade_parallax_px=bad)


def test_the_parallax_bound_decides_which_buildings_look_alike() -> None:
    # a relief of 0.3 m from 25 m, 10 m past the face's edge: between 1 and 1.5 pixels,
    # its texels within one
    g = _face(0.3)
    eye = np.array([-10.0, -25.0, 7.5])
    p, _, _ = facade_screen_error(g, eye, FOCAL)
    assert PARALLAX_PX < p < 1.5
    assert buildings_alike([g, _face(0.0)], eye, FOCAL, 0.0).tolist() == [False, True]
    assert buildings_alike([g, _face(0.0)], eye, FOCAL, 0.0, 1.5).tolist() == [True, True]
