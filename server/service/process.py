"""Run the service in a child process on a free local port (demo, benchmarks, tests).

The child is ``walkstream.server.service.serve`` in its own process group, so stopping it also
stops uvicorn's worker processes; :func:`server_process` waits until
``/v1/health`` answers before it yields and kills the group when it leaves.
"""

from __future__ import annotations

import contextlib
import os
import socket
import subprocess
import sys
import time
from collections.abc import Iterator, Sequence

from walkstream.shared.errors import ServiceError

__all__ = ["free_port", "healthy", "server_process"]


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port that was free a moment ago on ``host``."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


def healthy(host: str, port: int) -> bool:
    """Whether a walkstream server answers ``GET /v1/health`` with 200 on ``host:port``."""
    try:
        with socket.create_connection((host, port), timeout=1.0) as s:
            s.sendall(
                f"GET /v1/health HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n".encode()
            )
            data = b""
            while b"\r\n" not in data:
                chunk = s.recv(4096)
                if not chunk:
                    break
                data += chunk
        return data.startswith(b"HTTP/1.1 200")
    except OSError:
        return False


_SERVER_CODE = """
import os, sys
core = int(sys.argv[3])
if core >= 0:
    os.sched_setaffinity(0, {core})
from walkstream.server.service.run import serve
serve(sys.argv[5:], host="127.0.0.1", port=int(sys.argv[1]), workers=int(sys.argv[2]),
      log_level="warning", **({"per_client": int(sys.argv[4])} if int(sys.argv[4]) >= 0 else {}))
"""


@contextlib.contextmanager
def server_process(
    dbs: Sequence[str | os.PathLike[str]],
    port: int = 0,
    workers: int = 1,
    core: int = -1,
    timeout_s: float = 60.0,
    per_client: int | None = None,
) -> Iterator[tuple[str, int]]:
    """Serve ``dbs`` from a child process; yields ``(host, port)`` once it is healthy.

    Parameters
    ----------
    dbs:
        Scene databases.
    port:
        Port to listen on; 0 picks a free one.
    workers:
        uvicorn worker processes.
    core:
        Pin the server to this CPU core (>= 0), e.g. to keep it off a benchmark's core.
    timeout_s:
        How long to wait for ``/v1/health``.
    per_client:
        Connections one address may hold (0: no limit; None: the server's default),
        see :mod:`~walkstream.server.service.guard`.

    Raises
    ------
    RuntimeError
        The child exited or did not become healthy in time (its stderr is included).
    """
    host = "127.0.0.1"
    port = port or free_port(host)
    env = dict(os.environ)
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    proc = subprocess.Popen(
        [sys.executable, "-c", _SERVER_CODE, str(port), str(workers), str(core), str(-1 if per_client is None else per_client)]
        + [os.fspath(d) for d in dbs],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        start_new_session=True,
    )
    try:
        deadline = time.monotonic() + timeout_s
        while not healthy(host, port):
            if proc.poll() is not None:
                err = proc.stderr.read().decode(errors="replace") if proc.stderr else ""
                raise ServiceError(f"server exited with {proc.returncode}: {err[-2000:]}")
            if time.monotonic() > deadline:
                raise ServiceError(f"server did not answer /v1/health within {timeout_s:.0f} s")
            time.sleep(0.1)
        if workers > 1:  # let every worker come up before the load starts
            time.sleep(1.0)
        yield host, port
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, 15)
        try:
            proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(proc.pid, 9)
            proc.wait()
        if proc.stderr:
            proc.stderr.close()
