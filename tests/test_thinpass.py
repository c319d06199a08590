"""Tests of walkstream.server.bake.thinpass and ``walkstream bake --thin-pass``: objects under a pixel tested again."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from walkstream.cli import main
from walkstream.server.bake.thinpass import face_presence, thin_candidates
from walkstream.server.sources.citygen import write_city
from walkstream.server.store import SceneReader


def _box(cx: float, cy: float, cz: float, dx: float, dy: float, dz: float) -> tuple[np.ndarray, np.ndarray]:
    c, h = np.array([cx, cy, cz]), np.array([dx, dy, dz]) / 2.0
    return c - h, c + h


def test_candidates_are_the_unseen_objects_small_on_screen() -> None:
    boxes = [
        _box(0.0, 100.0, 0.05, 60.0, 2.0, 0.1),  # a street 100 m north, edge-on: wide, far under a pixel high
        _box(0.0, 20.0, 5.0, 10.0, 2.0, 10.0),  # a house 20 m north: large on screen
        _box(0.0, 0.05, 1.7, 0.02, 0.02, 0.02),  # a speck at the eye, inside the near plane
        _box(-300.0, 0.0, 2.0, 4.0, 4.0, 4.0),  # a small box 300 m west: under 1 px both ways at 128 px
    ]
    lo = np.array([b[0] for b in boxes])
    hi = np.array([b[1] for b in boxes])
    eye = np.array([[0.0, 0.0, 1.7]])
    draw = np.ones((6, 4), bool)
    seen = np.zeros((6, 4), bool)
    got = thin_candidates(eye, lo, hi, draw, seen, resolution=128, near=0.1, pixels=2.0)
    # face order +x -x +y -y +z -z: north is +y (face 2), west is -x (face 1)
    assert got[2, 0] and not got[2, 1] and not got[:, 2].any() and got[1, 3]
    # a box reaching behind a face's eye plane is not small in it (nor is it there)
    assert not got[0, 0] and not got[0, 3]
    # what the fill saw, or the face does not draw, is never a candidate
    seen[2, 0] = True
    draw[1, 3] = False
    got = thin_candidates(eye, lo, hi, draw, seen, resolution=128, near=0.1, pixels=2.0)
    assert not got[2, 0] and not got[1, 3]
    # a wider limit takes the house too
    assert thin_candidates(eye, lo, hi, np.ones((6, 4), bool), np.zeros((6, 4), bool), resolution=128, near=0.1,
                           pixels=64.0)[2, 1]


def test_face_presence_reads_each_tile_apart() -> None:
    res, n = 4, 3
    rows = np.zeros((2 * res, 6 * res), np.uint32)
    rows[0, 0] = 1  # point 0, face 0: object 0
    rows[res + 3, 5 * res + 2] = 3  # point 1, face 5: object 2
    got = face_presence(rows, res, 2, n)
    assert got.shape == (12, 3)
    assert np.argwhere(got).tolist() == [[0, 0], [11, 2]]


@pytest.mark.gl
def test_bake_with_the_thin_pass_keeps_every_object_and_adds_some(tmp_path: Path, gl_ctx: object) -> None:
    city = tmp_path / "c.geojson"
    write_city(city, 150, 2)
    pvs = {}
    for name, flags in (("plain", []), ("thin", ["--thin-pass", "2"])):
        db = tmp_path / f"{name}.db"
        assert main(["bake", str(city), "-o", str(db), "--resolution", "32", *flags]) == 0
        with SceneReader.open(db) as r:
            pvs[name] = {c.id: set(c.pvs.tolist()) for c in r.cells()}
            assert r.meta.settings.get("thin_pass") == (2.0 if name == "thin" else None)
    assert pvs["plain"].keys() == pvs["thin"].keys()
    assert all(pvs["plain"][k] <= pvs["thin"][k] for k in pvs["plain"])  # the pass only adds
    assert sum(len(v) for v in pvs["thin"].values()) > sum(len(v) for v in pvs["plain"].values())


@pytest.mark.parametrize("value", ["-1", "nan", "100"])
def test_a_bad_thin_pass_gets_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str], value: str) -> None:
    city = tmp_path / "c.geojson"
    write_city(city, 150, 2)
    assert main(["bake", str(city), "-o", str(tmp_path / "x.db"), "--thin-pass", value]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--thin-pass" in err[0]
    assert not (tmp_path / "x.db").exists()


def test_the_conservative_depth_is_the_farthest_around_within_a_tile() -> None:
    from walkstream.server.bake.thindepth import farthest_around

    d = np.full((4, 8), 0.5, np.float32)
    d[1, 1] = 1.0  # a sky pixel in the first tile: its 3 x 3 neighbours see it
    d[2, 4] = 0.9  # on the second tile's first column: it does not leak into the first tile
    got = farthest_around(d, 4)
    assert (got[0:3, 0:3] == 1.0).all() and got[3, 0] == 0.5 and got[0, 3] == 0.5
    assert got[2, 3] == 0.5 and (got[1:4, 4:6] == np.float32(0.9)).all()
    assert (got >= d).all()  # never nearer: occluders only shrink
