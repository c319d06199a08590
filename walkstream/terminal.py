"""What the command line shows on the terminal: progress bars and summaries.

Progress goes to stderr (so that stdout stays a clean table or JSON), through tqdm.
"""

from __future__ import annotations

import json
import sys
import threading
import time
from collections.abc import Callable
from typing import Any

__all__ = ["building_bar", "count_bar", "stage_setter", "WalkBar", "print_summary", "say_if_slow"]


def building_bar(total: int, desc: str) -> Any:
    """A stderr progress bar over ``total`` buildings (a context manager with ``update``)."""
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="bldg", file=sys.stderr, leave=False, dynamic_ncols=True)


def count_bar(desc: str, unit: str) -> tuple[Any, Callable[[int, int], None]]:
    """A stderr progress bar and the ``(done, total)`` callback that drives it."""
    from tqdm import tqdm

    bar = tqdm(total=0, desc=desc, unit=unit, file=sys.stderr, dynamic_ncols=True)

    def progress(done: int, total: int) -> None:
        bar.total = total
        bar.n = done
        bar.refresh()

    return bar, progress


def stage_setter(bar: Any) -> Callable[[str, str], None]:
    """A ``(step, unit)`` callback that starts ``bar`` (a :func:`count_bar`) afresh for a step.

    A bake counts field points, then PVS cells, then images, each with its own label.
    """

    def stage(step: str, unit: str) -> None:
        bar.set_description(step, refresh=False)
        bar.unit = unit
        bar.reset(total=0)

    return stage


class WalkBar:
    """A tqdm bar of walk seconds, made on the first progress call (so that a replay
    that fails during setup prints only its error)."""

    def __init__(self, desc: str) -> None:
        self.desc = desc
        self.bar: Any = None

    def __call__(self, done: float, total: float) -> None:
        if self.bar is None:
            from tqdm import tqdm

            self.bar = tqdm(
                total=max(total, 1e-9),
                desc=self.desc,
                unit="s",
                file=sys.stderr,
                leave=False,
                dynamic_ncols=True,
                bar_format="{l_bar}{bar}| {n:.0f}/{total:.0f} s walked [{elapsed}]",
            )
        if total != self.bar.total:  # an interior walk's whole path arrived after its head
            self.bar.total = max(total, 1e-9)
        self.bar.update(min(done, total) - self.bar.n)  # honours tqdm's refresh interval

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def print_summary(title: str, summary: dict[str, Any], as_json: bool) -> None:
    """A summary as aligned ``key  value`` lines under ``title``, or as one JSON object."""
    if as_json:
        print(json.dumps(summary))
        return
    print(f"{title}:")
    width = max(len(k) for k in summary)
    for k, v in summary.items():
        print(f"  {k:<{width}}  {v}")


def say_if_slow(work: Callable[[], None], what: str, after_s: float = 1.0) -> float:
    """Run ``work``; if it is still running after ``after_s`` seconds, say ``what`` on
    stderr and, when it ends, how long it took.  Returns its seconds.

    For a step that is quick but for its first run (compiled code made for the cache:
    the interiors' culling takes some 20 s once), so that the terminal is not silent then
    and says nothing the other times.  An error in ``work`` is raised here."""
    failed: list[BaseException] = []

    def run() -> None:
        try:
            work()
        except BaseException as exc:  # handed to the caller's thread
            failed.append(exc)

    t0 = time.perf_counter()
    worker = threading.Thread(target=run, daemon=True)
    worker.start()
    worker.join(after_s)
    slow = worker.is_alive()
    if slow:
        print(f"walkstream: {what} ...", file=sys.stderr, flush=True)
        worker.join()
    seconds = time.perf_counter() - t0
    if failed:
        raise failed[0]
    if slow:
        print(f"walkstream: {what}: done in {seconds:.0f} s", file=sys.stderr, flush=True)
    return seconds
