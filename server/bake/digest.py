"""What identifies a bake's input: a short digest of the source file's bytes."""

from __future__ import annotations

import hashlib
from pathlib import Path

__all__ = ["file_digest"]


def file_digest(path: Path) -> str:
    """First 16 hex digits of the sha256 of a file (what identifies a bake's input).

    Parameters
    ----------
    path:
        The source file, read in blocks of 1 MiB.
    """
    h = hashlib.sha256()
    with path.open("rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()[:16]
