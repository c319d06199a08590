"""Tests of the per-vertex lighting path and ``walkstream bench fill`` on a tiny scene."""

from __future__ import annotations

import math
from pathlib import Path

import moderngl
import numpy as np
import pytest
from scenes import build_city_db

from walkstream.benchmarks.fill import CASES, format_fill_table, run_fill_bench
from walkstream.cli import build_parser
from walkstream.client.draw.frames import FrameRenderer
from walkstream.client.draw.meshes import MeshRenderer
from walkstream.shared.buildings import build_lods
from walkstream.shared.camera import camera
from walkstream.shared.errors import InputError
from walkstream.shared.records import BuildingParams, StreetParams
from walkstream.shared.streets import build_street

SIZE = (96, 72)


@pytest.fixture(scope="module")
def city_db(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("fillbench") / "city.db"
    build_city_db(path, size=200.0, k=12)
    return path


def _scene() -> list:
    ring = np.array([[10.0, -5.0], [20.0, -5.0], [20.0, 5.0], [10.0, 5.0]])
    b = build_lods(BuildingParams(1, (ring,), (np.zeros(4),), floors=4, floor_height=3.0))
    road = np.array([[0.0, -4.0], [60.0, -4.0], [60.0, 4.0], [0.0, 4.0]])
    s = build_street(StreetParams(2, "street", road, 8.0))
    return [((1, 2), b[2]), ((2, 0), s)]


@pytest.mark.parametrize("batched", [True, False])
def test_vertex_lighting_matches_fragment_lighting(gl: moderngl.Context, batched: bool) -> None:
    """Per-vertex lighting shows the same frame (within one level) and the same ids."""
    imgs, ids = [], []
    for shading in ("fragment", "vertex"):
        with FrameRenderer(SIZE, ctx=gl, batched=batched, shading=shading) as fr:
            for key, mesh in _scene():
                fr.upload(key, mesh)
            view = camera((0.0, 0.0, 1.7), 0.1, -0.1)
            fr.draw([k for k, _ in _scene()], view)
            imgs.append(fr.snapshot().astype(int))
            ids.append(fr.draw_ids([(1, 2), (2, 0)], view))
    assert np.abs(imgs[0] - imgs[1]).max() <= 1
    assert np.array_equal(ids[0], ids[1])
    assert len(np.unique(ids[0])) == 3  # building, street and sky all in view


def test_fog_uses_the_fragment_program(gl: moderngl.Context) -> None:
    with FrameRenderer(SIZE, ctx=gl, shading="vertex") as fr:
        for key, mesh in _scene():
            fr.upload(key, mesh)
        view = camera((0.0, 0.0, 1.7), 0.0, 0.0)
        assert fr._r.program_name == "plain"
        fr.draw([(1, 2)], view)
        clear_img = fr.snapshot()
        fr.fog_m = 12.0  # the facade, 10 m away, is in the fog's last fifth: faded
        assert fr._r.program_name == "fog"
        fr.draw([(1, 2)], view)
        fogged = fr.snapshot()
        assert not np.array_equal(clear_img, fogged)
        fr.fog_m = 0.0
        fr.draw([(1, 2)], view)
        assert np.abs(fr.snapshot().astype(int) - clear_img.astype(int)).max() == 0


def test_bad_shading_rejected() -> None:
    with pytest.raises(InputError, match="shading"):
        MeshRenderer(shading="gouraud")


def test_run_fill_bench_on_a_tiny_db(gl: moderngl.Context, city_db: Path) -> None:
    result = run_fill_bench(city_db, views=2, size=(64, 48), repeats=1, progress=False, ctx=gl)
    rows = result["rows"]
    assert [r["case"] for r in rows] == list(CASES)
    by = {r["case"]: r for r in rows}
    assert by["clear"]["triangles"] == 0
    assert 0 < by["floor"]["triangles"] <= by["lod2"]["triangles"]
    assert all(r["finish_vertex"] >= 0.0 and r["finish_fragment"] >= 0.0 for r in rows)
    assert result["max_diff"] <= 1 and result["ids_equal"]
    table = format_fill_table(result)
    assert "floor" in table and "equal" in table and math.isfinite(result["diff_pct"])


def test_fill_parser_and_bad_repeat(city_db: Path) -> None:
    a = build_parser().parse_args(["bench", "fill", "x.db", "--size", "320x240", "--views", "2"])
    assert a.size == (320, 240) and a.views == 2 and a.repeat == 6
    with pytest.raises(InputError, match="--repeat"):
        run_fill_bench(city_db, repeats=0, progress=False)
