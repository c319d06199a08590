"""A one-worker Dask cluster of real processes for the tests that spread a bake over it."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from typing import Any


@contextlib.contextmanager
def local_cluster() -> Iterator[Any]:
    """A :class:`distributed.LocalCluster` of one worker process, closed however slowly.

    The dashboard takes a free port (None would mean the fixed 8787, which another xdist
    worker or job may hold).  Closing waits for the worker process with the nanny's fixed
    5 s timeout, which a loaded 2-core machine can overrun after the bake has finished;
    that timeout at close is not what the tests measure, so it is tolerated.
    """
    from distributed import LocalCluster

    cluster = LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=":0")
    try:
        yield cluster
    finally:
        with contextlib.suppress(TimeoutError):
            cluster.close()
