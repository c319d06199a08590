"""A shaped network link as an httpx transport: bandwidth, latency and loss.

:class:`ShapedTransport` wraps any :class:`httpx.AsyncBaseTransport` (the in-process
:class:`httpx.ASGITransport` or a real :class:`httpx.AsyncHTTPTransport`) and makes
every request cross a slow link described by a :class:`LinkProfile`:

- **Bandwidth.**  Each direction is one serialising pipe shared by all concurrent
  requests: ``n`` bytes occupy it for ``n * 8 / bps`` seconds from the moment it is
  free.  Bodies cross in chunks of ``chunk_bytes``; a chunk reserves its slot when the
  reader asks for it, so concurrent transfers interleave chunk by chunk and a slow
  reader stalls only itself (as TCP flow control would).  ``bps == 0`` means nothing
  ever arrives.
- **Metering.**  Request line, headers (``Name: value\\r\\n`` each, then CRLF) and body
  go up; status line, headers and body come down.  Everything is counted in
  :class:`LinkStats`.
- **Latency.**  A byte is usable ``rtt_s / 2`` after it left the pipe: the response
  head arrives one round trip (plus its transfer) after the request's last byte left,
  and each body chunk ``rtt_s / 2`` after its last byte left.
- **Loss.**  With probability ``loss`` per response (drawn from
  ``random.Random(seed)`` in the order the responses come back) the body is cut off at
  a uniformly random byte and the stream raises :class:`httpx.RemoteProtocolError`,
  like a dropped connection.

The inner transport's own I/O runs under :meth:`Clock.busy`, so under the simulated
clock talking to the server costs no virtual time: only the link does.  The link
never tells the client its bandwidth; the client has to measure it.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass, field
from typing import Any

import httpx

from walkstream.client.clock import Clock
from walkstream.client.units import parse_bandwidth, parse_duration
from walkstream.shared.errors import InputError

__all__ = ["LinkProfile", "LinkStats", "ShapedTransport"]


@dataclass(frozen=True, slots=True)
class LinkProfile:
    """What a link is like.

    Attributes
    ----------
    down_bps, up_bps
        Bandwidth server to client and client to server, bits per second (>= 0;
        0 means nothing ever arrives).
    rtt_s
        Round-trip time, seconds (half of it each way).
    loss
        Probability that a response body is cut off, in [0, 1].
    chunk_bytes
        Bytes per chunk crossing the link (a TCP segment by default).
    seed
        Seed of the loss draws.
    """

    down_bps: float
    up_bps: float
    rtt_s: float
    loss: float = 0.0
    chunk_bytes: int = 1460
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("down_bps", "up_bps", "rtt_s", "loss"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise InputError(f"link {name} must be a number, got {value!r}")
            if not math.isfinite(value) or value < 0:
                raise InputError(f"link {name} must be finite and >= 0, got {value!r}")
        if self.loss > 1:
            raise InputError(f"link loss must be a probability in [0, 1], got {self.loss!r}")
        if isinstance(self.chunk_bytes, bool) or not isinstance(self.chunk_bytes, int):
            raise InputError(f"link chunk_bytes must be an int, got {self.chunk_bytes!r}")
        if self.chunk_bytes < 1:
            raise InputError(f"link chunk_bytes must be >= 1, got {self.chunk_bytes!r}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int):
            raise InputError(f"link seed must be an int, got {self.seed!r}")

    @classmethod
    def parse(
        cls,
        bandwidth: str | float,
        rtt: str | float,
        *,
        loss: float = 0.0,
        up: str | float | None = None,
        chunk_bytes: int = 1460,
        seed: int = 0,
    ) -> LinkProfile:
        """Build a profile from command-line strings (``"56kbit"``, ``"200ms"``).

        ``up`` defaults to the same bandwidth as ``bandwidth`` (down).

        Examples
        --------
        >>> LinkProfile.parse("56kbit", "200ms")
        LinkProfile(down_bps=56000.0, up_bps=56000.0, rtt_s=0.2, loss=0.0, chunk_bytes=1460, seed=0)
        """
        down = parse_bandwidth(bandwidth)
        return cls(
            down_bps=down,
            up_bps=down if up is None else parse_bandwidth(up),
            rtt_s=parse_duration(rtt),
            loss=float(loss),
            chunk_bytes=chunk_bytes,
            seed=seed,
        )


@dataclass
class LinkStats:
    """What crossed a link.

    Attributes
    ----------
    bytes_up, bytes_down
        Bytes that crossed each direction (heads and bodies).
    requests
        Requests sent.
    responses_cut
        Responses cut off by simulated loss.
    down_log
        ``(time, cumulative bytes_down)`` after each delivered chunk, for plots.
    """

    bytes_up: int = 0
    bytes_down: int = 0
    requests: int = 0
    responses_cut: int = 0
    down_log: list[tuple[float, int]] = field(default_factory=list)


class _Pipe:
    """One direction of the link: a FIFO of reservations behind a frontier.

    ``free_at`` is when the pipe has sent everything reserved so far; a new
    reservation starts there (or later) and pushes it on.
    """

    __slots__ = ("bps", "free_at")

    def __init__(self, bps: float) -> None:
        self.bps = bps
        self.free_at = -math.inf

    def reserve(self, nbytes: int, earliest: float) -> tuple[float, float]:
        """Reserve the slot for ``nbytes``; returns its (start, end) times."""
        start = max(self.free_at, earliest)
        if nbytes <= 0:
            duration = 0.0
        elif self.bps <= 0:
            duration = math.inf
        else:
            duration = nbytes * 8.0 / self.bps
        end = start + duration
        self.free_at = end
        return start, end

    def release(self, start: float, end: float, now: float) -> None:
        """Give back the unsent part of a slot when nobody has queued behind it."""
        if self.free_at == end:
            self.free_at = max(start, min(now, end))


def _request_head_bytes(request: httpx.Request) -> int:
    line = len(request.method.encode()) + 1 + len(request.url.raw_path) + len(b" HTTP/1.1\r\n")
    return line + sum(len(k) + len(v) + 4 for k, v in request.headers.raw) + 2


def _response_head_bytes(response: httpx.Response) -> int:
    # Always "HTTP/1.1 <code> <standard phrase>": the same count in-process and over
    # real sockets, whatever reason phrase a server chose.
    phrase = httpx.codes.get_reason_phrase(response.status_code)
    line = len(f"HTTP/1.1 {response.status_code} {phrase}\r\n".encode())
    return line + sum(len(k) + len(v) + 4 for k, v in response.headers.raw) + 2


class ShapedTransport(httpx.AsyncBaseTransport):
    """An httpx transport that sends every request across a shaped link.

    Parameters
    ----------
    inner
        The transport that really talks to the server.
    profile
        Bandwidths, round-trip time and loss of the link.
    clock
        The clock to sleep on; under :class:`~walkstream.client.clock.SimClock` the link runs in
        virtual time and the inner transport's I/O takes none.

    Attributes
    ----------
    stats
        Bytes and requests that crossed the link so far.

    Examples
    --------
    >>> # transport = ShapedTransport(httpx.ASGITransport(app), LinkProfile.parse("56kbit", "200ms"), clock)
    >>> # async with httpx.AsyncClient(transport=transport, base_url="http://walkstream") as http: ...
    """

    def __init__(self, inner: httpx.AsyncBaseTransport, profile: LinkProfile, clock: Clock) -> None:
        self.inner = inner
        self.profile = profile
        self.clock = clock
        self.stats = LinkStats()
        self._up = _Pipe(profile.up_bps)
        self._down = _Pipe(profile.down_bps)
        self._half_rtt = profile.rtt_s / 2.0
        self._rng = random.Random(profile.seed)

    async def handle_async_request(self, request: httpx.Request) -> httpx.Response:
        """Send ``request`` up the link, then return its response as it comes down."""
        clock = self.clock
        self.stats.requests += 1
        with clock.busy():  # a streamed request body may be real I/O
            await request.aread()
        sent = await self._send_up(_request_head_bytes(request) + len(request.content))
        await clock.sleep_until(sent + self._half_rtt)

        with clock.busy():
            inner = await self.inner.handle_async_request(request)
        if not isinstance(inner.stream, httpx.AsyncByteStream):
            raise TypeError("ShapedTransport needs an inner transport with async streams")
        try:
            head = _response_head_bytes(inner)
            start, end = self._down.reserve(head, clock.now())
            await self._arrive(start, end)
            self._delivered(head)
            # Two draws per response whatever the outcome, so the sequence of cuts
            # depends on the seed and the order of responses only.
            hit, where = self._rng.random(), self._rng.random()
            cut = where if hit < self.profile.loss else None
        except BaseException:
            with clock.busy():
                await inner.aclose()
            raise
        stream = _ShapedStream(self, request, inner, inner.stream, end, cut)
        return httpx.Response(
            status_code=inner.status_code,
            headers=inner.headers,
            stream=stream,
            extensions=inner.extensions,
        )

    async def aclose(self) -> None:
        """Close the inner transport."""
        with self.clock.busy():
            await self.inner.aclose()

    # -- internals -------------------------------------------------------------------

    async def _send_up(self, nbytes: int) -> float:
        """Push ``nbytes`` up chunk by chunk; returns when the last byte left."""
        clock = self.clock
        chunk = self.profile.chunk_bytes
        earliest = clock.now()
        end = earliest
        while nbytes > 0:
            size = min(nbytes, chunk)
            start, end = self._up.reserve(size, earliest)
            try:
                await clock.sleep_until(end)
            except BaseException:
                self._up.release(start, end, clock.now())
                raise
            self.stats.bytes_up += size
            nbytes -= size
            earliest = end
        return end

    async def _arrive(self, start: float, end: float) -> None:
        """Wait until a down slot's bytes have arrived; give the slot back if cancelled."""
        try:
            await self.clock.sleep_until(end + self._half_rtt)
        except BaseException:
            self._down.release(start, end, self.clock.now())
            raise

    def _delivered(self, nbytes: int) -> None:
        stats = self.stats
        stats.bytes_down += nbytes
        stats.down_log.append((self.clock.now(), stats.bytes_down))


class _ShapedStream(httpx.AsyncByteStream):
    """A response body released chunk by chunk at its arrival times."""

    def __init__(
        self,
        link: ShapedTransport,
        request: httpx.Request,
        response: httpx.Response,
        inner: httpx.AsyncByteStream,
        head_end: float,
        cut: float | None,
    ) -> None:
        self._link = link
        self._request = request
        self._response = response
        self._inner = inner
        self._inner_iter: Any = None
        self._buffer = bytearray()
        self._eof = False
        self._error: Exception | None = None
        self._last_end = head_end  # when this stream's previous bytes left the pipe
        self._cut = cut  # uniform draw in [0, 1) when this body is to be cut
        self._cut_at: int | None = None
        self._total = 0  # body length, known once a cut body has been read whole
        self._delivered = 0
        self._inflight: tuple[float, float] | None = None
        self._done = False
        self._closed = False

    def __aiter__(self) -> _ShapedStream:
        return self

    async def __anext__(self) -> bytes:
        if self._done or self._closed:
            raise StopAsyncIteration
        link = self._link
        clock = link.clock
        want = link.profile.chunk_bytes
        if self._cut is not None:
            if self._cut_at is None:
                # The cut point needs the body's length: read it all (no virtual time).
                await self._fill(math.inf)
                self._total = self._delivered + len(self._buffer)
                self._cut_at = int(self._cut * self._total) if self._total else None
                if self._error is not None:
                    self._cut_at = None  # the server failed first: report that instead
            if self._cut_at is not None:
                want = min(want, self._cut_at - self._delivered)
                if want <= 0:
                    await self._finish()
                    link.stats.responses_cut += 1
                    raise httpx.RemoteProtocolError(
                        f"link: response cut off after {self._delivered} of {self._total} bytes",
                        request=self._request,
                    )
        await self._fill(want)
        if not self._buffer:
            await self._finish()
            if self._error is not None:
                raise self._error
            raise StopAsyncIteration

        data = bytes(self._buffer[:want])
        del self._buffer[:want]
        pipe = link._down
        # A prompt reader's request is "backdated" by half an RTT: the sender would
        # have sent on as soon as the previous chunk left, so one stream alone keeps
        # the pipe full; a slow reader only delays itself.
        start, end = pipe.reserve(len(data), max(self._last_end, clock.now() - link._half_rtt))
        self._inflight = (start, end)
        try:
            await clock.sleep_until(end + link._half_rtt)
        except BaseException:
            if self._inflight is not None:
                pipe.release(start, end, clock.now())
            self._inflight = None
            self._buffer[:0] = data  # not delivered: a reader that goes on gets it again
            raise
        self._inflight = None
        if self._closed:  # closed by another task while in flight
            raise StopAsyncIteration
        self._last_end = end
        self._delivered += len(data)
        link._delivered(len(data))
        return data

    async def _fill(self, want: float) -> None:
        """Read the inner stream until ``want`` bytes are buffered, or it ends or fails."""
        if self._inner_iter is None:
            self._inner_iter = self._inner.__aiter__()
        with self._link.clock.busy():
            while len(self._buffer) < want and not self._eof and self._error is None:
                try:
                    piece = await self._inner_iter.__anext__()
                except StopAsyncIteration:
                    self._eof = True
                except Exception as exc:  # the server's failure, delivered after the bytes
                    self._error = exc
                else:
                    self._buffer += piece

    async def _finish(self) -> None:
        """Stop: drop what is buffered and close the inner stream."""
        self._done = True
        self._buffer.clear()
        inner_iter, self._inner_iter = self._inner_iter, None
        with self._link.clock.busy():
            try:
                closer = getattr(inner_iter, "aclose", None)
                if closer is not None and not self._eof:
                    await closer()
            finally:
                await self._response.aclose()

    async def aclose(self) -> None:
        """Close early: the unsent rest costs the link nothing."""
        if self._closed:
            return
        self._closed = True
        if self._inflight is not None:
            start, end = self._inflight
            self._link._down.release(start, end, self._link.clock.now())
            self._inflight = None
        if not self._done:
            await self._finish()
