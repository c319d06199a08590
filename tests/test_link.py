"""The shaped link (walkstream.client.net.link) over an in-process app and over real sockets."""

from __future__ import annotations

import asyncio
import socket
import time
from collections.abc import AsyncIterator, Awaitable, Callable, Iterator
from typing import Any, TypeVar

import httpx
import pytest
from liveserver import serve_in_thread
from starlette.applications import Starlette
from starlette.requests import Request
from starlette.responses import Response, StreamingResponse
from starlette.routing import Route

from walkstream.client.clock import Clock, RealClock, SimClock
from walkstream.client.net.link import LinkProfile, LinkStats, ShapedTransport
from walkstream.shared.errors import InputError

T = TypeVar("T")

K56 = LinkProfile.parse("56kbit", "200ms")
CHUNK_S = 1460 * 8 / 56_000  # one full chunk at 56 kbit/s

# ---------------------------------------------------------------------------
# a tiny server
# ---------------------------------------------------------------------------


def _payload(n: int) -> bytes:
    return bytes(i % 251 for i in range(n))


async def blob(request: Request) -> Response:
    return Response(_payload(int(request.path_params["n"])), media_type="application/octet-stream")


async def upload(request: Request) -> Response:
    return Response(str(len(await request.body())).encode(), media_type="text/plain")


async def trickle(request: Request) -> StreamingResponse:
    data = _payload(int(request.path_params["n"]))

    async def pieces() -> AsyncIterator[bytes]:
        for i in range(0, len(data), 1000):
            yield data[i : i + 1000]

    return StreamingResponse(pieces(), media_type="application/octet-stream")


async def fail(request: Request) -> StreamingResponse:
    async def pieces() -> AsyncIterator[bytes]:
        yield b"x" * 5000
        await asyncio.sleep(0.01)
        raise RuntimeError("the server fell over")

    return StreamingResponse(pieces(), media_type="application/octet-stream")


APP = Starlette(
    routes=[
        Route("/blob/{n:int}", blob),
        Route("/upload", upload, methods=["POST"]),
        Route("/trickle/{n:int}", trickle),
        Route("/fail", fail),
    ]
)


Scenario = Callable[[httpx.AsyncClient, Clock, ShapedTransport], Awaitable[T]]


async def _with_link(
    clock: Clock, inner: httpx.AsyncBaseTransport, profile: LinkProfile, scenario: Scenario[T]
) -> tuple[T, LinkStats]:
    link = ShapedTransport(inner, profile, clock)
    async with httpx.AsyncClient(transport=link, base_url="http://link", timeout=30) as http:
        result = await scenario(http, clock, link)
    return result, link.stats


def simulate(
    profile: LinkProfile, scenario: Scenario[T], inner: httpx.AsyncBaseTransport | None = None
) -> tuple[T, LinkStats]:
    """Run ``scenario`` under a SimClock over the in-process app (or ``inner``)."""
    clock = SimClock()
    return clock.run(_with_link(clock, inner or httpx.ASGITransport(app=APP), profile, scenario))


async def arrivals(http: httpx.AsyncClient, clock: Clock, url: str) -> list[tuple[float, int]]:
    """(virtual time, size) of every chunk of ``url``'s body as it arrives."""
    got = []
    async with http.stream("GET", url) as r:
        assert r.status_code == 200
        async for chunk in r.aiter_raw():
            got.append((clock.now(), len(chunk)))
    return got


def head_bytes(r: httpx.Response) -> int:
    """Bytes of a response head as a server writes it, counted independently."""
    line = f"HTTP/1.1 {r.status_code} {r.reason_phrase}\r\n"
    return len(line) + sum(len(f"{k}: {v}\r\n") for k, v in r.headers.items()) + 2


def request_bytes(request: httpx.Request) -> int:
    """Bytes of a request (line, headers, body) as a client writes it, counted independently."""
    line = f"{request.method} {request.url.raw_path.decode()} HTTP/1.1\r\n"
    headers = sum(len(f"{k}: {v}\r\n") for k, v in request.headers.items())
    return len(line) + headers + 2 + len(request.content)


# ---------------------------------------------------------------------------
# the profile
# ---------------------------------------------------------------------------


def test_profile_from_command_line_strings() -> None:
    p = LinkProfile.parse("7kB/s", "500ms", loss=0.1, seed=3)
    assert (p.down_bps, p.up_bps, p.rtt_s, p.loss, p.seed) == (56_000, 56_000, 0.5, 0.1, 3)
    assert LinkProfile.parse("1Mbit", 0.05, up="64kbit").up_bps == 64_000


@pytest.mark.parametrize(
    ("kwargs", "needle"),
    [
        ({"down_bps": -1.0}, "down_bps"),
        ({"up_bps": float("inf")}, "up_bps"),
        ({"rtt_s": float("nan")}, "rtt_s"),
        ({"loss": 1.5}, "loss"),
        ({"loss": -0.1}, "loss"),
        ({"chunk_bytes": 0}, "chunk_bytes"),
        ({"chunk_bytes": 1.5}, "chunk_bytes"),
        ({"seed": "x"}, "seed"),
        ({"down_bps": "56kbit"}, "down_bps"),
    ],
)
def test_profile_validation(kwargs: dict[str, Any], needle: str) -> None:
    base: dict[str, Any] = {"down_bps": 1.0, "up_bps": 1.0, "rtt_s": 0.1}
    with pytest.raises(InputError, match=needle):
        LinkProfile(**{**base, **kwargs})


# ---------------------------------------------------------------------------
# bandwidth, latency, metering
# ---------------------------------------------------------------------------


def test_a_body_arrives_one_rtt_plus_its_transfer_later_in_chunks() -> None:
    async def scenario(
        http: httpx.AsyncClient, clock: Clock, link: ShapedTransport
    ) -> tuple[list[tuple[float, int]], httpx.Response]:
        got = await arrivals(http, clock, "/blob/7000")
        return got, await http.get("/blob/10")

    (got, small), stats = simulate(K56, scenario)
    # "7000" has two more digits than "10", in the request path and in Content-Length
    first_up = request_bytes(small.request) + 2
    head = head_bytes(small) + 2
    assert stats.bytes_up == 2 * first_up - 2
    assert [n for _, n in got] == [1460, 1460, 1460, 1460, 1160]
    expected = first_up * 8 / 56_000 + 0.2 + (head + 7000) * 8 / 56_000
    assert got[-1][0] == pytest.approx(expected, abs=1e-9)
    # progressive: a prompt reader gets chunks back to back at the link's pace
    gaps = [b[0] - a[0] for a, b in zip(got, got[1:], strict=False)]
    assert gaps[:3] == pytest.approx([CHUNK_S] * 3, abs=1e-9)
    assert gaps[3] == pytest.approx(1160 * 8 / 56_000, abs=1e-9)
    assert stats.requests == 2 and stats.responses_cut == 0
    assert stats.bytes_down == 2 * head_bytes(small) + 2 + 7000 + 10
    times = [t for t, _ in stats.down_log]
    assert times == sorted(times) and stats.down_log[5][1] == head + 7000
    assert small.headers["content-length"] == "10" and small.content == _payload(10)


def test_request_heads_and_bodies_are_metered_up() -> None:
    body = bytes(3000)

    async def scenario(
        http: httpx.AsyncClient, clock: Clock, link: ShapedTransport
    ) -> tuple[str, float, int]:
        r = await http.post("/upload", content=body)
        return r.text, clock.now(), request_bytes(r.request)

    (text, done, up), stats = simulate(K56, scenario)
    assert text == "3000" and stats.bytes_up == up
    down = stats.bytes_down
    assert done == pytest.approx((up + down) * 8 / 56_000 + 0.2, abs=1e-9)


def test_concurrent_downloads_share_the_bandwidth() -> None:
    async def scenario(
        http: httpx.AsyncClient, clock: Clock, link: ShapedTransport
    ) -> list[list[tuple[float, int]]]:
        return list(
            await asyncio.gather(
                arrivals(http, clock, "/blob/14600"), arrivals(http, clock, "/blob/14600")
            )
        )

    (a, b), stats = simulate(K56, scenario)
    alone = 14600 * 8 / 56_000
    for got in (a, b):
        assert sum(n for _, n in got) == 14600
        assert got[-1][0] - got[0][0] >= 1.8 * alone - 2 * CHUNK_S  # each takes about twice
    # the pipe never idles: both bodies are done after all the bytes had their turn
    # (from the first request's last byte up; the second head waits for its request)
    end = max(a[-1][0], b[-1][0])
    lower = stats.bytes_up / 2 * 8 / 56_000 + 0.2 + stats.bytes_down * 8 / 56_000
    assert lower <= end <= lower + 0.02
    assert abs(a[-1][0] - b[-1][0]) <= CHUNK_S + 1e-9  # interleaved chunk by chunk


def test_a_slow_reader_stalls_only_itself() -> None:
    async def slow(http: httpx.AsyncClient, clock: Clock) -> float:
        async with http.stream("GET", "/blob/14600") as r:
            async for _ in r.aiter_raw():
                await clock.sleep(5)  # busy elsewhere: the pipe is free for others
        return clock.now()

    async def scenario(
        http: httpx.AsyncClient, clock: Clock, link: ShapedTransport
    ) -> tuple[float, list[tuple[float, int]]]:
        s, fast = await asyncio.gather(slow(http, clock), arrivals(http, clock, "/blob/14600"))
        return s, fast

    (slow_end, fast), _ = simulate(K56, scenario)
    assert fast[-1][0] - fast[0][0] <= 14600 * 8 / 56_000 * 1.25
    assert slow_end > 50


def test_streamed_responses_are_rechunked_and_delivered_whole() -> None:
    async def scenario(
        http: httpx.AsyncClient, clock: Clock, link: ShapedTransport
    ) -> tuple[bytes, list[tuple[float, int]]]:
        r = await http.get("/trickle/4321")
        return r.content, await arrivals(http, clock, "/trickle/4321")

    (content, got), _ = simulate(K56, scenario)
    assert content == _payload(4321)
    assert [n for _, n in got] == [1460, 1460, 1401]


# ---------------------------------------------------------------------------
# zero bandwidth, loss, early close, failures
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("direction", ["down", "up"])
def test_zero_bandwidth_never_delivers_and_a_client_can_give_up(direction: str) -> None:
    profile = LinkProfile(
        down_bps=0.0 if direction == "down" else 56_000.0,
        up_bps=0.0 if direction == "up" else 56_000.0,
        rtt_s=0.2,
    )

    async def scenario(
        http: httpx.AsyncClient, clock: Clock, link: ShapedTransport
    ) -> tuple[float, bool]:
        fetch = asyncio.create_task(http.get("/blob/100"))
        await clock.sleep(60)  # the client's own patience
        gave_up = not fetch.done()
        fetch.cancel()
        await asyncio.gather(fetch, return_exceptions=True)
        return clock.now(), gave_up

    (now, gave_up), stats = simulate(profile, scenario)
    assert now == 60.0 and gave_up and stats.bytes_down == 0
    assert (stats.bytes_up > 0) == (direction == "down")


async def _outcomes(http: httpx.AsyncClient, clock: Clock, n: int) -> list[int | None]:
    """Per request: None when the body came whole, else the bytes received before the cut."""
    out: list[int | None] = []
    for _ in range(n):
        received = 0
        try:
            async with http.stream("GET", "/blob/3000") as r:
                async for chunk in r.aiter_raw():
                    received += len(chunk)
        except httpx.RemoteProtocolError as exc:
            assert f"cut off after {received} of 3000 bytes" in str(exc)
            out.append(received)
        else:
            assert received == 3000
            out.append(None)
    return out


def test_loss_cuts_bodies_deterministically() -> None:
    def run(loss: float, seed: int) -> tuple[list[int | None], LinkStats]:
        profile = LinkProfile(56_000.0, 56_000.0, 0.2, loss=loss, seed=seed)

        async def scenario(
            http: httpx.AsyncClient, clock: Clock, link: ShapedTransport
        ) -> list[int | None]:
            return await _outcomes(http, clock, 30)

        return simulate(profile, scenario)

    all_cut, stats = run(1.0, 0)
    assert None not in all_cut and stats.responses_cut == 30
    assert all(0 <= n < 3000 for n in all_cut if n is not None) and len(set(all_cut)) > 10

    half, stats = run(0.5, 7)
    cut = sum(n is not None for n in half)
    assert 5 <= cut <= 25 and stats.responses_cut == cut
    assert run(0.5, 7)[0] == half  # same seed, same cuts
    assert run(0.5, 8)[0] != half
    assert run(0.0, 7)[0] == [None] * 30


def test_lost_body_raises_through_aread() -> None:
    profile = LinkProfile(56_000.0, 56_000.0, 0.2, loss=1.0, seed=1)

    async def scenario(http: httpx.AsyncClient, clock: Clock, link: ShapedTransport) -> None:
        with pytest.raises(httpx.RemoteProtocolError, match="link: response cut off"):
            await http.get("/blob/5000")
        assert link.stats.bytes_down < head_bytes(await _plain_get()) + 5000

    async def _plain_get() -> httpx.Response:
        async with httpx.AsyncClient(
            transport=httpx.ASGITransport(app=APP), base_url="http://x"
        ) as h:
            return await h.get("/blob/5000")

    simulate(profile, scenario)


class _Recording(httpx.AsyncBaseTransport):
    """Wraps a transport and records which response streams were closed."""

    def __init__(self, inner: httpx.AsyncBaseTransport) -> None:
        self.inner = inner
        self.closed: list[str] = []

    async def handle_async_request(self, request: httpx.Request) -> httpx.Response:
        r = await self.inner.handle_async_request(request)
        assert isinstance(r.stream, httpx.AsyncByteStream)
        return httpx.Response(
            r.status_code,
            headers=r.headers,
            stream=_Closing(r.stream, request.url.path, self.closed),
        )


class _Closing(httpx.AsyncByteStream):
    def __init__(self, inner: httpx.AsyncByteStream, name: str, closed: list[str]) -> None:
        self.inner, self.name, self.closed = inner, name, closed

    async def __aiter__(self) -> AsyncIterator[bytes]:
        async for part in self.inner:
            yield part

    async def aclose(self) -> None:
        self.closed.append(self.name)
        await self.inner.aclose()


def test_closing_early_frees_the_pipe_and_closes_the_inner_stream() -> None:
    def run(stop_after: int | None) -> tuple[float, list[str]]:
        async def partial(http: httpx.AsyncClient) -> None:
            async with http.stream("GET", "/blob/29200") as r:
                seen = 0
                async for _ in r.aiter_raw():
                    seen += 1
                    if seen == stop_after:
                        break

        async def scenario(http: httpx.AsyncClient, clock: Clock, link: ShapedTransport) -> float:
            _, other = await asyncio.gather(partial(http), arrivals(http, clock, "/blob/14600"))
            return other[-1][0]

        recording = _Recording(httpx.ASGITransport(app=APP))
        end, _ = simulate(K56, scenario, recording)
        return end, recording.closed

    shared, closed = run(None)
    freed, closed_early = run(2)
    assert sorted(closed) == sorted(closed_early) == ["/blob/14600", "/blob/29200"]
    # while both read, the other download gets half the link; once the first is
    # closed it gets all of it, and finishes about 8 chunk times sooner
    assert freed < shared - 5 * CHUNK_S


def test_cancelling_a_reader_frees_its_reserved_chunk() -> None:
    async def scenario(
        http: httpx.AsyncClient, clock: Clock, link: ShapedTransport
    ) -> tuple[float, list[tuple[float, int]]]:
        victim = asyncio.create_task(arrivals(http, clock, "/blob/29200"))
        other = asyncio.create_task(arrivals(http, clock, "/blob/29200"))
        await clock.sleep(1.0)
        victim.cancel()
        cancelled_at = clock.now()
        await asyncio.gather(victim, return_exceptions=True)
        return cancelled_at, await other

    (cancelled_at, got), _ = simulate(K56, scenario)
    after = [t for t, _ in got if t > cancelled_at + 2 * CHUNK_S]
    gaps = [b - a for a, b in zip(after, after[1:], strict=False)]
    assert len(gaps) > 5 and gaps[:-1] == pytest.approx([CHUNK_S] * (len(gaps) - 1), abs=1e-9)


def test_cancelling_gives_back_the_unsent_part_of_a_reserved_chunk() -> None:
    # one chunk of 14600 bytes takes ~2.1 s: cancelled at 1 s, the next response
    # must not wait for the rest of it
    profile = LinkProfile(56_000.0, 56_000.0, 0.2, chunk_bytes=14600)

    async def scenario(
        http: httpx.AsyncClient, clock: Clock, link: ShapedTransport
    ) -> tuple[float, int, float, int, int]:
        victim = asyncio.create_task(arrivals(http, clock, "/blob/29200"))
        await clock.sleep(1.0)
        victim.cancel()
        await asyncio.gather(victim, return_exceptions=True)
        up, down = link.stats.bytes_up, link.stats.bytes_down
        r = await http.get("/blob/10")
        return (
            clock.now(),
            link.stats.bytes_up - up,
            1.0,
            link.stats.bytes_down - down,
            len(r.content),
        )

    (done, up, start, down, size), stats = simulate(profile, scenario)
    assert size == 10 and stats.bytes_down < 29200
    assert done == pytest.approx(start + 0.2 + (up + down) * 8 / 56_000, abs=1e-9)


class _Failing(httpx.AsyncBaseTransport):
    """A server that sends a head and ``good`` bytes, then loses the connection."""

    def __init__(self, good: int, connect: bool = True) -> None:
        self.good, self.connect = good, connect

    async def handle_async_request(self, request: httpx.Request) -> httpx.Response:
        if not self.connect:
            raise httpx.ConnectError("connection refused", request=request)
        return httpx.Response(200, headers={"content-length": "99999"}, stream=_Dying(self.good))


class _Dying(httpx.AsyncByteStream):
    def __init__(self, good: int) -> None:
        self.good = good

    async def __aiter__(self) -> AsyncIterator[bytes]:
        yield bytes(self.good // 2)
        yield bytes(self.good - self.good // 2)
        raise httpx.ReadError("connection reset by peer")


def test_inner_failures_propagate_after_the_bytes_already_delivered() -> None:
    async def scenario(
        http: httpx.AsyncClient, clock: Clock, link: ShapedTransport
    ) -> tuple[list[tuple[float, int]], float]:
        got: list[tuple[float, int]] = []
        with pytest.raises(httpx.ReadError, match="reset"):
            async with http.stream("GET", "/any") as r:
                assert r.headers["content-length"] == "99999"
                async for chunk in r.aiter_raw():
                    got.append((clock.now(), len(chunk)))
        return got, clock.now()

    (got, failed_at), stats = simulate(K56, scenario, _Failing(4000))
    assert [n for _, n in got] == [1460, 1460, 1080] and failed_at == got[-1][0]

    async def refused(http: httpx.AsyncClient, clock: Clock, link: ShapedTransport) -> float:
        with pytest.raises(httpx.ConnectError):
            await http.get("/any")
        return clock.now()

    at, stats = simulate(K56, refused, _Failing(0, connect=False))
    assert at == pytest.approx(stats.bytes_up * 8 / 56_000 + 0.1) and stats.bytes_down == 0


def test_app_exceptions_of_the_in_process_server_propagate() -> None:
    async def scenario(http: httpx.AsyncClient, clock: Clock, link: ShapedTransport) -> None:
        with pytest.raises(RuntimeError, match="fell over"):
            await http.get("/fail")

    simulate(K56, scenario)


# ---------------------------------------------------------------------------
# real time and real sockets
# ---------------------------------------------------------------------------


def test_real_clock_takes_about_the_expected_time() -> None:
    profile = LinkProfile.parse("2Mbit", "50ms")

    async def scenario(
        http: httpx.AsyncClient, clock: Clock, link: ShapedTransport
    ) -> tuple[float, int]:
        t0 = time.monotonic()
        r = await http.get("/blob/20000")
        return time.monotonic() - t0, len(r.content)

    (elapsed, size), stats = asyncio.run(
        _with_link(RealClock(), httpx.ASGITransport(app=APP), profile, scenario)
    )
    expected = 0.05 + (stats.bytes_up + stats.bytes_down) * 8 / 2e6
    assert size == 20000 and elapsed >= 0.8 * expected


@pytest.fixture(scope="module")
def live_url() -> Iterator[str]:
    """uvicorn serving APP on a free loopback port in a thread (no date/server headers)."""
    with serve_in_thread(
        APP, log_level="critical", server_header=False, date_header=False
    ) as url:
        yield url


async def _mixed(
    http: httpx.AsyncClient, clock: Clock, link: ShapedTransport
) -> list[list[tuple[float, int]]]:
    """One download alone, then two at once, then a streamed one."""
    first = await arrivals(http, clock, "/blob/7000")
    pair = await asyncio.gather(
        arrivals(http, clock, "/blob/5000"), arrivals(http, clock, "/blob/9000")
    )
    post = await http.post("/upload", content=bytes(2000))
    assert post.text == "2000"
    return [first, *pair]


def test_real_sockets_give_the_same_virtual_times_as_in_process(live_url: str) -> None:
    in_process, local_stats = simulate(K56, _mixed)
    clock = SimClock()
    over_sockets, socket_stats = clock.run(
        _with_link(
            clock,
            httpx.AsyncHTTPTransport(),
            K56,
            lambda http, clock, link: _mixed(_rebase(http, live_url), clock, link),
        )
    )
    assert [[n for _, n in g] for g in over_sockets] == [[n for _, n in g] for g in in_process]
    for a, b in zip(over_sockets, in_process, strict=True):
        assert [t for t, _ in a] == pytest.approx([t for t, _ in b], rel=0.01)
    assert socket_stats.bytes_down == pytest.approx(local_stats.bytes_down, rel=0.01)


def _rebase(http: httpx.AsyncClient, url: str) -> httpx.AsyncClient:
    http.base_url = httpx.URL(url)
    return http


def test_real_socket_failures_propagate(live_url: str) -> None:
    async def scenario(http: httpx.AsyncClient, clock: Clock, link: ShapedTransport) -> int:
        http.base_url = httpx.URL(live_url)
        received = 0
        with pytest.raises(httpx.RemoteProtocolError):
            async with http.stream("GET", "/fail") as r:
                async for chunk in r.aiter_raw():
                    received += len(chunk)
        return received

    clock = SimClock()
    received, stats = clock.run(_with_link(clock, httpx.AsyncHTTPTransport(), K56, scenario))
    assert received == 5000 and stats.bytes_down > 5000

    # nothing listens on a port we hold but never listen on
    with socket.socket() as unused:
        unused.bind(("127.0.0.1", 0))
        url = f"http://127.0.0.1:{unused.getsockname()[1]}"

        async def refused(http: httpx.AsyncClient, clock: Clock, link: ShapedTransport) -> None:
            http.base_url = httpx.URL(url)
            with pytest.raises(httpx.ConnectError):
                await http.get("/blob/1")

        clock = SimClock()
        clock.run(_with_link(clock, httpx.AsyncHTTPTransport(), K56, refused))
