"""A tiny run of the server load benchmark against a small baked scene."""

from __future__ import annotations

import pytest

from walkstream.benchmarks.load import format_table, run_server_bench
from walkstream.server.bake import BakeSettings, bake
from walkstream.server.sources.citygen import write_city


@pytest.fixture(scope="module")
def small_db(tmp_path_factory: pytest.TempPathFactory) -> str:
    d = tmp_path_factory.mktemp("loadbench")
    src = d / "city.geojson"
    write_city(src, 150, 2)
    out = d / "city.db"
    bake(src, out, settings=BakeSettings(resolution=32))
    return str(out)


@pytest.mark.gl
def test_tiny_run(small_db: str) -> None:
    rows = run_server_bench(
        small_db, walkers=(3,), workers=(1,), ramp_s=0.5, duration_s=1.5, pin=False
    )
    assert len(rows) == 1
    row = rows[0]
    assert row["walkers"] == 3 and row["workers"] == 1
    assert row["requests"] > 0
    assert row["errors"] == 0, row["error_kinds"]
    assert row["p99_ms"] >= row["p50_ms"] > 0
    assert 0.0 <= row["gen_cpu"]
    table = format_table(rows)
    assert "req/s" in table and "p99" in table
