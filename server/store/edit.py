"""Edits of a finished scene: a recorded path written into a copy that replaces it."""

from __future__ import annotations

import os
import secrets
import shutil
import sqlite3
from contextlib import suppress

from walkstream.shared.errors import StoreError

try:  # advisory locks between processes; POSIX only
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None  # type: ignore[assignment]
from walkstream.server.store.files import db_label, exclusive_lock, fsync_dir, fsync_file
from walkstream.server.store.reader import SceneReader
from walkstream.server.store.records import MAX_PATH_BYTES, check_path_name
from walkstream.server.store.schema import CORE_TABLES, check_header, content_version

__all__ = ["write_path"]


# ---------------------------------------------------------------------------
# recorded paths
# ---------------------------------------------------------------------------


def write_path(path_db: str | os.PathLike[str], name: str, blob: bytes) -> str:
    """Add or replace a recorded path in a finished scene, atomically.

    The database is copied beside itself, the copy edited and re-hashed, fsynced
    and moved onto ``path_db`` with ``os.replace``: readers see the old file or the
    new one, never a half-written one.  Concurrent calls are serialised with a lock
    file (``<path_db>.lock``).

    Parameters
    ----------
    path_db:
        A finished scene database.
    name:
        Path name, 1 to 200 printable characters.
    blob:
        The path's bytes (at most 64 MiB).

    Returns
    -------
    str
        The new scene version.

    Raises
    ------
    StoreError
        Bad name or blob, or the file is not a valid scene database.
    """
    label = db_label(path_db)
    name = check_path_name(name)
    if not isinstance(blob, bytes) or len(blob) > MAX_PATH_BYTES:
        raise StoreError(f"path {name!r}: expected bytes of at most {MAX_PATH_BYTES}")
    check_header(path_db)
    tmp = f"{label}.tmp-{os.getpid()}-{secrets.token_hex(4)}"
    try:
        with exclusive_lock(label + ".lock", blocking=True, what=label):
            shutil.copyfile(path_db, tmp)
            check_header(tmp)
            conn = sqlite3.connect(tmp, isolation_level=None)
            try:
                SceneReader._load_meta(conn, label)  # a finished walkstream scene?
                conn.execute("BEGIN")
                conn.execute(
                    CORE_TABLES["paths"].replace("CREATE TABLE", "CREATE TABLE IF NOT EXISTS")
                )
                conn.execute("INSERT OR REPLACE INTO paths(name, data) VALUES (?, ?)", (name, blob))
                version = content_version(conn)
                conn.execute("UPDATE meta SET value = ? WHERE key = 'version'", (version,))
                conn.execute("COMMIT")
            except sqlite3.DatabaseError as exc:
                raise StoreError(f"{label}: cannot write path {name!r} ({exc})") from exc
            finally:
                conn.close()
            fsync_file(tmp)
            os.replace(tmp, path_db)
        fsync_dir(label)
    finally:
        with suppress(FileNotFoundError):
            os.remove(tmp)
        with suppress(FileNotFoundError):
            os.remove(tmp + "-journal")
    return version
