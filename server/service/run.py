"""Run the service with uvicorn: ``walkstream serve scene.db [more.db ...]``.

Every database is validated *before* uvicorn starts, so a missing, corrupt or
wrong-version file stops the start at once with :class:`~walkstream.shared.errors.StoreError`
(the CLI prints its one-line message).  With ``workers > 1`` uvicorn starts worker
processes that import :func:`app_from_env` (factory mode); the database paths reach
them in the environment variable :data:`ENV_PATHS` as a JSON list, and each worker
opens its own read-only readers and caches.
"""

from __future__ import annotations

import json
import logging
import os
from collections.abc import Sequence

import uvicorn
from fastapi import FastAPI

from walkstream.server.service.guard import MAX_HEAD_BYTES, PER_CLIENT, READ_TIMEOUT, configure
from walkstream.server.service.main import create_app
from walkstream.shared.errors import InputError, StoreError

__all__ = ["ENV_PATHS", "LIMIT_CONCURRENCY", "serve", "app_from_env"]

ENV_PATHS = "WALKSTREAM_SERVE_PATHS"
"""Environment variable carrying the database paths (JSON list) to worker processes."""

log = logging.getLogger(__name__)

#: uvicorn's ``limit_concurrency``: connections and request tasks at once, per process.
LIMIT_CONCURRENCY = 4096


def _check_args(host: str, port: int, workers: int) -> None:
    if not isinstance(host, str) or not host:
        raise InputError(f"host: expected a host name or address, got {host!r}")
    if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= 65535:
        raise InputError(f"port: expected 0 to 65535, got {port!r}")
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise InputError(f"workers: expected a whole number >= 1, got {workers!r}")


def serve(
    paths: Sequence[str | os.PathLike[str]],
    host: str = "127.0.0.1",
    port: int = 8000,
    workers: int = 1,
    *,
    log_level: str = "info",
    access_log: bool = False,
    per_client: int = PER_CLIENT,
    read_timeout: float = READ_TIMEOUT,
) -> None:
    """Serve scene databases read-only until interrupted.

    Parameters
    ----------
    paths:
        Scene database files; each is served under its scene name.
    host, port:
        Where to listen (``0.0.0.0`` for every interface).
    workers:
        Server processes; more than one shares the port between processes started
        by uvicorn (each holds its own caches and metrics).
    log_level:
        uvicorn's log level.
    access_log:
        Log every request (off by default: at thousands of requests per second the
        log costs more than the answers; ``/metrics`` counts them instead).
    per_client, read_timeout:
        Connections one client address may hold open (0: no limit) and the seconds
        a request may take to arrive (:mod:`~walkstream.server.service.guard`).

    Raises
    ------
    StoreError
        A database cannot be served (raised before anything listens).
    InputError
        A bad host, port or worker count.
    """
    _check_args(host, port, workers)
    files = [os.path.abspath(os.fspath(p)) for p in paths]
    app = create_app(files)  # validates every database, or raises
    options: dict[str, object] = {
        "host": host,
        "port": port,
        "log_level": log_level,
        "access_log": access_log,
        "server_header": False,
        "ws": "none",  # no WebSocket routes: skip loading a WebSocket implementation
        # an idle keep-alive connection is dropped after this many seconds, so
        # vanished clients do not pile up
        "timeout_keep_alive": 5,
        # every connection and request task together; beyond, uvicorn answers 503
        "limit_concurrency": LIMIT_CONCURRENCY,
        # the request head's size under h11 (the guard bounds it under httptools)
        "h11_max_incomplete_event_size": MAX_HEAD_BYTES,
        # uvicorn's httptools protocol with a read deadline and a per-address cap
        "http": configure(read_timeout, per_client),
    }
    if workers == 1:
        try:
            uvicorn.run(app, **options)  # type: ignore[arg-type]
        finally:
            app.state.scenes.close()
        return
    # worker processes build their own app; this one only validated the files
    app.state.scenes.close()
    os.environ[ENV_PATHS] = json.dumps(files)
    uvicorn.run("walkstream.server.service.run:app_from_env", factory=True, workers=workers, **options)  # type: ignore[arg-type]


def app_from_env() -> FastAPI:
    """The app over the databases named in :data:`ENV_PATHS` (uvicorn factory for workers).

    Raises
    ------
    StoreError
        The variable is missing or not a JSON list of paths, or a database cannot be
        served.
    """
    raw = os.environ.get(ENV_PATHS)
    if raw is None:
        raise StoreError(f"{ENV_PATHS} is not set: start the server with `walkstream serve`")
    try:
        paths = json.loads(raw)
    except ValueError as exc:
        raise StoreError(f"{ENV_PATHS}: not JSON ({exc})") from exc
    if not isinstance(paths, list) or not all(isinstance(p, str) for p in paths):
        raise StoreError(f"{ENV_PATHS}: expected a JSON list of database paths")
    return create_app(paths)
