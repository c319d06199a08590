"""The tables of a scene database, its 100-byte header, and its content hash (the scene version)."""

from __future__ import annotations

import hashlib
import json
import os
import sqlite3
from pathlib import Path
from typing import Any

import msgpack

from walkstream.shared.errors import StoreError
from walkstream.shared.scene.cellkinds import CELL_KINDS

try:  # advisory locks between processes; POSIX only
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None  # type: ignore[assignment]
from walkstream.server.store.files import db_label

__all__ = [
    "SCHEMA_VERSION",
    "READABLE_VERSIONS",
    "SECTIONS_SCHEMA_VERSION",
    "schema_version_of",
    "APPLICATION_ID",
    "OBJECT_KINDS",
    "OPTIONAL_TABLES",
    "CORE_TABLES",
    "canonical_json",
    "content_version",
    "settings_hash",
    "read_header",
    "check_header",
]

SCHEMA_VERSION = 2
"""The schema version this code writes (``PRAGMA user_version``).

Version 2 added interiors: the cell kinds ``doorway`` and ``outside`` and the
optional tables of the ``rooms``, ``portals`` and ``meshes`` features.  A version 1
file (every city baked before) has none of them and is read as it is."""

READABLE_VERSIONS = (1, 2, 3)
"""Schema versions this code reads."""

SECTIONS_SCHEMA_VERSION = 3
"""The schema version of a scene with sections (the cell kind ``section``): an older
reader, whose ``cells`` table does not know the kind, refuses the file by its header."""


def schema_version_of(features: Any) -> int:
    """The schema version a scene with ``features`` is written with.

    Version 3 only for a scene of sections, so every other scene keeps version 2 (and
    its scene version, which hashes the header)."""
    return SECTIONS_SCHEMA_VERSION if "section_cells" in features else SCHEMA_VERSION

APPLICATION_ID = 0x57534442  # "WSDB"
"""``PRAGMA application_id`` of every walkstream scene database."""

OBJECT_KINDS = ("building", "street", "crossroad", "square", "area")
"""Kinds of the ``objects`` table's rows (checked by the writer, not the DDL).  ``area``
(a typed area, :class:`~walkstream.shared.records.AreaParams`) came without a new schema
version: a database without areas is the same file as before, and one with them is read
by the same reader."""

_SQLITE_MAGIC = b"SQLite format 3\x00"

# Core tables.  Convention relied on by the content hash: column 1 is the key.
CORE_TABLES: dict[str, str] = {
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
"""The tables every scene has: name -> ``CREATE TABLE`` statement."""

OPTIONAL_TABLES: dict[str, dict[str, str]] = {
    # feature name -> {table name: DDL}; created only when the scene lists the feature
    "rooms": {
        # interior cells: the room a cell is part of, its storey and plane set
        # (float64 little-endian rows nx, ny, nz, d; inside where n . p + d <= 0)
        "rooms": (
            "CREATE TABLE rooms(cell INTEGER PRIMARY KEY, name TEXT NOT NULL, room TEXT, "
            "storey INTEGER NOT NULL, planes BLOB NOT NULL)"
        ),
        "storeys": (
            "CREATE TABLE storeys(id INTEGER PRIMARY KEY, name TEXT NOT NULL, zmin REAL NOT NULL, "
            "zmax REAL NOT NULL)"
        ),
    },
    "portals": {
        # polygon: float64 little-endian (k, 3) rows; a stair's path likewise
        "portals": (
            "CREATE TABLE portals(id INTEGER PRIMARY KEY, cell_a INTEGER NOT NULL, "
            "cell_b INTEGER NOT NULL, polygon BLOB NOT NULL, kind TEXT NOT NULL, "
            "source TEXT NOT NULL, name TEXT NOT NULL)"
        ),
        "stairs": (
            "CREATE TABLE stairs(id INTEGER PRIMARY KEY, portal INTEGER NOT NULL, "
            "lower INTEGER NOT NULL, upper INTEGER NOT NULL, path BLOB NOT NULL, name TEXT NOT NULL)"
        ),
    },
    "meshes": {
        # a cell's contents: walkstream-cellmesh/2 or /1 (shared/codec/cellmesh.py)
        "contents": (
            "CREATE TABLE contents(cell INTEGER PRIMARY KEY, data BLOB NOT NULL, "
            "triangles INTEGER NOT NULL, vertices INTEGER NOT NULL, parts INTEGER NOT NULL, "
            "raw_bytes INTEGER NOT NULL, max_error REAL NOT NULL)"
        ),
    },
    "entrances": {
        # a building's entrance in a scene of streets and rooms: the portal (in the
        # portals table) joining a street cell to a doorway cell, the city object the
        # interior replaces and the cell whose contents stand for it from the street
        "entrances": (
            "CREATE TABLE entrances(portal INTEGER PRIMARY KEY, building INTEGER NOT NULL, "
            "street INTEGER NOT NULL, doorway INTEGER NOT NULL, shell INTEGER NOT NULL)"
        ),
        # the interior's contents are in its own frame: the move into the city's (a turn
        # about z by angle radians, a shift x, y and a lift dz) for cells first .. last;
        # a crossing scene without this table (baked before) stores them moved already
        "placements": (
            "CREATE TABLE placements(portal INTEGER PRIMARY KEY, angle REAL NOT NULL, x REAL NOT NULL, "
            "y REAL NOT NULL, dz REAL NOT NULL, first INTEGER NOT NULL, last INTEGER NOT NULL)"
        ),
    },
    "impostors": {
        # an impostor image of a building (shared/impostors.py): its direction bin
        # (level, az, el), its side in texels and the image file (shared/codec/image.py)
        "impostors": (
            "CREATE TABLE impostors(id INTEGER PRIMARY KEY, object INTEGER NOT NULL, level INTEGER NOT NULL, "
            "az INTEGER NOT NULL, el INTEGER NOT NULL, size INTEGER NOT NULL, media TEXT NOT NULL, "
            "data BLOB NOT NULL)"
        ),
        # which buildings a cell draws as impostors and with which images: msgpack
        # rows [object, level, az0, n_az, el0, n_el, image ids...] (server/bake/impostorplan.py)
        "cell_impostors": "CREATE TABLE cell_impostors(cell INTEGER PRIMARY KEY, data BLOB NOT NULL)",
    },
    "walls": {
        # a textured virtual wall's side (shared/walls.py): id portal * 2 + side, data the
        # msgpack list of WallSide.to_row (ends, heights, x_T, blend, zones, texture ids)
        "wall_sides": "CREATE TABLE wall_sides(id INTEGER PRIMARY KEY, data BLOB NOT NULL)",
        # one zone's texture: its side, zone, size in texels and the image file
        "wall_textures": (
            "CREATE TABLE wall_textures(id INTEGER PRIMARY KEY, portal INTEGER NOT NULL, side INTEGER NOT NULL, "
            "zone INTEGER NOT NULL, width INTEGER NOT NULL, height INTEGER NOT NULL, media TEXT NOT NULL, "
            "data BLOB NOT NULL)"
        ),
        # outdoors: a ringed cell's objects carried by its ring's textures (encode_pvs of
        # ids and coverage, normalised) and their share of the cell's whole coverage: drawn
        # as geometry while a texture in view has not arrived
        "ring_far": "CREATE TABLE ring_far(cell INTEGER PRIMARY KEY, pvs BLOB NOT NULL, share REAL NOT NULL)",
    },
}
"""Tables that exist only in scenes using a feature, declared in this one place."""

# meta keys that describe the run rather than the content: left out of the hash so
# that baking the same input twice gives the same version
_VOLATILE_META = ("version", "bake_seconds", "created")


def canonical_json(value: Any, what: str) -> str:
    """``value`` as canonical JSON (sorted keys, no spaces, no NaN), or a :class:`StoreError`."""
    try:
        return json.dumps(value, sort_keys=True, separators=(",", ":"), allow_nan=False)
    except (TypeError, ValueError) as exc:
        raise StoreError(f"{what}: not JSON-serialisable ({exc})") from exc


def _tables(conn: sqlite3.Connection) -> list[str]:
    """Tables of a scene in hashing order: core first, then optional by feature order."""
    present = {r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
    order = list(CORE_TABLES) + [t for tables in OPTIONAL_TABLES.values() for t in tables]
    return [t for t in order if t in present]


def content_version(conn: sqlite3.Connection) -> str:
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


def settings_hash(fields: dict[str, Any]) -> str:
    """The sha256 of the canonical JSON of bake settings (what a resumed bake must match)."""
    return hashlib.sha256(canonical_json(fields, "settings").encode()).hexdigest()


def read_header(path: str | os.PathLike[str]) -> tuple[int, int, bool]:
    """Check a file's SQLite header: ``(application_id, user_version, wal)``.

    Raises
    ------
    StoreError
        Missing, not a regular file, unreadable or not SQLite.
    """
    label = db_label(path)
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


def check_header(path: str | os.PathLike[str]) -> bool:
    """Validate the header of a walkstream database; returns whether it is in WAL mode."""
    label = db_label(path)
    app_id, user_version, wal = read_header(path)
    if app_id != APPLICATION_ID:
        raise StoreError(
            f"{label}: an SQLite database but not a walkstream scene database "
            f"(application id {app_id:#x}, expected {APPLICATION_ID:#x})"
        )
    if user_version not in READABLE_VERSIONS:
        raise StoreError(
            f"{label}: schema version {user_version}, this walkstream reads versions "
            f"{', '.join(map(str, READABLE_VERSIONS))}"
        )
    return wal
