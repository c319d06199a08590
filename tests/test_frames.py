"""Tests of walkstream.client.draw.frames: the per-frame renderer and the walker camera."""

from __future__ import annotations

import math
from pathlib import Path

import moderngl
import numpy as np
import pytest

from walkstream.client.draw.frames import VERTEX_BYTES, FrameRenderer
from walkstream.client.draw.meshes import BACKGROUND_RGB
from walkstream.shared.buildings import build_lods
from walkstream.shared.camera import camera, look_at
from walkstream.shared.errors import InputError, RenderError
from walkstream.shared.records import BuildingParams, Mesh, StreetParams
from walkstream.shared.streets import build_street

SIZE = (96, 72)


def building() -> BuildingParams:
    ring = np.array([[10.0, -5.0], [20.0, -5.0], [20.0, 5.0], [10.0, 5.0]])
    return BuildingParams(1, (ring,), (np.zeros(4),), floors=4, floor_height=3.0)


def street() -> StreetParams:
    ring = np.array([[0.0, -4.0], [60.0, -4.0], [60.0, 4.0], [0.0, 4.0]])
    return StreetParams(2, "street", ring, 8.0)


def not_background(img: np.ndarray) -> float:
    return float(np.mean(np.any(img != np.array(BACKGROUND_RGB, np.uint8), axis=-1)))


# eye in the street, 1.7 m up, looking east at the building's west facade
EYE = (0.0, 0.0, 1.7)


# --------------------------------------------------------------------------- camera


def test_camera_matches_look_at() -> None:
    for yaw, pitch in ((0.0, 0.0), (math.pi / 2, 0.0), (2.0, -0.3), (-1.0, 0.5)):
        fwd = np.array(
            [math.cos(pitch) * math.cos(yaw), math.cos(pitch) * math.sin(yaw), math.sin(pitch)]
        )
        expected = look_at(EYE, np.array(EYE) + fwd)
        assert np.allclose(camera(EYE, yaw, pitch), expected, atol=1e-6)


def test_camera_yaw_convention() -> None:
    # yaw pi/2 looks north (+y): a point north of the eye lands on the view axis (-z)
    v = camera((0.0, 0.0, 0.0), math.pi / 2, 0.0).astype(np.float64)
    p = v @ np.array([0.0, 10.0, 0.0, 1.0])
    assert np.allclose(p[:3], [0.0, 0.0, -10.0], atol=1e-5)


def test_camera_clamps_pitch_and_rejects_nonsense() -> None:
    v = camera(EYE, 0.0, math.pi / 2)  # straight up would have no screen-up
    assert np.all(np.isfinite(v))
    with pytest.raises(InputError):
        camera((0.0, float("nan"), 0.0), 0.0, 0.0)
    with pytest.raises(InputError):
        camera((0.0, 0.0), 0.0, 0.0)


# --------------------------------------------------------------------------- renderer


@pytest.mark.gl
def test_draws_a_building_at_lod2(gl: moderngl.Context) -> None:
    meshes = build_lods(building())
    with FrameRenderer(SIZE, ctx=gl) as fr:
        for lod, m in enumerate(meshes):
            fr.upload((1, lod), m)
        view = camera(EYE, 0.0, 0.0)
        dt = fr.draw([(1, 2)], view)
        assert dt > 0.0
        img = fr.snapshot()
        assert img.shape == (SIZE[1], SIZE[0], 3) and img.dtype == np.uint8
        covered = not_background(img)
        assert covered > 0.1  # the facade fills a good part of the view
        assert fr.last_triangles == meshes[2].triangles
        assert fr.last_drawn == 1
        # looking away (west) there is nothing: all background
        fr.draw([(1, 2)], camera(EYE, math.pi, 0.0))
        assert not_background(fr.snapshot()) == 0.0


@pytest.mark.gl
def test_lods_give_different_frames(gl: moderngl.Context) -> None:
    meshes = build_lods(building())
    with FrameRenderer(SIZE, ctx=gl) as fr:
        for lod, m in enumerate(meshes):
            fr.upload((1, lod), m)
        view = camera((0.0, 0.0, 6.0), 0.0, 0.0)
        fr.draw([(1, 0)], view)
        a = fr.snapshot()
        fr.draw([(1, 2)], view)
        b = fr.snapshot()
        assert np.any(a != b)  # windows at LOD2


@pytest.mark.gl
def test_missing_keys_are_skipped(gl: moderngl.Context) -> None:
    m = build_lods(building())[2]
    with FrameRenderer(SIZE, ctx=gl) as fr:
        fr.upload((1, 2), m)
        view = camera(EYE, 0.0, 0.0)
        fr.draw([(1, 2)], view)
        ref = fr.snapshot()
        fr.draw([(99, 0), (1, 2), (1, 1)], view)  # unknown keys: no error, same frame
        assert np.array_equal(fr.snapshot(), ref)
        assert fr.last_drawn == 1
        fr.draw([(99, 0)], view)
        assert not_background(fr.snapshot()) == 0.0
        assert fr.last_triangles == 0


@pytest.mark.gl
def test_forget_frees_and_shared_meshes_are_counted_once(gl: moderngl.Context) -> None:
    b0, b1, b2 = build_lods(building())
    s = build_street(street())
    with FrameRenderer(SIZE, ctx=gl) as fr:
        fr.upload((1, 0), b0)
        fr.upload((1, 2), b2)
        for lod in range(3):  # a street is one mesh at every LOD
            fr.upload((2, lod), s)
        assert fr.triangles_uploaded == b0.triangles + b2.triangles + s.triangles
        expect = sum(len(m.positions) * VERTEX_BYTES + m.triangles * 12 for m in (b0, b2, s))
        assert fr.gpu_bytes == expect
        fr.forget((2, 0))
        fr.forget((2, 1))
        assert fr.has((2, 2)) and not fr.has((2, 0))
        assert fr.triangles_uploaded == b0.triangles + b2.triangles + s.triangles
        fr.forget((2, 2))
        assert fr.triangles_uploaded == b0.triangles + b2.triangles
        fr.forget((2, 2))  # twice: no-op
        fr.forget_object(1)
        assert fr.triangles_uploaded == 0 and fr.gpu_bytes == 0
        assert not fr.has((1, 0)) and fr.keys() == []
        # forgotten keys draw nothing
        fr.draw([(1, 2)], camera(EYE, 0.0, 0.0))
        assert not_background(fr.snapshot()) == 0.0
        # upload again after forgetting
        fr.upload((1, 2), b2)
        fr.draw([(1, 2)], camera(EYE, 0.0, 0.0))
        assert not_background(fr.snapshot()) > 0.1
        # replacing a key's mesh releases the old one
        fr.upload((1, 2), b1)
        assert fr.triangles_uploaded == b1.triangles


@pytest.mark.gl
def test_street_is_flat_ground(gl: moderngl.Context) -> None:
    with FrameRenderer(SIZE, ctx=gl) as fr:
        fr.upload((2, 0), build_street(street()))
        fr.draw([(2, 0)], camera(EYE, 0.0, -0.2))
        img = fr.snapshot()
    h = img.shape[0]
    assert not_background(img[: h // 3]) == 0.0  # sky above
    assert not_background(img[-h // 4 :]) > 0.5  # street below the horizon


@pytest.mark.gl
def test_empty_mesh_and_custom_projection(gl: moderngl.Context, tmp_path: Path) -> None:
    empty = Mesh(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)))
    with FrameRenderer(SIZE, ctx=gl) as fr:
        fr.upload((5, 0), empty)
        assert fr.has((5, 0)) and fr.triangles_uploaded == 0
        fr.upload((1, 2), build_lods(building())[2])
        wide = np.array(fr.proj, copy=True)
        wide[0, 0] *= 0.25  # a much wider horizontal field of view
        wide[1, 1] *= 0.25
        fr.draw([(5, 0), (1, 2)], camera(EYE, 0.0, 0.0), wide)
        small = not_background(fr.snapshot())
        fr.draw([(5, 0), (1, 2)], camera(EYE, 0.0, 0.0))
        assert small < not_background(fr.snapshot())
        out = tmp_path / "frame.png"
        fr.save_png(out)
        assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.gl
def test_snapshot_before_draw_and_after_close(gl: moderngl.Context) -> None:
    fr = FrameRenderer(SIZE, ctx=gl)
    with pytest.raises(RenderError):
        fr.snapshot()
    fr.release()
    fr.release()  # idempotent
    with pytest.raises(RenderError):
        fr.draw([], camera(EYE, 0.0, 0.0))


def test_bad_sizes_rejected_before_any_gl() -> None:
    with pytest.raises(InputError):
        FrameRenderer((0, 10))
    with pytest.raises(ValueError):
        FrameRenderer((10, 10), near=5.0, far=1.0)
