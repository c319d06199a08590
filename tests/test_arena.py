"""Batched drawing (walkstream.client.draw.arena) and the frame loop's phase timing."""

from __future__ import annotations

import time
from pathlib import Path

import moderngl
import numpy as np
import pytest

from walkstream.client.draw.arena import MeshArena, Ranges
from walkstream.client.draw.frames import FrameRenderer
from walkstream.client.draw.meshes import MeshRenderer
from walkstream.client.draw.phases import PHASES, FramePhases
from walkstream.client.report import format_headline, headline_rows
from walkstream.client.report.phases import plot_phases, write_phases_csv
from walkstream.shared.buildings import build_lods
from walkstream.shared.camera import camera
from walkstream.shared.errors import InputError
from walkstream.shared.records import BuildingParams, StreetParams
from walkstream.shared.streets import build_street

SIZE = (128, 96)
EYE = (0.0, 0.0, 1.7)


def scene() -> dict[tuple[int, int], object]:
    """Keyed meshes: six buildings of different sizes along a street, every LOD, the street."""
    keys: dict[tuple[int, int], object] = {}
    for i in range(6):
        x0, y0 = 12.0 + 9.0 * i, (-14.0 if i % 2 else 4.0)
        ring = np.array([[x0, y0], [x0 + 7.0, y0], [x0 + 7.0, y0 + 10.0], [x0, y0 + 10.0]])
        b = BuildingParams(10 + i, (ring,), (np.zeros(4),), floors=2 + i, floor_height=3.0)
        for lod, m in enumerate(build_lods(b)):
            keys[(10 + i, lod)] = m
    ring = np.array([[0.0, -4.0], [80.0, -4.0], [80.0, 4.0], [0.0, 4.0]])
    keys[(2, 0)] = build_street(StreetParams(2, "street", ring, 8.0))
    return keys


def frames(fr: FrameRenderer, draw: list[tuple[int, int]]) -> tuple[np.ndarray, np.ndarray]:
    view = camera(EYE, 0.35, 0.05)
    fr.draw(draw, view)
    return fr.snapshot(), fr.draw_ids(draw, view)


# --------------------------------------------------------------------------- ranges


def test_ranges_first_fit_merge_and_grow() -> None:
    r = Ranges(10)
    assert [r.alloc(3), r.alloc(3), r.alloc(3)] == [0, 3, 6]
    assert r.alloc(2) is None and r.free == 1
    r.release(3, 3)
    assert r.alloc(4) is None  # 3 + 1 free, not adjacent
    r.release(0, 3)
    assert r.alloc(6) == 0  # [0, 3) and [3, 6) merged
    r.release(0, 6)
    r.release(6, 3)
    assert r.free == 10 and r.alloc(10) == 0
    r.grow(16)
    assert r.free == 6 and r.alloc(6) == 10


# --------------------------------------------------------------------------- batched frames


@pytest.mark.gl
def test_batched_frames_and_ids_equal_one_draw_per_object(gl: moderngl.Context) -> None:
    keys = scene()
    draw = [(10, 2), (11, 1), (12, 0), (13, 2), (14, 2), (15, 1), (2, 0)]
    with FrameRenderer(SIZE, ctx=gl, batched=True) as b, FrameRenderer(SIZE, ctx=gl, batched=False) as p:
        for k, m in keys.items():
            b.upload(k, m)
            p.upload(k, m)
        img_b, ids_b = frames(b, draw)
        img_p, ids_p = frames(p, draw)
        assert len(np.unique(ids_b)) >= 5  # the view shows several objects
        np.testing.assert_array_equal(img_b, img_p)
        np.testing.assert_array_equal(ids_b, ids_p)
        assert b.last_triangles == p.last_triangles and b.last_drawn == p.last_drawn == len(draw)
        assert b.last_issue_s > 0 and b.last_finish_s >= 0
        # forget some, upload them again (into freed ranges): still the same frames
        for k in [(11, 1), (13, 2), (12, 0)]:
            b.forget(k)
            p.forget(k)
        img_b2, ids_b2 = frames(b, draw)
        img_p2, ids_p2 = frames(p, draw)
        np.testing.assert_array_equal(img_b2, img_p2)
        np.testing.assert_array_equal(ids_b2, ids_p2)
        assert not np.array_equal(ids_b2, ids_b)  # the forgotten ones are gone
        for k in [(13, 2), (11, 1), (12, 0)]:
            b.upload(k, keys[k])
            p.upload(k, keys[k])
        img_b3, ids_b3 = frames(b, draw)
        np.testing.assert_array_equal(img_b3, img_b)
        np.testing.assert_array_equal(ids_b3, ids_b)


@pytest.mark.gl
def test_arena_grows_and_draws_what_a_mesh_renderer_draws(gl: moderngl.Context) -> None:
    meshes = list(scene().values())
    with MeshRenderer(gl) as r:
        arena = MeshArena(gl, r.program, vertices=16, indices=24)  # far too small: grows
        try:
            for m in meshes:
                arena.add(m)
            assert arena.capacity_bytes > 16 * 28 + 24 * 4
            view = camera(EYE, 0.35, 0.05)
            proj = FrameRenderer(SIZE, ctx=gl).proj
            r.begin(view, proj, SIZE)
            arena.draw(meshes)
            batched = r.read()
            r.draw(meshes, view, proj, SIZE)
            np.testing.assert_array_equal(batched, r.read())
        finally:
            arena.release()
            arena.release()  # idempotent


# --------------------------------------------------------------------------- phases


def test_frame_phases_marks_moves_and_summary() -> None:
    ph = FramePhases()
    for _ in range(4):
        ph.begin()
        time.sleep(0.002)
        ph.mark("visible")
        time.sleep(0.004)
        ph.mark("draw")
        ph.move("draw", "finish", 0.003)
        ph.move("draw", "finish", 10.0)  # never more than draw holds
        ph.end()
        time.sleep(0.003)  # between frames: "other"
    a = ph.array()
    assert a.shape == (4, len(PHASES)) and len(ph) == 4
    i = {p: k for k, p in enumerate(PHASES)}
    assert np.all(a[:, i["visible"]] >= 0.002)
    assert np.all(a[:, i["draw"]] == 0.0) and np.all(a[:, i["finish"]] >= 0.004)
    assert np.all(a[:-1, i["other"]] >= 0.003) and a[-1, i["other"]] == 0.0
    s = ph.summary(fps_target=1000.0)
    assert set(s["frame_phases_median_ms"]) == set(PHASES)
    assert s["frame_loop_median_ms"] >= 6.0 and s["frame_period_median_ms"] >= 9.0
    assert s["frame_period_within_10pct_ratio"] == 0.0  # 9 ms periods are far from 1 ms
    assert ph.summary(fps_target=5.0)["frame_period_within_10pct_ratio"] == 1.0  # 200 ms: room for a loaded machine
    assert FramePhases().summary() == {}


def test_phases_report_files_and_headline(tmp_path: Path) -> None:
    n = 50
    t = np.linspace(0.0, 2.0, n)
    rng = np.random.default_rng(0)
    phases = rng.uniform(0.0, 0.004, (n, len(PHASES)))
    csv = write_phases_csv(tmp_path / "phases.csv", t, phases)
    back = np.loadtxt(csv, delimiter=",", skiprows=1)
    assert back.shape == (n, len(PHASES) + 1)
    np.testing.assert_allclose(back[:, 1:], 1000.0 * phases, atol=1e-4)
    png = plot_phases(tmp_path / "phases.png", t, phases, "test")
    assert png.read_bytes()[:4] == b"\x89PNG"
    with pytest.raises(InputError, match="frame phases"):
        write_phases_csv(tmp_path / "bad.csv", t, phases[:, :3])
    summary = {"frame_phases_median_ms": {"cull": 0.25, "finish": 7.5}, "frame_period_median_ms": 17.0}
    text = format_headline(summary)
    assert "cull 0.25" in text and "finish 7.50" in text and "period 17.00 ms" in text
    rows = {k: v for k, _, v in headline_rows(summary)}
    assert rows["frame_phases_median_ms"] == "cull 0.25, finish 7.50"
    assert "frame loop" not in format_headline({})
