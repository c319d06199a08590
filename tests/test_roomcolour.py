"""Colour error of a walk with rooms against the full scene without fog (client/truth/roomcolour.py).

On a small baked office: a frame that drew everything without fog has no error; the
same frame under a near fog has error whose visible pixels are the fog's (what the
budget's fog hid); a frame that left out the cells beyond its own has error caused by
culling and none by fog; parts of a cell whose contents had not arrived are late.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from walkstream.client.truth.colour import COLOUR_CAUSES
from walkstream.client.truth.compare import CAUSES
from walkstream.client.truth.notes import FrameNote
from walkstream.client.truth.render import TruthRenderer
from walkstream.client.truth.roomcolour import pixel_distance, room_colour
from walkstream.server.store import SceneReader
from walkstream.shared.camera import camera, perspective
from walkstream.shared.codec.cellmesh import decode_cell_mesh
from walkstream.shared.paths import RecordedPath

pytestmark = pytest.mark.gl


def _note(frame: int, eye: np.ndarray, view: np.ndarray, parts: list[tuple[int, int]], fog: float,
          cell: int, waiting: tuple[int, ...] = ()) -> FrameNote:
    z = np.zeros(0, np.int64)
    return FrameNote(frame=frame, t=float(frame), eye=eye, view=view, cell=cell, pvs=z, received=z, built=z,
                     drawn=(), parts=tuple(parts), waiting=waiting, fog=fog)


def test_fog_and_culling_show_as_colour_error_with_their_causes(office_db: Path, gl: object) -> None:
    with SceneReader.open(office_db) as r:
        rooms = {c.id: decode_cell_mesh(r.contents(c.id)) for c in r.cells()}
        tour = RecordedPath.from_msgpack(r.path_blob("tour"))
        cells = [c for c in r.cells() if c.kind != "outside"]
    truth = TruthRenderer(size=(160, 120), rooms=rooms, near=0.1, far=100.0, two_sided=True, ctx=gl)
    try:
        # a pose looking along the corridor: much to see, some of it far
        far, eye, view = _far_pose(truth, tour)
        assert far > 0.2
        here = next(c.id for c in cells if _inside(c, eye))
        everything = list(truth.keys)
        own = [k for k in truth.keys if k[0] == here]
        notes = [
            _note(0, eye, view, everything, math.inf, here),  # drawn whole: no error
            _note(1, eye, view, everything, 2.5, here),  # a near fog: error, all of it the fog's
            _note(2, eye, view, own, math.inf, here),  # only its own cell: the rest culled
            _note(3, eye, view, own, math.inf, here, waiting=tuple(c for c in rooms if c != here)),  # the rest late
        ]
        rc = room_colour(truth, notes, viewer_ppd=12.0)
    finally:
        truth.release()
    c = rc.log.colour
    assert c is not None and len(c) == 4
    fog, culled, late = (CAUSES.index(k) for k in ("fog", "culled", "not_received"))
    # drawn whole, no fog: the same picture
    assert c.mean_error[0] == 0.0 and c.visible[0] == 0.0 and math.isinf(c.psnr_db[0])
    # under the fog: visible error, every visible pixel the fog's
    assert c.visible[1] > 0.05 and c.mean_error[1] > 0.0
    assert c.causes[1, fog] == pytest.approx(c.visible[1])
    # beside it the viewer-scale (S-CIELAB) share, asked for at 12 pixels per degree
    assert c.visible_scielab is not None and c.causes_scielab is not None and c.viewer_ppd == 12.0
    assert c.visible_scielab[0] == 0.0 and c.visible_scielab[1] > 0.0
    assert c.causes_scielab[1, fog] == pytest.approx(c.visible_scielab[1])
    assert rc.log.missing[1, fog] > 0.2 and rc.log.missing[1, culled] == 0.0
    # its own cell only: what the other cells show is culled, nothing of it the fog's
    assert c.causes[2, culled] > 0.0 and c.causes[2, fog] == 0.0
    # the other cells' contents had not arrived: late, not culled
    assert c.causes[3, late] == pytest.approx(c.causes[2, culled]) and c.causes[3, culled] == 0.0
    assert rc.worst is not None and rc.worst.frame in (1, 2, 3)
    np.testing.assert_array_equal(rc.fog_m[:2], [math.inf, 2.5])


def test_a_surface_the_frame_waited_for_at_the_same_depth_is_late_not_culled(office_db: Path, gl: object) -> None:
    # coincident surfaces (a wall's piece in two cells) show either key in the truth: the
    # frame that waited for one of them lacks the pixel because it is late, as the
    # culled-pixel check (which draws what the frame kept) counts it, not because of culling
    with SceneReader.open(office_db) as r:
        rooms = {c.id: decode_cell_mesh(r.contents(c.id)) for c in r.cells()}
        tour = RecordedPath.from_msgpack(r.path_blob("tour"))
        cells = [c for c in r.cells() if c.kind != "outside"]
    twin = max(rooms) + 1
    probe = TruthRenderer(size=(160, 120), rooms=rooms, near=0.1, far=100.0, two_sided=True, ctx=gl)
    try:
        _, eye, view = _far_pose(probe, tour)
    finally:
        probe.release()
    here = next(c.id for c in cells if _inside(c, eye))
    rooms[twin] = rooms[here]  # the walker's own cell twice: every surface of it in two keys
    truth = TruthRenderer(size=(160, 120), rooms=rooms, near=0.1, far=100.0, two_sided=True, ctx=gl)
    try:
        ids, _ = truth.render(eye, view)
        keys = [truth.keys[i] for i in np.unique(ids[ids >= 0]).tolist()]
        for late in (twin, here):  # waiting for either twin, drawing nothing
            others = tuple(c for c in rooms if c not in (here, twin))
            rc = room_colour(truth, [_note(0, eye, view, [], math.inf, here, waiting=(late, *others))])
            c = rc.log.colour
            assert c is not None
            assert c.causes[0, CAUSES.index("culled")] == 0.0, (late, keys[:4])
            assert c.causes[0, CAUSES.index("not_received")] > 0.5
    finally:
        truth.release()


def _far_pose(truth: TruthRenderer, tour: RecordedPath) -> tuple[float, np.ndarray, np.ndarray]:
    """Of 40 poses along ``tour``, the one whose frame shows most beyond 3 m: ``(share of
    the frame beyond 3 m, eye, view)``."""
    best: tuple[float, np.ndarray, np.ndarray] | None = None
    for t in np.linspace(0.0, tour.duration, 40).tolist():
        xyz, yaw, pitch = tour.at(t)
        eye = np.asarray(xyz, np.float64)
        view = camera(eye, float(yaw), float(pitch)).astype(np.float64)
        _, depth = truth.render(eye, view)
        far = float(np.mean(np.isfinite(depth) & (depth > 3.0)))
        if best is None or far > best[0]:
            best = (far, eye, view)
    assert best is not None
    return best


def _inside(cell: object, eye: np.ndarray) -> bool:
    import shapely

    return bool(shapely.Polygon(cell.boundary).contains(shapely.Point(eye[:2])) and cell.zmin <= eye[2] <= cell.zmax)


def test_pixel_distance_is_the_distance_along_each_pixels_ray() -> None:
    proj = perspective(90.0, 1.0, 0.1, 100.0).astype(np.float64)
    d = pixel_distance(np.full((2, 2), 1.0), proj)
    # at 90 degrees the pixel centres of a 2 x 2 frame look at (+-0.5, +-0.5, -1)
    assert d == pytest.approx(np.full((2, 2), math.sqrt(1.5)))


def _screen_quad(view: np.ndarray, proj: np.ndarray, d: float) -> np.ndarray:
    """``(4, 3)`` the corners (bottom-left, bottom-right, top-right, top-left) of a quad
    filling the whole view at distance ``d`` in front of the camera."""
    x, y = d / float(proj[0, 0]), d / float(proj[1, 1])
    eye_space = np.array([[-x, -y, -d, 1.0], [x, -y, -d, 1.0], [x, y, -d, 1.0], [-x, y, -d, 1.0]])
    world = eye_space @ np.linalg.inv(view).T
    out: np.ndarray = world[:, :3] / world[:, 3:4]
    return out


def test_a_wall_texture_is_painted_into_the_picture_with_its_own_cause(office_db: Path, gl: object) -> None:
    # the frame drew its own cell and one "wall" across the whole view at 1.5 m carrying
    # what lies behind: a right texture (the full scene itself) leaves little error and
    # nothing culled; a wrong one (flat magenta) is error, all of it the wall's
    with SceneReader.open(office_db) as r:
        rooms = {c.id: decode_cell_mesh(r.contents(c.id)) for c in r.cells()}
        tour = RecordedPath.from_msgpack(r.path_blob("tour"))
        cells = [c for c in r.cells() if c.kind != "outside"]
    truth = TruthRenderer(size=(160, 120), rooms=rooms, near=0.1, far=100.0, two_sided=True, ctx=gl)
    try:
        _, eye, view = _far_pose(truth, tour)
        here = next(c.id for c in cells if _inside(c, eye))
        own = [k for k in truth.keys if k[0] == here]
        truth.render(eye, view)
        full = truth.colour()
        corners = _screen_quad(view, np.asarray(truth.proj, np.float64), 1.5)
        right = np.dstack([full, np.full(full.shape[:2], 255, np.uint8)])
        wrong = np.zeros_like(right)
        wrong[..., 0], wrong[..., 2], wrong[..., 3] = 255, 255, 255
        z = np.zeros(0, np.int64)

        def note(frame: int, quads: tuple = ()) -> FrameNote:
            return FrameNote(frame=frame, t=float(frame), eye=eye, view=view, cell=here, pvs=z, received=z, built=z,
                             drawn=(), parts=tuple(own), waiting=(), fog=math.inf, wall_quads=quads)

        rc = room_colour(truth, [note(0), note(1, ((corners, -1, right, 1.0),)),
                                 note(2, ((corners, -2, wrong, 1.0),))])
    finally:
        truth.release()
    c = rc.log.colour
    assert c is not None and len(c) == 3
    # not asked for: no viewer-scale (S-CIELAB) figures, no filtered picture
    assert c.visible_scielab is None and c.causes_scielab is None and c.viewer_ppd is None
    assert rc.worst is not None and rc.worst.delta_e_scielab is None and rc.worst.visible_scielab is None
    culled, wall = CAUSES.index("culled"), COLOUR_CAUSES.index("wall")
    # without the wall: what lies beyond the own cell is culled
    assert c.causes[0, culled] > 0.05 and c.causes[0, wall] == 0.0
    # a right texture: most of that error gone, nothing of it culled any more
    assert c.mean_error[1] < 0.25 * c.mean_error[0] and c.visible[1] < 0.25 * c.visible[0]
    assert rc.log.missing[1, culled] < 0.5 * rc.log.missing[0, culled]
    # a wrong texture: error, the wall's
    assert c.mean_error[2] > c.mean_error[0] and c.causes[2, wall] > 0.5 * c.visible[2]
    assert c.causes[2, culled] < c.causes[0, culled]
