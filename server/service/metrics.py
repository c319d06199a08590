"""Prometheus metrics of the service: request counters by route and status, bytes, latency.

:class:`MetricsMiddleware` is a plain ASGI middleware (no per-request task or
thread, unlike Starlette's ``BaseHTTPMiddleware``) that counts every request into
:class:`Metrics` and adds ``Vary: Accept`` to every response.
"""

from __future__ import annotations

import bisect
import time
from typing import Any

from starlette.types import ASGIApp, Message, Receive, Scope, Send

from walkstream.server.service.registry import SceneRegistry

__all__ = ["LATENCY_BUCKETS", "Metrics", "MetricsMiddleware"]

LATENCY_BUCKETS: tuple[float, ...] = (
    0.0005,
    0.001,
    0.0025,
    0.005,
    0.01,
    0.025,
    0.05,
    0.1,
    0.25,
    0.5,
    1.0,
    2.5,
    5.0,
)
"""Upper bounds (seconds) of the latency histogram buckets (plus ``+Inf``)."""

# requests that match no route share one label, so junk URLs cannot grow the metrics
_UNMATCHED = "<unmatched>"


# ---------------------------------------------------------------------------
# metrics
# ---------------------------------------------------------------------------


def _label(value: str) -> str:
    return value.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n")


class Metrics:
    """Request counters of one process, rendered in the Prometheus text format.

    Updated from the event loop only (the middleware), so no lock is needed; with
    ``--workers N`` each worker has its own and a scrape sees one of them.
    """

    def __init__(self) -> None:
        self.requests: dict[tuple[str, str, int], int] = {}
        self.bytes_sent: dict[str, int] = {}
        # route -> [counts per bucket (+Inf last), sum of seconds, count]
        self.latency: dict[str, list[Any]] = {}
        self.in_flight = 0
        self.started = time.time()

    def observe(self, method: str, route: str, status: int, nbytes: int, seconds: float) -> None:
        """Record one finished request."""
        key = (method, route, status)
        self.requests[key] = self.requests.get(key, 0) + 1
        self.bytes_sent[route] = self.bytes_sent.get(route, 0) + nbytes
        h = self.latency.get(route)
        if h is None:
            h = self.latency[route] = [[0] * (len(LATENCY_BUCKETS) + 1), 0.0, 0]
        h[0][bisect.bisect_left(LATENCY_BUCKETS, seconds)] += 1
        h[1] += seconds
        h[2] += 1

    def render(self, registry: SceneRegistry | None = None) -> bytes:
        """The metrics as Prometheus text exposition format 0.0.4."""
        out = [
            "# HELP walkstream_requests_total HTTP requests answered, by method, route and status.",
            "# TYPE walkstream_requests_total counter",
        ]
        for (method, route, status), n in sorted(self.requests.items()):
            out.append(
                f'walkstream_requests_total{{method="{method}",route="{_label(route)}",'
                f'status="{status}"}} {n}'
            )
        out += [
            "# HELP walkstream_response_bytes_total Response body bytes sent, by route.",
            "# TYPE walkstream_response_bytes_total counter",
        ]
        for route, n in sorted(self.bytes_sent.items()):
            out.append(f'walkstream_response_bytes_total{{route="{_label(route)}"}} {n}')
        out += [
            "# HELP walkstream_request_duration_seconds Time from the request to its last "
            "response byte handed to the server, by route.",
            "# TYPE walkstream_request_duration_seconds histogram",
        ]
        for route, (counts, total, count) in sorted(self.latency.items()):
            r = _label(route)
            cumulative = 0
            for le, c in zip((*LATENCY_BUCKETS, "+Inf"), counts, strict=True):
                cumulative += c
                out.append(
                    f'walkstream_request_duration_seconds_bucket{{route="{r}",le="{le}"}} '
                    f"{cumulative}"
                )
            out.append(f'walkstream_request_duration_seconds_sum{{route="{r}"}} {total:.6f}')
            out.append(f'walkstream_request_duration_seconds_count{{route="{r}"}} {count}')
        out += [
            "# HELP walkstream_requests_in_flight Requests being answered now.",
            "# TYPE walkstream_requests_in_flight gauge",
            f"walkstream_requests_in_flight {self.in_flight}",
            "# HELP walkstream_start_time_seconds When this process started (Unix time).",
            "# TYPE walkstream_start_time_seconds gauge",
            f"walkstream_start_time_seconds {self.started:.3f}",
        ]
        if registry is not None:
            out += [
                "# HELP walkstream_scene_info The scenes served, with their versions.",
                "# TYPE walkstream_scene_info gauge",
            ]
            for s in registry.scenes.values():
                out.append(
                    f'walkstream_scene_info{{scene="{_label(s.name)}",version="{s.version}"}} 1'
                )
        return ("\n".join(out) + "\n").encode()


class MetricsMiddleware:
    """Counts every HTTP request into :class:`Metrics` and adds ``Vary: Accept``.

    The route label is the matched route's template (``/v1/scenes/{scene}``), read
    from the ASGI scope after routing, so there is one series per route rather
    than per URL.
    """

    def __init__(self, app: ASGIApp, metrics: Metrics) -> None:
        self.app = app
        self.metrics = metrics

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        """Run the request, measuring it."""
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        start = time.perf_counter()
        status = 500
        sent = 0

        async def counting_send(message: Message) -> None:
            nonlocal status, sent
            if message["type"] == "http.response.start":
                status = message["status"]
                headers = list(message.get("headers", ()))
                if not any(k.lower() == b"vary" for k, _ in headers):
                    headers.append((b"vary", b"Accept"))
                message = {**message, "headers": headers}
            elif message["type"] == "http.response.body":
                sent += len(message.get("body", b""))
            await send(message)

        m = self.metrics
        m.in_flight += 1
        try:
            await self.app(scope, receive, counting_send)
        finally:
            m.in_flight -= 1
            route = getattr(scope.get("route"), "path", None) or _UNMATCHED
            m.observe(scope.get("method", "?"), route, status, sent, time.perf_counter() - start)
