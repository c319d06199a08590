"""The scene database: one SQLite file per baked scene.

The bake writes it with :class:`SceneWriter`, the server reads it with
:class:`SceneReader`, and recorded paths are added with :func:`write_path`.

Layout (schema version :data:`SCHEMA_VERSION`)
---------------------------------------------
``meta(key, value)``
    ``app`` (``"walkstream"``), ``schema_version``, ``name``, ``version`` (content
    hash), ``crs``, ``origin_x``, ``origin_y``, ``grammar``, ``grammar_version``,
    ``features`` (JSON list), ``settings`` (JSON), ``settings_hash``,
    ``bake_seconds``, ``created``.
``objects(id, kind, params, minx, miny, minz, maxx, maxy, maxz, tris0, tris1, tris2)``
    ``params`` is :func:`shared.codec.encode_building` / ``encode_street`` output,
    streamed to clients as is; ``tris*`` are the triangle counts of LOD 0-2.
``cells(id, kind, boundary, zmin, zmax, neighbours, pvs, done)``
    ``boundary`` is :func:`shared.codec.encode_polygon` of the convex ``(n, 2)``
    outline, ``neighbours`` :func:`shared.codec.encode_ids`, ``pvs``
    :func:`shared.codec.encode_pvs`.
``viewpoints(name, x, y, z, yaw, cell)`` and ``paths(name, data)``.

Optional tables are declared once in :data:`OPTIONAL_TABLES`, keyed by the feature
name that needs them, and only created for scenes that list that feature.  The file
carries SQLite ``application_id`` :data:`APPLICATION_ID` and ``user_version``
:data:`SCHEMA_VERSION` so a foreign or newer file is refused from its 100-byte
header alone.

Atomicity: the bake writes ``<path>.partial`` (WAL, one small transaction per
cell, so a killed bake loses at most the cell it was on and can resume), and
:meth:`SceneWriter.finish` vacuums it into a fresh, self-contained file that
replaces ``path`` with ``os.replace``.  :func:`write_path` copies, edits and
replaces likewise.  Nothing ever modifies a finished file in place, which is
what lets readers open it ``immutable``.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import math
import os
import queue
import secrets
import shutil
import sqlite3
import threading
from collections.abc import Iterable, Iterator, Sequence
from contextlib import contextmanager, suppress
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import msgpack
import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.shared.cells import CELL_KINDS
from walkstream.shared.codec import (
    decode_building,
    decode_ids,
    decode_polygon,
    decode_pvs,
    decode_street,
    encode_building,
    encode_ids,
    encode_polygon,
    encode_pvs,
    encode_street,
    pvs_size,
)
from walkstream.shared.errors import CodecError, NotFoundError, StoreError
from walkstream.shared.records import BuildingParams, StreetParams, Viewpoint

try:  # advisory locks between processes; POSIX only
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None  # type: ignore[assignment]

__all__ = [
    "SCHEMA_VERSION",
    "APPLICATION_ID",
    "OBJECT_KINDS",
    "OPTIONAL_TABLES",
    "SceneMeta",
    "ObjectRow",
    "ObjectInfo",
    "CellRow",
    "CellInfo",
    "Viewpoint",
    "SceneWriter",
    "SceneReader",
    "write_path",
]

SCHEMA_VERSION = 1
"""The one schema version this code reads and writes (``PRAGMA user_version``)."""

APPLICATION_ID = 0x57534442  # "WSDB"
"""``PRAGMA application_id`` of every walkstream scene database."""

OBJECT_KINDS = ("building", "street", "crossroad", "square")

_SQLITE_MAGIC = b"SQLite format 3\x00"
_MAX_PATH_NAME = 200
_MAX_PATH_BYTES = 64 << 20

# Core tables.  Convention relied on by the content hash: column 1 is the key.
_CORE_TABLES: dict[str, str] = {
    "meta": "CREATE TABLE meta(key TEXT PRIMARY KEY NOT NULL, value)",
    "objects": (
        "CREATE TABLE objects(id INTEGER PRIMARY KEY, kind TEXT NOT NULL, params BLOB NOT NULL, "
        "minx REAL NOT NULL, miny REAL NOT NULL, minz REAL NOT NULL, "
        "maxx REAL NOT NULL, maxy REAL NOT NULL, maxz REAL NOT NULL, "
        "tris0 INTEGER NOT NULL, tris1 INTEGER NOT NULL, tris2 INTEGER NOT NULL)"
    ),
    "cells": (
        "CREATE TABLE cells(id INTEGER PRIMARY KEY, kind TEXT NOT NULL CHECK (kind IN "
        f"({', '.join(repr(k) for k in CELL_KINDS)})), boundary BLOB NOT NULL, "
        "zmin REAL NOT NULL, zmax REAL NOT NULL, neighbours BLOB NOT NULL, pvs BLOB, "
        "done INTEGER NOT NULL DEFAULT 0)"
    ),
    "viewpoints": (
        "CREATE TABLE viewpoints(name TEXT PRIMARY KEY NOT NULL, x REAL NOT NULL, "
        "y REAL NOT NULL, z REAL NOT NULL, yaw REAL NOT NULL, cell INTEGER)"
    ),
    "paths": "CREATE TABLE paths(name TEXT PRIMARY KEY NOT NULL, data BLOB NOT NULL)",
}

OPTIONAL_TABLES: dict[str, dict[str, str]] = {
    # feature name -> {table name: DDL}; created only when the scene lists the feature
    "portals": {
        "portals": (
            "CREATE TABLE portals(id INTEGER PRIMARY KEY, cell_a INTEGER NOT NULL, "
            "cell_b INTEGER NOT NULL, polygon BLOB NOT NULL)"
        ),
    },
}
"""Tables that exist only in scenes using a feature, declared in this one place."""

# meta keys that describe the run rather than the content: left out of the hash so
# that baking the same input twice gives the same version
_VOLATILE_META = ("version", "bake_seconds", "created")






# ---------------------------------------------------------------------------
# records
# ---------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class SceneMeta:
    """What the ``meta`` table says about a finished scene.

    ``origin`` is the CRS position of local (0, 0); ``version`` the first 16 hex
    digits of the content hash; ``settings_json`` the bake settings as canonical
    JSON (see :attr:`settings`).
    """

    schema_version: int
    name: str
    version: str
    crs: str
    origin: tuple[float, float]
    grammar_text: str
    grammar_version: str
    features: tuple[str, ...]
    settings_json: str
    bake_seconds: float
    created: str

    @property
    def settings(self) -> dict[str, Any]:
        """The bake settings (a fresh dict on each call)."""
        value: dict[str, Any] = json.loads(self.settings_json)
        return value


@dataclass(frozen=True, slots=True)
class ObjectRow:
    """One object as the bake hands it to :meth:`SceneWriter.add_objects`.

    ``bbox`` is ``(minx, miny, minz, maxx, maxy, maxz)`` in scene-local metres and
    ``tris`` the triangle counts of LOD 0, 1 and 2.
    """

    id: int
    kind: str
    params: bytes
    bbox: tuple[float, float, float, float, float, float]
    tris: tuple[int, int, int] = (0, 0, 0)

    @classmethod
    def of(
        cls,
        p: BuildingParams | StreetParams,
        *,
        tris: tuple[int, int, int] = (0, 0, 0),
        bbox: Sequence[float] | None = None,
        with_source_id: bool = True,
    ) -> ObjectRow:
        """Encode ``p`` and, unless given, derive its box from the footprint.

        The derived box spans z from 0 to ``p.height`` for a building and 0 to 0 for
        a street piece; pass ``bbox`` when the grammar builds above the eaves.
        """
        if isinstance(p, BuildingParams):
            blob, kind, xy, top = (
                encode_building(p, with_source_id=with_source_id),
                "building",
                p.rings[0],
                p.height,
            )
        else:
            blob, kind, xy, top = (
                encode_street(p, with_source_id=with_source_id),
                p.kind,
                p.ring,
                0.0,
            )
        if bbox is None:
            if len(xy) == 0:
                raise StoreError(f"object {p.id}: no vertices, pass bbox explicitly")
            lo, hi = xy.min(axis=0), xy.max(axis=0)
            bbox = (float(lo[0]), float(lo[1]), 0.0, float(hi[0]), float(hi[1]), float(top))
        b = tuple(float(v) for v in bbox)
        if len(b) != 6:
            raise StoreError(f"object {p.id}: bbox: expected 6 numbers, got {len(b)}")
        return cls(p.id, kind, blob, (b[0], b[1], b[2], b[3], b[4], b[5]), tris)


@dataclass(frozen=True, slots=True)
class ObjectInfo:
    """An object's kind, box ``(minx, miny, minz, maxx, maxy, maxz)`` and LOD triangle counts."""

    id: int
    kind: str
    bbox: tuple[float, float, float, float, float, float]
    tris: tuple[int, int, int]


@dataclass(frozen=True, slots=True)
class CellRow:
    """One view cell as the bake hands it to :meth:`SceneWriter.add_cells` (no PVS yet).

    ``boundary`` is the convex outline, ``(n, 2) float64`` local metres; ``zmin`` and
    ``zmax`` the height range of viewers in it; ``neighbours`` ``(m,)`` cell ids.
    """

    id: int
    kind: str
    boundary: NDArray[np.float64]
    zmin: float
    zmax: float
    neighbours: NDArray[np.int64]


@dataclass(frozen=True, slots=True)
class CellInfo:
    """A cell read back: :class:`CellRow` fields plus its PVS.

    ``pvs`` is ``(k,) int64`` ascending object ids and ``ach`` ``(k,) float64``
    their average coverage (sums to 1; both empty for a cell that sees nothing).
    """

    id: int
    kind: str
    boundary: NDArray[np.float64]
    zmin: float
    zmax: float
    neighbours: NDArray[np.int64]
    pvs: NDArray[np.int64]
    ach: NDArray[np.float64]




# ---------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------


def _label(path: str | os.PathLike[str]) -> str:
    return os.fspath(path)


def _canonical_json(value: Any, what: str) -> str:
    try:
        return json.dumps(value, sort_keys=True, separators=(",", ":"), allow_nan=False)
    except (TypeError, ValueError) as exc:
        raise StoreError(f"{what}: not JSON-serialisable ({exc})") from exc


def _finite(x: object, what: str) -> float:
    try:
        v = float(x)  # type: ignore[arg-type]
    except (TypeError, ValueError) as exc:
        raise StoreError(f"{what}: expected a number, got {x!r:.40}") from exc
    if not math.isfinite(v):
        raise StoreError(f"{what}: expected a finite number, got {v}")
    return v


def _index(x: object, what: str) -> int:
    if isinstance(x, bool) or not isinstance(x, int | np.integer):
        raise StoreError(f"{what}: expected an integer, got {type(x).__name__}")
    v = int(x)
    if not 0 <= v < 2**63:
        raise StoreError(f"{what}: expected a non-negative int64, got {v}")
    return v


def _check_path_name(name: object) -> str:
    if not isinstance(name, str) or not 0 < len(name) <= _MAX_PATH_NAME:
        raise StoreError(f"path name: expected 1 to {_MAX_PATH_NAME} characters, got {name!r:.60}")
    if not name.isprintable():
        raise StoreError(f"path name {name!r:.60}: control characters are not allowed")
    return name


def _fsync_file(path: str) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _fsync_dir(path: str) -> None:
    # makes the rename itself durable; not possible (nor needed) on every platform
    with suppress(OSError):
        _fsync_file(os.path.dirname(os.path.abspath(path)) or ".")


def _remove_db_files(path: str) -> None:
    for suffix in ("", "-wal", "-shm", "-journal"):
        with suppress(FileNotFoundError):
            os.remove(path + suffix)


@contextmanager
def _flock(lock_path: str, *, blocking: bool, what: str) -> Iterator[None]:
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


def _tables(conn: sqlite3.Connection) -> list[str]:
    """Tables of a scene in hashing order: core first, then optional by feature order."""
    present = {r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
    order = list(_CORE_TABLES) + [t for tables in OPTIONAL_TABLES.values() for t in tables]
    return [t for t in order if t in present]


def _content_version(conn: sqlite3.Connection) -> str:
    """First 16 hex digits of sha256 over a canonical dump of the scene.

    Every table is dumped in key order as a stream of msgpack arrays (msgpack is
    self-delimiting, so the concatenation is unambiguous); ``meta`` leaves out the
    run-dependent keys in ``_VOLATILE_META``.
    """
    h = hashlib.sha256()
    for table in _tables(conn):
        h.update(msgpack.packb(["table", table]))
        if table == "meta":
            marks = ", ".join("?" * len(_VOLATILE_META))
            rows = conn.execute(
                f"SELECT key, value FROM meta WHERE key NOT IN ({marks}) ORDER BY key",
                _VOLATILE_META,
            )
        else:
            rows = conn.execute(
                f"SELECT * FROM {table} ORDER BY 1"
            )  # table names come from _tables()
        for row in rows:
            h.update(msgpack.packb(list(row), use_bin_type=True))
    return h.hexdigest()[:16]


def _settings_hash(fields: dict[str, Any]) -> str:
    return hashlib.sha256(_canonical_json(fields, "settings").encode()).hexdigest()


def _read_header(path: str | os.PathLike[str]) -> tuple[int, int, bool]:
    """Check a file's SQLite header: ``(application_id, user_version, wal)``.

    Raises
    ------
    StoreError
        Missing, not a regular file, unreadable or not SQLite.
    """
    label = _label(path)
    p = Path(path)
    if not p.exists():
        raise StoreError(f"{label}: no such file")
    if not p.is_file():
        raise StoreError(f"{label}: not a file")
    try:
        with open(p, "rb") as f:
            head = f.read(100)
    except OSError as exc:
        raise StoreError(f"{label}: cannot read ({exc.strerror})") from exc
    if len(head) < 100 or not head.startswith(_SQLITE_MAGIC):
        raise StoreError(f"{label}: not an SQLite database (so not a walkstream scene database)")
    app_id = int.from_bytes(head[68:72], "big")
    user_version = int.from_bytes(head[60:64], "big")
    return app_id, user_version, head[18] == 2 or head[19] == 2


def _check_header(path: str | os.PathLike[str]) -> bool:
    """Validate the header of a walkstream database; returns whether it is in WAL mode."""
    label = _label(path)
    app_id, user_version, wal = _read_header(path)
    if app_id != APPLICATION_ID:
        raise StoreError(
            f"{label}: an SQLite database but not a walkstream scene database "
            f"(application id {app_id:#x}, expected {APPLICATION_ID:#x})"
        )
    if user_version != SCHEMA_VERSION:
        raise StoreError(
            f"{label}: schema version {user_version}, this walkstream reads version {SCHEMA_VERSION}"
        )
    return wal


def _parse_meta(raw: dict[str, Any], label: str) -> SceneMeta:
    try:
        if raw.get("app") != "walkstream":
            raise StoreError(f"{label}: meta table does not name walkstream")
        if raw["schema_version"] != SCHEMA_VERSION:
            raise StoreError(
                f"{label}: schema version {raw['schema_version']}, this walkstream reads "
                f"version {SCHEMA_VERSION}"
            )
        if raw.get("version") is None:
            raise StoreError(
                f"{label}: an unfinished bake (no content version); bake the scene again"
            )
        features = json.loads(raw["features"])
        if not isinstance(features, list) or not all(isinstance(f, str) for f in features):
            raise StoreError(f"{label}: meta 'features' is not a list of names")
        return SceneMeta(
            schema_version=int(raw["schema_version"]),
            name=str(raw["name"]),
            version=str(raw["version"]),
            crs=str(raw["crs"]),
            origin=(float(raw["origin_x"]), float(raw["origin_y"])),
            grammar_text=str(raw["grammar"]),
            grammar_version=str(raw["grammar_version"]),
            features=tuple(features),
            settings_json=str(raw["settings"]),
            bake_seconds=float(raw["bake_seconds"]),
            created=str(raw["created"]),
        )
    except KeyError as exc:
        raise StoreError(f"{label}: meta table lacks {exc.args[0]!r}") from exc
    except (TypeError, ValueError) as exc:
        raise StoreError(f"{label}: meta table damaged ({exc})") from exc


# ---------------------------------------------------------------------------
# writer
# ---------------------------------------------------------------------------


class SceneWriter:
    """Builds a scene database for the bake; see :meth:`create`.

    Not thread-safe: one bake, one thread.  Use as a context manager or call
    :meth:`close`; leaving without :meth:`finish` keeps ``<path>.partial`` for a
    later resume and leaves ``path`` untouched.
    """

    def __init__(
        self, conn: sqlite3.Connection, path: str, work: str, resumed: bool, lock_fd: int | None
    ) -> None:
        """Private: use :meth:`create`."""
        self._conn: sqlite3.Connection | None = conn
        self._lock_fd = lock_fd
        self.path = path
        """The final database path."""
        self.work_path = work
        """The work file (``<path>.partial``)."""
        self.resumed = resumed
        """True when an interrupted bake with the same settings was reopened."""

    # -- opening -----------------------------------------------------------

    @classmethod
    def create(
        cls,
        path: str | os.PathLike[str],
        *,
        name: str,
        crs: str,
        origin: tuple[float, float],
        grammar_text: str,
        grammar_version: str,
        features: Sequence[str],
        settings: dict[str, Any],
        resume: bool = True,
    ) -> SceneWriter:
        """Open the work file ``<path>.partial`` for a bake.

        If a work file from an interrupted bake exists, ``resume`` is true and it was
        made with the same arguments (compared by a hash of all of them), it is
        reopened: :attr:`resumed` is true and :meth:`done_cells` lists the cells
        whose PVS survived.  Otherwise any old work file is discarded.

        Parameters
        ----------
        path:
            Where :meth:`finish` puts the database.
        name, crs:
            Scene name and the CRS of ``origin``.
        origin:
            CRS position of local (0, 0), projected metres.
        grammar_text, grammar_version:
            The building grammar sent to clients.
        features:
            Feature names used by the scene (cell kinds, ``"portals"``, ...); a
            feature listed in :data:`OPTIONAL_TABLES` gets its tables.
        settings:
            Bake settings (JSON-serialisable).  Include whatever identifies the input
            (e.g. a source file hash): resuming trusts that equal settings mean an
            equal scene.
        resume:
            Reuse a matching work file (default) or always start over.

        Raises
        ------
        StoreError
            Bad arguments, another process is baking the same path, or the work file
            cannot be created.
        """
        label = _label(path)
        for what, v in (("name", name), ("crs", crs), ("grammar_text", grammar_text)):
            if not isinstance(v, str):
                raise StoreError(f"{label}: {what}: expected a string, got {type(v).__name__}")
        if (
            not isinstance(features, Sequence)
            or isinstance(features, str)
            or not all(isinstance(f, str) and f for f in features)
        ):
            raise StoreError(f"{label}: features: expected a list of names, got {features!r:.80}")
        if len(set(features)) != len(features):
            raise StoreError(f"{label}: features: names repeat in {list(features)}")
        if not isinstance(settings, dict):
            raise StoreError(f"{label}: settings: expected a dict, got {type(settings).__name__}")
        if len(origin) != 2:
            raise StoreError(f"{label}: origin: expected (x, y), got {origin!r:.80}")
        ox, oy = (_finite(v, f"{label}: origin") for v in origin)
        settings_json = _canonical_json(settings, f"{label}: settings")
        fields = {
            "schema_version": SCHEMA_VERSION,
            "name": name,
            "crs": crs,
            "origin": [ox, oy],
            "grammar": grammar_text,
            "grammar_version": str(grammar_version),
            "features": list(features),
            "settings": settings,
        }
        shash = _settings_hash(fields)
        work = label + ".partial"
        if not os.path.isdir(os.path.dirname(os.path.abspath(work))):
            raise StoreError(f"{label}: the folder does not exist")

        lock_fd = os.open(work + ".lock", os.O_RDWR | os.O_CREAT, 0o644)
        try:
            if fcntl is not None:
                try:
                    fcntl.flock(lock_fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                except BlockingIOError as exc:
                    raise StoreError(f"{label}: another bake is writing {work}") from exc
            conn = cls._reopen(work, shash) if resume else None
            resumed = conn is not None
            if conn is None:
                _remove_db_files(work)
                conn = cls._new(work, fields, settings_json, shash)
        except BaseException:
            os.close(lock_fd)
            raise
        return cls(conn, label, work, resumed, lock_fd)

    @staticmethod
    def _connect(work: str, *, new: bool = False) -> sqlite3.Connection:
        conn = sqlite3.connect(work, isolation_level=None)
        try:
            if new:
                # before WAL, so that they land in the file header itself, not in the WAL
                conn.execute(f"PRAGMA application_id={APPLICATION_ID}")
                conn.execute(f"PRAGMA user_version={SCHEMA_VERSION}")
            # WAL + NORMAL: each commit is an append without fsync; a killed process
            # loses nothing committed, a power cut at most the last few cells
            conn.execute("PRAGMA journal_mode=WAL")
            conn.execute("PRAGMA synchronous=NORMAL")
        except BaseException:
            conn.close()
            raise
        return conn

    @classmethod
    def _reopen(cls, work: str, shash: str) -> sqlite3.Connection | None:
        if not os.path.isfile(work):
            return None
        try:
            _read_header(work)  # is it SQLite at all? (sqlite3 would happily overwrite junk)
            conn = cls._connect(work)
        except (StoreError, sqlite3.DatabaseError):
            return None
        try:
            # ask SQLite, not the file header: after a kill, header updates may still
            # sit in the WAL
            app_id = conn.execute("PRAGMA application_id").fetchone()[0]
            user_version = conn.execute("PRAGMA user_version").fetchone()[0]
            row = conn.execute("SELECT value FROM meta WHERE key = 'settings_hash'").fetchone()
            if (app_id, user_version) == (APPLICATION_ID, SCHEMA_VERSION) and row == (shash,):
                return conn
        except sqlite3.DatabaseError:
            pass
        conn.close()
        return None

    @classmethod
    def _new(
        cls, work: str, fields: dict[str, Any], settings_json: str, shash: str
    ) -> sqlite3.Connection:
        try:
            conn = cls._connect(work, new=True)
        except sqlite3.Error as exc:
            raise StoreError(f"{work}: cannot create ({exc})") from exc
        try:
            conn.execute("BEGIN")
            for ddl in _CORE_TABLES.values():
                conn.execute(ddl)
            for feature in fields["features"]:
                for ddl in OPTIONAL_TABLES.get(feature, {}).values():
                    conn.execute(ddl)
            meta = {
                "app": "walkstream",
                "schema_version": SCHEMA_VERSION,
                "name": fields["name"],
                "version": None,
                "crs": fields["crs"],
                "origin_x": fields["origin"][0],
                "origin_y": fields["origin"][1],
                "grammar": fields["grammar"],
                "grammar_version": fields["grammar_version"],
                "features": json.dumps(fields["features"]),
                "settings": settings_json,
                "settings_hash": shash,
                "bake_seconds": None,
                "created": None,
            }
            conn.executemany("INSERT INTO meta(key, value) VALUES (?, ?)", meta.items())
            conn.execute("COMMIT")
            return conn
        except sqlite3.Error as exc:
            conn.close()
            raise StoreError(f"{work}: cannot create ({exc})") from exc

    # -- writing -----------------------------------------------------------

    @property
    def _db(self) -> sqlite3.Connection:
        if self._conn is None:
            raise StoreError(f"{self.work_path}: the writer is closed")
        return self._conn

    def _run(self, what: str, sql: str, rows: Iterable[Sequence[Any]]) -> None:
        db = self._db
        try:
            db.execute("BEGIN")
            db.executemany(sql, rows)
            db.execute("COMMIT")
        except sqlite3.Error as exc:
            if db.in_transaction:
                db.execute("ROLLBACK")
            raise StoreError(f"{self.work_path}: {what}: {exc}") from exc
        except BaseException:
            if db.in_transaction:
                db.execute("ROLLBACK")
            raise

    def add_objects(self, rows: Iterable[ObjectRow]) -> int:
        """Insert (or, on resume, replace) objects in one transaction; returns how many."""
        out = []
        for r in rows:
            what = f"object {r.id}"
            oid = _index(r.id, what)
            if r.kind not in OBJECT_KINDS:
                raise StoreError(
                    f"{what}: kind: expected one of {'|'.join(OBJECT_KINDS)}, got {r.kind!r}"
                )
            if not isinstance(r.params, bytes) or not r.params:
                raise StoreError(f"{what}: params: expected non-empty bytes")
            b = [_finite(v, f"{what}: bbox") for v in r.bbox]
            if len(b) != 6 or b[0] > b[3] or b[1] > b[4] or b[2] > b[5]:
                raise StoreError(
                    f"{what}: bbox: expected (minx, miny, minz, maxx, maxy, maxz), got {r.bbox}"
                )
            t = [_index(v, f"{what}: tris") for v in r.tris]
            if len(t) != 3:
                raise StoreError(f"{what}: tris: expected 3 counts, got {len(t)}")
            out.append((oid, r.kind, r.params, *b, *t))
        self._run("objects", "INSERT OR REPLACE INTO objects VALUES (?,?,?,?,?,?,?,?,?,?,?,?)", out)
        return len(out)

    def add_cells(self, cells: Iterable[CellRow]) -> int:
        """Insert cells without PVS in one transaction; returns how many.

        Re-adding a cell (on resume) keeps its PVS when its kind, boundary and
        height range are unchanged and clears it otherwise.
        """
        out = []
        for c in cells:
            what = f"cell {c.id}"
            cid = _index(c.id, what)
            if c.kind not in CELL_KINDS:
                raise StoreError(
                    f"{what}: kind: expected one of {'|'.join(CELL_KINDS)}, got {c.kind!r}"
                )
            zmin, zmax = _finite(c.zmin, f"{what}: zmin"), _finite(c.zmax, f"{what}: zmax")
            if zmin > zmax:
                raise StoreError(f"{what}: zmin {zmin} > zmax {zmax}")
            try:
                boundary = encode_polygon(c.boundary)
                neighbours = encode_ids(np.asarray(c.neighbours, dtype=np.int64).reshape(-1))
            except (CodecError, ValueError, TypeError) as exc:
                raise StoreError(f"{what}: {exc}") from exc
            out.append((cid, c.kind, boundary, zmin, zmax, neighbours))
        same = (
            "cells.kind IS excluded.kind AND cells.boundary IS excluded.boundary "
            "AND cells.zmin IS excluded.zmin AND cells.zmax IS excluded.zmax"
        )
        sql = (
            "INSERT INTO cells(id, kind, boundary, zmin, zmax, neighbours, pvs, done) "
            "VALUES (?,?,?,?,?,?,NULL,0) ON CONFLICT(id) DO UPDATE SET "
            f"pvs = CASE WHEN {same} THEN cells.pvs ELSE NULL END, "
            f"done = CASE WHEN {same} THEN cells.done ELSE 0 END, "
            "kind = excluded.kind, boundary = excluded.boundary, zmin = excluded.zmin, "
            "zmax = excluded.zmax, neighbours = excluded.neighbours"
        )
        self._run("cells", sql, out)
        return len(out)

    def set_pvs(self, cell_id: int, ids: ArrayLike, ach: ArrayLike) -> None:
        """Store a cell's PVS and mark it done, committed at once.

        Parameters
        ----------
        cell_id:
            A cell added with :meth:`add_cells`.
        ids:
            ``(k,)`` object ids it can see (``k`` may be 0).
        ach:
            ``(k,)`` their coverage, e.g. pixel counts (see
            :func:`shared.codec.encode_pvs`).
        """
        cid = _index(cell_id, "cell id")
        try:
            blob = encode_pvs(
                np.asarray(ids).reshape(-1), np.asarray(ach, dtype=np.float64).reshape(-1)
            )
        except CodecError as exc:
            raise StoreError(f"cell {cid}: {exc}") from exc
        try:
            # autocommit: one statement, one transaction, so a kill loses only this cell
            cur = self._db.execute("UPDATE cells SET pvs = ?, done = 1 WHERE id = ?", (blob, cid))
        except sqlite3.Error as exc:
            raise StoreError(f"{self.work_path}: cell {cid}: {exc}") from exc
        if cur.rowcount == 0:
            raise NotFoundError(f"{self.work_path}: no cell {cid}; add it with add_cells first")

    def done_cells(self) -> set[int]:
        """Ids of the cells whose PVS is stored."""
        return {r[0] for r in self._db.execute("SELECT id FROM cells WHERE done = 1")}

    def add_viewpoint(
        self, name: str, x: float, y: float, z: float, yaw: float = 0.0, cell: int | None = None
    ) -> None:
        """Add (or replace) a named viewpoint; ``yaw`` in radians, ``cell`` None if outside every cell."""
        if not isinstance(name, str) or not name:
            raise StoreError(f"viewpoint: name: expected a non-empty string, got {name!r:.40}")
        what = f"viewpoint {name!r}"
        row = (
            name,
            *(_finite(v, what) for v in (x, y, z, yaw)),
            None if cell is None else _index(cell, f"{what}: cell"),
        )
        self._run("viewpoints", "INSERT OR REPLACE INTO viewpoints VALUES (?,?,?,?,?,?)", [row])

    def add_path(self, name: str, blob: bytes) -> None:
        """Add (or replace) a recorded path during the bake (see also :func:`write_path`)."""
        name = _check_path_name(name)
        if not isinstance(blob, bytes) or len(blob) > _MAX_PATH_BYTES:
            raise StoreError(f"path {name!r}: expected bytes of at most {_MAX_PATH_BYTES}")
        self._run("paths", "INSERT OR REPLACE INTO paths VALUES (?, ?)", [(name, blob)])

    # -- finishing -----------------------------------------------------------

    def finish(self, bake_seconds: float) -> str:
        """Seal the bake: hash, compact into one file and atomically replace ``path``.

        Every cell must have its PVS.  The database is vacuumed into a fresh file
        beside ``path`` (no WAL, no free pages), fsynced and moved onto ``path`` with
        ``os.replace``; then the work file is removed.  If anything fails, ``path``
        is untouched and the work file stays for a resume.

        Returns
        -------
        str
            The scene version: the first 16 hex digits of the content hash.
        """
        db = self._db
        seconds = _finite(bake_seconds, "bake_seconds")
        missing = [
            r[0] for r in db.execute("SELECT id FROM cells WHERE done = 0 ORDER BY id LIMIT 6")
        ]
        if missing:
            n = db.execute("SELECT count(*) FROM cells WHERE done = 0").fetchone()[0]
            raise StoreError(
                f"{self.work_path}: {n} cells have no PVS yet (ids {missing[:5]}"
                f"{', ...' if n > 5 else ''}); set_pvs every cell before finish()"
            )
        created = _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")
        tmp = f"{self.path}.tmp-{os.getpid()}-{secrets.token_hex(4)}"
        try:
            db.execute("BEGIN")
            db.execute("UPDATE meta SET value = ? WHERE key = 'bake_seconds'", (seconds,))
            db.execute("UPDATE meta SET value = ? WHERE key = 'created'", (created,))
            version = _content_version(db)
            db.execute("UPDATE meta SET value = ? WHERE key = 'version'", (version,))
            db.execute("COMMIT")
            # VACUUM INTO writes a compact rollback-journal file: no -wal to carry along
            db.execute("VACUUM INTO ?", (tmp,))
            _fsync_file(tmp)
            with _flock(self.path + ".lock", blocking=True, what=self.path):
                os.replace(tmp, self.path)
            _fsync_dir(self.path)
        except sqlite3.Error as exc:
            if db.in_transaction:
                db.execute("ROLLBACK")
            with suppress(FileNotFoundError):
                os.remove(tmp)
            raise StoreError(f"{self.path}: cannot finish ({exc})") from exc
        except BaseException:
            with suppress(FileNotFoundError):
                os.remove(tmp)
            raise
        db.close()
        self._conn = None
        _remove_db_files(self.work_path)
        # safe to unlink while held: a rival create() never waits on this lock, it
        # fails at once, and one arriving later may start afresh
        with suppress(FileNotFoundError):
            os.remove(self.work_path + ".lock")
        self.close()
        return version

    def close(self) -> None:
        """Close without finishing (the work file stays for a resume); idempotent."""
        if self._conn is not None:
            self._conn.close()
            self._conn = None
        if self._lock_fd is not None:
            os.close(self._lock_fd)
            self._lock_fd = None

    def __enter__(self) -> SceneWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


# ---------------------------------------------------------------------------
# reader
# ---------------------------------------------------------------------------


class SceneReader:
    """Read-only access to a finished scene database; see :meth:`open`.

    Thread-safe: queries borrow a connection from a small pool, all opened on the
    same file at :meth:`open`, so every thread sees the same scene version even if
    :func:`write_path` replaces the file meanwhile (open a new reader to see it).
    """

    def __init__(
        self, label: str, pool: list[sqlite3.Connection], meta: SceneMeta, db_bytes: int
    ) -> None:
        """Private: use :meth:`open`."""
        self._label = label
        self._all = pool
        self._pool: queue.SimpleQueue[sqlite3.Connection] = queue.SimpleQueue()
        for c in pool:
            self._pool.put(c)
        self._meta = meta
        self._db_bytes = db_bytes
        self._closed = False
        self._summary: dict[str, Any] | None = None
        self._summary_lock = threading.Lock()

    @classmethod
    def open(
        cls, path: str | os.PathLike[str], *, pool_size: int = 4, check: bool = False
    ) -> SceneReader:
        """Open and validate a scene database read-only.

        Opening reads the header, the schema and the meta table; damage elsewhere
        shows when the damaged part is read (as :class:`StoreError`, or
        :class:`shared.errors.CodecError` for a damaged blob).  ``check=True`` also
        runs SQLite's ``quick_check`` over the whole file (linear in its size).

        Parameters
        ----------
        path:
            The database file.
        pool_size:
            Connections shared by the threads that use this reader.
        check:
            Verify every page now.

        Raises
        ------
        StoreError
            Not a file, not SQLite, not a walkstream database, a schema version this
            code does not read, an unfinished bake, or a damaged file.  The message
            starts with the file name.
        """
        label = _label(path)
        wal = _check_header(path)
        uri = Path(os.path.abspath(path)).as_uri() + "?mode=ro"
        if not wal:
            # finished files are never modified in place (only replaced), so SQLite
            # may skip locking and change detection
            uri += "&immutable=1"
        for _attempt in range(3):
            size = os.path.getsize(path)
            pool: list[sqlite3.Connection] = []
            try:
                for _ in range(max(1, pool_size)):
                    pool.append(sqlite3.connect(uri, uri=True, check_same_thread=False))
                metas = [cls._load_meta(c, label) for c in pool]
                if check:
                    cls._quick_check(pool[0], label)
            except BaseException:
                for c in pool:
                    c.close()
                raise
            if all(m.version == metas[0].version for m in metas):
                return cls(label, pool, metas[0], size)
            for c in pool:  # replaced while opening: try again
                c.close()
        raise StoreError(f"{label}: the file keeps changing while being opened")

    @staticmethod
    def _load_meta(conn: sqlite3.Connection, label: str) -> SceneMeta:
        try:
            tables = {
                r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type = 'table'")
            }
            missing = [t for t in _CORE_TABLES if t not in tables and t != "paths"]
            if missing:
                raise StoreError(
                    f"{label}: not a walkstream scene database (no table {missing[0]!r})"
                )
            raw = dict(conn.execute("SELECT key, value FROM meta").fetchall())
            meta = _parse_meta(raw, label)
            conn.execute("SELECT count(*) FROM objects").fetchone()
            conn.execute("SELECT count(*) FROM cells").fetchone()
            return meta
        except sqlite3.DatabaseError as exc:
            raise StoreError(f"{label}: damaged database ({exc})") from exc

    @staticmethod
    def _quick_check(conn: sqlite3.Connection, label: str) -> None:
        try:
            rows = conn.execute("PRAGMA quick_check(5)").fetchall()
        except sqlite3.DatabaseError as exc:
            raise StoreError(f"{label}: damaged database ({exc})") from exc
        if rows != [("ok",)]:
            detail = "; ".join(str(r[0]) for r in rows)
            raise StoreError(f"{label}: damaged database ({detail})")

    # -- plumbing -----------------------------------------------------------

    @contextmanager
    def _conn(self) -> Iterator[sqlite3.Connection]:
        if self._closed:
            raise StoreError(f"{self._label}: the reader is closed")
        conn = self._pool.get()
        try:
            yield conn
        except sqlite3.DatabaseError as exc:
            raise StoreError(f"{self._label}: damaged database ({exc})") from exc
        finally:
            self._pool.put(conn)

    def _query(self, sql: str, args: Sequence[Any] = ()) -> list[Any]:
        with self._conn() as c:
            return c.execute(sql, args).fetchall()

    def _by_ids(self, columns: str, ids: Iterable[int]) -> list[Any]:
        want = sorted({_index(i, "object id") for i in ids})
        out: list[Any] = []
        with self._conn() as c:
            for k in range(0, len(want), 500):  # stay below SQLite's bound-variable limit
                chunk = want[k : k + 500]
                marks = ",".join("?" * len(chunk))
                out += c.execute(
                    f"SELECT {columns} FROM objects WHERE id IN ({marks})", chunk
                ).fetchall()
        return out

    def close(self) -> None:
        """Close every connection (waits for the ones in use); idempotent."""
        if self._closed:
            return
        self._closed = True
        for _ in self._all:
            self._pool.get().close()

    def __enter__(self) -> SceneReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- scene ---------------------------------------------------------------

    @property
    def path(self) -> str:
        """The file this reader was opened on."""
        return self._label

    @property
    def meta(self) -> SceneMeta:
        """The scene's meta data."""
        return self._meta

    @property
    def version(self) -> str:
        """The scene version (content hash); use it as the ETag."""
        return self._meta.version

    def object_ids(self) -> NDArray[np.int64]:
        """All object ids, ``(n,) int64`` ascending."""
        rows = self._query("SELECT id FROM objects ORDER BY id")
        return np.array([r[0] for r in rows], dtype=np.int64)

    def object_params(self, ids: Iterable[int]) -> dict[int, bytes]:
        """Raw encoded parameters of the given objects, for streaming as they are.

        Unknown ids are left out of the result (the caller decides whether that is
        an error).  The dict is ordered by id.
        """
        return {int(r[0]): bytes(r[1]) for r in self._by_ids("id, params", ids)}

    def object_info(self, ids: Iterable[int]) -> dict[int, ObjectInfo]:
        """Kind, box and LOD triangle counts of the given objects (unknown ids left out)."""
        rows = self._by_ids(
            "id, kind, minx, miny, minz, maxx, maxy, maxz, tris0, tris1, tris2", ids
        )
        out: dict[int, ObjectInfo] = {}
        for oid, kind, x0, y0, z0, x1, y1, z1, t0, t1, t2 in rows:
            box = (float(x0), float(y0), float(z0), float(x1), float(y1), float(z1))
            out[int(oid)] = ObjectInfo(int(oid), str(kind), box, (int(t0), int(t1), int(t2)))
        return out

    def _object(self, oid: int, kinds: tuple[str, ...], what: str) -> bytes:
        i = _index(oid, "object id")
        rows = self._query("SELECT kind, params FROM objects WHERE id = ?", (i,))
        if not rows:
            raise NotFoundError(f"{self._label}: no object {i}")
        kind, params = rows[0]
        if kind not in kinds:
            raise StoreError(f"{self._label}: object {i} is a {kind}, not a {what}")
        return bytes(params)

    def building(self, oid: int) -> BuildingParams:
        """The decoded parameters of building ``oid``.

        Raises
        ------
        NotFoundError
            No such object.
        StoreError
            The object is not a building.
        CodecError
            Its stored parameters are damaged.
        """
        blob = self._object(oid, ("building",), "building")
        return decode_building(blob, f"{self._label}: building {oid}")

    def street(self, oid: int) -> StreetParams:
        """The decoded parameters of street piece (street, crossroad or square) ``oid``."""
        blob = self._object(oid, ("street", "crossroad", "square"), "street piece")
        return decode_street(blob, f"{self._label}: street {oid}")

    def bounds(self) -> tuple[float, float, float, float, float, float]:
        """Box over all objects ``(minx, miny, minz, maxx, maxy, maxz)``; zeros for an empty scene."""
        row = self._query(
            "SELECT min(minx), min(miny), min(minz), max(maxx), max(maxy), max(maxz) FROM objects"
        )[0]
        if row[0] is None:
            return (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        return tuple(float(v) for v in row)  # type: ignore[return-value]

    # -- cells ---------------------------------------------------------------

    def _cell_info(self, row: Sequence[Any]) -> CellInfo:
        cid, kind, boundary, zmin, zmax, neighbours, pvs = row
        what = f"{self._label}: cell {cid}"
        if pvs is None:
            ids, ach = np.zeros(0, np.int64), np.zeros(0, np.float64)
        else:
            ids, ach = decode_pvs(pvs, f"{what}: pvs")
        nb = decode_ids(neighbours, f"{what}: neighbours")
        for a in (ids, ach, nb):
            a.flags.writeable = False
        return CellInfo(
            id=int(cid),
            kind=str(kind),
            boundary=decode_polygon(boundary, f"{what}: boundary"),
            zmin=float(zmin),
            zmax=float(zmax),
            neighbours=nb,
            pvs=ids,
            ach=ach,
        )

    _CELL_COLUMNS = "id, kind, boundary, zmin, zmax, neighbours, pvs"

    def cell(self, cid: int) -> CellInfo:
        """Cell ``cid`` with its boundary, neighbours, PVS and ACH.

        Raises
        ------
        NotFoundError
            No such cell.
        """
        i = _index(cid, "cell id")
        rows = self._query(f"SELECT {self._CELL_COLUMNS} FROM cells WHERE id = ?", (i,))
        if not rows:
            raise NotFoundError(f"{self._label}: no cell {i}")
        return self._cell_info(rows[0])

    def cell_pvs_blob(self, cid: int) -> bytes:
        """Cell ``cid``'s PVS as stored (:func:`shared.codec.encode_pvs` bytes), for streaming."""
        i = _index(cid, "cell id")
        rows = self._query("SELECT pvs FROM cells WHERE id = ?", (i,))
        if not rows:
            raise NotFoundError(f"{self._label}: no cell {i}")
        return bytes(rows[0][0]) if rows[0][0] is not None else b"\x01\x00"

    def cells(self) -> Iterator[CellInfo]:
        """All cells in id order (fetched in pages, so no connection is held between them)."""
        last = -1
        while True:
            rows = self._query(
                f"SELECT {self._CELL_COLUMNS} FROM cells WHERE id > ? ORDER BY id LIMIT 256",
                (last,),
            )
            if not rows:
                return
            for r in rows:
                yield self._cell_info(r)
            last = rows[-1][0]

    # -- viewpoints and paths ------------------------------------------------

    def viewpoints(self) -> tuple[Viewpoint, ...]:
        """Named viewpoints, by name."""
        rows = self._query("SELECT name, x, y, z, yaw, cell FROM viewpoints ORDER BY name")
        return tuple(
            Viewpoint(str(n), float(x), float(y), float(z), float(w), c)
            for n, x, y, z, w, c in rows
        )

    def _has_paths(self) -> bool:
        rows = self._query("SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = 'paths'")
        return bool(rows)

    def path_names(self) -> list[str]:
        """Names of the recorded paths, sorted."""
        if not self._has_paths():
            return []
        return [r[0] for r in self._query("SELECT name FROM paths ORDER BY name")]

    def path_blob(self, name: str) -> bytes:
        """The stored bytes of recorded path ``name``.

        Raises
        ------
        NotFoundError
            No such path.
        """
        rows = (
            self._query("SELECT data FROM paths WHERE name = ?", (name,))
            if self._has_paths()
            else []
        )
        if not rows:
            raise NotFoundError(f"{self._label}: no recorded path {name!r:.60}")
        return bytes(rows[0][0])

    # -- summary -------------------------------------------------------------

    def summary(self) -> dict[str, Any]:
        """Figures about the scene (computed once, the file is immutable).

        Returns
        -------
        dict
            ``name``, ``version``, ``cells``, ``objects``, ``pvs_mean`` and
            ``pvs_max`` (objects per PVS), ``culled_ratio`` (mean over cells of
            ``1 - |PVS| / objects``), ``bake_seconds``, ``db_bytes``,
            ``schema_version``, ``features``, ``paths``.
        """
        with self._summary_lock:
            if self._summary is None:
                self._summary = self._compute_summary()
            return dict(self._summary)

    def _compute_summary(self) -> dict[str, Any]:
        n_objects = int(self._query("SELECT count(*) FROM objects")[0][0])
        sizes = np.array(
            [
                0 if b is None else pvs_size(b, f"{self._label}: cell {i}: pvs")
                for i, b in self._query("SELECT id, pvs FROM cells")
            ],
            dtype=np.float64,
        )
        n_cells = len(sizes)
        culled = float(np.mean(1.0 - sizes / n_objects)) if n_cells and n_objects else 0.0
        m = self._meta
        return {
            "name": m.name,
            "version": m.version,
            "cells": n_cells,
            "objects": n_objects,
            "pvs_mean": float(sizes.mean()) if n_cells else 0.0,
            "pvs_max": int(sizes.max()) if n_cells else 0,
            "culled_ratio": culled,
            "bake_seconds": m.bake_seconds,
            "db_bytes": self._db_bytes,
            "schema_version": m.schema_version,
            "features": list(m.features),
            "paths": len(self.path_names()),
        }


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
    label = _label(path_db)
    name = _check_path_name(name)
    if not isinstance(blob, bytes) or len(blob) > _MAX_PATH_BYTES:
        raise StoreError(f"path {name!r}: expected bytes of at most {_MAX_PATH_BYTES}")
    _check_header(path_db)
    tmp = f"{label}.tmp-{os.getpid()}-{secrets.token_hex(4)}"
    try:
        with _flock(label + ".lock", blocking=True, what=label):
            shutil.copyfile(path_db, tmp)
            _check_header(tmp)
            conn = sqlite3.connect(tmp, isolation_level=None)
            try:
                SceneReader._load_meta(conn, label)  # a finished walkstream scene?
                conn.execute("BEGIN")
                conn.execute(
                    _CORE_TABLES["paths"].replace("CREATE TABLE", "CREATE TABLE IF NOT EXISTS")
                )
                conn.execute("INSERT OR REPLACE INTO paths(name, data) VALUES (?, ?)", (name, blob))
                version = _content_version(conn)
                conn.execute("UPDATE meta SET value = ? WHERE key = 'version'", (version,))
                conn.execute("COMMIT")
            except sqlite3.DatabaseError as exc:
                raise StoreError(f"{label}: cannot write path {name!r} ({exc})") from exc
            finally:
                conn.close()
            _fsync_file(tmp)
            os.replace(tmp, path_db)
        _fsync_dir(label)
    finally:
        with suppress(FileNotFoundError):
            os.remove(tmp)
        with suppress(FileNotFoundError):
            os.remove(tmp + "-journal")
    return version
