"""``walkstream bench walls --quick``: the small hall without walls, baked with walls at A = 10°
and replayed with them and without on the walls' own database."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from walkstream.benchmarks.walls import format_walls_table, walls_support
from walkstream.cli import main

pytestmark = pytest.mark.gl


def test_bench_walls_quick_measures_the_hall_without_walls(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "bench"
    assert main(["bench", "walls", "--quick", "--no-gl", "--no-plots", "--out", str(out), "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    rows = result["rows"]
    base = [r for r in rows if r["variant"] == "no walls"]
    assert [r["scene"] for r in base] == ["hall"]
    r = base[0]
    # the budget holds the pda's rate by its fog, and the fog hides what the full scene shows
    assert r["kind"] == "interior" and r["pda_within_10pct"] > 0.9
    assert r["fog_m_median"] is not None and r["fog_m_median"] < 40.0
    assert r["compared_frames"] >= 1 and r["colour_error_median"] > 0.0 and r["fog_visible_share"] > 0.0
    assert 0.0 <= r["effective_culling"] < 1.0 and r["texture_bytes"] == 0
    # frustum culling alone against drawing the whole hall, on the tour's frames
    assert list(result["frustum"]) == ["hall"]
    modes = result["frustum"]["hall"]["modes"]
    assert 0 < modes["frustum"]["triangles_median"] <= modes["none"]["triangles_median"] == result["frustum"]["hall"]["triangles_in_hall"]
    assert modes["none"]["pda_ms_median"] > 1000.0 / 25.0
    bake, play = walls_support()
    assert bake and play  # the bake places walls and the replay switches them
    walls = {r["variant"]: r for r in rows if "A=10" in r["variant"]}
    assert set(walls) == {"walls A=10", "no walls (A=10 db)"}, result["notes"]
    on, off = walls["walls A=10"], walls["no walls (A=10 db)"]
    assert on["texture_bytes"] > 0 and on["textures_per_wall"] > 0 and off["texture_bytes"] == 0
    assert on["compared_frames"] >= 1 and on["colour_error_median"] is not None
    # the same walk both ways: the walls' database replays the plain hall's tour
    from walkstream.server.store import SceneReader

    with SceneReader.open(out / "hall.db") as a, SceneReader.open(out / "hall-walls-10.db") as b:
        assert a.path_blob("tour") == b.path_blob("tour")
    assert (out / "bench_walls.png").stat().st_size > 0
    table = format_walls_table(result)
    assert "frustum culling alone" in table and "hall" in table


def test_bench_walls_refuses_an_unknown_scene_in_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "walls", "--scenes", "hall,atlantis"]) != 0
    err = capsys.readouterr().err
    assert "--scenes" in err and "atlantis" in err and "Traceback" not in err
    assert "squares" in err  # the small generated city with squares is a scene of its own
    assert main(["bench", "walls", "--wall-errors", "10,ninety"]) != 0
    assert "--wall-errors" in capsys.readouterr().err


def test_bench_walls_texture_variants_are_parsed_and_a_bad_one_is_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    from walkstream.benchmarks.walls import parse_texture_variants, texture_label

    specs = parse_texture_variants("view=120; texels=4,quality=75,max-side=256")
    assert [texture_label(s) for s in specs] == ["view=120", "texels=4 max-side=256 quality=75"]
    for bad, message in (("size=3", "key=value with a key of"), ("view=x", "view='x': expected a number"),
                         ("quality=0", "--wall-quality: expected 1 to 100")):
        assert main(["bench", "walls", "--wall-textures", bad]) != 0
        err = capsys.readouterr().err
        assert message in err and "Traceback" not in err
