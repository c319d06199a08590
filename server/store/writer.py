"""Build a scene database for the bake: atomic, resumable (:class:`SceneWriter`)."""

from __future__ import annotations

import datetime as _dt
import json
import math
import os
import secrets
import sqlite3
from collections.abc import Iterable, Sequence
from contextlib import suppress
from typing import Any

import msgpack
import numpy as np
from numpy.typing import ArrayLike

from walkstream.shared.codec import (
    decode_pvs,
    encode_ids,
    encode_polygon,
    encode_pvs,
)
from walkstream.shared.errors import CodecError, NotFoundError, StoreError
from walkstream.shared.scene.cellkinds import CELL_KINDS

try:  # advisory locks between processes; POSIX only
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None  # type: ignore[assignment]
from walkstream.server.store.files import (
    db_label,
    exclusive_lock,
    fsync_dir,
    fsync_file,
    remove_db_files,
)
from walkstream.server.store.records import (
    MAX_PATH_BYTES,
    CellRow,
    ContentsInfo,
    EntranceInfo,
    ObjectRow,
    PortalInfo,
    RoomInfo,
    StairInfo,
    StoreyInfo,
    check_path_name,
    f64_blob,
    finite_number,
    row_index,
)
from walkstream.server.store.schema import (
    APPLICATION_ID,
    CORE_TABLES,
    OBJECT_KINDS,
    OPTIONAL_TABLES,
    SCHEMA_VERSION,
    canonical_json,
    content_version,
    read_header,
    schema_version_of,
    settings_hash,
)

__all__ = ["SceneWriter"]


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
        label = db_label(path)
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
        ox, oy = (finite_number(v, f"{label}: origin") for v in origin)
        settings_json = canonical_json(settings, f"{label}: settings")
        version = schema_version_of(features)
        fields = {
            "schema_version": version,
            "name": name,
            "crs": crs,
            "origin": [ox, oy],
            "grammar": grammar_text,
            "grammar_version": str(grammar_version),
            "features": list(features),
            "settings": settings,
        }
        shash = settings_hash(fields)
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
            conn = cls._reopen(work, shash, version) if resume else None
            resumed = conn is not None
            if conn is None:
                remove_db_files(work)
                conn = cls._new(work, fields, settings_json, shash)
        except BaseException:
            os.close(lock_fd)
            raise
        return cls(conn, label, work, resumed, lock_fd)

    @staticmethod
    def _connect(work: str, *, new: bool = False, version: int = SCHEMA_VERSION) -> sqlite3.Connection:
        conn = sqlite3.connect(work, isolation_level=None)
        try:
            if new:
                # before WAL, so that they land in the file header itself, not in the WAL
                conn.execute(f"PRAGMA application_id={APPLICATION_ID}")
                conn.execute(f"PRAGMA user_version={int(version)}")
            # WAL + NORMAL: each commit is an append without fsync; a killed process
            # loses nothing committed, a power cut at most the last few cells
            conn.execute("PRAGMA journal_mode=WAL")
            conn.execute("PRAGMA synchronous=NORMAL")
        except BaseException:
            conn.close()
            raise
        return conn

    @classmethod
    def _reopen(cls, work: str, shash: str, version: int) -> sqlite3.Connection | None:
        if not os.path.isfile(work):
            return None
        try:
            read_header(work)  # is it SQLite at all? (sqlite3 would happily overwrite junk)
            conn = cls._connect(work)
        except (StoreError, sqlite3.DatabaseError):
            return None
        try:
            # ask SQLite, not the file header: after a kill, header updates may still
            # sit in the WAL
            app_id = conn.execute("PRAGMA application_id").fetchone()[0]
            user_version = conn.execute("PRAGMA user_version").fetchone()[0]
            row = conn.execute("SELECT value FROM meta WHERE key = 'settings_hash'").fetchone()
            if (app_id, user_version) == (APPLICATION_ID, version) and row == (shash,):
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
            conn = cls._connect(work, new=True, version=fields["schema_version"])
        except sqlite3.Error as exc:
            raise StoreError(f"{work}: cannot create ({exc})") from exc
        try:
            conn.execute("BEGIN")
            for ddl in CORE_TABLES.values():
                conn.execute(ddl)
            for feature in fields["features"]:
                for ddl in OPTIONAL_TABLES.get(feature, {}).values():
                    conn.execute(ddl)
            meta = {
                "app": "walkstream",
                "schema_version": fields["schema_version"],
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
            oid = row_index(r.id, what)
            if r.kind not in OBJECT_KINDS:
                raise StoreError(
                    f"{what}: kind: expected one of {'|'.join(OBJECT_KINDS)}, got {r.kind!r}"
                )
            if not isinstance(r.params, bytes) or not r.params:
                raise StoreError(f"{what}: params: expected non-empty bytes")
            b = [finite_number(v, f"{what}: bbox") for v in r.bbox]
            if len(b) != 6 or b[0] > b[3] or b[1] > b[4] or b[2] > b[5]:
                raise StoreError(
                    f"{what}: bbox: expected (minx, miny, minz, maxx, maxy, maxz), got {r.bbox}"
                )
            t = [row_index(v, f"{what}: tris") for v in r.tris]
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
            cid = row_index(c.id, what)
            if c.kind not in CELL_KINDS:
                raise StoreError(
                    f"{what}: kind: expected one of {'|'.join(CELL_KINDS)}, got {c.kind!r}"
                )
            zmin, zmax = finite_number(c.zmin, f"{what}: zmin"), finite_number(c.zmax, f"{what}: zmax")
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
            :func:`~walkstream.shared.codec.encode_pvs`).
        """
        cid = row_index(cell_id, "cell id")
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
            *(finite_number(v, what) for v in (x, y, z, yaw)),
            None if cell is None else row_index(cell, f"{what}: cell"),
        )
        self._run("viewpoints", "INSERT OR REPLACE INTO viewpoints VALUES (?,?,?,?,?,?)", [row])

    def add_path(self, name: str, blob: bytes) -> None:
        """Add (or replace) a recorded path during the bake (see also :func:`write_path`)."""
        name = check_path_name(name)
        if not isinstance(blob, bytes) or len(blob) > MAX_PATH_BYTES:
            raise StoreError(f"path {name!r}: expected bytes of at most {MAX_PATH_BYTES}")
        self._run("paths", "INSERT OR REPLACE INTO paths VALUES (?, ?)", [(name, blob)])

    # -- interiors (features rooms, portals, meshes) ---------------------------

    def _require(self, table: str, feature: str) -> None:
        row = self._db.execute(
            "SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = ?", (table,)
        ).fetchone()
        if row is None:
            raise StoreError(f"{self.work_path}: no {table} table: list the feature {feature!r}")

    def add_storeys(self, rows: Iterable[StoreyInfo]) -> int:
        """Insert (or replace) the storeys of an interior; returns how many."""
        self._require("storeys", "rooms")
        out = []
        for r in rows:
            what = f"storey {r.id}"
            out.append((row_index(r.id, what), str(r.name), finite_number(r.zmin, what), finite_number(r.zmax, what)))
        self._run("storeys", "INSERT OR REPLACE INTO storeys VALUES (?,?,?,?)", out)
        return len(out)

    def add_rooms(self, rows: Iterable[RoomInfo]) -> int:
        """Insert (or replace) the room data of interior cells; returns how many."""
        self._require("rooms", "rooms")
        out = []
        for r in rows:
            what = f"cell {r.cell}"
            storey = int(r.storey)
            out.append((row_index(r.cell, what), str(r.name), r.room, storey, f64_blob(r.planes, 4, f"{what}: planes")))
        self._run("rooms", "INSERT OR REPLACE INTO rooms VALUES (?,?,?,?,?)", out)
        return len(out)

    def add_portals(self, rows: Iterable[PortalInfo]) -> int:
        """Insert (or replace) portals; returns how many."""
        self._require("portals", "portals")
        out = []
        for r in rows:
            what = f"portal {r.id}"
            poly = f64_blob(r.polygon, 3, f"{what}: polygon")
            if len(poly) < 3 * 24:
                raise StoreError(f"{what}: a polygon needs at least 3 points")
            out.append((row_index(r.id, what), row_index(r.a, what), row_index(r.b, what), poly, str(r.kind),
                        str(r.source), str(r.name)))
        self._run("portals", "INSERT OR REPLACE INTO portals VALUES (?,?,?,?,?,?,?)", out)
        return len(out)

    def add_stairs(self, rows: Iterable[StairInfo]) -> int:
        """Insert (or replace) stairs; returns how many."""
        self._require("stairs", "portals")
        out = []
        for r in rows:
            what = f"stair {r.id}"
            out.append((row_index(r.id, what), row_index(r.portal, what), row_index(r.lower, what), row_index(r.upper, what),
                        f64_blob(r.path, 3, f"{what}: path"), str(r.name)))
        self._run("stairs", "INSERT OR REPLACE INTO stairs VALUES (?,?,?,?,?,?)", out)
        return len(out)

    def add_contents(self, info: ContentsInfo, blob: bytes) -> None:
        """Store (or replace) a cell's encoded contents (``walkstream-cellmesh/2 or /1``)."""
        self._require("contents", "meshes")
        what = f"cell {info.cell}: contents"
        if not isinstance(blob, bytes) or not blob:
            raise StoreError(f"{what}: expected non-empty bytes")
        row = (row_index(info.cell, what), blob, row_index(info.triangles, what), row_index(info.vertices, what),
               row_index(info.parts, what), row_index(info.raw_bytes, what), finite_number(info.max_error, what))
        self._run("contents", "INSERT OR REPLACE INTO contents VALUES (?,?,?,?,?,?,?)", [row])

    def add_entrances(self, rows: Iterable[EntranceInfo]) -> int:
        """Insert (or replace) the entrances of a crossing scene; returns how many."""
        self._require("entrances", "entrances")
        out = []
        placed = []
        for r in rows:
            what = f"entrance {r.portal}"
            out.append(tuple(row_index(v, what) for v in (r.portal, r.building, r.street, r.doorway, r.shell)))
            p = r.placement
            if p is not None:
                if p.cells[0] > p.cells[1]:
                    raise StoreError(f"{what}: placement's cells {p.cells[0]} .. {p.cells[1]}: first after last")
                placed.append((row_index(r.portal, what), finite_number(p.angle, what), finite_number(p.shift[0], what),
                               finite_number(p.shift[1], what), finite_number(p.dz, what),
                               row_index(p.cells[0], what), row_index(p.cells[1], what)))
        self._run("entrances", "INSERT OR REPLACE INTO entrances VALUES (?,?,?,?,?)", out)
        if placed:
            self._run("placements", "INSERT OR REPLACE INTO placements VALUES (?,?,?,?,?,?,?)", placed)
        return len(out)

    # -- impostors (feature impostors) -----------------------------------------

    def stored_pvs(self) -> dict[int, np.ndarray]:
        """Each done cell's PVS object ids, by cell id (the impostor step plans from them)."""
        out = {}
        for cid, blob in self._db.execute("SELECT id, pvs FROM cells WHERE done = 1 AND pvs IS NOT NULL"):
            try:
                out[int(cid)] = decode_pvs(blob, f"cell {cid}: pvs")[0]
            except CodecError as exc:
                raise StoreError(f"{self.work_path}: {exc}") from exc
        return out

    def stored_coverage(self, cell_id: int, ids: ArrayLike) -> np.ndarray:
        """``(k,)`` the stored coverage of objects ``ids`` ``(k,)`` in cell ``cell_id``'s PVS
        (0 for one not in it): a PVS cut to a subset keeps its objects' figures."""
        cid = row_index(cell_id, "cell id")
        want = np.asarray(ids, np.int64).reshape(-1)
        row = self._db.execute("SELECT pvs FROM cells WHERE id = ? AND pvs IS NOT NULL", (cid,)).fetchone()
        if row is None:
            return np.zeros(len(want))
        try:
            have, ach = decode_pvs(row[0], f"cell {cid}: pvs")[:2]
        except CodecError as exc:
            raise StoreError(f"{self.work_path}: {exc}") from exc
        by_id = dict(zip(np.asarray(have, np.int64).tolist(), np.asarray(ach, np.float64).tolist(), strict=True))
        return np.array([by_id.get(int(i), 0.0) for i in want], np.float64)

    def add_impostor(self, image: int, obj: int, bin_: tuple[int, int, int], size: int, media: str, data: bytes) -> None:
        """Store (or replace) one impostor image, committed at once (a kill loses only those in flight).

        ``bin_`` is its ``(level, azimuth bin, elevation bin)``
        (:mod:`walkstream.shared.impostors`), ``size`` its side in texels, ``media``
        the file's media type.
        """
        self._require("impostors", "impostors")
        what = f"impostor {image}"
        if not isinstance(data, bytes) or not data:
            raise StoreError(f"{what}: expected non-empty bytes")
        row = (row_index(image, what), row_index(obj, what), *(row_index(v, what) for v in bin_),
               row_index(size, what), str(media), data)
        self._run("impostors", "INSERT OR REPLACE INTO impostors VALUES (?,?,?,?,?,?,?,?)", [row])

    def done_impostors(self) -> set[int]:
        """Ids of the impostor images stored (empty without the feature)."""
        if not self._db.execute("SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = 'impostors'").fetchone():
            return set()
        return {int(r[0]) for r in self._db.execute("SELECT id FROM impostors")}

    def set_cell_impostors(self, cells: Iterable[tuple[int, list[list[int]]]]) -> int:
        """Store (or replace) which objects each cell draws as impostors: ``(cell, rows)`` with
        rows ``[object, level, az0, n_az, el0, n_el, image ids...]``; returns how many cells."""
        self._require("cell_impostors", "impostors")
        out = []
        for cid, rows in cells:
            what = f"cell {cid}: impostors"
            clean = [[row_index(v, what) for v in r] for r in rows]
            out.append((row_index(cid, what), msgpack.packb(clean)))
        self._run("cell_impostors", "INSERT OR REPLACE INTO cell_impostors VALUES (?,?)", out)
        return len(out)

    # -- virtual walls (feature walls) ----------------------------------------

    def add_wall_texture(self, tid: int, portal: int, side: int, zone: int, width: int, height: int, media: str,
                         data: bytes) -> None:
        """Store (or replace) one wall texture, committed at once (a kill loses only those in flight)."""
        self._require("wall_textures", "walls")
        what = f"wall texture {tid}"
        if not isinstance(data, bytes) or not data:
            raise StoreError(f"{what}: expected non-empty bytes")
        row = (*(row_index(v, what) for v in (tid, portal, side, zone, width, height)), str(media), data)
        self._run("wall_textures", "INSERT OR REPLACE INTO wall_textures VALUES (?,?,?,?,?,?,?,?)", [row])

    def done_wall_textures(self) -> set[int]:
        """Ids of the wall textures stored (empty without the feature)."""
        if not self._db.execute("SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = 'wall_textures'").fetchone():
            return set()
        return {int(r[0]) for r in self._db.execute("SELECT id FROM wall_textures")}

    def wall_texture_bytes(self) -> int:
        """Bytes of every stored wall texture."""
        if not self.done_wall_textures():
            return 0
        return int(self._db.execute("SELECT COALESCE(SUM(length(data)), 0) FROM wall_textures").fetchone()[0])

    def set_wall_sides(self, rows: Iterable[list[float | int]]) -> int:
        """Store (or replace) the wall sides (``WallSide.to_row`` each); returns how many."""
        self._require("wall_sides", "walls")
        out = []
        for r in rows:
            what = f"wall {r[0]}/{r[1]}"
            if not all(math.isfinite(float(v)) for v in r):
                raise StoreError(f"{what}: not finite")
            out.append((row_index(int(r[0]) * 2 + int(r[1]), what), msgpack.packb([float(v) for v in r[:13]]
                        + [int(v) for v in r[13:]])))
        self._run("wall_sides", "INSERT OR REPLACE INTO wall_sides VALUES (?,?)", out)
        return len(out)

    def set_ring_far(self, cell_id: int, ids: ArrayLike, ach: ArrayLike, share: float) -> None:
        """Store the objects ``ids`` ``(k,)`` (coverage ``ach`` ``(k,)``) a ring's textures
        carry for cell ``cell_id`` (those its geometry PVS lost to the ring), and their
        share (0..1) of the cell's whole coverage."""
        self._require("ring_far", "walls")
        cid = row_index(cell_id, "cell id")
        if not 0.0 <= float(share) <= 1.0:
            raise StoreError(f"cell {cid}: ring far field: share {share!r:.20} outside [0, 1]")
        try:
            blob = encode_pvs(np.asarray(ids).reshape(-1), np.asarray(ach, dtype=np.float64).reshape(-1))
        except CodecError as exc:
            raise StoreError(f"cell {cid}: ring far field: {exc}") from exc
        self._run("ring_far", "INSERT OR REPLACE INTO ring_far VALUES (?,?,?)", [(cid, blob, float(share))])

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
        seconds = finite_number(bake_seconds, "bake_seconds")
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
            version = content_version(db)
            db.execute("UPDATE meta SET value = ? WHERE key = 'version'", (version,))
            db.execute("COMMIT")
            # VACUUM INTO writes a compact rollback-journal file: no -wal to carry along
            db.execute("VACUUM INTO ?", (tmp,))
            fsync_file(tmp)
            with exclusive_lock(self.path + ".lock", blocking=True, what=self.path):
                os.replace(tmp, self.path)
            fsync_dir(self.path)
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
        remove_db_files(self.work_path)
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
