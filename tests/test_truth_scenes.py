"""One ground truth for every scene: city objects and room parts drawn together, culled told from late."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from walkstream.client.truth.culled import (
    CROSSING_FIGURES,
    INTERIOR_FIGURES,
    CulledRow,
    check_kept,
    culled_figures,
    kept_keys,
)
from walkstream.client.truth.culledview import cell_rgb, culled_view, worst_row
from walkstream.client.truth.recorder import TruthRecorder
from walkstream.client.truth.render import TruthRenderer, object_key
from walkstream.client.truth.solid import SolidProbe
from walkstream.shared.camera import camera
from walkstream.shared.codec.cellmesh import CellMesh, CellPart
from walkstream.shared.records import Mesh

SIZE = (64, 48)
EYE = np.array([0.0, 0.0, 1.5])
OID, CELL = 7, 3


def _quad(x: float, y0: float, y1: float) -> tuple[np.ndarray, np.ndarray]:
    """A wall at ``x`` from ``y0`` to ``y1``, 0 to 3 m high, facing the eye at the origin (-x)."""
    p = np.array([[x, y0, 0.0], [x, y1, 0.0], [x, y1, 3.0], [x, y0, 3.0]], np.float32)
    return p, np.array([[0, 1, 2], [0, 2, 3]], np.uint32)


def _scene() -> tuple[dict[int, Mesh], dict[int, CellMesh]]:
    """An object on the right, a room part on the left, both in front of the eye."""
    p, i = _quad(10.0, -2.0, -0.2)
    obj = Mesh(p, np.tile([-1.0, 0.0, 0.0], (4, 1)).astype(np.float32), i, np.zeros(4, np.uint8))
    q, j = _quad(10.0, 0.2, 2.0)
    room = CellMesh((CellPart(1, 0, q, j),), (0.0, 0.0, 0.0), (1.0, 1.0, 1.0))
    return {OID: obj}, {CELL: room}


def _recorder(**note: Any) -> TruthRecorder:
    rec = TruthRecorder(1, SIZE, 60.0, near=0.1, far=100.0)
    rec.record(frame=0, t=0.0, eye=EYE, view=camera(EYE, 0.0).astype(np.float64), **note)
    return rec


def test_one_truth_draws_objects_and_parts_together(gl: Any) -> None:
    objects, rooms = _scene()
    with TruthRenderer(objects, SIZE, rooms=rooms, near=0.1, far=100.0, two_sided=True, ctx=gl) as truth:
        assert truth.keys == [object_key(OID), (CELL, 0)]
        ids, depth = truth.render(EYE, camera(EYE, 0.0))
        shown = {truth.keys[k] for k in np.unique(ids[ids >= 0]).tolist()}
        assert shown == {object_key(OID), (CELL, 0)}
        assert np.allclose(depth[ids >= 0], 10.0, atol=0.01)
        # the city's view of the same frame: object id + 1, nothing for a room part
        assert set(np.unique(truth.object_ids(ids)).tolist()) == {0, OID + 1}
        # fog nearer than the walls hides both
        ids, _ = truth.render(EYE, camera(EYE, 0.0), None, 5.0)
        assert (ids < 0).all()


def test_a_culled_part_is_culled_and_a_late_object_late(gl: Any) -> None:
    objects, rooms = _scene()
    view = camera(EYE, 0.0).astype(np.float64)
    with TruthRenderer(objects, SIZE, rooms=rooms, near=0.1, far=100.0, two_sided=True, ctx=gl) as truth:
        # the object is in the visible set but not built (late); the part neither drawn nor waited for
        note = _recorder(pvs=[OID], built=[]).notes[0]
        _, kept = kept_keys(truth, note)
        chk = check_kept(truth, kept, EYE, view)
        assert chk.missed == {(CELL, 0)} and chk.missed_pixels > 0
        # the object built and still not drawn: culled; the part's cell waiting for contents: late
        note = _recorder(pvs=[OID], built=[OID], waiting=[CELL]).notes[0]
        _, kept = kept_keys(truth, note)
        assert check_kept(truth, kept, EYE, view).missed == {object_key(OID)}
        # everything drawn or late: nothing culled, and the figures say so
        rec = _recorder(pvs=[OID], built=[], parts=[(CELL, 0)], fog=math.inf)
        rec.record(frame=1, t=0.1, eye=EYE, view=view, pvs=None)  # no visible set known yet
        got = culled_figures(truth, rec.notes, CROSSING_FIGURES)
        assert got == {"frames": 2, "unknown": 1, "culled_pixels": 0, "culled_frames": 0, "pinholes": 0,
                       "refused_poses": 0, "worst_frame": None}
        got = culled_figures(truth, _recorder(parts=[]).notes, INTERIOR_FIGURES)
        assert set(got) == set(INTERIOR_FIGURES) and got["culled_pixels"] > 0 and got["culled_frames"] == 1


def test_a_pose_in_solid_geometry_is_refused_not_culled(gl: Any) -> None:
    objects, rooms = _scene()
    probe = SolidProbe(rooms)
    assert probe.nearest(EYE, 0.15) == math.inf
    with TruthRenderer({}, SIZE, rooms=rooms, near=0.1, far=100.0, two_sided=True, ctx=gl) as truth:
        rec = _recorder(parts=[])  # the part culled, seen from 10 m: counted
        for eye, yaw in (([9.9, 1.0, 1.5], 0.0), ([10.0, 1.0, 1.5], math.pi / 2)):  # 10 cm from it, in its face
            e = np.array(eye)
            assert probe.nearest(e, 0.15) < 0.15
            rec.record(frame=len(rec.notes), t=0.0, eye=e, view=camera(e, yaw).astype(np.float64), parts=[])
        got = culled_figures(truth, rec.notes, INTERIOR_FIGURES, solid=probe)
        assert got["refused_poses"] == 2 and got["culled_frames"] == 1 and got["frames"] == 3


def test_the_worst_culled_frame_as_images_with_a_mask_by_cell(gl: Any) -> None:
    _, rooms = _scene()
    with TruthRenderer({}, SIZE, rooms=rooms, near=0.1, far=100.0, two_sided=True, ctx=gl) as truth:
        rec = _recorder(parts=[])  # the part culled
        rec.record(frame=1, t=0.1, eye=EYE, view=camera(EYE, 0.0).astype(np.float64), parts=[(CELL, 0)])
        rows: list[CulledRow] = []
        culled_figures(truth, rec.notes, INTERIOR_FIGURES, rows=rows)
        assert [r.frame for r in rows] == [0, 1] and rows[0].culled_pixels > 0 == rows[1].culled_pixels
        worst = worst_row(rows)
        assert worst is not None and worst.frame == 0
        view = culled_view(truth, rec.notes[0])
        assert view.client.shape == view.truth.shape == view.mask.shape == (SIZE[1], SIZE[0], 3)
        assert view.cells == (CELL,) and view.culled_pixels == rows[0].culled_pixels
        painted = np.all(view.mask == np.array(cell_rgb(CELL), np.uint8), axis=2)
        assert int(painted.sum()) == view.culled_pixels
        assert (view.client != view.truth).any(axis=2).sum() >= view.culled_pixels  # the part missing in the frame
