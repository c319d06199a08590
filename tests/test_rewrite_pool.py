"""The rewrite pool rebuilds several objects per call, in priority order, on both clocks."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest

from walkstream.client.clock import RealClock, SimClock
from walkstream.client.rewrite.geometry import ObjectGeometry, rebuild, rebuild_batch
from walkstream.client.rewrite.pool import RewritePool
from walkstream.server.sources.citygen import generate_city
from walkstream.server.sources.geojson import load_geojson_dict
from walkstream.shared.buildings import default_grammar
from walkstream.shared.errors import InputError
from walkstream.shared.records import BuildingParams, StreetParams


@pytest.fixture(scope="module")
def objects() -> list[BuildingParams | StreetParams]:
    scene = load_geojson_dict(generate_city(200, 1), name="city")
    return [*scene.buildings[:14], *scene.streets[:3]]


def test_rebuild_batch_equals_rebuild_per_object(objects: list[BuildingParams | StreetParams]) -> None:
    g = default_grammar()
    jobs = [(1000 + k, p) for k, p in enumerate(objects)]
    many = rebuild_batch(jobs, g)
    assert [x.id for x in many] == [oid for oid, _ in jobs]
    for (oid, p), got in zip(jobs, many, strict=True):
        want = rebuild(oid, p, g)
        assert (got.triangles == want.triangles).all() and (got.available == want.available).all()
        assert (got.bbox_min == want.bbox_min).all() and (got.bbox_max == want.bbox_max).all()
        assert got.nbytes == want.nbytes
        for a, b in zip(want.meshes, got.meshes, strict=True):
            assert a is not None and b is not None
            assert (a.indices == b.indices).all() and (a.positions == b.positions).all()
    assert all(x.cpu_s > 0 for x in many)
    assert len({x.cpu_s for x in many}) == 1  # an equal share each


def _run_pool(
    clock: SimClock | RealClock,
    objects: list[BuildingParams | StreetParams],
    priorities: list[tuple[float, float]],
    *,
    workers: int,
    batch: int,
    bump: tuple[int, tuple[float, float]] | None = None,
) -> tuple[list[int], RewritePool]:
    built: list[int] = []

    def on_built(g: ObjectGeometry) -> None:
        built.append(g.id)

    pool = RewritePool(clock, None, on_built, workers=workers, batch=batch)

    async def main() -> None:
        pool.start()
        for k, (p, prio) in enumerate(zip(objects, priorities, strict=True)):
            pool.submit(k, p, prio)
        if bump is not None:
            pool.bump(*bump)
        pool.set_grammar(default_grammar())  # every job is queued before any starts
        while len(built) < len(objects):
            await clock.sleep(0.01)
        await pool.close()

    if isinstance(clock, SimClock):
        clock.run(main())
    else:
        asyncio.run(main())
    return built, pool


def test_batches_keep_the_priority_order(objects: list[BuildingParams | StreetParams]) -> None:
    rng = np.random.default_rng(3)
    # the current cell's objects (0 s, by ACH), then later cells by the time they are needed
    prios = [(0.0, -float(a)) for a in rng.random(6)] + [(float(t), -0.1) for t in rng.random(len(objects) - 6) * 9]
    built, pool = _run_pool(SimClock(), objects, prios, workers=1, batch=4)
    assert built == sorted(range(len(objects)), key=lambda k: prios[k])
    assert pool.built == len(objects) and pool.batches == -(-len(objects) // 4)
    assert pool.cpu_s > 0


def test_a_bumped_job_joins_the_first_batch(objects: list[BuildingParams | StreetParams]) -> None:
    prios = [(float(k + 1), 0.0) for k in range(len(objects))]
    last = len(objects) - 1
    built, _ = _run_pool(SimClock(), objects, prios, workers=1, batch=3, bump=(last, (0.0, -1.0)))
    assert built[0] == last
    assert built[1:] == list(range(last))


def test_idle_workers_share_what_waits(objects: list[BuildingParams | StreetParams]) -> None:
    n = 8
    prios = [(float(k), 0.0) for k in range(n)]
    built, pool = _run_pool(SimClock(), objects[:n], prios, workers=2, batch=32)
    # two workers, eight jobs: one batch of four each (not one worker with all eight)
    assert pool.batches == 2 and sorted(built) == list(range(n))


def test_real_clock_rebuilds_in_threads(objects: list[BuildingParams | StreetParams]) -> None:
    prios = [(float(k), 0.0) for k in range(len(objects))]
    built, pool = _run_pool(RealClock(), objects, prios, workers=2, batch=5)
    assert sorted(built) == list(range(len(objects))) and pool.batches >= 4


def test_bad_batch_size() -> None:
    with pytest.raises(InputError, match="batch must be >= 1"):
        RewritePool(SimClock(), None, lambda g: None, batch=0)
