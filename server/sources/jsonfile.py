"""Read a JSON source file (UTF-8, BOM allowed) with every failure as a one-line SourceError.

An integer longer than :data:`MAX_NUMBER_CHARS` digits is read as NaN instead of
being converted (a float64 holds 17 significant digits and no finite value needs
more than about 310, while Python refuses, with a ``ValueError``, to turn an integer
of more than 4,300 digits into an ``int`` at all; an overlong decimal fraction is
read as infinity by ``float`` itself).  The feature that holds
such a number is then skipped by the reader's NaN rule, with its id, and the rest of
the file is read.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any

from walkstream.shared.errors import SourceError

__all__ = ["MAX_NUMBER_CHARS", "read_json_file"]

#: Characters in one JSON number beyond which it is read as NaN (see the module docstring).
MAX_NUMBER_CHARS = 400


def _parse_int(text: str) -> int | float:
    return int(text) if len(text) <= MAX_NUMBER_CHARS else math.nan


# --------------------------------------------------------------------------- public


def read_json_file(path: str | os.PathLike[str], max_bytes: int | None = None) -> Any:
    """Parse a JSON file (UTF-8, BOM allowed); every failure is a :class:`SourceError` naming it.

    ``max_bytes`` refuses larger files before reading them; an integer longer than
    :data:`MAX_NUMBER_CHARS` digits is read as NaN.
    """
    p = Path(path)
    try:
        if max_bytes is not None and p.stat().st_size > max_bytes:
            raise SourceError(f"{p}: larger than {max_bytes >> 20} MiB")
        text = p.read_text(encoding="utf-8-sig")
        try:
            return json.loads(text)
        except ValueError as exc:
            if isinstance(exc, json.JSONDecodeError) or "digits" not in str(exc):
                raise
        # an integer too long for int(): read again, it and its kind as NaN (floats
        # of any length become inf by themselves, and the readers skip both)
        return json.loads(text, parse_int=_parse_int)
    except OSError as exc:
        raise SourceError(f"{p}: cannot read file: {exc.strerror or exc}") from exc
    except UnicodeDecodeError as exc:
        raise SourceError(f"{p}: not JSON: not UTF-8 text ({exc.reason})") from exc
    except json.JSONDecodeError as exc:
        raise SourceError(
            f"{p}: not JSON: {exc.msg} at line {exc.lineno} column {exc.colno}"
        ) from exc
    except RecursionError as exc:
        raise SourceError(f"{p}: not JSON: nested too deeply") from exc
