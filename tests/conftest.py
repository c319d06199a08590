"""Shared pytest fixtures."""

from __future__ import annotations

from collections.abc import Iterator
from typing import TYPE_CHECKING

import pytest

pytest_plugins = ["ci_skips"]

if TYPE_CHECKING:
    import moderngl


@pytest.fixture(scope="session")
def gl_ctx() -> Iterator[moderngl.Context]:
    """One headless OpenGL context for the session; skips the test when none can be made."""
    from walkstream.shared.errors import RenderError
    from walkstream.shared.gl import create_context

    try:
        ctx = create_context()
    except RenderError as exc:
        pytest.skip(str(exc))
    yield ctx
    ctx.release()


@pytest.fixture
def gl(gl_ctx: moderngl.Context) -> Iterator[moderngl.Context]:
    """The session context, with the GL error state checked before and after the test."""
    from walkstream.shared.gl import check_gl_error

    check_gl_error(gl_ctx, "before the test (left by an earlier one)")
    yield gl_ctx
    check_gl_error(gl_ctx, "after the test")
