"""The far field's horizon band (``walkstream bake --far-band``): finer pixels near the horizon, only what is seen."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from walkstream.cli import main
from walkstream.server.bake.faceset import FaceSet
from walkstream.server.bake.settings import BakeSettings
from walkstream.server.bake.visibility import VisibilityRenderer
from walkstream.shared.errors import InputError
from walkstream.shared.records import BuildingParams


def _block(oid: int, x0: float, y0: float, x1: float, y1: float, height: float) -> BuildingParams:
    ring = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], np.float64)
    return BuildingParams(oid, (ring,), (np.zeros(4),), floors=1, floor_height=height)


def test_a_band_is_the_four_sideways_faces_cut_short_with_square_pixels() -> None:
    b = FaceSet.band(1000, 3.0)
    assert len(b) == 4 and b.cube_faces == (0, 1, 2, 3)
    assert b.tile == (1000, math.ceil(1000 * math.tan(math.radians(3.0))))
    # the pixels are square and the faces 90 degrees across: aspect * tan(fovy / 2) = 1
    w, h = b.tile
    assert (w / h) * math.tan(math.radians(b.fovy_deg) / 2.0) == pytest.approx(1.0)
    assert FaceSet.cube(64).tile == (64, 64) and len(FaceSet.cube(64)) == 6
    with pytest.raises(InputError):
        FaceSet.band(100, 45.0)


def test_axis_points_run_down_the_middle_of_a_street_cell_and_out_of_buildings() -> None:
    from shapely import Point, Polygon, STRtree

    from walkstream.server.bake.samples import axis_points

    street = np.array([[0.0, 0.0], [40.0, 0.0], [40.0, 12.0], [0.0, 12.0]])  # 40 m long, 12 m wide
    pts = axis_points(street, 1.5, 2.0, spacing=20.0)
    assert np.allclose(pts, [[10.0, 6.0, 2.0], [30.0, 6.0, 1.5]])  # half a step in, heights alternating
    assert len(axis_points(street[:, ::-1], 1.5, 2.0, spacing=15.0)) == 3  # the long axis whichever way it runs
    kiosk = STRtree([Polygon([(8.0, 4.0), (12.0, 4.0), (12.0, 8.0), (8.0, 8.0)])])
    moved = axis_points(street, 1.5, 2.0, spacing=20.0, footprints=kiosk)
    assert kiosk.geometries[0].distance(Point(moved[0, :2])) >= 0.25  # moved out, the margin from the walls kept
    assert np.allclose(moved[1], [30.0, 6.0, 1.5])
    with pytest.raises(InputError, match="spacing"):
        axis_points(street, 1.5, 2.0, spacing=0.0)


@pytest.mark.gl
def test_the_band_sees_a_far_post_between_bake_pixels_and_not_what_a_wall_hides(gl: object) -> None:
    from walkstream.server.bake.idpack import meshes_for_scene
    from walkstream.server.sources.scene import SourceScene

    post = _block(1, 199.5, -0.5, 200.5, 0.5, 3.0)  # 1 m wide, 200 m east, straight ahead: 0.29 degrees
    hidden = _block(2, -200.5, -0.5, -199.5, 0.5, 3.0)  # the same 200 m west ...
    wall = _block(3, -20.0, -10.0, -19.0, 10.0, 6.0)  # ... behind a wall 20 m west
    scene = SourceScene("band", "local", (0.0, 0.0), (post, hidden, wall), ())
    meshes, ids = meshes_for_scene(scene, 0)
    eye = np.array([[0.0, 0.0, 1.7]])
    # 32 px a face: the post lies between the pixel centres around the face's axis
    with VisibilityRenderer(meshes, ids, resolution=32, view_distance=400.0, ctx=gl) as cube:  # type: ignore[arg-type]
        assert set(cube.cell_counts(eye)[0].tolist()) == {3}
    with VisibilityRenderer(meshes, ids, resolution=1024, band=3.0, view_distance=400.0, ctx=gl) as band:  # type: ignore[arg-type]
        got, px = band.cell_counts(eye)
    assert set(got.tolist()) == {1, 3}
    with pytest.raises(InputError, match="thin pass"):
        VisibilityRenderer(meshes, ids, resolution=64, band=3.0, thin_pass=2.0, ctx=gl)  # type: ignore[arg-type]


@pytest.mark.gl
def test_a_bake_with_the_band_keeps_every_object_and_says_so_in_its_header(tmp_path: Path, gl_ctx: object) -> None:
    from walkstream.server.sources.citygen import write_city
    from walkstream.server.store import SceneReader

    city = tmp_path / "c.geojson"
    write_city(city, 150, 2)
    pvs = {}
    for name, flags in (("plain", []), ("band", ["--far-band", "3", "--far-pixels", "256", "--far-axis", "20", "--far-edges"])):
        db = tmp_path / f"{name}.db"
        assert main(["bake", str(city), "-o", str(db), "--resolution", "32", *flags]) == 0
        with SceneReader.open(db) as r:
            pvs[name] = {c.id: set(c.pvs.tolist()) for c in r.cells()}
            assert r.meta.settings.get("far_band") == (3.0 if name == "band" else None)
            assert r.meta.settings.get("far_axis") == (20.0 if name == "band" else None)
            assert r.meta.settings.get("far_edges") == (True if name == "band" else None)
    assert all(pvs["plain"][k] <= pvs["band"][k] for k in pvs["plain"])  # the band only adds
    assert sum(len(v) for v in pvs["band"].values()) > sum(len(v) for v in pvs["plain"].values())


@pytest.mark.parametrize(("flags", "word"), [(["--far-band", "-1"], "--far-band"), (["--far-band", "3", "--far-pixels", "4"], "--far-pixels"),
                                             (["--far-band", "3", "--sampling", "field"], "--far-band"),
                                             (["--far-axis", "20"], "--far-axis"), (["--far-edges"], "--far-edges"), (["--far-band", "3", "--far-axis", "-1"], "--far-axis")])
def test_a_bad_far_band_gets_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str], flags: list[str], word: str) -> None:
    city = tmp_path / "c.geojson"
    city.write_text('{"type": "FeatureCollection", "features": []}')
    assert main(["bake", str(city), "-o", str(tmp_path / "x.db"), *flags]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and word in err[0]


def test_the_header_of_a_bake_without_the_band_is_unchanged() -> None:
    assert "far_band" not in BakeSettings().record() and "far_pixels" not in BakeSettings().record()
    assert BakeSettings(far_band=2.0).record()["far_pixels"] == 1109
