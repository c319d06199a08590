"""What uvicorn does not bound by itself: how long a request may take to arrive, and
how many connections one client address may hold.

uvicorn's own settings (:func:`~walkstream.server.service.run.serve` sets them)
bound idle keep-alive connections (``timeout_keep_alive``), all connections and
tasks together (``limit_concurrency``: beyond it every new request is a 503) and
the size of an incomplete request head (``h11_max_incomplete_event_size``, h11
only).  None of them closes a connection that sends its headers one byte at a time
(a slowloris): 1,500 such connections were all still held after 20 s.  uvicorn
takes the HTTP protocol as a class (``http=``), so :class:`GuardedHttpToolsProtocol` adds the
missing bounds to its httptools protocol, which ``http="auto"`` picks anyway:

* a read deadline: from a connection's start, and from the end of each response,
  the next request (head and body) must have arrived within ``read_timeout``
  seconds, else the connection is closed (bodies here are at most a few
  kilobytes; a client that sends slower is not one we can serve);
* at most ``per_client`` connections open at once from one address: one more is
  answered ``503`` with ``Retry-After`` and closed before anything is read;
* a request head of at most :data:`MAX_HEAD_BYTES`: a longer one is a ``431``.
"""

from __future__ import annotations

import asyncio
import json
import logging
import os
from collections import Counter
from typing import ClassVar

from uvicorn.protocols.http.httptools_impl import HttpToolsProtocol

__all__ = ["ENV_GUARD", "MAX_HEAD_BYTES", "PER_CLIENT", "READ_TIMEOUT", "GuardedHttpToolsProtocol", "configure"]

log = logging.getLogger(__name__)

#: Seconds a request (head and body) may take to arrive.
READ_TIMEOUT = 10.0
#: Connections one client address may hold open at once (0: no limit).
PER_CLIENT = 128
#: Bytes a request head may have (uvicorn's httptools protocol keeps every header it
#: is sent): a longer one is answered 431 and the connection closed.
MAX_HEAD_BYTES = 64 << 10
#: Environment variable carrying the bounds to uvicorn's worker processes.
ENV_GUARD = "WALKSTREAM_SERVE_GUARD"


def _busy_response(per_client: int) -> bytes:
    body = json.dumps(
        {"error": f"more than {per_client} connections from this address", "detail": {"per_client": per_client}}
    ).encode()
    head = (
        "HTTP/1.1 503 Service Unavailable\r\ncontent-type: application/json\r\nretry-after: 1\r\n"
        f"connection: close\r\ncontent-length: {len(body)}\r\n\r\n"
    )
    return head.encode() + body


def _head_too_large() -> bytes:
    body = json.dumps(
        {"error": f"request head over {MAX_HEAD_BYTES} bytes", "detail": {"max_head_bytes": MAX_HEAD_BYTES}}
    ).encode()
    return (
        "HTTP/1.1 431 Request Header Fields Too Large\r\ncontent-type: application/json\r\n"
        f"connection: close\r\ncontent-length: {len(body)}\r\n\r\n"
    ).encode() + body


class _Guarded(HttpToolsProtocol):
    """uvicorn's httptools protocol with a read deadline and a per-address cap."""

    read_timeout: ClassVar[float] = READ_TIMEOUT
    per_client: ClassVar[int] = PER_CLIENT
    # open connections by (server, address): every server in the process shares the class
    _open: ClassVar[Counter[tuple[int, str]]] = Counter()

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        self._read_timer: asyncio.TimerHandle | None = None
        self._key: tuple[int, str] | None = None
        self._in_head = False
        self._head_bytes = 0
        key = (id(self.server_state), self.client[0] if self.client else "")
        if self.per_client and self._open[key] >= self.per_client:
            transport.write(_busy_response(self.per_client))
            transport.close()
            return
        self._open[key] += 1
        self._key = key
        self._arm()

    def _arm(self) -> None:
        self._disarm()
        self._head_bytes = 0
        self._in_head = True
        self._read_timer = self.loop.call_later(self.read_timeout, self._read_timed_out)

    def data_received(self, data: bytes) -> None:
        if self._key is None:
            return  # refused: closing
        if self._in_head:
            self._head_bytes += len(data)
            if self._head_bytes > MAX_HEAD_BYTES:
                self._in_head = False
                self.transport.write(_head_too_large())
                self.transport.close()
                return
        super().data_received(data)

    def on_headers_complete(self) -> None:
        self._in_head = False
        super().on_headers_complete()

    def _disarm(self) -> None:
        if self._read_timer is not None:
            self._read_timer.cancel()
            self._read_timer = None

    def _read_timed_out(self) -> None:
        self._read_timer = None
        # debug, not info: a slowloris would write one line per connection
        log.debug("closing %s: no whole request within %g s", self.client, self.read_timeout)
        self.transport.close()

    def on_message_complete(self) -> None:
        self._disarm()
        super().on_message_complete()

    def on_response_complete(self) -> None:
        super().on_response_complete()
        if not self.transport.is_closing():
            self._arm()

    def connection_lost(self, exc: Exception | None) -> None:
        self._disarm()
        if self._key is not None:
            self._open[self._key] -= 1
            if self._open[self._key] <= 0:
                del self._open[self._key]
            self._key = None
        super().connection_lost(exc)


class GuardedHttpToolsProtocol(_Guarded):
    """The protocol class :func:`~walkstream.server.service.run.serve` gives uvicorn.

    Module-level, so uvicorn's worker processes can unpickle it; its bounds come from
    :func:`configure` (and, in a worker process, from :data:`ENV_GUARD`, which
    ``configure`` sets for it).
    """


def configure(read_timeout: float = READ_TIMEOUT, per_client: int = PER_CLIENT) -> type[GuardedHttpToolsProtocol]:
    """Set the bounds of :class:`GuardedHttpToolsProtocol` (here and in worker processes).

    Parameters
    ----------
    read_timeout:
        Seconds a request may take to arrive, from the connection's start or the
        previous response's end.
    per_client:
        Connections one address may hold open at once; 0 for no limit.
    """
    GuardedHttpToolsProtocol.read_timeout = float(read_timeout)
    GuardedHttpToolsProtocol.per_client = int(per_client)
    os.environ[ENV_GUARD] = f"{float(read_timeout)!r},{int(per_client)}"
    return GuardedHttpToolsProtocol


def _from_env() -> None:
    raw = os.environ.get(ENV_GUARD)
    if raw:
        timeout, per_client = raw.split(",")
        GuardedHttpToolsProtocol.read_timeout = float(timeout)
        GuardedHttpToolsProtocol.per_client = int(per_client)


_from_env()
