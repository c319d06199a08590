"""The HTTP service: a FastAPI app over read-only scene databases.

:func:`create_app` builds the app (:mod:`.main`); :func:`serve` runs it with uvicorn
(:mod:`.run`); :func:`server_process` runs it in a child process on a free port
(:mod:`.process`).  Per-scene state and caches are in :mod:`.scenes`, the start
bundle in :mod:`.startbundle`, content negotiation and ETags in :mod:`.http`, the
FastAPI dependencies in :mod:`.dependencies`, the routes in :mod:`.routers` (one module per resource) and
their documented shapes in :mod:`.models`.  The records sent are defined once in
:mod:`walkstream.shared.wire`.
"""

from walkstream.server.service.main import create_app
from walkstream.server.service.process import free_port, server_process
from walkstream.server.service.run import serve

__all__ = ["create_app", "serve", "server_process", "free_port"]
