"""One error hierarchy for the whole project.

Every error a user can cause derives from :class:`WalkstreamError`; the subclasses also
derive from the built-in they refine (mostly ``ValueError``) so callers that only know
built-ins still catch them.  The server maps them to 4xx responses and the CLI to one
clear line and a non-zero exit.

Inputs: :class:`InputError` and its kinds (grammar, source, codec, store, route); a
damaged scene database (:class:`DatabaseDamagedError`) is a store error the service
answers 503.
Runtime: :class:`RenderError`, :class:`DerivationLimitError`, :class:`ServiceError`,
:class:`SimulationStalled`.  The HTTP API: :class:`ApiError` (a refused request, on
either side of the wire) and :class:`StreamCut` (an object stream cut short).
"""

from __future__ import annotations

from typing import Any

__all__ = [
    "WalkstreamError",
    "InputError",
    "GrammarError",
    "DerivationLimitError",
    "DatabaseDamagedError",
    "SourceError",
    "CodecError",
    "RenderError",
    "StoreError",
    "NotFoundError",
    "CacheDamagedError",
    "RouteError",
    "ApiError",
    "StreamCut",
    "ServiceError",
    "SimulationStalled",
    "WorkerGone",
]


class WalkstreamError(Exception):
    """Base class of every error walkstream raises on purpose."""


class InputError(WalkstreamError, ValueError):
    """A value given by a user (argument, file, request) is not acceptable."""


class GrammarError(InputError):
    """A grammar text cannot be parsed or is inconsistent.

    ``line`` is the 1-based line of the grammar text that is at fault (0 when the
    error is not tied to one line).
    """

    def __init__(self, message: str, line: int = 0) -> None:
        self.line = line
        super().__init__(f"grammar line {line}: {message}" if line else message)


class DerivationLimitError(WalkstreamError, RuntimeError):
    """An L-system derivation exceeded its depth or module-count limit."""


class SourceError(InputError):
    """A scene source (GeoJSON file, generated city) cannot be read at all."""


class CodecError(InputError):
    """Bytes on the wire or in a database do not decode to a valid record."""


class RenderError(WalkstreamError, RuntimeError):
    """No OpenGL context could be created, or a draw failed."""


class StoreError(InputError):
    """A scene database cannot be opened, read or written as asked."""


class NotFoundError(StoreError):
    """An object, cell or path asked for is not in the scene."""


class DatabaseDamagedError(StoreError):
    """A scene database's stored pages or blobs cannot be read: the server's fault, not the request's.

    The service answers it 503 with ``Retry-After`` (a replaced file is picked up
    within a second); at start it stops the start like any :class:`StoreError`.
    """


class CacheDamagedError(StoreError):
    """A client cache file is not a (readable) walkstream cache of this scene version.

    Raised and handled inside the disk cache, which moves such a file aside.
    """


class RouteError(InputError):
    """No route can be made: a point outside every cell, or cells not connected."""


class ApiError(WalkstreamError):
    """A request of the HTTP API that is refused, or whose answer cannot be used.

    The service raises it with the HTTP ``status`` to answer and a JSON-able
    ``detail``; its handler turns it into ``{"error": message, "detail": detail}``.
    The client raises it for a 4xx answer (``status`` set) or an answer it cannot
    use (``status`` None).
    """

    def __init__(self, message: str, status: int | None = None, detail: Any = None) -> None:
        super().__init__(message)
        self.message = message
        self.status = status
        self.detail = detail


class StreamCut(WalkstreamError):
    """An object stream ended before every asked object arrived intact.

    ``received`` objects were yielded before the cut; the rest must be asked again.
    """

    def __init__(self, message: str, received: int) -> None:
        super().__init__(message)
        self.received = received


class ServiceError(WalkstreamError, RuntimeError):
    """The service could not be started, or did not answer its health check."""


class SimulationStalled(WalkstreamError, RuntimeError):
    """The simulated program waits, but nothing it waits for can ever happen.

    No task sleeps on the clock with a finite deadline, no busy section is open and
    the main coroutine has not finished: typically a task waits on ``asyncio.sleep``
    (real time) or on an event nobody sets, or everything sleeps forever (a link of
    zero bandwidth with no timeout).
    """


class WorkerGone(WalkstreamError, RuntimeError):
    """A rewrite worker process could not start or died; its batch must run elsewhere."""
