"""Build an expensive test scene once per pytest run, shared by every xdist worker.

A session-scoped fixture is built once per *process*: under ``make test`` (pytest-xdist,
one worker per core) each worker that needs a baked IFC interior would bake its own copy,
the same minutes of CPU twice. :func:`once_per_run` is pytest-xdist's documented pattern
for that: the first worker to ask builds the thing into a folder of the run's own
temporary directory (``tmp_path_factory.getbasetemp().parent`` under xdist, the run's
base folder otherwise) while holding an exclusive lock on it; the others wait on the lock
and then read the stored result.

The cache lives only as long as the run (pytest makes a new base folder per run), so a
change to the code between two runs can never serve a stale bake.  What a fixture built
this way returns is shared: tests read it (open the database read-only, or only read)
and never change it.
"""

from __future__ import annotations

import fcntl
import os
import pickle
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

import pytest

__all__ = ["once_per_run"]

T = TypeVar("T")


def run_folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The temporary folder of this whole run: every xdist worker's base folder's parent."""
    base = tmp_path_factory.getbasetemp()
    return base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base


def once_per_run(tmp_path_factory: pytest.TempPathFactory, name: str, build: Callable[[Path], T]) -> T:
    """``build(folder)`` once in this pytest run, whichever worker asks first; its result to every caller.

    Parameters
    ----------
    tmp_path_factory:
        The session's ``tmp_path_factory``.
    name:
        What is built: one folder per name (``<run folder>/once/<name>``), so it names
        everything that decides the result (source file, settings).
    build:
        Writes its files into the new, empty folder it is given and returns a picklable
        result (the paths and the summary a fixture returns).  A ``pytest.skip`` or an
        error inside it stores nothing: the next caller tries again, in a folder of its own.

    Returns
    -------
    T
        ``build``'s result, from this call or from the first one in the run.
    """
    folder = run_folder(tmp_path_factory) / "once" / name
    folder.mkdir(parents=True, exist_ok=True)
    done = folder / "result.pickle"
    with open(folder.parent / f"{name}.lock", "w") as lock:
        # the other workers wait here while the first one builds
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            if done.exists():
                result: T = pickle.loads(done.read_bytes())
                return result
            result = build(Path(tempfile.mkdtemp(prefix="build-", dir=folder)))
            part = done.with_suffix(".part")
            part.write_bytes(pickle.dumps(result))
            part.replace(done)
            return result
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)
