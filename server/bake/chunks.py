"""The one chunk runner of the bake: independent tasks in this process, local processes or on Dask.

Every kind of cell work the bake spreads is a *chunk task*: a module-level function
``task(chunk, *shared)`` taking a list of plain items (cell ids and arrays) and the
data every chunk needs (a city scene and its settings, an interior's triangle soup),
returning one result per item.  :func:`run_chunks` cuts the items into chunks, runs
them and yields each chunk's results as it finishes:

- ``workers == 1``: here, in order;
- ``workers > 1``: a pool of ``spawn``-ed local processes (a forked child would
  inherit this process's GL state), the shared data sent once to each at start;
- ``scheduler``: a Dask distributed cluster, the shared data scattered once to every
  worker and each chunk a task.

Results come in the order chunks finish; the caller writes them by cell id, so the
database does not depend on it.  The city's visibility cells
(:func:`~.workers.cell_task`) and the interior's room contents
(:func:`~.roomcontents.contents_task`) both run here.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from typing import Any, TypeVar

from walkstream.shared.errors import InputError

__all__ = ["chunked", "dask_client", "run_chunks"]

T = TypeVar("T")
R = TypeVar("R")

_SHARED: dict[str, Any] = {}


def _init_worker(task: Callable[..., Any], shared: tuple[Any, ...]) -> None:
    _SHARED["task"], _SHARED["shared"] = task, shared


def _pool_task(chunk: list[Any]) -> list[Any]:
    return list(_SHARED["task"](chunk, *_SHARED["shared"]))


def chunked(items: Sequence[T], size: int) -> list[list[T]]:
    """``items`` cut into consecutive lists of at most ``size``."""
    return [list(items[i : i + size]) for i in range(0, len(items), size)]


def run_chunks(
    task: Callable[..., list[R]],
    items: Sequence[Any],
    shared: tuple[Any, ...] = (),
    *,
    size: int,
    workers: int = 1,
    scheduler: str | None = None,
    progress: Callable[[int, int], None] | None = None,
    done: int = 0,
    total: int | None = None,
    release: Callable[[], None] | None = None,
) -> Iterator[list[R]]:
    """Run ``task(chunk, *shared)`` over ``items`` in chunks of ``size``; yield each chunk's results.

    Parameters
    ----------
    task:
        A module-level function (it is pickled by name for processes and Dask).
    items:
        Plain, picklable work items.
    shared:
        Arguments every chunk gets after its chunk: sent once per process or
        scattered once to every Dask worker.
    size:
        Items per chunk: big enough to amortise a task's overhead, small enough for
        a smooth progress bar.
    workers, scheduler:
        Local processes, or ``tcp://HOST:PORT`` of a Dask scheduler (wins over
        ``workers``).
    progress:
        Called with ``(items done, total)`` before the first chunk and after each.
    done, total:
        Items counted as done before this run (a resumed bake) and the total
        (default ``done + len(items)``).
    release:
        Called when a run in this process ends (the task's per-process state, a GL
        context, freed).
    """
    all_ = done + len(items) if total is None else total
    count = done
    if progress:
        progress(count, all_)
    for results in _run(task, chunked(items, size), shared, workers, scheduler, release):
        count += len(results)
        if progress:
            progress(count, all_)
        yield results


def _run(
    task: Callable[..., list[R]],
    chunks: list[list[Any]],
    shared: tuple[Any, ...],
    workers: int,
    scheduler: str | None,
    release: Callable[[], None] | None,
) -> Iterator[list[R]]:
    if not chunks:
        return
    if scheduler:
        yield from _run_dask(task, chunks, shared, scheduler)
    elif workers > 1:
        import multiprocessing as mp

        # spawn: a forked child would inherit this process's GL state
        ctx = mp.get_context("spawn")
        with ctx.Pool(workers, initializer=_init_worker, initargs=(task, shared)) as pool:
            yield from pool.imap_unordered(_pool_task, chunks)
    else:
        try:
            for chunk in chunks:
                yield task(chunk, *shared)
        finally:
            if release is not None:
                release()


def dask_client(scheduler: str) -> Any:
    """A ``distributed.Client`` of the scheduler at ``tcp://HOST:PORT`` (close it when done).

    Raises
    ------
    InputError
        Dask is not installed, or the scheduler cannot be reached.
    """
    try:
        from distributed import Client
    except ImportError as exc:  # optional dependency: fail only when used
        raise InputError("--scheduler needs Dask: pip install 'dask[distributed]'") from exc
    try:
        return Client(scheduler, timeout=20)
    except OSError as exc:
        raise InputError(f"--scheduler {scheduler}: cannot reach the Dask scheduler ({exc})") from exc


def _run_dask(
    task: Callable[..., list[R]], chunks: list[list[Any]], shared: tuple[Any, ...], scheduler: str
) -> Iterator[list[R]]:
    from distributed import as_completed

    client = dask_client(scheduler)
    try:
        # ship the shared data once; every task refers to the same scattered copies
        remote = client.scatter(list(shared), broadcast=True) if shared else []
        futures = [client.submit(task, c, *remote, pure=False) for c in chunks]
        for fut in as_completed(futures):
            yield fut.result()
    finally:
        client.close()
