"""``walkstream bench pvs-misses``: every missed pixel gets one reason, and the figures add up."""

from __future__ import annotations

from pathlib import Path

import pytest

from walkstream.benchmarks.pvsmisses import REASONS, run_pvs_misses
from walkstream.cli import main


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


def test_an_unknown_path_is_a_one_line_error(small_city_db: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "pvs-misses", str(small_city_db), "--paths", "nowhere"]) != 0
    err = capsys.readouterr().err
    assert "nowhere" in err and "Traceback" not in err
