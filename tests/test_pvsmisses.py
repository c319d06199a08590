"""``walkstream bench pvs-misses``: every missed pixel gets one reason, and the figures add up."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from walkstream.benchmarks.pvsmisses import OVER_SHARE, REASONS, pvs_floor, run_pvs_misses
from walkstream.cli import main
from walkstream.shared.errors import InputError


@pytest.mark.gl
def test_every_missed_pixel_gets_a_reason_and_the_mean_is_theirs(small_city_db: Path, gl: object) -> None:
    # the small city is baked coarsely (32 px at the box corners): it misses things for several reasons
    r = run_pvs_misses(small_city_db, ["SE"], every=4.0, size=(160, 120), top=3, ctx=gl)  # type: ignore[arg-type]
    f = r["paths"]["SE"]
    assert r["probe_resolution"] == 278  # 160 px over 60 degrees: as fine at the centre
    assert set(f["reasons"]) == set(REASONS)
    missed = sum(f["reasons"].values())
    assert missed > 0
    assert sum(row["share"] for row in r["rows"]) * 160 * 120 == pytest.approx(missed)
    assert f["mean"] * f["poses"] >= sum(row["share"] for row in r["rows"]) > 0
    for row in r["rows"]:
        assert row["share"] > 1e-4 and len(row["objects"]) <= 3
        assert all(o["reason"] in REASONS and o["pixels"] > 0 for o in row["objects"])
        assert row["inside"] or row["to_outline"] < 1.0 or row["cell"] is None
    # the floor: every object that alone put a pose over is one the PVS lacked there, or one it holds
    fl = r["floor"]
    assert fl["cells"] > 0 and fl["yardstick_mean"] is None and fl["must_ratio"] is None
    alone = {(row["cell"], o["id"]) for row in r["rows"] for o in row["objects"] if o["pixels"] > OVER_SHARE * 160 * 120}
    assert fl["lacking"] >= len(alone) > 0
    assert fl["need_mean"] >= fl["must_mean"] > 0


@pytest.mark.gl
def test_the_floor_against_a_yardstick_of_the_same_cells(small_city_db: Path, office_db: Path, gl: object) -> None:
    r = run_pvs_misses(small_city_db, ["SE"], every=8.0, size=(160, 120), yardstick=small_city_db, ctx=gl)  # type: ignore[arg-type]
    fl = r["floor"]
    assert fl["yardstick_mean"] == fl["pvs_mean"] and fl["must_ratio"] == pytest.approx(fl["must_mean"] / fl["pvs_mean"])
    with pytest.raises(InputError, match="yardstick"):
        run_pvs_misses(small_city_db, ["SE"], every=8.0, size=(160, 120), yardstick=office_db, ctx=gl)  # type: ignore[arg-type]


def test_pvs_floor_counts_what_each_visited_cell_must_hold() -> None:
    must = {3: {1, 2, 9}, 5: set()}
    baked = {3: np.array([1, 2, 4]), 5: np.array([7]), 6: np.arange(50)}
    got = pvs_floor(must, baked, {3: np.arange(6), 5: np.arange(2)})
    # cell 6 was never visited: it counts in no mean
    assert got == {"cells": 2, "must_mean": 1.5, "pvs_mean": 2.0, "yardstick_mean": 4.0, "must_ratio": 0.375, "lacking": 1}
    assert pvs_floor({}, baked)["cells"] == 0


def test_an_unknown_path_is_a_one_line_error(small_city_db: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "pvs-misses", str(small_city_db), "--paths", "nowhere"]) != 0
    err = capsys.readouterr().err
    assert "nowhere" in err and "Traceback" not in err
