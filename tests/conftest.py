"""Shared pytest fixtures."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest
from hypothesis import settings
from onceperrun import once_per_run
from teamdata import team_data

pytest_plugins = ["ci_skips"]

# No timed assertions in tests: hypothesis's 200 ms deadline per example is one, and it
# failed test_codec.py's mutated records on the loaded 2-core machine (963 ms once, 43 ms
# on the rerun).  Every property test runs without it; a test's own @settings keep the rest.
settings.register_profile("walkstream", deadline=None)
settings.load_profile("walkstream")

if TYPE_CHECKING:
    import moderngl


@pytest.fixture(scope="session")
def gl_ctx() -> Iterator[moderngl.Context]:
    """One headless OpenGL context for the session; skips the test when none can be made."""
    from walkstream.shared.errors import RenderError
    from walkstream.shared.gl import create_context

    try:
        ctx = create_context()
    except RenderError as exc:
        pytest.skip(str(exc))
    yield ctx
    ctx.release()


@pytest.fixture
def gl(gl_ctx: moderngl.Context) -> Iterator[moderngl.Context]:
    """The session context, with the GL error state checked before and after the test."""
    from walkstream.shared.gl import check_gl_error

    # a replay run in-process makes its own context current and releases it: this one is
    # made current again (and left current, as the tests that take gl_ctx itself expect)
    gl_ctx.__enter__()
    check_gl_error(gl_ctx, "before the test (left by an earlier one)")
    yield gl_ctx
    check_gl_error(gl_ctx, "after the test")


# --------------------------------------------------------------------------- interiors
# Baked once per run and shared by every xdist worker (tests/onceperrun.py): Interiors I's
# tests and the portal culling tests share them, and only read them.

def _baked_ifc(tmp_path_factory: pytest.TempPathFactory, name: str) -> tuple[Path, dict[str, Any]]:
    pytest.importorskip("ifcopenshell", reason="the ifc extra (make test installs it)")
    src = team_data("indoor", name)

    def build(folder: Path) -> tuple[Path, dict[str, Any]]:
        from walkstream.server.bake import bake

        out = folder / f"{src.stem}.db"
        return out, bake(src, out)

    return once_per_run(tmp_path_factory, src.stem, build)


@pytest.fixture(scope="session")
def office_db(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A small generated office (2 storeys, 20 x 14 m), baked."""

    def build(folder: Path) -> Path:
        from walkstream.server.bake import bake
        from walkstream.server.sources.interiorgen import InteriorPlan, write_interior

        src = folder / "office.json"
        write_interior(src, InteriorPlan(storeys=2, length=20, width=14, seed=2))
        bake(src, folder / "office.db")
        return folder / "office.db"

    return once_per_run(tmp_path_factory, "office", build)


@pytest.fixture(scope="session")
def small_city_db(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 150 m generated city (seed 2), baked coarsely (32 px, corners): for walks that need a city, not its PVS."""

    def build(folder: Path) -> Path:
        from walkstream.server.bake import BakeSettings, bake
        from walkstream.server.sources.citygen import write_city

        write_city(folder / "city.geojson", 150, 2)
        bake(folder / "city.geojson", folder / "city.db", settings=BakeSettings(resolution=32, sampling="corners"), name="city")
        return folder / "city.db"

    return once_per_run(tmp_path_factory, "small-city", build)


@pytest.fixture(scope="session")
def duplex_db(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any]]:
    """../shared/data/indoor/duplex.ifc, baked, and the bake's summary."""
    return _baked_ifc(tmp_path_factory, "duplex.ifc")


@pytest.fixture(scope="session")
def fzk_db(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any]]:
    """../shared/data/indoor/AC20-FZK-Haus.ifc, baked, and the bake's summary."""
    return _baked_ifc(tmp_path_factory, "AC20-FZK-Haus.ifc")


# --------------------------------------------------------------------------- crossings
# The crossing scene (a generated city with the generated office at its entrance) is what
# tests/test_crossing.py and tests/test_crosswalk.py both walk: one bake per run for both,
# shared by the xdist workers.  Tests that write (record a path, bake again) work on a copy
# or in their own tmp_path.

@pytest.fixture(scope="session")
def crossing_scene(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any], Path]:
    """The crossing bake ``scene.db``, its summary, and its folder.

    The folder also holds the sources (``city.geojson``: 250 m, seed 1; ``office.json``: 2
    storeys, 16 x 14 m, seed 2) and ``city.db``, the same city baked alone.  All at
    ``BakeSettings(resolution=16)``.  Read only: copy the database before writing to it.
    """

    def build(folder: Path) -> tuple[Path, dict[str, Any], Path]:
        from walkstream.server.bake import BakeSettings, bake
        from walkstream.server.sources.citygen import write_city
        from walkstream.server.sources.interiorgen import InteriorPlan, write_interior

        fast = BakeSettings(resolution=16)
        write_city(folder / "city.geojson", 250, 1)
        # 16 m along the street side: the office enters by its 14 m end wall
        write_interior(folder / "office.json", InteriorPlan(storeys=2, length=16, width=14, seed=2))
        summary = bake(folder / "city.geojson", folder / "scene.db", settings=fast, interior=folder / "office.json")
        bake(folder / "city.geojson", folder / "city.db", settings=fast)
        return folder / "scene.db", summary, folder

    return once_per_run(tmp_path_factory, "crossing", build)
