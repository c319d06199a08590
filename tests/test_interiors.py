"""Interiors I: IFC and generated interiors, room cells, doorways, portals, contents, tour.

The traps of the issue, each on a small IFC model written here (tests/ifcmodels.py)
or a small generated interior, plus the two real models of ../shared/data/indoor
(imported and baked once per module; they never skip in CI).
"""

from __future__ import annotations

import json
import sqlite3
from collections import Counter
from contextlib import closing
from pathlib import Path

import numpy as np
import pytest
import shapely
from ifcmodels import IfcBuilder, l_room_model, stair_model, stairwell_model, two_rooms_model
from teamdata import TEAM_DATA, team_data

from walkstream.cli import main
from walkstream.server.bake import bake
from walkstream.server.bake.roomgeom import clip_polygons, convex_parts, is_convex, shared_segments
from walkstream.server.bake.roomnav import EYE_HEIGHT
from walkstream.server.bake.rooms import room_layout
from walkstream.server.paths.graph import interior_graph
from walkstream.server.paths.record import record_walk
from walkstream.server.sources.ifc import load_ifc
from walkstream.server.sources.interiorfile import load_interior, load_interior_dict
from walkstream.server.sources.interiorgen import (
    PRESETS,
    InteriorPlan,
    generate_interior,
    write_interior,
)
from walkstream.server.sources.read import READERS, read_source
from walkstream.server.store import SceneReader
from walkstream.shared.cells import CellLocator
from walkstream.shared.codec.cellmesh import decode_cell_mesh
from walkstream.shared.errors import InputError, RouteError, SourceError
from walkstream.shared.paths import RecordedPath

DUPLEX = TEAM_DATA / "indoor" / "duplex.ifc"
FZK = TEAM_DATA / "indoor" / "AC20-FZK-Haus.ifc"

pytest.importorskip("ifcopenshell", reason="the ifc extra (make test installs it)")


def _real(path: Path) -> Path:
    return team_data(*path.relative_to(TEAM_DATA).parts)


def _locator(reader: SceneReader) -> CellLocator:
    """The service's 3D locator: every cell but the outside, with its height range."""
    cells = [c for c in reader.cells() if c.kind != "outside"]
    return CellLocator([c.id for c in cells], [c.boundary for c in cells], [[c.zmin, c.zmax] for c in cells])


def _errors(err: str) -> list[str]:
    """The error lines of stderr (progress bars left out)."""
    return [ln for ln in err.replace("\r", "\n").splitlines() if ln.startswith("walkstream:")]


def _tour(reader: SceneReader) -> RecordedPath:
    return RecordedPath.from_msgpack(reader.path_blob("tour"))


# --------------------------------------------------------------------------- sources


def test_generated_interior_is_deterministic_and_sized(tmp_path: Path) -> None:
    a = generate_interior(InteriorPlan(storeys=2, length=20, width=14, seed=3))
    b = generate_interior(InteriorPlan(storeys=2, length=20, width=14, seed=3))
    assert json.dumps(a) == json.dumps(b)
    assert json.dumps(a) != json.dumps(generate_interior(InteriorPlan(storeys=2, length=20, width=14, seed=4)))
    tiny = generate_interior(InteriorPlan(storeys=1, length=10, width=8))  # a few rooms, no stair
    assert 3 <= len(tiny["rooms"]) <= 6 and not tiny["stairs"]
    # coordinates of millions of metres in the file, small ones in the scene
    scene = load_interior_dict(a)
    assert scene.origin[0] > 599_000 and scene.origin[1] > 5_339_000
    assert all(np.abs(r.outline).max() < 50 for r in scene.rooms)
    with pytest.raises(InputError, match="--storeys"):
        generate_interior(InteriorPlan(storeys=0))
    with pytest.raises(InputError, match="--size"):
        generate_interior(InteriorPlan(storeys=3, width=9))


def test_interior_file_errors_name_the_element(tmp_path: Path) -> None:
    doc = generate_interior(InteriorPlan(storeys=1, length=12, width=8))
    doc["walls"][0]["openings"] = [{"id": "bad", "kind": "door", "offset": -5, "width": 0.9, "head": 2.1}]
    with pytest.raises(SourceError, match="opening 'bad'"):
        load_interior_dict(doc)
    with pytest.raises(SourceError, match="not a walkstream-interior"):
        load_interior_dict({"type": "FeatureCollection"})
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": "walkstream-interior", "version": 1, ')
    with pytest.raises(SourceError, match="not a JSON file"):
        load_interior(bad)


def test_read_source_picks_the_reader_by_the_file_ending(tmp_path: Path) -> None:
    assert set(READERS) >= {".geojson", ".json", ".ifc"}
    office = tmp_path / "office.json"
    write_interior(office, InteriorPlan(storeys=1, length=12, width=8))
    assert type(read_source(office)).__name__ == "InteriorScene"
    city = tmp_path / "city.json"
    city.write_text(json.dumps({"type": "FeatureCollection", "features": [
        {"type": "Feature", "id": "b1", "properties": {"height": 10},
         "geometry": {"type": "Polygon", "coordinates": [[[16.37, 48.2], [16.3702, 48.2], [16.3702, 48.2002], [16.37, 48.2]]]}}]}))
    assert type(read_source(city)).__name__ == "SourceScene"
    assert type(read_source(two_rooms_model(tmp_path / "two.IFC"))).__name__ == "InteriorScene"


def test_damaged_ifc_files_are_one_clear_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    good = two_rooms_model(tmp_path / "good.ifc")
    cut = tmp_path / "cut.ifc"
    cut.write_bytes(good.read_bytes()[: len(good.read_bytes()) // 2])
    junk = tmp_path / "junk.ifc"
    junk.write_bytes(b"ISO-10303-21;\nHEADER;\nthis is not STEP at all ((((\n")
    text = tmp_path / "text.ifc"
    text.write_text("hello")
    for bad, what in ((cut, "truncated"), (junk, "damaged or truncated"), (text, "not an IFC file")):
        with pytest.raises(SourceError, match=what):
            load_ifc(bad)
        assert main(["bake", str(bad), "-o", str(tmp_path / "x.db")]) == 2
        err = capsys.readouterr().err
        assert bad.name in err and "Traceback" not in err and len(_errors(err)) == 1
    assert not (tmp_path / "x.db").exists()


def test_an_ifc_without_spaces_says_what_to_do(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    b = IfcBuilder()
    s = b.storey("ground", 0.0)
    b.wall(s, (0, 0), (5, 0), 0.2, 0.0, 2.8)
    path = b.write(tmp_path / "nospaces.ifc")
    with pytest.raises(SourceError, match="no spaces \\(IfcSpace\\)"):
        load_ifc(path)
    assert main(["bake", str(path), "-o", str(tmp_path / "x.db")]) == 2
    err = capsys.readouterr().err
    assert len(_errors(err)) == 1 and "add spaces" in err and "Traceback" not in err


# --------------------------------------------------------------------------- cells and portals


def test_convex_parts_cut_rooms_into_convex_pieces() -> None:
    u = [[0, 0], [6, 0], [6, 4], [4, 4], [4, 1], [2, 1], [2, 4], [0, 4]]
    parts = convex_parts(u)
    assert len(parts) == 3 and all(is_convex(p) for p in parts)
    assert sum(shapely.Polygon(p).area for p in parts) == pytest.approx(shapely.Polygon(u).area)


def test_a_straight_side_split_by_a_vertex_is_one_shared_segment() -> None:
    """The duplex's bedroom door: the doorway cell's face on the bedroom side has a
    vertex 37 mm from its end (where the room's corner met the wall's hole), and the
    short edge, under the 5 cm minimum on its own, was dropped: the portal stopped
    37 mm short of the opening and the bedroom was culled where it showed through."""
    doorway = [[-1.718, -2.674], [-1.718, -2.55], [-2.582, -2.55], [-2.582, -2.674], [-1.755, -2.674]]
    room = [[0.125, -2.674], [-3.583, -2.674], [-3.583, -8.383], [0.125, -8.383]]
    segs = shared_segments(doorway, room, 0.02)
    assert len(segs) == 1
    assert np.allclose(sorted(segs[0][:, 0].tolist()), [-2.582, -1.718]) and np.allclose(segs[0][:, 1], -2.674)
    # the same through the ring's first vertex, and a bend is not a straight side
    assert len(shared_segments(np.roll(doorway, 1, axis=0), room, 0.02)) == 1
    bent = [[0, 0], [1, 0], [2, 0.01], [2, 1], [0, 1]]  # a 1 cm bend over a metre
    assert len(shared_segments(bent, [[0, -1], [3, -1], [3, 0], [0, 0]], 0.02)) == 2


def test_l_shaped_room_is_two_convex_cells_joined_by_an_open_portal(tmp_path: Path) -> None:
    layout = room_layout(load_ifc(l_room_model(tmp_path / "l.ifc")))
    rooms = [c for c in layout.cells if c.kind == "room"]
    assert len(rooms) == 2 and all(is_convex(c.outline) for c in rooms)
    assert sum(c.polygon.area for c in rooms) == pytest.approx(27.0, abs=0.05)
    [split] = [p for p in layout.portals if p.kind == "split"]
    assert {split.a, split.b} == {rooms[0].id, rooms[1].id} and split.walkable
    # an open portal: the whole shared edge, from the floor to the ceiling
    assert np.ptp(split.polygon[:, 2]) == pytest.approx(2.8, abs=0.01)
    assert np.hypot(*np.ptp(split.polygon[:, :2], axis=0)) == pytest.approx(3.0, abs=0.05)
    # every cell's planes hold its outline and its centre
    for c in rooms:
        centre = np.append(c.outline.mean(axis=0), 1.0)
        assert np.all(c.planes[:, :3] @ centre + c.planes[:, 3] <= 1e-9)


def test_doors_windows_and_an_element_spanning_two_rooms(tmp_path: Path) -> None:
    src = two_rooms_model(tmp_path / "two.ifc")
    summary = bake(src, tmp_path / "two.db")
    assert summary["kind"] == "interior" and summary["rooms"] == 2
    with SceneReader.open(tmp_path / "two.db") as r:
        cells = {c.id: c for c in r.cells()}
        rooms = r.rooms()
        portals = r.portals()
        outside = next(i for i, c in cells.items() if c.kind == "outside")
        west = next(i for i, ri in rooms.items() if ri.name == "West")
        east = next(i for i, ri in rooms.items() if ri.name == "East")
        doorways = [i for i, c in cells.items() if c.kind == "doorway"]
        assert len(doorways) == 2
        between = [d for d in doorways if {p.b if p.a == d else p.a for p in portals if d in (p.a, p.b)} == {west, east}]
        assert len(between) == 1, "a doorway cell between the two rooms"
        to_out = [d for d in doorways if outside in {p.b if p.a == d else p.a for p in portals if d in (p.a, p.b)}]
        assert len(to_out) == 1, "the door to the outside: a doorway cell with a portal to the outside"
        [window] = [p for p in portals if p.kind == "window"]
        assert {window.a, window.b} == {east, outside}
        assert window.polygon[:, 2].min() == pytest.approx(0.9, abs=0.01)
        assert window.polygon[:, 2].max() == pytest.approx(2.2, abs=0.01)
        # the bench lies in both rooms (and in the middle wall): each room holds its own piece
        bench = {}
        for cid in (west, east):
            cm = decode_cell_mesh(r.contents(cid))
            lo, hi = np.array(cells[cid].boundary).min(axis=0), np.array(cells[cid].boundary).max(axis=0)
            pieces = [p for p in cm.parts if p.bbox[1][2] <= 0.31 and p.bbox[0][2] >= -0.01 and p.material == 13]
            assert pieces, f"cell {cid} holds no piece of the bench"
            for p in pieces:
                assert np.all(p.bbox[0][:2] >= lo - 0.061) and np.all(p.bbox[1][:2] <= hi + 0.061)
            bench[cid] = pieces
        assert bench[west][0].element == bench[east][0].element
        # the outside cell holds the outer faces of the outer walls, not the rooms' insides
        out = decode_cell_mesh(r.contents(outside))
        assert out.triangles > 0
        tour = _tour(r)
        assert tour.duration > 0


def test_an_eye_in_a_doorway_is_in_a_cell_every_2cm(tmp_path: Path) -> None:
    src = two_rooms_model(tmp_path / "two.ifc")
    bake(src, tmp_path / "two.db")
    scene = load_ifc(src)
    with SceneReader.open(tmp_path / "two.db") as r:
        _doorways_hold_the_eye(r, scene.openings)


def _doorways_hold_the_eye(reader: SceneReader, openings: object) -> None:
    """Walk through every door from 0.5 m before its wall to 0.5 m past it (to the wall's
    outer face for an outer door) every 2 cm, at eye height: always in a cell."""
    loc = _locator(reader)
    storeys = reader.storeys()
    checked = 0
    for op in openings:  # type: ignore[attr-defined]
        if op.kind != "door":
            continue
        floor = storeys[op.storey].zmin
        steps = np.arange(-0.5 - 0.5 * op.depth, 0.5 + 0.5 * op.depth + 1e-9, 0.02)
        for side in (-1.0, 1.0):
            probe = op.centre[:2] + op.normal * side * (0.5 * op.depth + 0.3)
            if loc.locate(float(probe[0]), float(probe[1]), floor + EYE_HEIGHT) is None:
                # an outer door: walk only up to the outer face of its wall
                steps = steps[steps * side <= 0.5 * op.depth + 1e-9]
        pts = op.centre[:2] + steps[:, None] * op.normal
        ids = loc.locate_many(np.column_stack([pts, np.full(len(pts), floor + EYE_HEIGHT)]))
        assert (ids >= 0).all(), f"door {op.name}: eye outside every cell at {pts[ids < 0][:3]}"
        checked += 1
    assert checked > 0


def test_a_stair_joins_two_storeys_and_the_tour_climbs_it(tmp_path: Path) -> None:
    summary = bake(stair_model(tmp_path / "stair.ifc"), tmp_path / "stair.db")
    assert summary["stairs"] == 1 and summary["portal_kinds"].get("stair") == 1
    with SceneReader.open(tmp_path / "stair.db") as r:
        [st] = r.stairs()
        [portal] = [p for p in r.portals() if p.kind == "stair"]
        assert st.portal == portal.id and {st.lower, st.upper} == {portal.a, portal.b}
        assert portal.polygon[:, 2] == pytest.approx(np.full(len(portal.polygon), 3.0))
        hole = shapely.Polygon(portal.polygon[:, :2])
        assert hole.area == pytest.approx(5.5 * 1.2, rel=0.05)  # the hole in the upper slab
        assert st.path[0, 2] < 0.5 and st.path[-1, 2] == pytest.approx(3.0)
        tour = _tour(r)
        z = tour.xyz[:, 2]
        assert z.min() == pytest.approx(EYE_HEIGHT, abs=1e-6) and z.max() == pytest.approx(3.0 + EYE_HEIGHT, abs=1e-6)
        # on the way up the eye follows the treads: 1.6 m above the stair line
        mid = tour.sample(np.linspace(0, tour.duration, 400))[0]
        on_stair = (mid[:, 2] > EYE_HEIGHT + 0.3) & (mid[:, 2] < 3.0 + EYE_HEIGHT - 0.3)
        assert on_stair.any()
        # wherever the eye is between the storeys it is over the stair, 1.6 m above its line
        d = np.linalg.norm(mid[on_stair, None, :2] - st.path[None, :, :2], axis=2)
        assert d.min(axis=1).max() < 0.35
        line_z = st.path[d.argmin(axis=1), 2]
        assert np.abs(mid[on_stair, 2] - EYE_HEIGHT - line_z).max() < 0.25
    # routed by room name, and in 3D by the storey's height
    path, _ = record_walk(tmp_path / "stair.db", "up", "Hall", "Landing")
    assert path.xyz[-1, 2] == pytest.approx(3.0 + EYE_HEIGHT)
    # scene-local metres (the origin is the centre of the rooms, (4, 2) in the model)
    path, _ = record_walk(tmp_path / "stair.db", "down", (3.0, 2.0, 4.6), (3.0, 2.0, 1.6))
    assert path.xyz[0, 2] == pytest.approx(3.0 + EYE_HEIGHT) and path.xyz[-1, 2] == pytest.approx(EYE_HEIGHT)
    with pytest.raises(RouteError, match="no room named"):
        record_walk(tmp_path / "stair.db", "x", "Cellar", "Hall")
    with pytest.raises(RouteError, match="outside every cell"):
        record_walk(tmp_path / "stair.db", "x", (50.0, 50.0, 1.6), "Hall")


def _triangles_in_holes(reader: SceneReader, openings: object, kinds: tuple[str, ...]) -> int:
    """How many drawn triangles (of every cell's contents) have their centre inside the
    hole of a door (or other opening of ``kinds``), 5 cm in from its sides (a frame's
    lining is 4 cm)."""
    cents = []
    for cid in [c.id for c in reader.cells()]:
        for part in decode_cell_mesh(reader.contents(cid)).parts:
            tri = np.asarray(part.positions, float)[np.asarray(part.indices).reshape(-1, 3)]
            cents.append(tri.mean(axis=1))
    c = np.concatenate(cents)
    inside = 0
    for op in openings:  # type: ignore[attr-defined]
        if op.kind not in kinds:
            continue
        along = np.array([op.normal[1], -op.normal[0]])
        d = c[:, :2] - op.centre[:2]
        hit = (
            (np.abs(d @ op.normal) < 0.5 * op.depth)
            & (np.abs(d @ along) < 0.5 * op.width - 0.05)
            & (c[:, 2] > op.zmin + 0.02)
            & (c[:, 2] < op.zmax - 0.05)
        )
        inside += int(hit.sum())
    return inside


def test_doors_are_drawn_open_or_left_out(tmp_path: Path, office_db: Path) -> None:
    """A door leaf exported closed would hide everything behind it: nothing drawn fills
    a door's hole, neither in an IFC model (the leaf left out) nor in a generated
    interior (the leaf drawn open, beside the doorway)."""
    src = two_rooms_model(tmp_path / "two.ifc")
    bake(src, tmp_path / "two.db")
    scene = load_ifc(src)
    assert sum(op.kind == "door" for op in scene.openings) == 2
    with SceneReader.open(tmp_path / "two.db") as r:
        assert _triangles_in_holes(r, scene.openings, ("door",)) == 0
    with SceneReader.open(office_db) as r:
        openings = load_interior(Path(r.meta.settings["source"])).openings
        assert sum(op.kind == "door" for op in openings) > 5
        assert _triangles_in_holes(r, openings, ("door",)) == 0


def test_a_stair_space_on_one_storey_is_a_room_of_both(tmp_path: Path) -> None:
    """Exporters put a stair space on the storey it starts on although its solid rises
    through the next: it becomes a cell of each storey it rises through, and the
    stair joins the two."""
    summary = bake(stairwell_model(tmp_path / "well.ifc"), tmp_path / "well.db")
    assert summary["rooms"] == 3
    assert summary["cells_per_storey"]["ground"] >= 2 and summary["cells_per_storey"]["upper"] >= 2
    with SceneReader.open(tmp_path / "well.db") as r:
        rooms = r.rooms()
        wells = sorted((ri.storey, cid) for cid, ri in rooms.items() if ri.name == "Stair")
        assert [s for s, _ in wells] == [0, 1]
        [stair] = [p for p in r.portals() if p.kind == "stair"]
        assert {stair.a, stair.b} == {wells[0][1], wells[1][1]}
        # the storey's height decides the cell: the same spot in the stair space
        loc = _locator(r)
        [well] = [c for c in r.cells() if c.id == wells[0][1]]
        x, y = np.asarray(well.boundary, float).mean(axis=0)[:2]
        ids = {loc.locate(float(x), float(y), z) for z in (EYE_HEIGHT, 3.0 + EYE_HEIGHT)}
        assert ids == {wells[0][1], wells[1][1]}
    assert summary["tour"]["visited"] == 3 and summary["tour"]["storeys_visited"] == 2
    path, _ = record_walk(tmp_path / "well.db", "up", "Hall", "Landing")
    assert path.xyz[0, 2] == pytest.approx(EYE_HEIGHT) and path.xyz[-1, 2] == pytest.approx(3.0 + EYE_HEIGHT)


def test_coordinates_of_millions_of_metres(tmp_path: Path) -> None:
    far = two_rooms_model(tmp_path / "far.ifc", offset=(600_000.0, 5_340_000.0))
    near = two_rooms_model(tmp_path / "near.ifc")
    sf, sn = load_ifc(far), load_ifc(near)
    assert sf.origin[:2] == (600_004.0, 5_340_002.0)
    for a, b in zip(sf.rooms, sn.rooms, strict=True):
        np.testing.assert_allclose(a.outline, b.outline, atol=1e-6)
    bake(far, tmp_path / "far.db")
    with SceneReader.open(tmp_path / "far.db") as r:
        assert r.meta.origin == (600_004.0, 5_340_002.0)
        assert max(np.abs(c.boundary).max() for c in r.cells()) < 10
        for cid in r.rooms():
            cm = decode_cell_mesh(r.contents(cid))
            assert all(np.abs(p.positions).max() < 20 for p in cm.parts)


def test_clip_polygons_keeps_winding_and_area() -> None:
    tri = np.array([[[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 2.0, 0.0]]])
    poly, count = clip_polygons(tri, np.array([3]), [1.0, 0.0, 0.0, -1.0])  # keep x <= 1
    assert count[0] == 4
    p = poly[0, :4]
    area = 0.5 * np.cross(p[1] - p[0], p[2] - p[0])[2] + 0.5 * np.cross(p[2] - p[0], p[3] - p[0])[2]
    assert area == pytest.approx(1.5)


# --------------------------------------------------------------------------- generated interiors


def test_generated_office_bakes_into_cells_portals_and_a_tour(office_db: Path) -> None:
    with SceneReader.open(office_db) as r:
        s = r.summary()
        assert s["kind"] == "interior" and s["features"] == ["rooms", "portals", "meshes"]
        assert s["objects"] == 0 and s["pvs_max"] == 0 and r.meta.grammar_text == ""
        assert s["storeys"] == 2 and all(v > 0 for v in s["cells_per_storey"].values())
        assert {"door", "window", "stair"} <= set(s["portal_kinds"])
        assert s["portals_per_cell"][0] >= 2
        assert s["max_position_error"] <= 0.001
        tour = _tour(r)
        graph = interior_graph(r)
        from walkstream.server.bake.roomwalks import rooms_along

        floor = tour.xyz.copy()
        floor[:, 2] -= EYE_HEIGHT
        rooms, storeys = rooms_along(graph, floor)
        assert len(rooms) >= 0.8 * s["rooms"] and storeys == {0, 1}
        assert tour.duration >= 180.0  # three minutes at walking speed
        # the eye is 1.6 m over the floor of its storey but on the stairs, climbed once
        st = r.storeys()
        z = tour.sample(np.linspace(0.0, tour.duration, 2000))[0][:, 2] - EYE_HEIGHT
        flat = np.isclose(z, st[0].zmin, atol=1e-4) | np.isclose(z, st[1].zmin, atol=1e-4)
        assert flat.mean() > 0.9
        assert np.count_nonzero(np.diff((z > st[1].zmin - 0.1).astype(int))) == 1


def test_generated_doorways_hold_the_eye(office_db: Path, tmp_path: Path) -> None:
    with SceneReader.open(office_db) as r:
        src = Path(r.meta.settings["source"])
        _doorways_hold_the_eye(r, load_interior(src).openings)


def test_paper_preset_has_the_papers_scale() -> None:
    doc = generate_interior(PRESETS["paper"])
    layout = room_layout(load_interior_dict(doc))
    inside = [c for c in layout.cells if c.kind != "outside"]
    assert 85 <= len(inside) <= 100  # the paper: 93 cells
    ends = Counter()
    for p in layout.portals:
        ends[p.a] += 1
        ends[p.b] += 1
    assert all(2 <= ends[c.id] <= 4 for c in inside)  # the paper: 2 to 4 portals per cell


# --------------------------------------------------------------------------- real models


def test_duplex(duplex_db: tuple[Path, dict]) -> None:
    db, s = duplex_db
    assert s["rooms"] == 21 and s["storeys"] == 4
    assert s["cells_per_storey"]["Level 1"] > 10 and s["cells_per_storey"]["Level 2"] > 10
    assert s["cells_per_storey"]["T/FDN"] == 0
    # first-level boundaries name one space each: a door's two rooms are the spaces of
    # the boundaries naming it; the rest from the geometry
    assert s["portal_sources"]["boundary"] > 0 and s["portal_sources"]["geometry"] > 0
    assert s["doorways"] >= 12 and s["portal_kinds"]["stair"] == 2
    # two homes with no door between them: the tour covers one home (all of it, both storeys)
    tour = s["tour"]
    assert tour["reachable"] == tour["visited"] and tour["visited"] >= 0.8 * tour["reachable"]
    assert tour["storeys_visited"] == tour["storeys_reachable"] == 2
    assert tour["unreachable_count"] == 11  # the other home (10 rooms) and the roof space
    with SceneReader.open(db) as r:
        _doorways_hold_the_eye(r, load_ifc(DUPLEX).openings)
        _tour_stays_in_cells(r)
        with closing(sqlite3.connect(db)) as c:
            assert c.execute("PRAGMA user_version").fetchone()[0] == 2


def test_fzk_haus(fzk_db: tuple[Path, dict]) -> None:
    db, s = fzk_db
    assert s["rooms"] == 7 and s["storeys"] == 2
    assert s["cells_per_storey"] == {"Erdgeschoss": 12, "Dachgeschoss": 1}
    assert s["portal_kinds"]["virtual"] >= 3  # the IfcVirtualElement boundaries, paired
    assert s["portal_kinds"]["stair"] == 1  # the spiral stair through the gallery's hole
    assert s["tour"]["visited"] == 7 and s["tour"]["storeys_visited"] == 2
    with SceneReader.open(db) as r:
        [st] = r.stairs()
        # a spiral: the walking line turns around the newel
        d = np.diff(st.path[:, :2], axis=0)
        heading = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
        assert np.ptp(heading) > np.pi
        info = r.contents_info()
        # walkstream-cellmesh/2: half the 1 mm grid plus float32 rounding (a 100 m model: 6 um)
        assert max(i.max_error for i in info.values()) <= 5e-4 + 2.0**-24 * 100
        _tour_stays_in_cells(r)


MODEL_GAP_M = 0.03
"""The widest gap a model leaves between a space and the doorway through its wall that a
walk may cross (the duplex's living room stops 2.6 cm short of its foyer's doorway)."""


def _tour_stays_in_cells(reader: SceneReader) -> None:
    """Every 5 cm of the tour the eye is in a cell (it never walks through a wall), or
    crossing a gap of at most :data:`MODEL_GAP_M` that the model leaves between two."""
    tour = _tour(reader)
    xyz = tour.sample(np.arange(0.0, tour.duration, 0.05 / (4.0 / 3.6)))[0]
    ids = _locator(reader).locate_many(xyz)
    cells = [c for c in reader.cells() if c.kind != "outside"]
    for p in xyz[ids < 0]:
        near = [shapely.Polygon(c.boundary).distance(shapely.Point(p[:2])) for c in cells
                if c.zmin <= p[2] < c.zmax]
        assert min(near, default=np.inf) <= MODEL_GAP_M, f"the tour leaves every cell at {p}"


def test_worker_processes_get_plain_arrays_and_bake_the_same_scene(tmp_path: Path) -> None:
    """The contents of cells are clipped in worker processes from plain arrays (no IFC
    objects cross a process boundary): the same database, byte for byte in content."""
    src = two_rooms_model(tmp_path / "two.ifc")
    one = bake(src, tmp_path / "one.db", workers=1, name="same")
    two = bake(src, tmp_path / "two.db", workers=2, name="same")
    assert one["version"] == two["version"]
