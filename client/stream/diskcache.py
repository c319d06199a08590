"""m-LOMA's cache on disk: index tiles, cell records and object frames of a scene version.

:class:`DiskCache` keeps tiles of the cell index, cell records and object frames
between runs in a real SQLite file per scene version,
``cache_dir/<scene>/<version>.sqlite``, plus the scene's last manifest and its ETag
(``cache_dir/<scene>/manifest.msgpack``) so that the client can revalidate the
manifest with ``If-None-Match`` and learn whether the scene version changed.  A
scene version is immutable, so what the version's file holds is used as it is,
without a request: the manifest's revalidation is the one check.  Nothing it does may stop a walk: a damaged or foreign file is
moved aside and replaced, a locked database skips the write, and every failure is
counted in :attr:`DiskCache.errors` instead of raised.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import re
import sqlite3
import threading
import time
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any

import msgpack

from walkstream.shared.codec import unpack_bounded
from walkstream.shared.errors import CacheDamagedError, CodecError, InputError

try:  # POSIX; elsewhere the directory lock is skipped (SQLite still locks its file)
    import fcntl
except ImportError:  # pragma: no cover - not on Linux
    fcntl = None  # type: ignore[assignment]

__all__ = ["DEFAULT_DISK_BYTES", "KEEP_VERSIONS", "safe_name", "DiskCache"]

DEFAULT_DISK_BYTES = 256 << 20
"""Default bound of one scene version's disk cache (bodies only)."""

KEEP_VERSIONS = 3
"""Disk cache files of a scene kept, newest first; older versions are deleted."""


# ---------------------------------------------------------------------------
# on disk
# ---------------------------------------------------------------------------

_APP = "walkstream-client-cache"
_FORMAT = "2"  # 2: slim cell records (PVS and ACH), index tiles
_MAX_MANIFEST_BYTES = 64 << 20
_BUSY_TIMEOUT_S = 10.0
_CHUNK = 500  # ids per query, under SQLite's host-parameter limit
_SAFE = re.compile(r"[^A-Za-z0-9_-]")

_SCHEMA = (
    "CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT NOT NULL)",
    "CREATE TABLE cells (id INTEGER PRIMARY KEY, body BLOB NOT NULL)",
    "CREATE TABLE indexes (id INTEGER PRIMARY KEY, body BLOB NOT NULL)",
    "CREATE TABLE objects (id INTEGER NOT NULL, form TEXT NOT NULL, body BLOB NOT NULL,"
    " PRIMARY KEY (id, form)) WITHOUT ROWID",
)


def safe_name(name: str) -> str:
    """A file-system-safe, collision-free form of a scene name or version.

    Letters, digits, ``_`` and ``-`` are kept; anything else (``/``, dots, spaces,
    non-ASCII) becomes ``_`` and a short hash of the original is appended, so two
    names never share a file and no name can leave the cache directory.
    """
    safe = _SAFE.sub("_", name)[:80]
    if safe != name or not safe:
        safe = f"{safe}-{hashlib.sha256(name.encode('utf-8', 'surrogatepass')).hexdigest()[:12]}"
    return safe


@contextlib.contextmanager
def _dir_lock(directory: Path) -> Iterator[None]:
    """An exclusive lock on a scene's cache directory (open, repair and prune)."""
    if fcntl is None:  # pragma: no cover - not on Linux
        yield
        return
    fd = os.open(directory / ".lock", os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)  # closing releases the lock


class DiskCache:
    """m-LOMA's local cache: index tiles, cell records and object frames of one scene version.

    Build with :meth:`open`, or construct on a directory, use the manifest methods
    (which need no version), then :meth:`use` a scene version.  Files: ``cache_dir/<scene>/<version>.sqlite``
    (names made safe with :func:`safe_name`) in WAL mode, every write one
    transaction, and ``cache_dir/<scene>/manifest.msgpack``.  Opening a version
    deletes the scene's versions beyond the newest :data:`KEEP_VERSIONS`.

    Parameters
    ----------
    cache_dir:
        The cache directory (created if missing).
    max_bytes:
        Bound on the bodies stored per scene version; past it, puts store nothing.

    Attributes
    ----------
    errors:
        Failures absorbed instead of raised (locked database, damaged file, disk full).
    recovered:
        Files moved aside as damaged or foreign.
    full:
        Whether a put was refused for :attr:`max_bytes`.

    Notes
    -----
    Safe to use from several threads (one lock) and several processes (SQLite
    locking plus a lock file for opening and repairing).
    """

    def __init__(
        self, cache_dir: str | os.PathLike[str], *, max_bytes: int = DEFAULT_DISK_BYTES
    ) -> None:
        if type(max_bytes) is not int or max_bytes < 0:
            raise InputError(
                f"disk cache max_bytes: expected a non-negative integer, got {max_bytes!r}"
            )
        self.cache_dir = Path(cache_dir)
        self.max_bytes = max_bytes
        self.errors = 0
        self.recovered = 0
        self.full = False
        self.scene: str | None = None
        self.version: str | None = None
        self.path: Path | None = None
        self.last_error: str | None = None
        self._conn: sqlite3.Connection | None = None
        self._lock = threading.RLock()

    @classmethod
    def open(
        cls,
        cache_dir: str | os.PathLike[str],
        scene: str,
        version: str,
        *,
        max_bytes: int = DEFAULT_DISK_BYTES,
    ) -> DiskCache:
        """Open (creating, or repairing) the cache of ``scene`` at ``version``.

        Never raises for the file system or the database: when no usable file can
        be made, the cache is returned unavailable (:attr:`available` False,
        :attr:`last_error` says why) and every get misses, every put stores nothing.
        """
        dc = cls(cache_dir, max_bytes=max_bytes)
        dc.use(scene, version)
        return dc

    @property
    def available(self) -> bool:
        """Whether a version file is open."""
        return self._conn is not None

    def scene_dir(self, scene: str) -> Path:
        """The directory of ``scene``'s files."""
        return self.cache_dir / safe_name(scene)

    # -- version files -------------------------------------------------------

    def use(self, scene: str, version: str) -> bool:
        """Switch to ``scene`` at ``version`` (closing any other), repairing and pruning.

        A damaged or foreign file at the version's path is moved aside (renamed
        ``<name>.corrupt-<n>``) and a fresh one made; then the scene's versions
        beyond the newest :data:`KEEP_VERSIONS` are deleted.

        Returns
        -------
        bool
            Whether the version file is open; if not, :attr:`last_error` says why
            (an unwritable directory, a file locked by another process for long).
        """
        self.close()
        d = self.scene_dir(scene)
        path = d / f"{safe_name(version)}.sqlite"
        with self._lock:
            self.path, self.scene, self.version, self.full = path, scene, version, False
            try:
                d.mkdir(parents=True, exist_ok=True)
                with _dir_lock(d):
                    try:
                        conn = self._connect(path, scene, version)
                    except CacheDamagedError:
                        self._move_aside(path)
                        conn = self._connect(path, scene, version)
                    with contextlib.suppress(OSError):
                        os.utime(path)  # the version in use is the newest
                    self._prune(d, keep=path)
            except (OSError, sqlite3.Error, CacheDamagedError) as exc:
                self.errors += 1
                self.last_error = f"disk cache {path}: cannot open ({exc})"
                return False
            self._conn = conn
            return True

    def _connect(self, path: Path, scene: str, version: str) -> sqlite3.Connection:
        """Open and check (or initialise) one version file; :class:`CacheDamagedError` if unusable."""
        try:
            conn = sqlite3.connect(
                path, timeout=_BUSY_TIMEOUT_S, isolation_level=None, check_same_thread=False
            )
        except sqlite3.Error as exc:
            raise CacheDamagedError(str(exc)) from exc
        try:
            conn.execute("PRAGMA journal_mode=WAL")
            conn.execute("PRAGMA synchronous=NORMAL")
            conn.execute("BEGIN IMMEDIATE")
            try:
                tables = {r[0] for r in conn.execute("SELECT name FROM sqlite_master")}
                if not tables:
                    for sql in _SCHEMA:
                        conn.execute(sql)
                    conn.executemany(
                        "INSERT INTO meta VALUES (?, ?)",
                        [
                            ("app", _APP),
                            ("format", _FORMAT),
                            ("scene", scene),
                            ("version", version),
                            ("bytes", "0"),
                        ],
                    )
                elif not {"meta", "cells", "indexes", "objects"} <= tables:
                    raise CacheDamagedError(f"not a walkstream cache (tables {sorted(tables)[:5]})")
                else:
                    meta = dict(conn.execute("SELECT key, value FROM meta").fetchall())
                    want = {"app": _APP, "format": _FORMAT, "scene": scene, "version": version}
                    bad = [k for k, v in want.items() if meta.get(k) != v]
                    if bad or not str(meta.get("bytes", "")).isdigit():
                        raise CacheDamagedError(f"meta {bad[0] if bad else 'bytes'} does not match")
                conn.execute("COMMIT")
            except BaseException:
                with contextlib.suppress(sqlite3.Error):
                    conn.execute("ROLLBACK")
                raise
            row = conn.execute("PRAGMA quick_check").fetchone()
            if not row or row[0] != "ok":
                raise CacheDamagedError(f"quick_check: {row[0] if row else 'no answer'}")
        except sqlite3.OperationalError as exc:
            conn.close()
            if not _is_damage(exc):
                raise  # locked by another process, unopenable directory: not damage
            raise CacheDamagedError(str(exc)) from exc
        except (sqlite3.DatabaseError, CacheDamagedError) as exc:
            conn.close()
            raise CacheDamagedError(str(exc)) from exc
        return conn

    def _move_aside(self, path: Path) -> Path:
        """Rename a damaged file (and its WAL/SHM) to ``<name>.corrupt-<n>``."""
        n = 1
        while Path(f"{path}.corrupt-{n}").exists():
            n += 1
        target = Path(f"{path}.corrupt-{n}")
        if path.exists():
            os.replace(path, target)
        for suffix in ("-wal", "-shm"):
            side = Path(f"{path}{suffix}")
            if side.exists():
                # a stale WAL must never be applied to the fresh file of the same name
                os.replace(side, Path(f"{target}{suffix}"))
        self.recovered += 1
        return target

    @staticmethod
    def _prune(d: Path, keep: Path) -> None:
        """Delete version files (and damaged copies) beyond the newest :data:`KEEP_VERSIONS`."""

        def newest_first(paths: list[Path]) -> list[Path]:
            def mtime(p: Path) -> float:
                try:
                    return p.stat().st_mtime
                except OSError:
                    return 0.0

            return sorted(paths, key=lambda p: (p != keep, -mtime(p)))

        versions = newest_first(list(d.glob("*.sqlite")))
        damaged = newest_first(list(d.glob("*.sqlite.corrupt-*[0-9]")))
        for old in versions[KEEP_VERSIONS:] + damaged[KEEP_VERSIONS:]:
            for p in (old, Path(f"{old}-wal"), Path(f"{old}-shm")):
                with contextlib.suppress(FileNotFoundError):
                    p.unlink()

    def close(self) -> None:
        """Close the version file (idempotent; the manifest methods still work)."""
        with self._lock:
            if self._conn is not None:
                with contextlib.suppress(sqlite3.Error):
                    self._conn.close()
            self._conn = None

    def __enter__(self) -> DiskCache:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- reads and writes ----------------------------------------------------

    def _failed(self, exc: sqlite3.Error) -> None:
        """Absorb a database failure; a damaged file is moved aside and replaced."""
        self.errors += 1
        if isinstance(exc, sqlite3.OperationalError) and not _is_damage(exc):
            return  # locked, busy, disk full: try again next time
        if self.path is None or self.scene is None or self.version is None:
            return
        path, scene, version = self.path, self.scene, self.version
        self.close()
        try:
            with _dir_lock(path.parent):
                try:
                    self._conn = self._connect(path, scene, version)  # another process fixed it
                except CacheDamagedError:
                    self._move_aside(path)
                    self._conn = self._connect(path, scene, version)
        except (OSError, sqlite3.Error, CacheDamagedError):
            self._conn = None  # no disk cache for the rest of the run

    def _get_body(self, table: str, key: int) -> bytes | None:
        with self._lock:
            if self._conn is None:
                return None
            try:
                row = self._conn.execute(
                    f"SELECT body FROM {table} WHERE id = ?", (int(key),)
                ).fetchone()
            except sqlite3.Error as exc:
                self._failed(exc)
                return None
            return None if row is None else bytes(row[0])

    def get_cell(self, cid: int) -> bytes | None:
        """The stored record of cell ``cid``, or None (not cached, or unreadable)."""
        return self._get_body("cells", cid)

    def put_cell(self, cid: int, body: bytes) -> bool:
        """Store (or replace) cell ``cid``'s record; False when it was not stored (full or failing)."""
        return self._write("cells", [(int(cid), bytes(body))])

    def get_index(self, key: int) -> bytes | None:
        """The stored index tile ``key`` (the streamer's tile key), or None."""
        return self._get_body("indexes", key)

    def put_index(self, key: int, body: bytes) -> bool:
        """Store (or replace) index tile ``key``; False when it was not stored."""
        return self._write("indexes", [(int(key), bytes(body))])

    def get_objects(self, ids: Iterable[int], form: str = "params") -> dict[int, bytes]:
        """The stored frames of ``ids`` in ``form`` (those absent are left out)."""
        want = list(dict.fromkeys(int(i) for i in ids))
        out: dict[int, bytes] = {}
        with self._lock:
            if self._conn is None:
                return out
            try:
                for k in range(0, len(want), _CHUNK):
                    part = want[k : k + _CHUNK]
                    marks = ",".join("?" * len(part))
                    rows = self._conn.execute(
                        f"SELECT id, body FROM objects WHERE form = ? AND id IN ({marks})",
                        (form, *part),
                    )
                    out.update((int(r[0]), bytes(r[1])) for r in rows)
            except sqlite3.Error as exc:
                self._failed(exc)
        return out

    def put_objects(
        self, items: Mapping[int, bytes] | Iterable[tuple[int, bytes]], form: str = "params"
    ) -> bool:
        """Store object frames ``{id: body}`` in ``form``, in one transaction.

        Returns False when nothing was stored: the version's bound would be passed,
        or the database failed (counted in :attr:`errors`).
        """
        pairs = items.items() if isinstance(items, Mapping) else items
        return self._write("objects", [(int(i), str(form), bytes(b)) for i, b in pairs])

    def _write(self, table: str, rows: list[tuple[Any, ...]]) -> bool:
        # one row per key (the last wins), so the byte count sees what is stored
        keyed = 2 if table == "objects" else 1
        rows = list({r[:keyed]: r for r in rows}.values())
        if not rows:
            return True
        with self._lock:
            conn = self._conn
            if conn is None:
                return False
            try:
                conn.execute("BEGIN IMMEDIATE")
                try:
                    used = int(
                        conn.execute("SELECT value FROM meta WHERE key = 'bytes'").fetchone()[0]
                    )
                    if table != "objects":
                        old = [
                            conn.execute(
                                f"SELECT length(body) FROM {table} WHERE id = ?", r[:1]
                            ).fetchone()
                            for r in rows
                        ]
                    else:
                        old = [
                            conn.execute(
                                "SELECT length(body) FROM objects WHERE id = ? AND form = ?", r[:2]
                            ).fetchone()
                            for r in rows
                        ]
                    delta = sum(len(r[-1]) for r in rows) - sum(o[0] for o in old if o)
                    if used + delta > self.max_bytes:
                        conn.execute("ROLLBACK")
                        self.full = True
                        return False
                    marks = ",".join("?" * len(rows[0]))
                    conn.executemany(f"INSERT OR REPLACE INTO {table} VALUES ({marks})", rows)
                    conn.execute(
                        "UPDATE meta SET value = ? WHERE key = 'bytes'", (str(used + delta),)
                    )
                    conn.execute("COMMIT")
                except BaseException:
                    with contextlib.suppress(sqlite3.Error):
                        conn.execute("ROLLBACK")
                    raise
            except (sqlite3.Error, ValueError, TypeError) as exc:
                self._failed(
                    exc if isinstance(exc, sqlite3.Error) else sqlite3.DatabaseError(str(exc))
                )
                return False
            return True

    def bytes_stored(self) -> int:
        """Bytes of bodies stored in this version's file (0 when none is open)."""
        with self._lock:
            if self._conn is None:
                return 0
            try:
                row = self._conn.execute("SELECT value FROM meta WHERE key = 'bytes'").fetchone()
                return int(row[0])
            except (sqlite3.Error, ValueError, TypeError):
                return 0

    # -- manifest (per scene, not per version) -------------------------------

    def _manifest_path(self, scene: str) -> Path:
        return self.scene_dir(scene) / "manifest.msgpack"

    def get_manifest(self, scene: str) -> tuple[str, bytes] | None:
        """The last stored ``(etag, body)`` of ``scene``'s manifest, or None."""
        try:
            data = self._manifest_path(scene).read_bytes()
            obj = unpack_bounded(
                data,
                f"cached manifest of {scene!r}",
                max_bytes=_MAX_MANIFEST_BYTES,
                max_array_len=0,
                max_map_len=4,
                max_str_len=4096,
                max_bin_len=_MAX_MANIFEST_BYTES,
            )
        except FileNotFoundError:
            return None
        except (OSError, CodecError):
            self.errors += 1
            return None
        if (
            not isinstance(obj, dict)
            or obj.get("app") != _APP
            or not isinstance(obj.get("etag"), str)
            or not isinstance(obj.get("body"), bytes)
        ):
            self.errors += 1
            return None
        return obj["etag"], obj["body"]

    def manifest_etag(self, scene: str) -> str | None:
        """The ETag of ``scene``'s stored manifest (for ``If-None-Match``), or None."""
        got = self.get_manifest(scene)
        return None if got is None else got[0]

    def put_manifest(self, scene: str, etag: str, body: bytes) -> bool:
        """Store ``scene``'s manifest and its ETag, replacing the file atomically."""
        path = self._manifest_path(scene)
        data = msgpack.packb(
            {"app": _APP, "etag": str(etag), "body": bytes(body)}, use_bin_type=True
        )
        tmp = path.with_name(
            f".{path.name}.{os.getpid()}.{threading.get_ident()}.{time.monotonic_ns()}"
        )
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp.write_bytes(data)
            os.replace(tmp, path)
        except OSError:
            self.errors += 1
            with contextlib.suppress(OSError):
                tmp.unlink()
            return False
        return True


def _is_damage(exc: sqlite3.Error) -> bool:
    """Whether an SQLite error means the file is damaged (not merely busy or full)."""
    if not isinstance(exc, sqlite3.OperationalError):
        return isinstance(exc, sqlite3.DatabaseError)
    text = str(exc).lower()
    return "malformed" in text or "not a database" in text or "no such table" in text
