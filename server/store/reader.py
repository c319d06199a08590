"""Read-only access to a finished scene database (:class:`SceneReader`)."""

from __future__ import annotations

import os
import queue
import sqlite3
import threading
from collections.abc import Iterable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import msgpack
import numpy as np
from numpy.typing import NDArray

from walkstream.shared.codec import (
    decode_area,
    decode_building,
    decode_ids,
    decode_polygon,
    decode_pvs,
    decode_street,
    pvs_size,
)
from walkstream.shared.content.cellmesh import KIND as CELLMESH
from walkstream.shared.content.params import KIND as PARAMS
from walkstream.shared.content.registry import content_kind
from walkstream.shared.errors import CodecError, DatabaseDamagedError, NotFoundError, StoreError
from walkstream.shared.records import AreaParams, BuildingParams, StreetParams, Viewpoint
from walkstream.shared.scene.placement import ContentsPlacement

try:  # advisory locks between processes; POSIX only
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None  # type: ignore[assignment]
from walkstream.server.store.files import db_label
from walkstream.server.store.records import (
    CellInfo,
    ContentsInfo,
    EntranceInfo,
    ObjectInfo,
    PortalInfo,
    RoomInfo,
    SceneMeta,
    StairInfo,
    StoreyInfo,
    f64_array,
    finite_number,
    parse_meta,
    row_index,
)
from walkstream.server.store.schema import CORE_TABLES, check_header

__all__ = ["SceneReader"]


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
        :class:`~walkstream.shared.errors.CodecError` for a damaged blob).  ``check=True`` also
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
        label = db_label(path)
        wal = check_header(path)
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
            missing = [t for t in CORE_TABLES if t not in tables and t != "paths"]
            if missing:
                raise StoreError(
                    f"{label}: not a walkstream scene database (no table {missing[0]!r})"
                )
            raw = dict(conn.execute("SELECT key, value FROM meta").fetchall())
            meta = parse_meta(raw, label)
            conn.execute("SELECT count(*) FROM objects").fetchone()
            conn.execute("SELECT count(*) FROM cells").fetchone()
            return meta
        except sqlite3.DatabaseError as exc:
            raise DatabaseDamagedError(f"{label}: damaged database ({exc})") from exc

    @staticmethod
    def _quick_check(conn: sqlite3.Connection, label: str) -> None:
        try:
            rows = conn.execute("PRAGMA quick_check(5)").fetchall()
        except sqlite3.DatabaseError as exc:
            raise DatabaseDamagedError(f"{label}: damaged database ({exc})") from exc
        if rows != [("ok",)]:
            detail = "; ".join(str(r[0]) for r in rows)
            raise DatabaseDamagedError(f"{label}: damaged database ({detail})")

    # -- plumbing -----------------------------------------------------------

    @contextmanager
    def _conn(self) -> Iterator[sqlite3.Connection]:
        if self._closed:
            raise StoreError(f"{self._label}: the reader is closed")
        conn = self._pool.get()
        try:
            yield conn
        except sqlite3.DatabaseError as exc:
            raise DatabaseDamagedError(f"{self._label}: damaged database ({exc})") from exc
        finally:
            self._pool.put(conn)

    def _query(self, sql: str, args: Sequence[Any] = ()) -> list[Any]:
        with self._conn() as c:
            return c.execute(sql, args).fetchall()

    def _by_ids(
        self, columns: str, ids: Iterable[int], table: str = "objects", key: str = "id", what: str = "object id"
    ) -> list[Any]:
        want = sorted({row_index(i, what) for i in ids})
        out: list[Any] = []
        with self._conn() as c:
            for k in range(0, len(want), 500):  # stay below SQLite's bound-variable limit
                chunk = want[k : k + 500]
                marks = ",".join("?" * len(chunk))
                out += c.execute(
                    f"SELECT {columns} FROM {table} WHERE {key} IN ({marks})", chunk
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
        return self.content_blobs(PARAMS.name, ids)

    def content_blobs(self, kind: str, ids: Iterable[int]) -> dict[int, bytes]:
        """The stored bytes of content ``kind`` of the given objects or cells, as stored.

        The kind (:mod:`walkstream.shared.content.registry`) names the table and
        columns; a scene without the kind's optional table has none.  Unknown ids are
        left out of the result.

        Raises
        ------
        InputError
            ``kind`` is not a registered content kind.
        """
        k = content_kind(kind)
        if k.feature is not None and not self._has_table(k.table):
            return {}
        rows = self._by_ids(f"{k.key_column}, {k.column}", ids, k.table, k.key_column, f"{k.owner} id")
        return {int(r[0]): bytes(r[1]) for r in rows}

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
        i = row_index(oid, "object id")
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

    def area(self, oid: int) -> AreaParams:
        """The decoded parameters of typed area ``oid`` (kind ``"area"``)."""
        blob = self._object(oid, ("area",), "area")
        return decode_area(blob, f"{self._label}: area {oid}")

    def bounds(self) -> tuple[float, float, float, float, float, float]:
        """Box over all objects ``(minx, miny, minz, maxx, maxy, maxz)``; for an interior
        (no objects) the box of its cells other than the outside; zeros for an empty scene."""
        row = self._query(
            "SELECT min(minx), min(miny), min(minz), max(maxx), max(maxy), max(maxz) FROM objects"
        )[0]
        if row[0] is None:
            cells = [c for c in self.cells() if c.kind != "outside"]
            if not cells:
                return (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
            pts = np.concatenate([c.boundary for c in cells])
            lo, hi = pts.min(axis=0), pts.max(axis=0)
            z0 = min(c.zmin for c in cells)
            z1 = max(c.zmax for c in cells)
            return (float(lo[0]), float(lo[1]), float(z0), float(hi[0]), float(hi[1]), float(z1))
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
        i = row_index(cid, "cell id")
        rows = self._query(f"SELECT {self._CELL_COLUMNS} FROM cells WHERE id = ?", (i,))
        if not rows:
            raise NotFoundError(f"{self._label}: no cell {i}")
        return self._cell_info(rows[0])

    def cell_pvs_blob(self, cid: int) -> bytes:
        """Cell ``cid``'s PVS as stored (:func:`~walkstream.shared.codec.encode_pvs` bytes), for streaming."""
        i = row_index(cid, "cell id")
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

    # -- interiors -------------------------------------------------------------

    def _has_table(self, name: str) -> bool:
        rows = self._query("SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = ?", (name,))
        return bool(rows)

    def storeys(self) -> list[StoreyInfo]:
        """The storeys of an interior, bottom to top (empty for a city)."""
        if not self._has_table("storeys"):
            return []
        rows = self._query("SELECT id, name, zmin, zmax FROM storeys ORDER BY id")
        return [StoreyInfo(int(i), str(n), float(a), float(b)) for i, n, a, b in rows]

    def rooms(self) -> dict[int, RoomInfo]:
        """Cell id -> its room data, for every cell of an interior (empty for a city)."""
        if not self._has_table("rooms"):
            return {}
        rows = self._query("SELECT cell, name, room, storey, planes FROM rooms ORDER BY cell")
        return {
            int(c): RoomInfo(int(c), str(n), None if r is None else str(r), int(k),
                             f64_array(pl, 4, f"{self._label}: cell {c}: planes"))
            for c, n, r, k, pl in rows
        }

    def portals(self) -> list[PortalInfo]:
        """Every portal, by id (empty for a city)."""
        if not self._has_table("portals"):
            return []
        rows = self._query("SELECT id, cell_a, cell_b, polygon, kind, source, name FROM portals ORDER BY id")
        return [
            PortalInfo(int(i), int(a), int(b), f64_array(pg, 3, f"{self._label}: portal {i}: polygon"), str(k),
                       str(s), str(n))
            for i, a, b, pg, k, s, n in rows
        ]

    def stairs(self) -> list[StairInfo]:
        """Every stair, by id (empty for a city)."""
        if not self._has_table("stairs"):
            return []
        rows = self._query("SELECT id, portal, lower, upper, path, name FROM stairs ORDER BY id")
        return [
            StairInfo(int(i), int(p), int(lo), int(up), f64_array(pa, 3, f"{self._label}: stair {i}: path"), str(n))
            for i, p, lo, up, pa, n in rows
        ]

    def entrances(self) -> list[EntranceInfo]:
        """The entrances joining streets to rooms, by portal id (empty but in a crossing scene)."""
        if not self._has_table("entrances"):
            return []
        rows = self._query("SELECT portal, building, street, doorway, shell FROM entrances ORDER BY portal")
        placed: dict[int, ContentsPlacement] = {}
        if self._has_table("placements"):  # a crossing scene baked before has none: contents placed already
            for pid, angle, x, y, dz, first, last in self._query(
                "SELECT portal, angle, x, y, dz, first, last FROM placements ORDER BY portal"
            ):
                what = f"{self._label}: placement of entrance {pid}"
                placed[int(pid)] = ContentsPlacement(
                    finite_number(angle, what), (finite_number(x, what), finite_number(y, what)),
                    finite_number(dz, what), (row_index(first, what), row_index(last, what)),
                )
        return [EntranceInfo(int(p), int(b), int(s), int(d), int(sh), placed.get(int(p))) for p, b, s, d, sh in rows]

    def contents_info(self) -> dict[int, ContentsInfo]:
        """Cell id -> the sizes of its contents (empty for a city)."""
        if not self._has_table("contents"):
            return {}
        rows = self._query(
            "SELECT cell, triangles, vertices, parts, length(data), raw_bytes, max_error FROM contents ORDER BY cell"
        )
        return {int(r[0]): ContentsInfo(int(r[1]), int(r[2]), int(r[3]), int(r[4]), int(r[5]), float(r[6]), cell=int(r[0]))
                for r in rows}

    def contents(self, cid: int) -> bytes:
        """Cell ``cid``'s contents as stored (``walkstream-cellmesh/2 or /1`` bytes), for streaming.

        Raises
        ------
        NotFoundError
            No such cell, or the scene has no cell contents.
        """
        i = row_index(cid, "cell id")
        blob = self.content_blobs(CELLMESH.name, [i]).get(i)
        if blob is None:
            raise NotFoundError(f"{self._label}: no contents for cell {i}")
        return blob

    # -- impostors -----------------------------------------------------------

    def has_impostors(self) -> bool:
        """Whether the scene was baked with impostor images (``--impostors``)."""
        return self._has_table("impostors")

    def impostor_images(self, ids: Iterable[int]) -> dict[int, tuple[str, bytes]]:
        """Image id -> ``(media type, file bytes)`` of the stored ones among ``ids`` (empty without impostors)."""
        if not self.has_impostors():
            return {}
        want = [row_index(i, "impostor id") for i in ids]
        out: dict[int, tuple[str, bytes]] = {}
        for k in range(0, len(want), 500):
            part = want[k:k + 500]
            marks = ",".join("?" * len(part))
            for i, media, data in self._query(f"SELECT id, media, data FROM impostors WHERE id IN ({marks})", part):
                out[int(i)] = (str(media), bytes(data))
        return out

    def impostor_info(self) -> dict[int, tuple[int, int, int, int, int, int]]:
        """Image id -> ``(object, level, az, el, size, bytes)`` of every stored image."""
        if not self.has_impostors():
            return {}
        rows = self._query("SELECT id, object, level, az, el, size, length(data) FROM impostors ORDER BY id")
        return {int(r[0]): tuple(int(v) for v in r[1:]) for r in rows}  # type: ignore[misc]

    def cell_impostors(self, cid: int) -> list[list[int]]:
        """Cell ``cid``'s impostor rows ``[object, level, az0, n_az, el0, n_el, image ids...]``
        (empty for a cell without impostors or a scene baked without them)."""
        if not self._has_table("cell_impostors"):
            return []
        rows = self._query("SELECT data FROM cell_impostors WHERE cell = ?", (row_index(cid, "cell id"),))
        if not rows:
            return []
        return [list(map(int, r)) for r in msgpack.unpackb(rows[0][0])]

    # -- virtual walls ---------------------------------------------------------

    def has_walls(self) -> bool:
        """Whether the scene was baked with textured virtual walls (``--virtual-walls``)."""
        return self._has_table("wall_sides")

    def wall_sides(self) -> list[list[float | int]]:
        """Every wall side's row (``WallSide.to_row``), by id (empty without walls)."""
        if not self.has_walls():
            return []
        return [list(msgpack.unpackb(r[0])) for r in self._query("SELECT data FROM wall_sides ORDER BY id")]

    def ring_far(self, cid: int) -> tuple[NDArray[np.int64], NDArray[np.float64], float] | None:
        """The objects ``(k,)`` and their coverage ``(k,)`` (normalised) that cell ``cid``'s
        ring of walls carries on its textures, and their share of the cell's whole
        coverage (None: a cell without a ring, or a scene baked before they were stored)."""
        if not self._has_table("ring_far"):
            return None
        rows = self._query("SELECT pvs, share FROM ring_far WHERE cell = ?", (row_index(cid, "cell id"),))
        if not rows:
            return None
        try:
            ids, ach = decode_pvs(bytes(rows[0][0]), f"cell {cid}: ring far field")[:2]
        except CodecError as exc:
            raise StoreError(f"{self._label}: {exc}") from exc
        return np.asarray(ids, np.int64), np.asarray(ach, np.float64), float(rows[0][1])

    def wall_texture_info(self) -> dict[int, tuple[int, int, int, int, int, int]]:
        """Texture id -> ``(portal, side, zone, width, height, bytes)`` of every stored texture."""
        if not self._has_table("wall_textures"):
            return {}
        rows = self._query("SELECT id, portal, side, zone, width, height, length(data) FROM wall_textures ORDER BY id")
        return {int(r[0]): tuple(int(v) for v in r[1:]) for r in rows}  # type: ignore[misc]

    def wall_textures(self, ids: Iterable[int]) -> dict[int, tuple[str, bytes]]:
        """Texture id -> ``(media type, file bytes)`` of the stored ones among ``ids`` (empty without walls)."""
        if not self._has_table("wall_textures"):
            return {}
        want = [row_index(i, "wall texture id") for i in ids]
        out: dict[int, tuple[str, bytes]] = {}
        for k in range(0, len(want), 500):
            part = want[k:k + 500]
            marks = ",".join("?" * len(part))
            for i, media, data in self._query(f"SELECT id, media, data FROM wall_textures WHERE id IN ({marks})", part):
                out[int(i)] = (str(media), bytes(data))
        return out

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
            "kind": m.kind,
            "portals": len(self.portals()),
        } | (self._impostor_summary() if self.has_impostors() else {}) | (
            self._interior_summary() if m.kind in ("interior", "crossing") else {}) | (
            {"entrances": len(self.entrances())} if m.kind == "crossing" else {}
        )

    def _impostor_summary(self) -> dict[str, Any]:
        n, nbytes, texels = self._query("SELECT count(*), coalesce(sum(length(data)), 0), "
                                        "coalesce(sum(size * size), 0) FROM impostors")[0]
        return {"impostor_images": int(n), "impostor_bytes": int(nbytes), "impostor_texels": int(texels)}

    def _interior_summary(self) -> dict[str, Any]:
        rooms = self.rooms()
        info = self.contents_info()
        storeys = self.storeys()
        kinds = {c.id: c.kind for c in self.cells() if c.id in rooms}
        inside = [c for c, k in kinds.items() if k != "outside"]
        per_storey = {s.name: sum(1 for c in inside if rooms[c].storey == s.id) for s in storeys}
        nbytes = np.array([info[c].nbytes for c in info], dtype=np.float64)
        raw = np.array([info[c].raw_bytes for c in info], dtype=np.float64)
        tris = np.array([info[c].triangles for c in inside if c in info], dtype=np.int64)
        portals = self.portals()
        ends = dict.fromkeys(kinds, 0)
        for p in portals:
            for c in (p.a, p.b):
                if c in ends:
                    ends[c] += 1
        pin = np.array([ends[c] for c in inside] if inside else [0], np.int64)
        return {
            "storeys": len(storeys),
            "rooms": len({r.room for r in rooms.values() if r.room is not None}),
            "cells_inside": len(inside),
            "doorways": sum(1 for k in kinds.values() if k == "doorway"),
            "cells_per_storey": per_storey,
            "portal_kinds": {k: sum(1 for p in portals if p.kind == k) for k in sorted({p.kind for p in portals})},
            "portals_per_cell": [int(pin.min()), int(pin.max())],
            "stairs": len(self.stairs()),
            "triangles": int(sum(i.triangles for i in info.values())),
            "triangles_per_cell": [int(tris.min()), int(tris.max())] if len(tris) else [0, 0],
            "contents_bytes": int(nbytes.sum()),
            "contents_raw_bytes": int(raw.sum()),
            "bytes_per_cell_mean": float(nbytes.mean()) if len(nbytes) else 0.0,
            "bytes_per_cell_max": int(nbytes.max()) if len(nbytes) else 0,
            "max_position_error": float(max((i.max_error for i in info.values()), default=0.0)),
        }
