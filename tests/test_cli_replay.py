"""`walkstream replay`, `bench stream`, `bench budget`, `path` and `demo` from the command line."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from scenes import add_default_paths, build_city_db

from walkstream.cli import main
from walkstream.server.store import SceneReader

ISSUE5_KEYS = {
    "frames", "perfect_frame_ratio", "download_quality_mean", "rewrite_quality_mean",
    "bytes_received", "overfetch_ratio", "redownloads", "rebuilds",
    "time_to_first_perfect_frame_s", "prefetch", "stream", "bandwidth_bps", "rtt_s",
}  # fmt: skip
ISSUE6_KEYS = {
    "fps_mean", "fps_target", "fps_within_10pct_ratio", "floor_limited_ratio",
    "budget_median", "budget_min", "budget_max",
}  # fmt: skip


@pytest.fixture(scope="module")
def db(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("cli-replay") / "city.db"
    build_city_db(path, name="city", size=300.0, k=30)
    add_default_paths(path)
    return path


def test_replay_writes_the_report(db: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    report = tmp_path / "report"
    argv = [
        "replay", str(db), "--path", "SE", "--bandwidth", "7kB/s", "--rtt", "200ms",
        "--duration", "12s", "--device", "desktop2003", "--snapshot-every", "60",
        "--size", "160x120", "--report", str(report),
    ]  # fmt: skip
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "perfect" in out and "index.html" in out
    summary = json.loads((report / "report.json").read_text())
    assert ISSUE5_KEYS | ISSUE6_KEYS <= set(summary)
    assert summary["bandwidth_bps"] == 56_000 and summary["rtt_s"] == 0.2
    html = (report / "index.html").read_text()
    for png in ("quality.png", "bytes.png", "fps.png", "budget.png"):
        assert (report / png).stat().st_size > 1000 and png in html
    frames = sorted(report.rglob("frame_*.png"))
    assert len(frames) >= 4  # 12 s at 25 fps, every 60th frame
    assert all(f.name in html for f in frames)


def test_replay_without_start_bundle_or_gzip(db: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    report = tmp_path / "plain"
    argv = [
        "replay", str(db), "--path", "drive", "--bandwidth", "40kbit", "--rtt", "500ms",
        "--duration", "6s", "--device", "desktop2003", "--no-start-bundle", "--no-gzip",
        "--report", str(report),
    ]  # fmt: skip
    assert main(argv) == 0
    summary = json.loads((report / "report.json").read_text())
    assert summary["start_bundle"] is False and summary["gzip"] is False
    assert summary["frames"] > 0 and "link_utilisation" in summary
    assert "link utilisation" in capsys.readouterr().out


@pytest.mark.gl
def test_replay_on_the_gl_device_really_draws(db: Path, tmp_path: Path, gl_ctx: object) -> None:
    report = tmp_path / "gl"
    argv = [
        "replay", str(db), "--duration", "3s", "--device", "gl", "--size", "96x64",
        "--bandwidth", "1Mbit", "--rtt", "50ms", "--report", str(report),
    ]  # fmt: skip
    assert main(argv) == 0
    summary = json.loads((report / "report.json").read_text())
    assert summary["device"] == "gl" and summary["frames"] > 0 and summary["fps_mean"] > 0


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--bandwidth", "56 parsecs"], "56 parsecs"),
        (["--rtt", "soon"], "soon"),
        (["--cache=-5MB"], "-5MB"),
        (["--loss", "2"], "--loss"),
        (["--size", "640by480"], "--size"),
        (["--path", "nowhere"], "nowhere"),
        (["--facade-texels", "0"], "--facade-texels"),
        (["--facade-bake-share", "2"], "--facade-bake-share"),
        (["--facade-budget", "lots"], "lots"),
        (["--facade-grazing", "120"], "--facade-grazing"),
    ],
)
def test_bad_replay_arguments_are_one_line(
    db: Path, tmp_path: Path, extra: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["replay", str(db), "--device", "desktop2003", "--report", str(tmp_path / "r"), *extra]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("walkstream: error:") and message in err
    assert "Traceback" not in err and len(err.splitlines()) == 1


def test_replay_of_a_missing_database(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["replay", str(tmp_path / "nope.db"), "--report", str(tmp_path / "r")]) == 2
    assert "nope.db" in capsys.readouterr().err


def test_bench_stream_prints_one_table(db: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "bench"
    names = ["SE 56k prefetch", "SE 56k no-prefetch", "SE 56k meshes", "SE 56k cache 8MB", "other SE GPRS"]
    # the four 56k modes of SE, and another scene database joining the table (a row per path
    # and link: its GPRS row here) in the one run: every row's report and plots cost more than
    # its walk, and a second run wrote a second comparison page
    argv = [
        "bench", "stream", str(db), "--scene", f"other={db}:SE",
        "--only", ",".join(names), "--duration", "5s", "--out", str(out), "--no-plots",
    ]  # fmt: skip
    assert main(argv) == 0
    text = capsys.readouterr().out
    for name in names:
        assert name in text
    assert "util%" in text and "overfetch" in text
    rows = json.loads((out / "bench_stream.json").read_text())
    assert [r["scenario"] for r in rows] == names and (out / "index.html").exists()
    # --no-plots: each row's own report has its figures and no plot; the comparison has its plots
    assert (out / "01-se-56k-prefetch" / "frames.csv").exists() and not list((out / "01-se-56k-prefetch").glob("*.png"))
    assert (out / "compare_bytes.png").exists()
    assert all(0.0 <= r["link_utilisation"] <= 1.05 and r["overfetch_ratio"] <= 0.5 for r in rows)
    assert main(["bench", "stream", str(db), "--scene", "nonsense", "--out", str(out)]) == 2
    assert "LABEL=DB" in capsys.readouterr().err


def test_bench_budget_table(db: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # 5 s after the cost's step: each row has recovered from it within a few frames
    argv = [
        "bench", "budget", str(db), "--no-gl", "--duration", "10s", "--step-at", "5",
        "--out", str(tmp_path / "b"), "--no-plots",
    ]  # fmt: skip
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "desktop2003" in text and "pda" in text
    rows = json.loads((tmp_path / "b" / "bench_budget.json").read_text())
    assert [r["device"] for r in rows] == ["desktop2003", "desktop2003", "pda"]
    assert all(r["recover"] is not None for r in rows)


def test_path_record_then_replay_it(db: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    copy = tmp_path / "city.db"
    copy.write_bytes(db.read_bytes())
    with SceneReader.open(copy) as r:
        cells = [c for c in r.cells() if c.kind == "street"]
    a = cells[0].boundary.mean(axis=0)
    b = cells[-1].boundary.mean(axis=0)
    argv = [
        "path", "record", str(copy), "mine", f"--from={a[0]},{a[1]}", f"--to={b[0]},{b[1]}",
        "--speed", "20",
    ]  # fmt: skip
    assert main(argv) == 0
    assert main(["path", "list", str(copy)]) == 0
    assert "mine" in capsys.readouterr().out
    argv = [
        "replay", str(copy), "--path", "mine", "--duration", "5s", "--device", "pda",
        "--report", str(tmp_path / "r"),
    ]  # fmt: skip
    assert main(argv) == 0


@pytest.mark.slow
@pytest.mark.gl
def test_demo_end_to_end(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], gl_ctx: object, monkeypatch: pytest.MonkeyPatch
) -> None:
    from walkstream.server.sources import citygen

    # every step of `make demo` (generate, rebuild, bake, serve, replay SE) on a 300 m default
    # city: the 700 m one's bake and rebuilds were two thirds of the test, and nothing below
    # depends on the city's size (SE is recorded on any generated city)
    monkeypatch.setattr(citygen, "DEFAULT_SIZE", 300.0)
    # the first 8 s of the walk: the whole walk is `make demo`'s, not the suite's
    assert main(["demo", "--out", str(tmp_path), "--duration", "8s"]) == 0
    out = capsys.readouterr().out
    assert "server on http://127.0.0.1:" in out and "perfect" in out
    summary = json.loads((tmp_path / "report" / "report.json").read_text())
    assert summary["path"] == "SE" and summary["device"] == "desktop2003"
    assert summary["clock"] == "sim" and summary["bandwidth_bps"] == 56_000
    # 8 s of walk at 25 fps, after the start's hold for the first view (at most 3 s)
    assert 0 < summary["start_hold_s"] <= 3.0
    assert 8 * 25 <= summary["frames"] <= 25 * (8 + summary["start_hold_s"]) + 3


@pytest.mark.gl
def test_bench_budget_gl_rows_under_the_real_clock(db: Path, tmp_path: Path, gl: object) -> None:
    from walkstream.benchmarks.budget import (
        format_budget_table,
        format_gl_real_table,
        run_gl_real_rows,
    )
    from walkstream.client.draw.phases import PHASES
    from walkstream.cmd_replay import replay_with_options

    rows = run_gl_real_rows(
        str(db), replay_with_options, out=tmp_path, runs=1, duration="2s", cases=(("160x120", 30.0),)
    )
    assert [(r["draws"], r["clock"], r["size"]) for r in rows] == [
        ("batched", "real", "160x120"),
        ("per-object", "real", "160x120"),
    ]
    for r in rows:
        assert r["rewrite"] == "process" and r["rewrite_path"]["mode"] == "process"
        assert r["python_ms"] > 0 and r["python_start_ms"] > 0
        assert set(r["phases_ms"]) == set(PHASES)
        assert r["phases_ms"]["finish"] > 0.0 and r["fps_mean"] > 0
        assert len(r["per_run"]) == 1
    report = json.loads((tmp_path / "real-160x120-30fps-per-object-1" / "report.json").read_text())
    assert report["batched_draws"] is False and report["clock"] == "real"
    assert (tmp_path / "real-160x120-30fps-batched-1" / "phases.png").exists()
    text = format_gl_real_table(rows)
    assert "per-object" in text and "finish" in text
    assert "160x120" not in format_budget_table(rows)  # the real-clock rows have their own table


def test_a_bad_start_hold_is_refused_by_name(db: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    for bad in ("-1", "soon", "nan"):
        with pytest.raises(SystemExit) as e:
            main(["replay", str(db), "--report", str(tmp_path / "r"), f"--start-hold={bad}"])
        assert e.value.code == 2
        err = capsys.readouterr().err
        assert "--start-hold" in err.splitlines()[-1] and "Traceback" not in err
