"""The team's real third-party data beside the checkout (``../shared/data``), one home for finding it.

Tests on that data call :func:`team_data`: it returns the path, or skips the test with
the reason when the file is not there (a fresh clone with nothing beside it).  Under
CI the ``ci_skips`` plugin turns that skip into a failure, so the data cannot go
missing there unnoticed.
"""

from __future__ import annotations

from pathlib import Path

import pytest

__all__ = ["TEAM_DATA", "team_data"]

TEAM_DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
"""``../shared/data`` seen from the checkout (``vienna/``, ``osm/``, ``indoor/``)."""


def team_data(*parts: str) -> Path:
    """The path ``../shared/data/<parts>``; skips the calling test when it does not exist."""
    path = TEAM_DATA.joinpath(*parts)
    if not path.exists():
        pytest.skip(f"{path} is missing (the team's ../shared/data, beside the checkout)")
    return path
