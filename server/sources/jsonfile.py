"""Read a JSON source file (UTF-8, BOM allowed) with every failure as a one-line SourceError."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from walkstream.shared.errors import SourceError

__all__ = ["read_json_file"]


# --------------------------------------------------------------------------- public


def read_json_file(path: str | os.PathLike[str], max_bytes: int | None = None) -> Any:
    """Parse a JSON file (UTF-8, BOM allowed); every failure is a :class:`SourceError` naming it.

    ``max_bytes`` refuses larger files before reading them.
    """
    p = Path(path)
    try:
        if max_bytes is not None and p.stat().st_size > max_bytes:
            raise SourceError(f"{p}: larger than {max_bytes >> 20} MiB")
        with p.open("r", encoding="utf-8-sig") as fh:
            return json.load(fh)
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
