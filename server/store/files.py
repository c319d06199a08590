"""Durable, exclusive file handling for scene databases: fsync, locks, removal."""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager, suppress

from walkstream.shared.errors import StoreError

__all__ = ["db_label", "fsync_file", "fsync_dir", "remove_db_files", "exclusive_lock"]

try:  # advisory locks between processes; POSIX only
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None  # type: ignore[assignment]


# ---------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------


def db_label(path: str | os.PathLike[str]) -> str:
    """How errors name a database: its path as given."""
    return os.fspath(path)


def fsync_file(path: str) -> None:
    """Flush the file at ``path`` to disk."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def fsync_dir(path: str) -> None:
    """Flush the directory that holds ``path``, so that a rename into it survives a crash."""
    # makes the rename itself durable; not possible (nor needed) on every platform
    with suppress(OSError):
        fsync_file(os.path.dirname(os.path.abspath(path)) or ".")


def remove_db_files(path: str) -> None:
    """Remove a database file with its ``-wal``, ``-shm`` and ``-journal`` files, if there."""
    for suffix in ("", "-wal", "-shm", "-journal"):
        with suppress(FileNotFoundError):
            os.remove(path + suffix)


@contextmanager
def exclusive_lock(lock_path: str, *, blocking: bool, what: str) -> Iterator[None]:
    """Hold an exclusive advisory lock on ``lock_path`` (no-op without fcntl)."""
    fd = os.open(lock_path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        if fcntl is not None:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | (0 if blocking else fcntl.LOCK_NB))
            except BlockingIOError as exc:
                raise StoreError(
                    f"{what}: another process is writing it ({lock_path} is locked)"
                ) from exc
        yield
    finally:
        os.close(fd)  # closing releases the lock
