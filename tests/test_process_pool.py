"""Rebuilding in worker processes: same meshes as inline, bounded shared memory with a
pipe fallback, nothing left in /dev/shm, cancellation, clean shutdown."""

from __future__ import annotations

import asyncio
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from walkstream.client.clock import RealClock
from walkstream.client.rewrite.geometry import ObjectGeometry, rebuild_batch
from walkstream.client.rewrite.pool import RewriteOptions, RewritePool
from walkstream.client.rewrite.shm import SHM_PREFIX, ShmArena, pack_layout, unpack, write_packed
from walkstream.server.sources.citygen import generate_city
from walkstream.server.sources.geojson import load_geojson_dict
from walkstream.shared.buildings import default_grammar
from walkstream.shared.errors import InputError
from walkstream.shared.records import BuildingParams, StreetParams

SHM = Path("/dev/shm")


def _segments(pid: int | None = None) -> set[str]:
    # the segments a client process made (this one by default): only our own, since other
    # pytest-xdist workers and other programs create and remove segments meanwhile
    prefix = f"{SHM_PREFIX}{os.getpid() if pid is None else pid}_"
    return {p.name for p in SHM.glob(f"{prefix}*")} if SHM.is_dir() else set()


def _stat(pid: int) -> list[str]:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return ["Z", "0"]


def _state(pid: int) -> str:
    return _stat(pid)[0]


def _cmdline(pid: int) -> bytes:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return b""


def _children(parent: int | None = None) -> set[int]:
    # a process's live children (zombies do not count; nor does multiprocessing's resource
    # tracker, which lives as long as the process)
    me = os.getpid() if parent is None else parent
    out = set()
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            st = _stat(int(d.name))
            if int(st[1]) == me and st[0] != "Z" and b"resource_tracker" not in _cmdline(int(d.name)):
                out.add(int(d.name))
    return out


@pytest.fixture(scope="module")
def objects() -> list[BuildingParams | StreetParams]:
    scene = load_geojson_dict(generate_city(200, 1), name="city")
    return [*scene.buildings[:12], *scene.streets[:2]]


def _same(a: ObjectGeometry, b: ObjectGeometry) -> None:
    assert a.id == b.id and a.nbytes == b.nbytes
    assert (a.triangles == b.triangles).all() and (a.available == b.available).all()
    assert np.array_equal(a.bbox_min, b.bbox_min) and np.array_equal(a.bbox_max, b.bbox_max)
    for x, y in zip(a.meshes, b.meshes, strict=True):
        assert (x is None) == (y is None)
        if x is not None and y is not None:
            for f in ("positions", "normals", "indices", "materials"):
                assert np.array_equal(getattr(x, f), getattr(y, f)), f


def _replay_pool(
    objects: list[BuildingParams | StreetParams],
    shm_bytes: int,
    workers: int = 2,
    prune_after: int | None = None,
    wait_ready: bool = True,
) -> tuple[dict[int, ObjectGeometry], RewritePool]:
    built: dict[int, ObjectGeometry] = {}
    pool = RewritePool(
        RealClock(), None, lambda g: built.__setitem__(g.id, g), workers=workers, batch=4,
        options=RewriteOptions("process", shm_bytes),
    )

    async def main() -> None:
        pool.start()
        try:
            if wait_ready:  # (else the first batches run in threads while the workers start)
                await pool._procs.wait_ready()
            for k, p in enumerate(objects):
                pool.submit(k, p, (float(k), 0.0))
            if prune_after is not None:
                # the walker turned away: only the first objects' cell is still needed
                pool.prune([np.arange(prune_after)])
            pool.set_grammar(default_grammar())
            want = len(objects) if prune_after is None else prune_after
            for _ in range(3000):
                if len(built) >= want and not pool.pending and not pool._running:
                    break
                await asyncio.sleep(0.01)
        finally:
            await pool.close()

    asyncio.run(main())
    return built, pool


def test_packing_round_trip(objects: list[BuildingParams | StreetParams]) -> None:
    geoms = rebuild_batch([(k, p) for k, p in enumerate(objects)], default_grammar())
    layout, meshes = pack_layout(geoms)
    buf = np.zeros(layout[2], np.uint8)
    write_packed(buf, layout, meshes)
    back = unpack(buf, layout)
    for a, b in zip(geoms, back, strict=True):
        _same(a, b)
    street = back[-1]
    assert street.meshes[0] is street.meshes[2]  # a street's one mesh is packed once


def test_process_meshes_equal_inline_and_shm_is_bounded(
    objects: list[BuildingParams | StreetParams],
) -> None:
    before_segments, before_children = _segments(), _children()
    built, pool = _replay_pool(objects, shm_bytes=4 << 20)
    inline = rebuild_batch([(k, p) for k, p in enumerate(objects)], default_grammar())
    assert sorted(built) == list(range(len(objects)))
    for want in inline:
        _same(built[want.id], want)
    d = pool.describe()
    assert d["mode"] == "process" and d["shm_batches"] >= 1 and d["thread_batches"] == 0
    assert 0 < d["shm_peak_bytes"] <= 4 << 20
    assert d["workers_ready_s"] is not None and d["workers_ready_s"] > 0
    # the meshes are views of the shared segment (no copy on the client's side)
    mesh = built[0].meshes[2]
    assert mesh is not None and not mesh.positions.flags.owndata
    # nothing left in /dev/shm; no worker process outlives the pool
    assert _segments() <= before_segments
    assert _children() <= before_children


def test_tiny_or_zero_bound_falls_back_to_the_pipe(objects: list[BuildingParams | StreetParams]) -> None:
    before = _segments()
    for bound in (0, 4096):
        built, pool = _replay_pool(objects[:6], shm_bytes=bound, workers=1)
        assert sorted(built) == list(range(6))
        d = pool.describe()
        assert d["pipe_batches"] >= 1 and d["shm_batches"] == 0, d
        assert d["thread_batches"] == 0
        if bound == 0:
            assert d["shm_error"] == "bound 0"
    inline = rebuild_batch([(k, p) for k, p in enumerate(objects[:6])], default_grammar())
    for want in inline:
        _same(built[want.id], want)
    assert _segments() <= before


def test_a_full_arena_waits_for_views_to_go() -> None:
    arena = ShmArena(1 << 16)
    try:
        # the segment is named after this process, so tests can tell their own apart
        assert arena.name is not None and _segments() == {arena.name}
        arena.unlink()
        assert arena.name is None and not _segments()
        off, size = arena.reserve(1 << 16)
        assert size == 1 << 16 and arena.reserve(64) == (0, 0)  # full: the pipe is used
        base = arena.view(off, size, 1000)
        assert arena.held == 1024  # the unused tail went back at once
        view = base[10:20]
        del base
        assert arena.held == 1024  # a view still holds the region
        del view
        assert arena.held == 0
    finally:
        arena.close()


def test_batches_run_in_threads_while_the_workers_start(
    objects: list[BuildingParams | StreetParams],
) -> None:
    before_children = _children()
    built, pool = _replay_pool(objects, shm_bytes=1 << 20, wait_ready=False)
    assert sorted(built) == list(range(len(objects)))
    d = pool.describe()
    assert d["thread_batches"] >= 1  # (all of them, here: the workers were still starting)
    assert _children() <= before_children


def test_prune_drops_jobs_no_longer_needed(objects: list[BuildingParams | StreetParams]) -> None:
    built, pool = _replay_pool(objects, shm_bytes=1 << 20, workers=1, prune_after=5)
    assert sorted(built) == list(range(5))  # the others were dropped, not rebuilt
    assert pool.dropped == len(objects) - 5 and pool.built == 5


def test_a_worker_that_dies_leaves_its_lane_to_a_thread(
    objects: list[BuildingParams | StreetParams],
) -> None:
    built: dict[int, ObjectGeometry] = {}
    pool = RewritePool(
        RealClock(), None, lambda g: built.__setitem__(g.id, g), workers=1, batch=4,
        options=RewriteOptions("process", 1 << 20),
    )

    async def main() -> None:
        pool.start()
        try:
            await pool._procs._ready[0]
            pool._procs._procs[0].kill()
            pool._procs._procs[0].join()
            for k, p in enumerate(objects[:6]):
                pool.submit(k, p, (float(k), 0.0))
            pool.set_grammar(default_grammar())
            for _ in range(3000):
                if len(built) == 6:
                    break
                await asyncio.sleep(0.01)
        finally:
            await pool.close()

    asyncio.run(main())
    assert sorted(built) == list(range(6))
    assert pool.describe()["thread_batches"] >= 1


def test_bad_options() -> None:
    with pytest.raises(InputError, match="--rewrite 'fork': choose one of auto, process, thread"):
        RewriteOptions("fork")
    with pytest.raises(InputError, match="--shm -1"):
        RewriteOptions("process", -1)


def test_auto_picks_processes_only_with_cores_to_spare() -> None:
    from walkstream.client.rewrite.pool import auto_mode

    cores = len(os.sched_getaffinity(0))
    assert auto_mode(cores - 2) == "process" if cores >= 3 else auto_mode(1) == "thread"
    assert auto_mode(cores - 1) == "thread"


@pytest.fixture(scope="module")
def db(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from scenes import add_default_paths, build_city_db

    path = tmp_path_factory.mktemp("procpool") / "city.db"
    build_city_db(path, name="city", size=300.0, k=30)
    add_default_paths(path)
    return path


@pytest.mark.solo
@pytest.mark.gl
def test_real_clock_replay_with_the_process_pool_from_the_cli(
    db: Path, tmp_path: Path, gl: object, capsys: pytest.CaptureFixture[str]
) -> None:
    from walkstream.cli import main

    before_segments, before_children = _segments(), _children()
    report = tmp_path / "gl"
    argv = [
        "replay", str(db), "--path", "SE", "--clock", "real", "--device", "gl", "--size", "96x64",
        "--fps", "30", "--duration", "8s", "--bandwidth", "10mbit", "--rtt", "20ms",
        "--rewrite", "process", "--shm", "1MB", "--report", str(report), "--no-plots",
    ]  # fmt: skip
    assert main(argv) == 0
    summary = json.loads((report / "report.json").read_text())
    rw = summary["rewrite"]
    # (batches due before the workers have started run in threads)
    assert rw["mode"] == "process" and rw["shm_batches"] + rw["pipe_batches"] >= 1
    assert rw["shm_batches"] + rw["pipe_batches"] + rw["thread_batches"] == rw["batches"]
    assert rw["shm_peak_bytes"] <= rw["shm_bytes"] == 1_000_000 // 64 * 64
    assert summary["rebuilds"] >= 0 and summary["rewrite_quality_mean"] > 0
    assert "rebuilds ran in process" in capsys.readouterr().out
    assert _segments() <= before_segments and _children() <= before_children


def test_bad_rewrite_arguments_are_one_line(
    db: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from walkstream.cli import main

    for extra, message in ((["--rewrite", "fork"], "--rewrite 'fork'"), (["--shm", "lots"], "lots")):
        argv = ["replay", str(db), "--device", "desktop2003", "--report", str(tmp_path / "r"), *extra]
        assert main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("walkstream: error:") and message in err and len(err.splitlines()) == 1


def test_bad_bench_rewrite_is_one_line(
    db: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from walkstream.cli import main

    argv = ["bench", "budget", str(db), "--no-gl", "--rewrite", "thread,fork", "--out", str(tmp_path)]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err == "walkstream: error: --rewrite 'fork': choose from process, thread"


# solo: run beside another xdist worker on 2 cores, the replay has been seen to miss the
# Ctrl-C sent one second into its rebuilding (it walked on and exited 0); alone it never
# has. The lost interrupt under load is an open bug (CHANGELOG), not a property of this test
@pytest.mark.solo
def test_ctrl_c_leaves_no_worker_process_or_segment(db: Path, tmp_path: Path) -> None:
    argv = [
        sys.executable, "-m", "walkstream.cli", "replay", str(db), "--path", "SE",
        "--clock", "real", "--device", "desktop2003", "--duration", "60s",
        "--rewrite", "process", "--report", str(tmp_path / "r"),
    ]  # fmt: skip
    # a shell gives the replay Ctrl-C's default disposition; a child inherits an ignored
    # SIGINT (Python then never installs its handler), and the test runner may ignore it
    proc = subprocess.Popen(
        argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )  # fmt: skip
    workers: set[int] = set()
    try:
        deadline = time.monotonic() + 60
        while len(workers) < 2 and time.monotonic() < deadline and proc.poll() is None:
            workers = {p for p in _children(proc.pid) if b"spawn_main" in _cmdline(p)}
            time.sleep(0.1)
        assert len(workers) == 2, "the replay did not start its two rewrite workers"
        time.sleep(1.0)  # rebuilding is under way
        proc.send_signal(signal.SIGINT)
        # generous: the assertion is what is left behind, not how fast (a loaded 2-core CI
        # machine has taken over 30 s to wind the pool down)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()  # drains and closes the pipes, so no unclosed file reaches a later test
    assert proc.returncode == 130 and b"interrupted" in err, err.decode()[-1500:]
    assert b"Traceback" not in err, err.decode()[-2000:]
    time.sleep(0.2)
    assert not [p for p in workers if Path(f"/proc/{p}").exists() and _state(p) != "Z"]
    assert not _segments(proc.pid)  # the replay's segment went with it
