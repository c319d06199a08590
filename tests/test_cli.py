"""The walkstream command line: each subcommand end to end, and its error handling."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from walkstream.cli import main


@pytest.fixture(scope="module")
def city(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("cli") / "city.geojson"
    assert main(["generate", "city", "--size", "200", "--seed", "3", "-o", str(path)]) == 0
    return path


def test_help_lists_subcommands(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    for cmd in ("demo", "generate", "buildings", "grammar", "bench"):
        assert cmd in out


def test_generate_is_deterministic(city: Path, tmp_path: Path) -> None:
    again = tmp_path / "again.geojson"
    assert main(["generate", "city", "--size", "200", "--seed", "3", "-o", str(again)]) == 0
    assert again.read_bytes() == city.read_bytes()
    fc = json.loads(city.read_text())
    kinds = {f["properties"]["kind"] for f in fc["features"]}
    assert {"building", "street", "crossroad"} <= kinds


def test_buildings_stats_json(city: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["buildings", "stats", str(city), "--json"]) == 0
    stats = json.loads(capsys.readouterr().out)
    for key in ("buildings", "skipped", "triangles", "rebuild_per_s", "param_bytes", "lod2_bytes", "ratio"):
        assert key in stats
    t = stats["triangles"]
    assert stats["buildings"] > 10 and t[0] < t[1] < t[2]
    assert 0 < stats["ratio"] < 0.01
    assert stats["ratio"] == pytest.approx(stats["param_bytes"] / stats["lod2_bytes"])


@pytest.mark.gl
def test_buildings_render_png_and_glb(city: Path, tmp_path: Path, gl_ctx: object) -> None:
    fc = json.loads(city.read_text())
    bid = next(f["id"] for f in fc["features"] if f["properties"]["kind"] == "building")
    png, glb = tmp_path / "lods.png", tmp_path / "b.glb"
    assert main(["buildings", "render", str(city), "--id", bid, "-o", str(png), "--gltf", str(glb)]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    import trimesh

    assert len(trimesh.load(glb, force="scene").geometry) == 1


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["buildings", "stats", "/nonexistent/x.geojson"], "x.geojson"),
        (["generate", "city", "--size", "50", "-o", "{tmp}/never.geojson"], "size"),
        (["grammar", "/nonexistent/g.lsys"], "g.lsys"),
    ],
)
def test_bad_input_is_one_clear_line(
    argv: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # (a file the command would write goes in the test's own folder, never a shared one)
    assert main([a.replace("{tmp}", str(tmp_path)) for a in argv]) == 2
    err = capsys.readouterr().err
    assert err.startswith("walkstream: error:")
    assert message in err
    assert "Traceback" not in err


def test_unknown_building_id(city: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["buildings", "render", str(city), "--id", "nope", "-o", str(tmp_path / "x.png")]) == 2
    assert "no building with id 'nope'" in capsys.readouterr().err


def test_malformed_geojson(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.geojson"
    bad.write_text("{not json")
    assert main(["buildings", "stats", str(bad)]) == 2
    assert "bad.geojson" in capsys.readouterr().err


def test_grammar_file_error_names_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    g = tmp_path / "g.lsys"
    g.write_text("grammar x 1\nA(x) -> B(\n")
    assert main(["grammar", str(g)]) == 2
    assert "grammar line 2" in capsys.readouterr().err


def test_bench_rebuild_compares_paths_in_one_run(city: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "rebuild", str(city), "--repeat", "1", "--batch", "4,1000"]) == 0
    out = capsys.readouterr().out
    for row in ("one by one", "batch 4 ", "batch 1000 (all)", "trimesh extrude_polygon", "LOD0 batch 4 vs trimesh"):
        assert row in out, row
    assert main(["bench", "rebuild", str(city), "--repeat", "1", "--batch", "0"]) == 2
    assert "--batch" in capsys.readouterr().err


def test_a_step_slow_only_on_its_first_run_is_said_then_and_only_then(capsys: pytest.CaptureFixture[str]) -> None:
    import time

    from walkstream.terminal import say_if_slow

    assert say_if_slow(lambda: time.sleep(0.3), "compiling the thing", after_s=0.05) >= 0.3
    err = capsys.readouterr().err
    assert "walkstream: compiling the thing ..." in err and "compiling the thing: done in" in err
    say_if_slow(lambda: None, "loading the thing", after_s=0.5)  # quick: the terminal stays quiet
    assert capsys.readouterr().err == ""

    def broken() -> None:
        raise ValueError("no kernel")

    with pytest.raises(ValueError, match="no kernel"):  # raised where the caller waits
        say_if_slow(broken, "compiling")
