"""A generated interior written as IFC4 (``walkstream generate interior -o x.ifc``) and read
back through the IFC reader: the same rooms, doors, stairs and portals as its JSON."""

from __future__ import annotations

import json
import sys
from collections import Counter
from pathlib import Path

import pytest

pytest.importorskip("ifcopenshell")

from walkstream.cli import main
from walkstream.server.bake.roomlayout import RoomLayout
from walkstream.server.bake.rooms import room_layout
from walkstream.server.sources.ifc import load_ifc
from walkstream.server.sources.interiorfile import load_interior_dict
from walkstream.server.sources.interiorgen import InteriorPlan, generate_interior, write_interior
from walkstream.shared.errors import InputError

# two storeys and a stair, a dozen rooms: small enough to write, read and lay out in about a second
PLAN = InteriorPlan(storeys=2, length=16.0, width=13.0, seed=3, furniture=0.5)


def _portals(layout: RoomLayout, room_id: dict[str, str]) -> Counter[tuple[str, str, frozenset[str | None]]]:
    """Each portal as (kind, name, the rooms of its two cells), rooms named by their ids."""
    cells = {c.id: c for c in layout.cells}
    return Counter(
        (p.kind, p.name, frozenset(room_id.get(r, r) if r else None for r in (cells[p.a].room, cells[p.b].room)))
        for p in layout.portals
    )


def test_a_generated_interior_survives_ifc(tmp_path: Path) -> None:
    summary = write_interior(tmp_path / "office.ifc", PLAN)
    doc = generate_interior(PLAN)
    ifc = load_ifc(tmp_path / "office.ifc", threads=1)
    ref = load_interior_dict(doc)
    assert summary["rooms"] == len(ifc.rooms) == len(ref.rooms)
    assert Counter(o.kind for o in ifc.openings) == Counter(o.kind for o in ref.openings)
    assert sum(1 for o in ifc.openings if o.kind == "door") == summary["doors"]
    assert len(ifc.stairs) == len(ref.stairs) == summary["stairs"] == 1
    # the walking line climbs the whole storey
    path = ifc.stairs[0].path
    assert path[-1, 2] - path[0, 2] > 0.9 * (ref.storeys[1].elevation - ref.storeys[0].elevation)
    assert Counter(e.kind for e in ifc.elements)["furniture"] == summary["furniture"]
    # a space's Name is the room's id: every portal joins the same rooms as from the JSON
    room_id = {r.key: r.name.split()[0] for r in ifc.rooms}
    from_ifc, from_json = room_layout(ifc), room_layout(ref)
    assert len(from_ifc.cells) == len(from_json.cells)
    assert _portals(from_ifc, room_id) == _portals(from_json, {})
    door = next(p for p in from_ifc.portals if p.name == "d0.01")
    cells = {c.id: c for c in from_ifc.cells}
    assert {room_id.get(cells[c].room or "", None) for c in (door.a, door.b)} & {"r0.01", "c0.00"}


@pytest.mark.parametrize("schema", ["IFC4", "IFC2X3"])
def test_same_plan_same_bytes_and_space_boundaries(tmp_path: Path, schema: str) -> None:
    tiny = InteriorPlan(storeys=1, length=12.0, width=8.0, seed=5, furniture=0.5)
    a, b = tmp_path / "a.ifc", tmp_path / "b.ifc"
    assert write_interior(a, tiny, True, schema) == write_interior(b, tiny, True, schema)
    assert a.read_bytes() == b.read_bytes()
    # with space boundaries the reader takes a door's two rooms from them
    scene = load_ifc(a, threads=1)
    assert scene.source_format == schema
    room_id = {r.key: r.name.split()[0] for r in scene.rooms}
    doors = {o.name: o for o in scene.openings if o.kind == "door"}
    assert doors["entrance"].source == "geometry" and len(doors["entrance"].rooms) == 1
    inner = [o for name, o in doors.items() if name != "entrance"]
    assert inner and all(o.source == "boundary" for o in inner)
    assert {room_id[k] for k in doors["d0.01"].rooms} == {"r0.01", "c0.00"}


def test_the_cli_writes_ifc_beside_the_summary(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "office.ifc"
    args = ["generate", "interior", "--storeys", "1", "--size", "12x8", "-o", str(out)]
    assert main([*args, "--ifc-schema", "ifc2x3", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["rooms"] >= 3
    assert out.read_text(encoding="utf-8").startswith("ISO-10303-21;") and "FILE_SCHEMA(('IFC2X3'))" in out.read_text()
    assert main(["generate", "interior", "--space-boundaries", "-o", str(tmp_path / "office.json")]) == 2
    assert "only for an .ifc output" in capsys.readouterr().err
    assert main([*args, "--ifc-schema", "IFC5"]) == 2
    assert "IFC schema 'IFC5'" in capsys.readouterr().err


def test_an_ifc_into_a_missing_folder_is_one_line(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="cannot write"):
        write_interior(tmp_path / "missing" / "office.ifc", InteriorPlan(storeys=1, length=12.0, width=8.0))
    assert not (tmp_path / "missing").exists()


def test_writing_ifc_without_ifcopenshell_is_one_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "ifcopenshell", None)
    with pytest.raises(InputError, match="ifcopenshell.*walkstream\\[ifc\\]"):
        write_interior(tmp_path / "office.ifc", PLAN)
    assert not (tmp_path / "office.ifc").exists()
