"""Cell kinds: one table names each kind's visibility model, and the store and the locator follow it."""

from __future__ import annotations

import contextlib
import sqlite3
from pathlib import Path

import pytest

from walkstream.shared.cells import CellLocator
from walkstream.shared.errors import InputError
from walkstream.shared.scene.cellkinds import (
    CELL_KIND_TABLE,
    CELL_KINDS,
    LOCATABLE_KINDS,
    VISIBILITY_MODELS,
    CellKind,
    cell_kind,
    visibility_of,
)


def test_every_kind_has_one_visibility_model() -> None:
    assert len(set(CELL_KINDS)) == len(CELL_KINDS)
    assert all(k.visibility in VISIBILITY_MODELS for k in CELL_KIND_TABLE)
    assert {k: visibility_of(k) for k in CELL_KINDS} == {
        "crossroad": "pvs", "street": "pvs", "square": "pvs", "grid": "pvs",
        "room": "portals", "doorway": "portals", "outside": "portals", "section": "pvs",
    }
    assert LOCATABLE_KINDS == set(CELL_KINDS) - {"outside"}


def test_the_order_the_bake_numbers_cells_by_is_kept() -> None:
    # cell ids of every baked scene follow this order: it may only grow at the end
    assert CELL_KINDS == ("crossroad", "street", "square", "grid", "room", "doorway", "outside", "section")


def test_the_store_takes_exactly_the_kinds(office_db: Path) -> None:
    with contextlib.closing(sqlite3.connect(f"file:{office_db}?mode=ro", uri=True)) as c:
        ddl = c.execute("SELECT sql FROM sqlite_master WHERE name = 'cells'").fetchone()[0]
    assert f"kind IN ({', '.join(repr(k) for k in CELL_KINDS)})" in ddl


def test_unknown_kinds_and_models_are_refused() -> None:
    with pytest.raises(InputError, match="cell kind 'hexagon'"):
        cell_kind("hexagon")
    with pytest.raises(InputError, match="visibility 'field'"):
        CellKind("hexagon", "field")  # type: ignore[arg-type]


def test_a_scene_of_both_models_locates_each_cell_by_its_kind() -> None:
    # a street cell (2D) beside two stacked room cells (3D) and an outside cell
    sq = [[0, 0], [1, 0], [1, 1], [0, 1]]
    street = [[1, 0], [2, 0], [2, 1], [1, 1]]
    loc = CellLocator.of_kinds(
        [1, 2, 3, 4], ["street", "room", "room", "outside"], [street, sq, sq, street],
        [[0, 0], [0, 3], [3, 6], [0, 9]],
    )
    assert len(loc) == 3
    assert loc.locate(1.5, 0.5, 1.6) == 1
    assert loc.locate(0.5, 0.5, 1.6) == 2
    assert loc.locate(0.5, 0.5, 4.0) == 3
    assert loc.locate(1.5, 0.5) == 1
    assert loc.locate(0.5, 0.5, 7.0) is None


def test_a_city_keeps_its_2d_locator() -> None:
    sq = [[0, 0], [1, 0], [1, 1], [0, 1]]
    loc = CellLocator.of_kinds([5], ["street"], [sq], [[0.0, 0.0]])
    # no height range: a city cell holds a point at any height, as before
    assert loc.locate(0.5, 0.5, 100.0) == 5
