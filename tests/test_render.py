"""Tests of shared.camera, shared.gl, shared.export and walkstream.client.draw.meshes."""

from __future__ import annotations

import types
from pathlib import Path

import moderngl
import numpy as np
import pytest

from walkstream.client.draw.meshes import BACKGROUND_RGB, MeshRenderer, render_lods_figure
from walkstream.shared.camera import (
    CUBE_FACE_DIRECTIONS,
    cube_face_views,
    fit_view,
    look_at,
    perspective,
)
from walkstream.shared.errors import InputError, RenderError
from walkstream.shared.export import export_glb
from walkstream.shared.gl import BACKEND_ENV, Framebuffer, check_gl_error, create_context
from walkstream.shared.palette import MATERIALS, PALETTE, UNKNOWN_RGB, material_rgb
from walkstream.shared.records import Mesh

WALL = 0
WINDOW = 1


def unit_cube(origin: tuple[float, float, float] = (0.0, 0.0, 0.0), material: int = WALL) -> Mesh:
    """A flat-shaded unit cube, 24 vertices and 12 triangles, CCW seen from outside."""
    o = np.asarray(origin, dtype=np.float64)
    pos: list[np.ndarray] = []
    nrm: list[np.ndarray] = []
    idx: list[list[int]] = []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            normal = np.zeros(3)
            normal[axis] = sign
            # u, v span the face so that u x v points along the outward normal.
            u = np.zeros(3)
            v = np.zeros(3)
            u[(axis + 1) % 3] = 1.0
            v[(axis + 2) % 3] = 1.0
            if sign < 0:
                u, v = v, u
            centre = 0.5 + 0.5 * normal
            base = len(pos)
            for a, b in ((-0.5, -0.5), (0.5, -0.5), (0.5, 0.5), (-0.5, 0.5)):
                pos.append(o + centre + a * u + b * v)
                nrm.append(normal)
            idx += [[base, base + 1, base + 2], [base, base + 2, base + 3]]
    return Mesh(np.array(pos), np.array(nrm), np.array(idx), np.full(len(pos), material))


def reversed_winding(m: Mesh) -> Mesh:
    return Mesh(m.positions, m.normals, m.indices[:, ::-1], m.materials)


def ndc(m: np.ndarray, p: np.ndarray) -> np.ndarray:
    h = m.astype(np.float64) @ np.append(p, 1.0)
    return h[:3] / h[3]


# -- palette --------------------------------------------------------------------------


def test_palette_table_and_unknown_ids() -> None:
    assert PALETTE.shape == (256, 3) and PALETTE.dtype == np.uint8
    assert not PALETTE.flags.writeable
    assert [m[0] for m in MATERIALS] == list(range(len(MATERIALS)))
    rgb = material_rgb([0, 1, 200, 300])
    assert rgb.shape == (4, 3) and rgb.dtype == np.uint8
    assert tuple(rgb[0]) == MATERIALS[0][2]
    assert tuple(rgb[2]) == UNKNOWN_RGB and tuple(rgb[3]) == UNKNOWN_RGB


def test_unit_cube_is_outward_ccw() -> None:
    m = unit_cube()
    tri = m.positions[m.indices].astype(np.float64)
    face_n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    assert np.all(np.einsum("ij,ij->i", face_n, m.normals[m.indices[:, 0]]) > 0)
    # And the normals point away from the centre.
    centroid = tri.mean(axis=1) - 0.5
    assert np.all(np.einsum("ij,ij->i", face_n, centroid) > 0)


# -- camera ---------------------------------------------------------------------------


def test_look_at_maps_target_to_negative_z() -> None:
    eye = np.array([3.0, -4.0, 2.0])
    target = np.array([1.0, 2.0, 0.5])
    v = look_at(eye, target)
    assert v.dtype == np.float32 and v.shape == (4, 4)
    dist = float(np.linalg.norm(target - eye))
    np.testing.assert_allclose(ndc(v, target), [0, 0, -dist], atol=1e-5)
    np.testing.assert_allclose(ndc(v, eye), [0, 0, 0], atol=1e-5)
    # World up stays up on screen.
    assert ndc(v, target + [0, 0, 1])[1] > 0
    with pytest.raises(ValueError, match="parallel"):
        look_at((0, 0, 0), (0, 0, 5))
    with pytest.raises(ValueError, match="coincide"):
        look_at((1, 1, 1), (1, 1, 1))


def test_perspective_maps_near_far_to_ndc() -> None:
    p = perspective(60.0, 1.5, 0.5, 200.0)
    assert p.dtype == np.float32
    assert ndc(p, np.array([0, 0, -0.5]))[2] == pytest.approx(-1.0, abs=1e-6)
    assert ndc(p, np.array([0, 0, -200.0]))[2] == pytest.approx(1.0, abs=1e-5)
    # Top edge of the frustum at the near plane maps to y = 1.
    top = 0.5 * np.tan(np.radians(30.0))
    assert ndc(p, np.array([0, top, -0.5]))[1] == pytest.approx(1.0, abs=1e-5)
    assert ndc(p, np.array([top * 1.5, 0, -0.5]))[0] == pytest.approx(1.0, abs=1e-5)
    with pytest.raises(ValueError):
        perspective(60.0, 1.0, 0.0, 10.0)


def test_cube_faces_cover_all_directions() -> None:
    eye = np.array([10.0, -5.0, 1.7])
    views = cube_face_views(eye)
    assert views.shape == (6, 4, 4) and views.dtype == np.float32
    # Each face looks along its own axis direction: the six forward vectors are the
    # six signed axes.
    forwards = -views[:, 2, :3].astype(np.float64)
    np.testing.assert_allclose(forwards, CUBE_FACE_DIRECTIONS, atol=1e-7)
    assert {tuple(np.round(f).astype(int)) for f in forwards} == {
        (1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1),
    }  # fmt: skip
    # Every direction falls inside at least one 90-degree frustum.
    proj = perspective(90.0, 1.0, 0.1, 100.0)
    dirs = np.random.default_rng(1).normal(size=(2000, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    covered = np.zeros(len(dirs), bool)
    for v in views:
        for k, d in enumerate(dirs):
            c = ndc(proj @ v, eye + 10.0 * d)
            if np.all(np.abs(c) <= 1.0 + 1e-6):
                covered[k] = True
    assert covered.all()


def test_fit_view_keeps_box_on_screen() -> None:
    lo, hi = np.array([100.0, 50.0, 0.0]), np.array([130.0, 60.0, 45.0])
    view, proj = fit_view(lo, hi, (-1.0, -1.0, 0.8), 30.0, 1.6)
    corners = np.array(
        [[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]
    )
    c = np.array([ndc(proj @ view, p) for p in corners])
    assert np.all(np.abs(c) < 1.0)
    assert np.abs(c[:, :2]).max() > 0.8  # tight, not lost in the middle


# -- context --------------------------------------------------------------------------


def test_create_context_reports_missing_egl(monkeypatch: pytest.MonkeyPatch) -> None:
    tried: list[object] = []

    def fail(**kwargs: object) -> None:
        tried.append(kwargs.get("backend"))
        if kwargs.get("backend") == "egl":
            raise Exception("libEGL.so.1 not loaded")
        raise Exception("(standalone) XOpenDisplay: cannot open display")

    monkeypatch.delenv(BACKEND_ENV, raising=False)
    monkeypatch.setattr(moderngl, "create_standalone_context", fail)
    with pytest.raises(RenderError) as info:
        create_context()
    msg = str(info.value)
    assert tried == ["egl", None]
    assert "\n" not in msg
    assert msg.startswith("no OpenGL context")
    assert "libEGL.so.1" in msg and "install libegl1" in msg


def test_create_context_honours_backend_env(monkeypatch: pytest.MonkeyPatch) -> None:
    tried: list[object] = []

    def fail(**kwargs: object) -> None:
        tried.append(kwargs.get("backend"))
        raise Exception("nope")

    monkeypatch.setattr(moderngl, "create_standalone_context", fail)
    monkeypatch.setenv(BACKEND_ENV, "default")
    with pytest.raises(RenderError, match=BACKEND_ENV):
        create_context()
    assert tried == [None]
    tried.clear()
    monkeypatch.setenv(BACKEND_ENV, "EGL")
    with pytest.raises(RenderError):
        create_context()
    assert tried == ["egl"]


def test_check_gl_error_raises_on_error() -> None:
    check_gl_error(types.SimpleNamespace(error="GL_NO_ERROR"), "here")  # type: ignore[arg-type]
    with pytest.raises(RenderError, match="after drawing: GL_INVALID_ENUM"):
        check_gl_error(types.SimpleNamespace(error="GL_INVALID_ENUM"), "after drawing")  # type: ignore[arg-type]


# -- GL rendering ---------------------------------------------------------------------


@pytest.mark.gl
def test_framebuffer_reads_back_top_row_first(gl: moderngl.Context) -> None:
    with Framebuffer(gl, (8, 4)) as fb:
        fb.use()
        fb.clear((0.0, 0.0, 0.0, 1.0))
        # Clear the bottom row only (GL y = 0) to red via a scissored clear.
        fb.fbo.clear(1.0, 0.0, 0.0, 1.0, viewport=(0, 0, 8, 1))
        img = fb.read()
    assert img.shape == (4, 8, 4) and img.dtype == np.uint8
    assert tuple(img[-1, 0]) == (255, 0, 0, 255)
    assert tuple(img[0, 0]) == (0, 0, 0, 255)
    with pytest.raises(RenderError, match="after release"):
        fb.read()


CUBE_EYE = (-2.0, -2.5, 2.2)


def _cube_camera(size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    view = look_at(CUBE_EYE, (0.5, 0.5, 0.5))
    proj = perspective(40.0, size[0] / size[1], 0.5, 20.0)
    return view, proj


def facing(m: Mesh, eye: tuple[float, float, float]) -> Mesh:
    """The triangles of ``m`` whose outward side faces ``eye``."""
    p0 = m.positions[m.indices[:, 0]].astype(np.float64)
    n = m.normals[m.indices[:, 0]].astype(np.float64)
    keep = np.einsum("ij,ij->i", n, np.asarray(eye) - p0) > 0
    return Mesh(m.positions, m.normals, m.indices[keep], m.materials)


@pytest.mark.gl
def test_cube_from_outside_shows_shaded_wall(gl: moderngl.Context) -> None:
    size = (96, 64)
    view, proj = _cube_camera(size)
    with MeshRenderer(gl) as r:
        img = r.render([unit_cube()], view, proj, size)
        assert r.uploaded == 1
    assert img.shape == (64, 96, 3) and img.dtype == np.uint8
    bg = np.all(img == BACKGROUND_RGB, axis=2)
    # The cube is in the middle, the corners are background.
    assert not bg[32, 48]
    assert bg[0, 0] and bg[0, -1] and bg[-1, 0] and bg[-1, -1]
    assert 0.1 < (~bg).mean() < 0.7
    # Every cube pixel is the wall colour scaled by one lighting factor in [ambient, 1]
    # (same factor on all channels, up to 8-bit rounding) ...
    wall = PALETTE[WALL].astype(np.float64)
    k = img[~bg].astype(np.float64) / wall
    assert np.all(k.max(axis=1) - k.min(axis=1) < 0.03)
    assert k.min() > 0.3 and k.max() <= 1.0 + 1e-6
    # ... and the three visible faces (south, west, top) are lit differently.
    shades = np.unique(np.round(k.mean(axis=1), 2))
    assert len(shades) >= 3


@pytest.mark.gl
def test_reversed_winding_is_culled(gl: moderngl.Context) -> None:
    size = (96, 64)
    view, proj = _cube_camera(size)
    front = facing(unit_cube(), CUBE_EYE)
    assert front.triangles == 6  # west, south and top
    with MeshRenderer(gl) as r:
        right = r.render([front], view, proj, size)
        wrong = r.render([reversed_winding(front)], view, proj, size)
        # A closed cube turned inside out is not empty: its far faces now face the
        # camera, so it keeps its outline but shows the unlit far side.
        inside_out = r.render([reversed_winding(unit_cube())], view, proj, size)
        correct = r.render([unit_cube()], view, proj, size)
    assert not np.all(right == BACKGROUND_RGB)
    assert np.all(wrong == BACKGROUND_RGB)
    bg_correct = np.all(correct == BACKGROUND_RGB, axis=2)
    np.testing.assert_array_equal(np.all(inside_out == BACKGROUND_RGB, axis=2), bg_correct)
    assert not np.array_equal(inside_out, correct)


@pytest.mark.gl
def test_materials_and_depth(gl: moderngl.Context) -> None:
    size = (96, 64)
    view, proj = _cube_camera(size)
    near = unit_cube((0.0, 0.0, 0.0), WINDOW)  # in front of the wall cube, seen from the SW
    far = unit_cube((0.6, 0.6, 0.1), WALL)  # no coplanar faces: no z-fighting
    with MeshRenderer(gl) as r:
        a = r.render([near, far], view, proj, size)
        b = r.render([far, near], view, proj, size)  # draw order must not matter
        assert r.uploaded == 2
        r.forget(near)
        assert r.uploaded == 1
    np.testing.assert_array_equal(a, b)
    centre = a[32, 48].astype(np.float64)
    k = centre / PALETTE[WINDOW]
    assert k.max() - k.min() < 0.05


@pytest.mark.gl
def test_render_lods_figure_writes_png(gl: moderngl.Context, tmp_path: Path) -> None:
    from PIL import Image

    meshes = [
        unit_cube(),
        Mesh.concat([unit_cube(), unit_cube((0.0, 0.0, 1.0), WINDOW)]),
        Mesh.concat([unit_cube((x, y, 0.0), x + y) for x in (0, 1, 2) for y in (0, 1, 2)]),
    ]
    out = tmp_path / "lods.png"
    render_lods_figure(meshes, out, size=(600, 250), ctx=gl)
    with Image.open(out) as im:
        assert im.size == (600, 250)
        assert im.format == "PNG"
    # An empty mesh gets a blank panel rather than an error.
    render_lods_figure([unit_cube(), Mesh.concat([])], tmp_path / "empty.png", ctx=gl)
    with Image.open(tmp_path / "empty.png") as im:
        assert im.size == (1200, 500)


# -- export ---------------------------------------------------------------------------


def test_export_glb_round_trip(tmp_path: Path) -> None:
    import trimesh

    meshes = [unit_cube(), unit_cube((2.0, 0.0, 0.0), WINDOW), Mesh.concat([])]
    path = tmp_path / "scene.glb"
    written = export_glb(meshes, path)
    assert written == path.stat().st_size > 0
    scene = trimesh.load(path)
    assert isinstance(scene, trimesh.Scene)
    assert len(scene.geometry) == 2
    assert sum(len(g.faces) for g in scene.geometry.values()) == 24
    colours = {tuple(c[:3]) for g in scene.geometry.values() for c in g.visual.vertex_colors}
    assert colours == {tuple(PALETTE[WALL]), tuple(PALETTE[WINDOW])}
    # z-up scene stood up for y-up viewers: the cubes' height (z) becomes y.
    bounds = scene.bounds
    np.testing.assert_allclose(bounds[:, 1], [0.0, 1.0], atol=1e-6)


def test_export_glb_refuses_empty_scene(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="no triangles"):
        export_glb([Mesh.concat([])], tmp_path / "empty.glb")
    assert not (tmp_path / "empty.glb").exists()
