"""One error hierarchy for the whole project.

Every error a user can cause derives from :class:`WalkstreamError`; the subclasses also
derive from the built-in they refine (mostly ``ValueError``) so callers that only know
built-ins still catch them.  The server maps them to 4xx responses and the CLI to one
clear line and a non-zero exit.
"""

from __future__ import annotations

__all__ = [
    "WalkstreamError",
    "InputError",
    "GrammarError",
    "DerivationLimitError",
    "SourceError",
    "CodecError",
    "RenderError",
]


class WalkstreamError(Exception):
    """Base class of every error walkstream raises on purpose."""


class InputError(WalkstreamError, ValueError):
    """A value given by a user (argument, file, request) is not acceptable."""


class GrammarError(InputError):
    """A grammar text cannot be parsed or is inconsistent.

    ``line`` is the 1-based line of the grammar text that is at fault (0 when the
    error is not tied to one line).
    """

    def __init__(self, message: str, line: int = 0) -> None:
        self.line = line
        super().__init__(f"grammar line {line}: {message}" if line else message)


class DerivationLimitError(WalkstreamError, RuntimeError):
    """An L-system derivation exceeded its depth or module-count limit."""


class SourceError(InputError):
    """A scene source (GeoJSON file, generated city) cannot be read at all."""


class CodecError(InputError):
    """Bytes on the wire or in a database do not decode to a valid record."""


class RenderError(WalkstreamError, RuntimeError):
    """No OpenGL context could be created, or a draw failed."""
