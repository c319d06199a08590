"""Perspective impostor images (issue 27): rendered off-axis from a sampling eye onto the
quad's plane, placed by the client where the projection put them; an orthographic bake
unchanged on the wire and in its settings record."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

from walkstream.client.walk.impostors import quad_corners
from walkstream.server.bake import ImpostorSettings
from walkstream.shared.camera import look_at, off_axis, perspective
from walkstream.shared.errors import CodecError, InputError
from walkstream.shared.impostors import (
    bin_direction,
    eye_distance,
    half_side,
    image_parallax,
    level_for,
    orthographic_parallax,
)
from walkstream.shared.impostorwire import CellImpostors, ImpostorRow, impostors_from_wire
from walkstream.shared.records import Mesh

BOX = (-6.0, -4.0, 0.0, 6.0, 4.0, 30.0)  # a tower: its parallax is large near it


def _mesh() -> Mesh:
    tm = trimesh.creation.box(bounds=np.reshape(BOX, (2, 3)))
    faces = np.asarray(tm.faces)
    normals = np.repeat(np.asarray(tm.face_normals), 3, axis=0)
    return Mesh(np.asarray(tm.vertices)[faces.ravel()], normals, np.arange(faces.size).reshape(-1, 3))


def _silhouettes(gl: object, eye_m: float) -> tuple[int, int, int]:
    """From a sampling eye ``eye_m`` from the tower's centre: the pixels where the
    tower's geometry and its quad disagree (covered or not), perspective and
    orthographic image, and the tower's pixels."""
    from walkstream.client.draw.frames import FrameRenderer
    from walkstream.server.bake.impostorrender import ImpostorRenderer

    level, ia, ie = 3, 21, 8  # a direction a little above the horizon
    u = bin_direction(level, ia, ie)
    lo, hi = np.asarray(BOX[:3]), np.asarray(BOX[3:])
    c = (lo + hi) / 2.0
    mesh = _mesh()
    imp = ImpostorRenderer([mesh], [1], [BOX], ctx=gl)
    try:
        persp = imp.render(1, u, 128, eye=eye_m)
        ortho = imp.render(1, u, 128)
    finally:
        imp.release()
    size = (160, 160)
    eye = c + u * eye_m
    view, proj = look_at(eye, c), perspective(60.0, 1.0, 0.5, 400.0)
    r = FrameRenderer(size=size, fov_deg=60.0, ctx=gl)  # type: ignore[arg-type]
    try:
        r.upload((1, 2), mesh)
        r.draw([(1, 2)], view, proj)
        truth = r.snapshot().astype(int)
        bg = truth[0, 0]
        shown = []
        for img, e in ((persp, eye_m), (ortho, math.inf)):
            r.impostors = [(quad_corners(BOX, level, ia, ie, e), 1, img, 1.0)]
            r.draw([], view, proj)
            shown.append(np.abs(r.snapshot().astype(int) - bg).sum(axis=2) > 30)
            r.impostors = []
    finally:
        r.release()
    tower = np.abs(truth - bg).sum(axis=2) > 30
    return int((shown[0] != tower).sum()), int((shown[1] != tower).sum()), int(tower.sum())


@pytest.mark.gl
def test_from_the_sampling_eye_the_quad_lands_on_the_towers_pixels(gl: object) -> None:
    radius = math.dist(BOX[:3], BOX[3:]) / 2.0
    persp, ortho, tower = _silhouettes(gl, 1.8 * radius)
    assert tower > 2000  # the tower fills much of the frame
    assert persp <= 0.03 * tower  # the silhouette's edge pixels at most (here 2.3 %; a texel is 1.5 pixels)
    assert ortho >= 5 * max(persp, 20)  # the orthographic image drawn there is pixels off (here 11 times)


def test_the_off_axis_projection_puts_the_rectangle_on_the_whole_image() -> None:
    eye = np.array([3.0, -20.0, 5.0])
    right, up = np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.6, 0.8])
    corner, w, h = np.array([-2.0, 1.0, 0.0]), 7.0, 4.0
    m = off_axis(eye, corner, right, up, w, h, near=5.0, far=100.0)
    for (a, b), want in zip(((0, 0), (1, 0), (1, 1), (0, 1)), ((-1, -1), (1, -1), (1, 1), (-1, 1)), strict=True):
        p = m @ np.array([*(corner + a * w * right + b * h * up), 1.0])
        assert p[:2] / p[3] == pytest.approx(want)
    with pytest.raises(InputError, match="off_axis"):
        off_axis(corner + np.cross(right, up) * -3.0, corner, right, up, w, h)  # the eye behind it


def test_the_sampling_eye_sits_in_its_levels_band_and_shrinks_the_parallax() -> None:
    bound, radius = math.radians(2.0), 20.0
    for d in (70.0, 90.0, 140.0, 300.0):
        level = int(level_for(radius, d, bound))
        e = float(eye_distance(radius, level, bound, 60.0))
        assert e >= 60.0 and e > radius
        assert float(image_parallax(radius, e, e)) == pytest.approx(0.0, abs=1e-12)
        assert float(image_parallax(radius, d, e)) < float(orthographic_parallax(radius, d))
    assert float(half_side(radius)) == radius and float(half_side(radius, 2 * radius)) > radius


def test_the_projection_is_on_the_wire_only_when_perspective() -> None:
    row = ImpostorRow(7, 2, 0, 1, 0, 1, (0.0, 0.0, 0.0, 10.0, 10.0, 20.0), (5,))
    ortho = CellImpostors(60.0, 0.03, (row,))
    assert "p" not in ortho.to_wire() and ortho.eye(row) == math.inf
    back = impostors_from_wire(ortho.to_wire(), "cell 1")
    assert back is not None and not back.perspective  # an orthographic bake's record as before
    persp = impostors_from_wire(CellImpostors(60.0, 0.03, (row,), True).to_wire(), "cell 1")
    assert persp is not None and persp.perspective and math.isfinite(persp.eye(row))
    with pytest.raises(CodecError, match="p must be 1"):
        impostors_from_wire({**ortho.to_wire(), "p": 2}, "cell 1")
    assert "projection" not in ImpostorSettings().record()  # an orthographic bake's settings as before
    assert ImpostorSettings(projection="perspective").check().record()["projection"] == "perspective"
    with pytest.raises(InputError, match="--impostor-projection"):
        ImpostorSettings(projection="fisheye").check()
