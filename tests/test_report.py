"""Tests of walkstream.client.report: report.json, the CSV logs, the plots and the HTML pages."""

from __future__ import annotations

import json
import math
import re
from html.parser import HTMLParser
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from walkstream.client.report import (
    BASE_PLOT_NAMES,
    PLOT_NAMES,
    SERIES_COLOURS,
    format_comparison_table,
    format_headline,
    json_safe,
    load_run,
    read_frames_csv,
    write_comparison,
    write_json,
    write_report,
)
from walkstream.client.report import files as report_files
from walkstream.client.report import plots as report_plots
from walkstream.client.report.framelog import FrameLog, FrameLogBuilder
from walkstream.client.report.metrics import summarise
from walkstream.shared.errors import InputError

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def walk_log(n: int = 400, *, prefetch: bool = True, seed: int = 0) -> FrameLog:
    """A plausible replay: quality climbs, the budget wobbles, a few floor-limited frames."""
    rng = np.random.default_rng(seed)
    b = FrameLogBuilder(fps_cap=25.0)
    t, down = 5.0, 0
    for i in range(n):
        ft = 0.04 * float(rng.lognormal(0.0, 0.05))
        q = min(1.0, i / 40) if prefetch else (1.0 if i % 100 > 30 else (i % 100) / 30)
        down += int(rng.integers(0, 300))
        b.append(
            t=t,
            frame_time=ft,
            download_quality=q,
            rewrite_quality=min(q, max(0.0, (i - 4) / 40)),
            bytes_down=down,
            cell=i // 50,
            pvs=40,
            budget=int(40_000 + 5_000 * math.sin(i / 20)),
            triangles=int(38_000 + 5_000 * math.sin(i / 20)),
            visible=25,
            floor_limited=i % 37 == 0,
            all_lod2=False,
        )
        t += max(ft, 0.04)
    return b.build()


def run_parts(
    n: int = 400, *, prefetch: bool = True, seed: int = 0
) -> tuple[dict[str, Any], FrameLog, tuple[Any, Any]]:
    log = walk_log(n, prefetch=prefetch, seed=seed)
    bytes_log = (np.concatenate([[4.5], log.t]), np.concatenate([[0], log.bytes_down]))
    summary = summarise(
        log,
        fps_target=25.0,
        fps_cap=25.0,
        bytes_received=int(log.bytes_down[-1]),
        t_start=4.5,
        extra={
            "prefetch": prefetch,
            "stream": "params",
            "bandwidth_bps": 56_000,
            "rtt_s": 0.2,
            "overfetch_ratio": np.float64(0.12),
            "redownloads": np.int64(0),
            "rebuilds": 2,
            "odd": math.nan,
        },
    )
    return summary, log, bytes_log


class _Refs(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.refs: list[str] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        for name, value in attrs:
            if name in ("src", "href") and value:
                self.refs.append(value)


def html_refs(path: Path) -> list[str]:
    p = _Refs()
    p.feed(path.read_text(encoding="utf-8"))
    return p.refs


def png_pixels(path: Path) -> np.ndarray[Any, Any]:
    import matplotlib.image

    assert path.read_bytes()[:8] == PNG_MAGIC, path
    img: np.ndarray[Any, Any] = matplotlib.image.imread(path)
    return img


def colour_pixels(img: np.ndarray[Any, Any], hex_colour: str, tol: float = 0.08) -> int:
    rgb = np.array([int(hex_colour[i : i + 2], 16) for i in (1, 3, 5)]) / 255.0
    return int((np.abs(img[..., :3] - rgb).max(axis=-1) < tol).sum())


def write_png(path: Path, value: float) -> Path:
    import matplotlib.image

    path.parent.mkdir(parents=True, exist_ok=True)
    img = np.zeros((8, 8, 3))
    img[..., 0] = value
    img[:4, :4, 1] = 1.0
    matplotlib.image.imsave(path, img)
    return path


# --------------------------------------------------------------------------- JSON


def test_json_safe_converts_numpy_nan_and_containers() -> None:
    obj = {
        "a": np.float32(1.5),
        "b": np.int64(7),
        "c": np.bool_(True),
        "d": math.nan,
        "e": -math.inf,
        "f": np.array([1.0, np.nan, 3.0]),
        "g": (1, 2),
        "h": Path("x/y.png"),
        3: [np.float64(np.inf)],
    }
    safe = json_safe(obj)
    assert safe == {
        "a": 1.5,
        "b": 7,
        "c": True,
        "d": None,
        "e": None,
        "f": [1.0, None, 3.0],
        "g": [1, 2],
        "h": "x/y.png",
        "3": [None],
    }
    assert json.loads(json.dumps(safe, allow_nan=False)) == safe
    with pytest.raises(InputError, match="JSON"):
        json_safe({"x": object()})


def test_write_json_leaves_no_trace_when_the_value_is_bad(tmp_path: Path) -> None:
    p = write_json(tmp_path / "r.json", {"x": 1})
    with pytest.raises(InputError):
        write_json(p, {"x": object()})
    assert json.loads(p.read_text()) == {"x": 1}
    assert sorted(q.name for q in tmp_path.iterdir()) == ["r.json"]


def test_atomic_write_keeps_the_old_file_when_writing_fails(tmp_path: Path) -> None:
    p = write_json(tmp_path / "r.json", {"x": 1})
    with pytest.raises(RuntimeError), report_files.atomic_open(p) as f:
        f.write('{"x": 2')
        raise RuntimeError("disk full")
    assert json.loads(p.read_text()) == {"x": 1}
    assert sorted(q.name for q in tmp_path.iterdir()) == ["r.json"]


# --------------------------------------------------------------------------- one report


@pytest.fixture(scope="module")
def written(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    out = tmp_path_factory.mktemp("report")
    outside = tmp_path_factory.mktemp("elsewhere")
    snaps = [
        write_png(out / "snapshots" / "frame_000010.png", 0.2),
        write_png(outside / "frame_000020.png", 0.6),
        write_png(outside / "sub" / "frame_000020.png", 0.9),  # same name: must not collide
    ]
    missing = outside / "nope.png"  # listed as missing, not fatal
    summary, log, bytes_log = run_parts()
    index = write_report(out, summary, log, bytes_log, snapshots=[*snaps, missing], title="SE test")
    return {
        "out": out,
        "index": index,
        "summary": summary,
        "log": log,
        "bytes": bytes_log,
        "snaps": snaps,
    }


def test_report_files_exist(written: dict[str, Any]) -> None:
    out: Path = written["out"]
    assert written["index"] == out / "index.html"
    for name in ("report.json", "frames.csv", "bytes.csv", "index.html", *BASE_PLOT_NAMES):
        assert (out / name).is_file(), name
        assert (out / name).stat().st_size > 0
    assert not list(out.glob(".*.tmp"))


def test_report_json_is_the_summary_without_nan(written: dict[str, Any]) -> None:
    text = (written["out"] / "report.json").read_text()
    assert "NaN" not in text and "Infinity" not in text
    data = json.loads(text)
    assert data == json_safe(written["summary"])
    assert data["odd"] is None
    assert data["overfetch_ratio"] == pytest.approx(0.12)
    for key in ("frames", "perfect_frame_ratio", "download_quality_mean", "fps_within_10pct_ratio"):
        assert key in data


def test_frames_csv_round_trips(written: dict[str, Any]) -> None:
    back = read_frames_csv(written["out"] / "frames.csv")
    log: FrameLog = written["log"]
    for name, a in log.columns().items():
        np.testing.assert_array_equal(getattr(back, name), a, err_msg=name)
    summary, frames, (bt, bb) = load_run(written["out"])
    assert summary == json_safe(written["summary"]) and len(frames) == len(log)
    np.testing.assert_allclose(bt, written["bytes"][0])
    np.testing.assert_array_equal(bb, written["bytes"][1])


def test_pngs_are_images_with_data_drawn(written: dict[str, Any]) -> None:
    out: Path = written["out"]
    for name in BASE_PLOT_NAMES:
        img = png_pixels(out / name)
        assert img.ndim == 3 and img.shape[0] > 200 and img.shape[1] > 400, name
        assert np.ptp(img[..., :3]) > 0.5, f"{name} is one colour"
        packed = (img[..., :3] * 255).astype(np.uint32) @ np.array([1, 256, 65536], np.uint32)
        assert len(np.unique(packed)) > 20, name
    # The data lines themselves are drawn, not just axes: the series colour shows up.
    assert colour_pixels(png_pixels(out / "quality.png"), SERIES_COLOURS[0]) > 400
    assert colour_pixels(png_pixels(out / "bytes.png"), SERIES_COLOURS[0]) > 200
    assert colour_pixels(png_pixels(out / "fps.png"), "#D00000") > 10  # floor-limited marks


def test_html_references_every_plot_and_snapshot_and_they_exist(written: dict[str, Any]) -> None:
    out: Path = written["out"]
    refs = html_refs(written["index"])
    for name in (*BASE_PLOT_NAMES, "report.json", "frames.csv"):
        assert name in refs, name
    for ref in refs:
        assert not ref.startswith("/") and "://" not in ref, f"not relative: {ref}"
        assert (out / ref).is_file(), ref
    snaps = [r for r in refs if r.endswith(".png") and r not in PLOT_NAMES]
    # Inside the folder: linked in place; outside: copied in, without name clashes.
    assert "snapshots/frame_000010.png" in snaps
    copied = {r for r in snaps if r.startswith("snapshots/frame_000020")}
    assert len(copied) == 2
    contents = {(out / r).read_bytes() for r in copied}
    assert contents == {p.read_bytes() for p in written["snaps"][1:]}
    text = written["index"].read_text()
    assert "perfect frames" in text and "&quot;frames&quot;: 400" in text
    assert "missing snapshot" in text and "nope.png" in text


def test_writing_over_a_report_replaces_files_atomically(tmp_path: Path) -> None:
    s1, log1, b1 = run_parts(120, prefetch=True)
    write_report(tmp_path, s1, log1, b1, title="first")
    old_json = tmp_path / "report.json"
    with old_json.open(encoding="utf-8") as held:  # a reader that opened the old report
        s2, log2, b2 = run_parts(90, prefetch=False)
        write_report(tmp_path, s2, log2, b2, title="second")
        # The old file was replaced, not rewritten in place: the reader still sees it whole.
        assert json.loads(held.read())["frames"] == 120
    assert json.loads(old_json.read_text())["frames"] == 90
    assert len(read_frames_csv(tmp_path / "frames.csv")) == 90
    assert "second" in (tmp_path / "index.html").read_text()
    assert not list(tmp_path.glob(".*.tmp"))


def test_empty_log_and_no_bytes_log_still_give_a_report(tmp_path: Path) -> None:
    s = summarise(FrameLog.empty(), fps_target=25.0, fps_cap=25.0, bytes_received=0)
    index = write_report(tmp_path, s, FrameLog.empty(), None, title="empty")
    for name in BASE_PLOT_NAMES:
        png_pixels(tmp_path / name)
    data = json.loads((tmp_path / "report.json").read_text())
    assert data["frames"] == 0 and data["fps_mean"] is None
    assert len(read_frames_csv(tmp_path / "frames.csv")) == 0
    assert "n/a" in index.read_text()


def test_bytes_log_with_unequal_arrays_is_rejected(tmp_path: Path) -> None:
    s, log, _ = run_parts(30)
    with pytest.raises(InputError, match="bytes log"):
        write_report(tmp_path, s, log, (np.zeros(3), np.zeros(2)), title="t")


def test_long_log_plots(tmp_path: Path) -> None:
    s, log, b = run_parts(15_000)
    write_report(tmp_path, s, log, b, title="long")
    img = png_pixels(tmp_path / "fps.png")
    assert colour_pixels(img, SERIES_COLOURS[0]) > 500


@pytest.mark.parametrize("draw", ["plot_bytes", "plot_quality", "plot_fps", "plot_budget"])
def test_fixed_margins_keep_every_label_inside_the_figure_and_clear_of_other_axes(
    draw: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The report's grids are placed by fixed margins, not measured: no tick label, axis
    label, title or legend may leave the figure or run into another axes."""
    figures: list[Any] = []
    save = report_plots.save_figure

    def keep(fig: Any, path: Path) -> Path:
        figures.append(fig)
        return save(fig, path)

    monkeypatch.setattr(report_plots, "save_figure", keep)
    runs = [report_plots.make_run(f"run {i} 56k prefetch", *run_parts(300, seed=i), i) for i in range(3)]
    getattr(report_plots, draw)(tmp_path / "p.png", runs, "a title\nof two lines")
    (fig,) = figures
    assert report_plots._grid_layout(fig)  # placed by the margins, not by tight_layout
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    renderer = FigureCanvasAgg(fig).get_renderer()
    fig.draw(renderer)
    page, frames = fig.bbox, [ax.get_window_extent(renderer) for ax in fig.axes]
    for k, ax in enumerate(fig.axes):
        drawn = ax.get_tightbbox(renderer)  # the axes with every label, title and legend drawn
        assert page.x0 - 1 <= drawn.x0 and drawn.x1 <= page.x1 + 1 and page.y0 - 1 <= drawn.y0 and drawn.y1 <= page.y1 + 1
        assert not any(drawn.overlaps(f) for m, f in enumerate(frames) if m != k), (draw, k)


def test_envelope_keeps_extremes_and_bounds_points() -> None:
    x = np.arange(20_000, dtype=float)
    y = np.zeros(20_000)
    y[12_345] = 9.0
    y[777] = -4.0
    xs, ys = report_plots._envelope(x, y, max_points=1000)
    assert len(xs) <= 1100
    assert ys.max() == 9.0 and ys.min() == -4.0
    assert 12_345.0 in xs and xs[0] == 0.0 and xs[-1] == 19_999.0
    assert np.all(np.diff(xs) > 0)


# --------------------------------------------------------------------------- headline, comparison


def test_headline_text() -> None:
    s, _, _ = run_parts(100)
    text = format_headline(s)
    assert re.search(r"^frames \d+, perfect \d+\.\d %, first perfect frame at ", text)
    assert re.search(r"download quality \d+\.\d %, rewrite quality \d+\.\d %", text)
    assert re.search(r"bytes received [\d,]+, overfetch", text)
    assert re.search(r"link utilisation (n/a|\d+\.\d %) \(", text)
    assert len(text.splitlines()) == 5
    empty = format_headline({"time_to_first_perfect_frame_s": None})
    assert "first perfect frame at never" in empty and "within 10 % n/a" in empty


def test_comparison_overlays_and_links(tmp_path: Path) -> None:
    runs: list[Any] = []
    reports = {}
    for i, label in enumerate(("prefetch", "no prefetch")):
        s, log, b = run_parts(300, prefetch=i == 0, seed=i + 1)
        d = tmp_path / label.replace(" ", "_")
        d.mkdir()
        (d / "index.html").write_text("<html>run report</html>")  # stands in for write_report
        runs.append((label, s, log, b, d))  # the folder as a fifth item ...
        reports[label] = d
    s, log, _ = run_parts(200, seed=3)
    runs.append(("meshes", s, log, None))
    out = tmp_path / "compare"
    paths = write_comparison(out, runs, "SE 56 kbit/s")
    assert paths[-1] == out / "index.html"
    for p in paths:
        assert p.is_file() and p.parent == out
    pngs = [p for p in paths if p.suffix == ".png"]
    assert len(pngs) == 4
    cmp_bytes = png_pixels(out / "compare_bytes.png")
    for colour in SERIES_COLOURS[:3]:  # every run's line is drawn
        assert colour_pixels(cmp_bytes, colour) > 100, colour
    refs = html_refs(out / "index.html")
    for p in pngs:
        assert p.name in refs
    for label, d in reports.items():
        rel = next(r for r in refs if r.endswith("index.html") and label.replace(" ", "_") in r)
        assert (out / rel).resolve() == (d / "index.html").resolve()
    data = json.loads((out / "comparison.json").read_text())
    assert [r["label"] for r in data["runs"]] == ["prefetch", "no prefetch", "meshes"]
    assert data["runs"][2]["report"] is None
    # ... or given apart, overriding the fifth item.
    other = tmp_path / "other"
    write_comparison(tmp_path / "compare2", runs, "x", reports={"prefetch": other})
    data2 = json.loads((tmp_path / "compare2" / "comparison.json").read_text())
    assert data2["runs"][0]["report"] == "../other/index.html"
    assert data2["runs"][1]["report"] == "../no_prefetch/index.html"
    table = format_comparison_table([(r[0], r[1]) for r in runs])
    assert "no prefetch" in table.splitlines()[0] and "perfect frames" in table


def test_comparison_rejects_bad_runs(tmp_path: Path) -> None:
    s, log, b = run_parts(20)
    with pytest.raises(InputError, match="at least one"):
        write_comparison(tmp_path, [], "x")
    with pytest.raises(InputError, match="distinct"):
        write_comparison(tmp_path, [("a", s, log, b), ("a", s, log, b)], "x")
    with pytest.raises(InputError, match="items"):
        write_comparison(tmp_path, [("a", s, log)], "x")  # type: ignore[list-item]
    with pytest.raises(InputError, match="unknown run labels"):
        write_comparison(tmp_path, [("a", s, log, b)], "x", reports={"b": tmp_path})


def test_plot_names_hold_every_plot_a_report_writes(tmp_path: Path) -> None:
    """With phases and an interior walk's series the optional plots come too, all named."""
    from walkstream.client.draw.phases import PHASES

    s, log, b = run_parts(60)
    n = len(log.t)
    rng = np.random.default_rng(0)
    interior = {k: rng.random(n) for k in ("cells", "portals", "triangles", "cull_ms", "fog_m")}
    write_report(tmp_path, s, log, b, title="all", phases=rng.random((n, len(PHASES))) / 100, interior=interior)
    written = {p.name for p in tmp_path.glob("*.png")}
    assert written <= set(PLOT_NAMES), written - set(PLOT_NAMES)
    assert {*BASE_PLOT_NAMES, "phases.png", "interior.png"} <= written
    assert PLOT_NAMES[: len(BASE_PLOT_NAMES)] == BASE_PLOT_NAMES and "error.png" in PLOT_NAMES
