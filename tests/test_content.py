"""Content kinds: each names all its parts, and the store, service, wire and cache take exactly them."""

from __future__ import annotations

import contextlib
import re
import sqlite3
from pathlib import Path
from typing import get_args

import pytest
from scenes import build_city_db

from walkstream.client.content.cellmesh import CELLMESH_CONTENT
from walkstream.client.content.objects import MESH_CONTENT
from walkstream.client.content.registry import CLIENT_CONTENT, client_content
from walkstream.client.stream.cache import CONTENTS, EVICTION_ORDER, KINDS, Cache, Kind
from walkstream.server.service.scenes import OBJECT_FORMS, Form, Scene
from walkstream.server.store import OPTIONAL_TABLES, SceneReader
from walkstream.shared.codec.cellmesh import CellMesh
from walkstream.shared.content.kind import ContentKind
from walkstream.shared.content.registry import (
    CONTENT_KINDS,
    by_form,
    cache_kinds,
    content_kind,
    frame_keys,
    object_forms,
)
from walkstream.shared.errors import InputError
from walkstream.shared.wire import FRAME_KEYS


@pytest.fixture(scope="module")
def tables(office_db: Path) -> dict[str, str]:
    """Table name -> its DDL, as a baked interior holds them (the core tables and those
    of the ``rooms``, ``portals`` and ``meshes`` features)."""
    with contextlib.closing(sqlite3.connect(f"file:{office_db}?mode=ro", uri=True)) as c:
        return dict(c.execute("SELECT name, sql FROM sqlite_master WHERE type = 'table'").fetchall())


@pytest.mark.parametrize("kind", CONTENT_KINDS, ids=lambda k: k.name)
def test_every_kind_names_all_its_parts(kind: ContentKind, tables: dict[str, str]) -> None:
    assert kind.name and kind.cache_kind and kind.wire
    assert kind.owner in ("object", "cell", "image")
    assert callable(kind.decode)
    # the store: its table (a core one, or one of its feature's) with both columns
    optional = {t for ts in OPTIONAL_TABLES.values() for t in ts}
    if kind.feature is None:
        assert kind.table not in optional
    else:
        assert kind.table in OPTIONAL_TABLES[kind.feature]
    # (a table the office has not: its declared DDL)
    ddl = tables.get(kind.table) or OPTIONAL_TABLES[kind.feature or ""][kind.table]
    cols = re.findall(r"[(,]\s*(\w+) ", ddl)
    assert kind.key_column in cols and kind.column in cols
    # the wire: an object kind streams by a form and a frame key; a cell kind has a media type
    if kind.owner == "object":
        assert kind.form and FRAME_KEYS[kind.form] == kind.wire
    else:
        assert kind.form is None and kind.wire.startswith(("application/", "image/"))
    # the client: a cache kind and a client side registered under its name
    assert kind.cache_kind in KINDS
    assert client_content(kind.name).kind is kind


def test_names_are_unique() -> None:
    for attr in ("name", "cache_kind"):
        values = [getattr(k, attr) for k in CONTENT_KINDS]
        assert len(set(values)) == len(values), attr
    forms = [k.form for k in CONTENT_KINDS if k.form is not None]
    assert len(set(forms)) == len(forms)


def test_the_service_and_the_wire_take_exactly_the_registered_forms() -> None:
    assert OBJECT_FORMS == object_forms() == ("params", "lod2")
    assert get_args(Form) == OBJECT_FORMS
    assert FRAME_KEYS == frame_keys() == {"params": "params", "lod2": "mesh"}
    with pytest.raises(InputError, match="form 'image'"):
        by_form("image")


def test_the_cache_takes_exactly_the_registered_kinds() -> None:
    assert CONTENTS == cache_kinds() == ("params", "mesh", "cellmesh", "impostor", "walltex")
    assert get_args(Kind) == KINDS == ("index", "cell", *CONTENTS, "geom")
    # the eviction order of the kinds there were before cell meshes is unchanged
    assert [k for k in EVICTION_ORDER if k not in ("cellmesh", "impostor", "walltex")] == ["geom", "params", "mesh", "cell", "index"]
    with pytest.raises(InputError, match="cache kind"):
        Cache(100).put("image", 1, b"", 1)
    assert set(CLIENT_CONTENT) == {k.name for k in CONTENT_KINDS}


def test_a_city_mesh_and_a_cells_contents_with_the_same_id_do_not_collide() -> None:
    evicted: list[tuple[str, int]] = []
    c = Cache(10_000, on_evict=lambda k, i: evicted.append((k, i)))
    cm = CellMesh(parts=(), lo=(0.0, 0.0, 0.0), extent=(1.0, 1.0, 1.0))
    c.put(MESH_CONTENT.kind.cache_kind, 7, b"city mesh", 100)
    c.put(CELLMESH_CONTENT.kind.cache_kind, 7, cm, 200)
    assert c.peek("mesh", 7) == b"city mesh"
    assert c.peek("cellmesh", 7) is cm
    assert c.bytes_used == 300
    c.remove("cellmesh", 7)
    assert c.peek("mesh", 7) == b"city mesh" and evicted == [("cellmesh", 7)]
    # and on the GPU: an object's LOD and a cell's part never share a key
    assert MESH_CONTENT.gpu_key(7, 0) != CELLMESH_CONTENT.gpu_key(7, 0)


def test_the_store_reads_exactly_the_registered_kinds(tmp_path: Path, office_db: Path) -> None:
    city = build_city_db(tmp_path / "city.db")
    with SceneReader.open(city.path) as r:
        ids = r.object_ids().tolist()[:3]
        assert r.content_blobs("params", ids) == r.object_params(ids)
        assert r.content_blobs("mesh", ids) == r.object_params(ids)  # rebuilt from the parameters
        assert r.content_blobs("cellmesh", [0, 1]) == {}  # a city has no contents table
        with pytest.raises(InputError, match="content kind 'image'"):
            r.content_blobs("image", ids)
    with SceneReader.open(office_db) as r:
        cells = sorted(r.contents_info())[:2]
        got = r.content_blobs("cellmesh", cells)
        assert list(got) == cells and all(got[c] == r.contents(c) for c in cells)
        content_kind("cellmesh").decode(got[cells[0]], "cell")


def test_the_service_makes_the_frames_of_every_object_kind(tmp_path: Path) -> None:
    city = build_city_db(tmp_path / "city.db")
    scene = Scene.load(city.path)
    try:
        assert scene.payload_kinds == {k.name for k in CONTENT_KINDS if k.owner == "object"}
        oid = int(scene.reader.object_ids()[0])
        for form in OBJECT_FORMS:
            frame = scene.load_frames([oid], form)[oid]
            assert len(frame) > 0
    finally:
        scene.close()
