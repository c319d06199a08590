"""The one chunk runner of the bake: the same results here, in local processes and on Dask."""

from __future__ import annotations

import pytest

from walkstream.server.bake.chunks import chunked, run_chunks


def square_task(chunk: list[int], offset: int) -> list[tuple[int, int]]:
    return [(k, k * k + offset) for k in chunk]


def test_chunks_cut_in_order() -> None:
    assert chunked(list(range(7)), 3) == [[0, 1, 2], [3, 4, 5], [6]]
    assert chunked([], 3) == []


@pytest.mark.parametrize("workers", [1, 2])
def test_the_runner_gives_every_result_and_counts_progress(workers: int) -> None:
    seen: list[tuple[int, int]] = []
    released: list[bool] = []
    out = [r for res in run_chunks(square_task, list(range(10)), (5,), size=3, workers=workers,
                                   progress=lambda a, b: seen.append((a, b)), done=4, total=14,
                                   release=lambda: released.append(True))
           for r in res]
    assert sorted(out) == [(k, k * k + 5) for k in range(10)]
    assert seen[0] == (4, 14) and seen[-1] == (14, 14) and len(seen) == 5
    assert released == ([True] if workers == 1 else [])  # the release is for this process's own state


def test_no_items_no_work() -> None:
    assert list(run_chunks(square_task, [], (0,), size=3)) == []
