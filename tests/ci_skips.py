"""A pytest plugin: under CI (``CI`` set to a true value) a skipped test is a failed test.

Locally a test that cannot run (no GL context, no data in ../shared/data) is skipped
with its reason; in CI every test must run, so a machine that lost Mesa or the data
cannot pass with those tests quietly left out.
"""

from __future__ import annotations

import os
from collections.abc import Generator
from typing import Any

import pytest

__all__ = ["in_ci"]


def in_ci() -> bool:
    """Whether the tests run under CI (the variable ``CI`` is 1, true or yes)."""
    return os.environ.get("CI", "").strip().lower() in ("1", "true", "yes")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo[Any]) -> Generator[None, Any, None]:
    outcome = yield
    report = outcome.get_result()
    if in_ci() and report.skipped and not hasattr(report, "wasxfail"):
        reason = report.longrepr[2] if isinstance(report.longrepr, tuple) else str(report.longrepr)
        report.outcome = "failed"
        report.longrepr = f"skipped under CI, where every test must run: {reason}"
