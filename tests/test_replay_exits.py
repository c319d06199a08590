"""Replay exits that tell the truth (issue 25): a scene that never arrived or a server
unreachable for too much of the walk is exit 3 with one line; outages lived through are
named in the printed summary."""

from __future__ import annotations

import argparse
import asyncio
from pathlib import Path

import httpx
import pytest

from walkstream.cli import main
from walkstream.client.clock import SimClock
from walkstream.client.net.api import SceneClient
from walkstream.client.net.transferstats import TransferStats
from walkstream.cmd_replay import MAX_OUTAGE_SHARE, REPLAY_FAILED, outage_line, replay_failure
from walkstream.server.service.process import free_port


def test_outages_are_timed_on_the_walks_clock() -> None:
    s = TransferStats()
    s.reached(1.0)
    s.failed(2.0)
    s.failed(3.0)  # the same outage
    s.reached(5.5)
    s.failed(10.0)
    figures = s.outage_figures(12.0)  # still down at the end
    assert figures == {"outages": 2, "outage_s": 5.5, "longest_outage_s": 3.5, "down_at_end": True}


def test_a_refused_server_is_an_outage_for_the_client() -> None:
    clock = SimClock()
    calls = {"n": 0}

    def handler(request: httpx.Request) -> httpx.Response:
        calls["n"] += 1
        if calls["n"] <= 3:
            raise httpx.ConnectError("refused", request=request)
        return httpx.Response(200, json=["city"])

    async def go() -> TransferStats:
        async with httpx.AsyncClient(transport=httpx.MockTransport(handler), base_url="http://x") as http:
            api = SceneClient(http, clock)
            await clock.drive(api._get("/v1/scenes", "scenes"))
            return api.stats

    stats = asyncio.run(go())
    figures = stats.outage_figures(clock.now())
    assert stats.retries == 3 and figures["outages"] == 1 and figures["outage_s"] > 0.5
    assert not figures["down_at_end"]


def test_the_exit_decision_reads_the_summary() -> None:
    walk = {"duration_s": 100.0, "retries": 7}
    assert replay_failure(walk | {"outages": 1, "outage_s": 5.0}) is None
    why = replay_failure(walk | {"outages": 1, "outage_s": 100 * MAX_OUTAGE_SHARE + 1, "down_at_end": True})
    assert why is not None and "unreachable for 21.0 s of the 100.0 s walk" in why and "7 retries" in why
    assert replay_failure({"error": "the scene ... did not arrive within 60 s"}) is not None
    assert outage_line(walk) is None
    line = outage_line(walk | {"outages": 2, "outage_s": 3.25, "longest_outage_s": 2.0})
    assert line == "server unreachable 2 times, 3.2 s in all (longest 2.0 s), 7 retries"


def test_a_replay_against_a_closed_port_exits_3_with_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    url = f"http://127.0.0.1:{free_port()}"
    rc = main(["replay", url, "--path", "SE", "--device", "desktop2003", "--report", str(tmp_path / "r")])
    err = [ln for ln in capsys.readouterr().err.replace("\r", "\n").splitlines() if ln.startswith("walkstream:")]
    assert rc == REPLAY_FAILED
    assert len(err) == 1 and err[0].startswith("walkstream: error:") and "did not arrive" in err[0]


class _GoneAfter(httpx.AsyncBaseTransport):
    """The app in-process until ``n`` requests have been answered, then no server at all."""

    def __init__(self, inner: httpx.AsyncBaseTransport, n: int) -> None:
        self.inner, self.left = inner, n

    async def handle_async_request(self, request: httpx.Request) -> httpx.Response:
        if self.left <= 0:
            raise httpx.ConnectError("connection refused", request=request)
        self.left -= 1
        return await self.inner.handle_async_request(request)


def test_a_server_gone_mid_walk_fails_the_replay(tmp_path: Path) -> None:
    from scenes import add_default_paths, build_city_db

    from walkstream.client.replay import run_replay
    from walkstream.cmd_replay import add_replay_arguments, config_from_args
    from walkstream.server.service.main import create_app

    db = tmp_path / "city.db"
    build_city_db(db, name="city", size=300.0, k=30)
    add_default_paths(db)
    parser = argparse.ArgumentParser()
    add_replay_arguments(parser)
    ns = parser.parse_args(["--device", "desktop2003", "--duration", "40s"])
    ns.report = str(tmp_path / "report")
    app = create_app([db])
    try:
        result = run_replay(_GoneAfter(httpx.ASGITransport(app=app), 3), "http://x", config_from_args(ns))
    finally:
        app.state.scenes.close()
    s = result.summary
    assert s["frames"] > 0 and s["outages"] == 1 and s["down_at_end"] and s["retries"] > 0
    why = replay_failure(s)
    assert why is not None and "unreachable for" in why
    assert outage_line(s) is not None and "still unreachable at the end" in str(outage_line(s))


def test_a_manifest_that_does_not_decode_ends_the_replay_with_one_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # a client whose decoder refuses the server's manifest (here: a grammar bound below
    # the grammar's length, as when the grammar outgrew it) used to drop the manifest
    # silently and walk on rebuilding no building at all
    from scenes import add_default_paths, build_city_db

    from walkstream.client.replay import run_replay
    from walkstream.cmd_replay import add_replay_arguments, config_from_args
    from walkstream.server.service.main import create_app
    from walkstream.shared import wire
    from walkstream.shared.errors import ApiError

    db = tmp_path / "city.db"
    build_city_db(db, name="city", size=200.0, k=20)
    add_default_paths(db)
    parser = argparse.ArgumentParser()
    add_replay_arguments(parser)
    app = create_app([db])
    monkeypatch.setattr(wire, "MAX_GRAMMAR_TEXT", 64)
    try:
        for flags in ([], ["--no-start-bundle"]):  # the manifest in the start bundle, and on its own
            ns = parser.parse_args(["--device", "desktop2003", "--duration", "20s", *flags])
            ns.report = str(tmp_path / f"report{len(flags)}")
            with pytest.raises(ApiError) as got:
                run_replay(httpx.ASGITransport(app=app), "http://x", config_from_args(ns))
            line = str(got.value)
            assert "scene 'city' manifest: undecodable answer" in line and "max_str_len" in line and "\n" not in line
    finally:
        app.state.scenes.close()
