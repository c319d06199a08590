"""The field's renderers count what the bake's plain renderer counts.

A small generated city at a low resolution: every field point of its walkable cover
at both heights, rendered plain (``each_point_counts``, as the field's blocks are)
by the field's renderer (two passes in flight) and by the two steps of
:mod:`walkstream.benchmarks.fieldcull` with culling forced on; and ``walkstream bench
field`` on it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from walkstream.benchmarks.fieldcull import CulledRenderer
from walkstream.benchmarks.fieldspeed import _field_points, format_field_speed, run_field_speed
from walkstream.cli import main
from walkstream.server.bake.field import FIELD_HEIGHTS
from walkstream.server.bake.idpack import meshes_for_scene
from walkstream.server.bake.visibility import VisibilityRenderer
from walkstream.server.sources.citygen import write_city
from walkstream.server.sources.read import read_source
from walkstream.shared.errors import InputError


@pytest.fixture(scope="module")
def small_city(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("fieldcull") / "city.geojson"
    write_city(path, 150, 2)
    return path


@pytest.mark.gl
def test_culled_counts_are_the_plain_renders(small_city: Path, gl: object) -> None:
    scene = read_source(small_city)
    eyes = _field_points(scene, 6.0)[:48]
    pts = np.vstack([np.column_stack([eyes, np.full(len(eyes), z)]) for z in FIELD_HEIGHTS])
    meshes, ids = meshes_for_scene(scene, 0)
    with VisibilityRenderer(meshes, ids, resolution=64, ctx=gl) as plain:  # type: ignore[arg-type]
        want = plain.each_point_counts(pts)
    with CulledRenderer(meshes, ids, resolution=64, ctx=gl, min_triangles=0) as culled:  # type: ignore[arg-type]
        got = culled.field_counts(pts)
        stats = dict(culled.stats)
    # the culling did leave objects out, and drew fewer triangles than the plain render
    assert stats["passes_plain"] == 0 and stats["hidden"] > 0
    assert stats["triangles"] < stats["triangles_plain"]
    same = 0
    for (wi, wp), (gi, gp) in zip(want, got, strict=True):
        assert np.array_equal(wi, gi)  # every point sees the same objects
        # pixels: the rasteriser may split a sliver's pixel differently between draw calls
        assert np.abs(wp - gp).max(initial=0) <= 1
        same += bool(np.array_equal(wp, gp))
    assert same >= 0.95 * len(pts)


@pytest.mark.gl
def test_the_fields_renderer_counts_pixel_for_pixel_with_two_passes_in_flight(small_city: Path, gl: object) -> None:
    from walkstream.server.bake.fieldrender import FieldRenderer

    scene = read_source(small_city)
    eyes = _field_points(scene, 6.0)[:40]  # 80 renders: five passes of 16, the last one short
    pts = np.vstack([np.column_stack([eyes, np.full(len(eyes), z)]) for z in FIELD_HEIGHTS])
    meshes, ids = meshes_for_scene(scene, 0)
    with VisibilityRenderer(meshes, ids, resolution=48, ctx=gl, max_points_per_pass=16) as plain:  # type: ignore[arg-type]
        want = plain.each_point_counts(pts)
    with FieldRenderer(meshes, ids, resolution=48, ctx=gl, max_points_per_pass=16) as field:  # type: ignore[arg-type]
        got = field.field_counts(pts)
        assert field.field_counts(pts[:0]) == []
    assert len(got) == len(pts)
    for (wi, wp), (gi, gp) in zip(want, got, strict=True):
        assert np.array_equal(wi, gi) and np.array_equal(wp, gp)


@pytest.mark.gl
def test_a_box_behind_a_wall_is_left_out_and_nothing_changes(gl: object) -> None:
    from walkstream.shared.records import Mesh

    def box(x0: float, y0: float, x1: float, y1: float, h: float) -> Mesh:
        v = np.array([[x, y, z] for z in (0.0, h) for x, y in ((x0, y0), (x1, y0), (x1, y1), (x0, y1))], np.float32)
        faces = [(0, 2, 1), (0, 3, 2), (4, 5, 6), (4, 6, 7)]
        for k in range(4):
            a, b = k, (k + 1) % 4
            faces += [(a, b, b + 4), (a, b + 4, a + 4)]
        return Mesh(v, np.zeros_like(v), np.array(faces, np.uint32))

    # a long wall 20 m east of the eyes, a small box 60 m east behind it, one 40 m north
    meshes = [box(20, -200, 22, 200, 30), box(60, -2, 64, 2, 4), box(-2, 40, 2, 44, 4)]
    for k in range(40):
        meshes.append(box(-300 + 15 * k, -300, -295 + 15 * k, -295, 6))  # far away to the south
    ids = np.arange(len(meshes))
    pts = np.array([[0.0, y, z] for z in FIELD_HEIGHTS for y in np.linspace(-8, 8, 16)])
    with VisibilityRenderer(meshes, ids, resolution=32, ctx=gl) as plain:  # type: ignore[arg-type]
        want = plain.each_point_counts(pts)
    with CulledRenderer(meshes, ids, resolution=32, ctx=gl, min_triangles=0, near_radius=25.0) as culled:  # type: ignore[arg-type]
        got = culled.field_counts(pts)
        assert culled.stats["hidden"] > 0
    for (wi, wp), (gi, gp) in zip(want, got, strict=True):
        assert 1 not in wi.tolist() and 2 in wi.tolist()
        assert np.array_equal(wi, gi) and np.array_equal(wp, gp)


@pytest.mark.gl
def test_bench_field_prints_both_renderers(small_city: Path, capsys: pytest.CaptureFixture[str]) -> None:
    row = run_field_speed(small_city, points=8, starts=2, spacing=6.0, resolution=32)
    assert row["renders"] == 2 * 2 * 8
    assert row["culled"]["same_sets"] == row["renders"]
    # the field's renderer: the plain render's counts, pixel for pixel
    assert row["bake"]["same_counts"] == row["renders"]
    table = format_field_speed([row])
    assert "plain" in table and "bake" in table and "culled" in table
    assert main(["bench", "field", str(small_city), "--points", "0"]) != 0
    err = capsys.readouterr().err
    assert "--points" in err and "Traceback" not in err


def test_bad_points_are_refused(small_city: Path) -> None:
    with pytest.raises(InputError, match="--points"):
        run_field_speed(small_city, points=0)
