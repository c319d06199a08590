"""A crossing scene: a generated city and a generated office in one database, joined at the entrance."""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import shapely
from daskcluster import local_cluster

from walkstream.server.bake import BakeSettings, bake
from walkstream.server.bake.crossing import STAND_IN_INSET
from walkstream.server.paths.graph import scene_graph
from walkstream.server.paths.record import record_walk
from walkstream.server.sources.interiorgen import InteriorPlan, write_interior
from walkstream.server.store import SceneReader
from walkstream.shared.cells import CellLocator
from walkstream.shared.errors import InputError, RouteError
from walkstream.shared.paths import RecordedPath

FAST = BakeSettings(resolution=16)
STREET_KINDS = {"street", "crossroad", "square"}
ROOM_KINDS = {"room", "doorway", "outside"}


@pytest.fixture
def baked(crossing_scene: tuple[Path, dict[str, Any], Path]) -> tuple[Path, dict[str, Any], Path]:
    """The crossing bake shared with tests/test_crosswalk.py (tests/conftest.py): read only."""
    return crossing_scene


def _own_copy(db: Path, tmp_path: Path) -> Path:
    """A copy of the shared database to write to (record a path into)."""
    out = tmp_path / db.name
    shutil.copyfile(db, out)
    return out


def _cells(reader: SceneReader) -> dict[int, Any]:
    return {c.id: c for c in reader.cells()}


def _visits(reader: SceneReader, path: RecordedPath, step_s: float = 0.05) -> list[int]:
    """The cells a walk's eye passes, in order (streets in 2D, rooms in 3D; each once per visit)."""
    cells = _cells(reader)
    rooms = reader.rooms()
    street = [c for c in cells.values() if c.id not in rooms]
    inner = [c for c in cells.values() if c.id in rooms and c.kind != "outside"]
    on_street = CellLocator([c.id for c in street], [c.boundary for c in street])
    indoors = CellLocator([c.id for c in inner], [c.boundary for c in inner], [[c.zmin, c.zmax] for c in inner])
    t = np.arange(0.0, path.duration, step_s)
    xyz = np.column_stack([np.interp(t, path.t, path.xyz[:, k]) for k in range(3)])
    ids = indoors.locate_many(xyz)
    out = np.where(ids >= 0, ids, on_street.locate_many(xyz[:, :2])).tolist()
    seq: list[int] = []
    for c in out:
        if c >= 0 and (not seq or seq[-1] != c):
            seq.append(c)
    return seq


def test_one_database_holds_cells_of_both_models(baked: tuple[Path, dict[str, Any], Path]) -> None:
    db, summary, _ = baked
    assert summary["kind"] == "crossing" and summary["entrances"] == 1
    with SceneReader.open(db) as r:
        assert r.meta.kind == "crossing"
        assert set(r.meta.features) >= {"buildings", "street_cells", "rooms", "portals", "meshes", "entrances"}
        cells = _cells(r)
        rooms = r.rooms()
        assert sorted(cells) == list(range(len(cells)))  # one id space
        city = [c for c in cells.values() if c.id not in rooms]
        assert {c.kind for c in city} <= STREET_KINDS and {cells[i].kind for i in rooms} == ROOM_KINDS
        assert max(c.id for c in city) < min(rooms)  # city cells first, then the interior's
        assert all(len(c.pvs) for c in city) and not any(len(cells[i].pvs) for i in rooms)  # PVS outdoors only
        assert set(r.contents_info()) == set(rooms)
        assert all(p.a in rooms and p.b in rooms or p.source == "entrance" for p in r.portals())


def test_the_entrance_portal_joins_the_street_in_front_to_the_doorway(baked: tuple[Path, dict[str, Any], Path]) -> None:
    db, _, _ = baked
    with SceneReader.open(db) as r:
        cells = _cells(r)
        (e,) = r.entrances()
        portal = next(p for p in r.portals() if p.id == e.portal)
        street, doorway = cells[e.street], cells[e.doorway]
        assert (portal.a, portal.b, portal.kind, portal.source) == (e.street, e.doorway, "door", "entrance")
        assert street.kind in STREET_KINDS and doorway.kind == "doorway" and cells[e.shell].kind == "outside"
        assert e.doorway in street.neighbours.tolist() and e.street in doorway.neighbours.tolist()
        mid = shapely.Point(portal.polygon[:, :2].mean(axis=0))
        # the door's outer face lies on the doorway's outline and at the street's edge
        assert shapely.Polygon(doorway.boundary).exterior.distance(mid) < 1e-6
        assert shapely.Polygon(street.boundary).distance(mid) < 0.1
        # the same face as the doorway's portal to the interior's outside (the hole in the shell)
        outer = [p for p in r.portals() if {p.a, p.b} == {e.doorway, e.shell}]
        assert len(outer) == 1 and np.allclose(outer[0].polygon, portal.polygon)
        # the building's stand-in, ledges and parapet included, lies inside the shell (the
        # rooms' plan and the 0.3 m outer walls): it hides nothing the shell would not
        ring = shapely.Polygon(r.building(e.building).rings[0])
        inside = [c for c in cells.values() if c.kind in ("room", "doorway")]
        plan = shapely.union_all([shapely.Polygon(c.boundary) for c in inside])
        assert plan.buffer(0.3 + 0.01, join_style="mitre").contains(ring.buffer(STAND_IN_INSET - 0.01, join_style="mitre"))
        assert r.object_info([e.building])[e.building].bbox[5] <= cells[e.shell].zmax


def test_the_enter_walk_goes_from_the_street_through_the_door_and_back(baked: tuple[Path, dict[str, Any], Path]) -> None:
    db, summary, _ = baked
    with SceneReader.open(db) as r:
        (e,) = r.entrances()
        enter = RecordedPath.from_msgpack(r.path_blob("enter"), "enter")
        seq = _visits(r, enter)
        rooms = r.rooms()
    assert seq[0] not in rooms and seq[-1] not in rooms
    pairs = list(zip(seq, seq[1:], strict=False))
    assert (e.street, e.doorway) in pairs and (e.doorway, e.street) in pairs
    # every step between a street and a room passes the entrance
    assert all((a in rooms) == (b in rooms) or {a, b} == {e.street, e.doorway} for a, b in pairs)
    assert any(rooms[c].room is not None and rooms[c].name == summary["enter"]["room"] for c in seq if c in rooms)


def test_record_a_path_from_a_street_to_a_named_room_and_back(baked: tuple[Path, dict[str, Any], Path], tmp_path: Path) -> None:
    db = _own_copy(baked[0], tmp_path)
    with SceneReader.open(db) as r:
        enter = RecordedPath.from_msgpack(r.path_blob("enter"), "enter")
        (e,) = r.entrances()
        graph = scene_graph(r)
    start = (float(enter.xyz[0, 0]), float(enter.xyz[0, 1]))
    room = "0.c00 corridor"
    path, version = record_walk(db, "in", start, room)
    back, _ = record_walk(db, "out", room, start)
    with SceneReader.open(db) as r:
        assert r.version == version or "out" in r.path_names()
        for p in (path, back):
            seq = _visits(r, p)
            pairs = list(zip(seq, seq[1:], strict=False))
            assert {(e.street, e.doorway), (e.doorway, e.street)} & set(pairs)
        assert r.rooms()[_visits(r, path)[-1]].name == room
    with pytest.raises(RouteError, match="outside every street cell"):
        graph.route((1e4, 1e4), room)
    with pytest.raises(RouteError, match="no room named"):
        graph.route(start, "no such room")


def test_the_city_part_matches_the_city_alone(baked: tuple[Path, dict[str, Any], Path]) -> None:
    db, _, d = baked
    with SceneReader.open(db) as r, SceneReader.open(d / "city.db") as c:
        assert c.meta.kind == "city" and "entrances" not in c.meta.features and c.entrances() == []
        for name in ("SE", "SM", "drive"):
            assert r.path_blob(name) == c.path_blob(name)
        mine = {x.id: x for x in r.cells()}
        for x in c.cells():
            assert x.kind == mine[x.id].kind and np.array_equal(x.boundary, mine[x.id].boundary)
        assert r.object_ids().tolist() == c.object_ids().tolist()


def test_an_interior_too_large_for_the_building_says_so(baked: tuple[Path, dict[str, Any], Path], tmp_path: Path) -> None:
    _, _, d = baked
    write_interior(tmp_path / "big.json", InteriorPlan(storeys=1, length=80, width=40, seed=1))
    with pytest.raises(InputError, match="does not fit building"):
        bake(d / "city.geojson", tmp_path / "big.db", settings=FAST, interior=tmp_path / "big.json", building="b103")
    with pytest.raises(InputError, match="no building with that"):
        bake(d / "city.geojson", tmp_path / "big.db", settings=FAST, interior=tmp_path / "big.json", building="nope")


def test_cli_inspect_map_and_record(
    baked: tuple[Path, dict[str, Any], Path], capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    from walkstream.cli import main

    db = _own_copy(baked[0], tmp_path)
    assert main(["inspect", str(db), "--map", str(tmp_path / "map.png")]) == 0
    assert (tmp_path / "map.png").stat().st_size > 10_000
    assert "entrances" in capsys.readouterr().out
    with SceneReader.open(db) as r:
        start = RecordedPath.from_msgpack(r.path_blob("enter"), "enter").xyz[0]
    assert main(["path", "record", str(db), "cli-in", f"--from={start[0]:.3f},{start[1]:.3f}", "--to-room", "0.01"]) == 0
    assert main(["path", "record", str(db), "cli-out", "--from-room", "0.01", f"--to={start[0]:.3f},{start[1]:.3f}"]) == 0
    assert "recorded path 'cli-out'" in capsys.readouterr().out


def test_an_ifc_model_enters_from_the_street_too(baked: tuple[Path, dict[str, Any], Path], tmp_path: Path) -> None:
    """The FZK house (its door 0.5 m behind the shell's front) in the same city."""
    pytest.importorskip("ifcopenshell", reason="the ifc extra (make test installs it)")
    src = Path(__file__).resolve().parents[2] / "shared" / "data" / "indoor" / "AC20-FZK-Haus.ifc"
    if not src.exists():
        pytest.skip(f"no {src} (the shared test data)")
    _, _, d = baked
    summary = bake(d / "city.geojson", tmp_path / "fzk.db", settings=FAST, interior=src)
    assert summary["kind"] == "crossing" and summary["entrance_gap_m"] <= 1.0
    with SceneReader.open(tmp_path / "fzk.db") as r:
        (e,) = r.entrances()
        seq = _visits(r, RecordedPath.from_msgpack(r.path_blob("enter"), "enter"))
    pairs = list(zip(seq, seq[1:], strict=False))
    assert (e.street, e.doorway) in pairs and (e.doorway, e.street) in pairs


def test_the_suggested_office_size_fits_the_building_it_names(baked: tuple[Path, dict[str, Any], Path], tmp_path: Path) -> None:
    from walkstream.server.bake.cells import make_cells
    from walkstream.server.bake.siting import office_size, pick_building
    from walkstream.server.sources.read import read_source

    _, _, d = baked
    city = read_source(d / "city.geojson")
    cells = make_cells(city)
    size = office_size(city, cells)
    assert size is not None
    length, width, building = size
    write_interior(tmp_path / "fit.json", InteriorPlan(storeys=1, length=length, width=width, seed=3))
    k, _, gap = pick_building(city, cells, read_source(tmp_path / "fit.json"), building)
    assert city.buildings[k].source_id == building and gap <= 1.0
    write_interior(tmp_path / "wide.json", InteriorPlan(storeys=1, length=length, width=width + 2, seed=3))
    with pytest.raises(InputError, match="does not fit"):
        pick_building(city, cells, read_source(tmp_path / "wide.json"), building)


def test_the_service_serves_a_crossing_scene_with_its_kind(baked: tuple[Path, dict[str, Any], Path]) -> None:
    import asyncio

    import httpx

    from walkstream.server.service.main import create_app
    from walkstream.shared.wire import decode_manifest

    db, _, _ = baked

    async def get(url: str) -> httpx.Response:
        async with httpx.AsyncClient(transport=httpx.ASGITransport(app=create_app([db])), base_url="http://t") as c:
            return await c.get(url)

    r = asyncio.run(get("/v1/scenes/scene"))
    assert r.status_code == 200
    m = decode_manifest(r.content, "m")
    assert m.kind == "crossing" and "entrances" in m.features and {"enter", "tour", "SE"} <= set(m.paths)


def test_the_service_serves_the_rooms_of_a_crossing_and_locates_in_3d(baked: tuple[Path, dict[str, Any], Path]) -> None:
    import asyncio
    import json

    import httpx

    from walkstream.server.service.main import create_app
    from walkstream.shared.roomwire import decode_topology

    db, _, _ = baked
    app = create_app([db])

    async def get(url: str) -> httpx.Response:
        async with httpx.AsyncClient(transport=httpx.ASGITransport(app=app), base_url="http://t") as c:
            return await c.get(url, headers={"accept": "application/json"} if "locate" in url else {})

    with SceneReader.open(db) as r:
        rooms = r.rooms()
        (e,) = r.entrances()
        stair = r.stairs()[0]
        storeys = r.storeys()
        cells = _cells(r)
    topo = decode_topology(asyncio.run(get("/v1/scenes/scene/topology")).content, "t")
    assert {c.id for c in topo.cells} == set(rooms)
    doorway = next(c for c in topo.cells if c.id == e.doorway)
    assert any(p.cell == e.street for p in doorway.portals)  # the entrance leads to the street
    assert asyncio.run(get(f"/v1/scenes/scene/rooms/{e.doorway}/contents")).status_code == 200
    x, y = np.asarray(cells[stair.lower].boundary).mean(axis=0)
    found = [json.loads(asyncio.run(get(f"/v1/scenes/scene/locate?x={x}&y={y}&z={s.zmin + 1.6}")).text)["cell"]
             for s in storeys]
    assert found == [stair.lower, stair.upper]
    sx, sy = np.asarray(cells[e.street].boundary).mean(axis=0)
    assert json.loads(asyncio.run(get(f"/v1/scenes/scene/locate?x={sx}&y={sy}&z=1.6")).text)["cell"] == e.street


def test_the_interior_keeps_its_own_cells_and_portals(baked: tuple[Path, dict[str, Any], Path]) -> None:
    """The interior is cut into cells in its own frame and moved whole: the same layout as alone."""
    from collections import Counter

    from walkstream.server.bake.rooms import room_layout
    from walkstream.server.sources.read import read_source

    db, _, d = baked
    alone = room_layout(read_source(d / "office.json"))
    with SceneReader.open(db) as r:
        rooms = r.rooms()
        cells = _cells(r)
        kinds = Counter(p.kind for p in r.portals() if p.source != "entrance")
        offset = min(rooms)
        for c in alone.cells:
            mine = cells[c.id + offset]
            assert (mine.kind, rooms[mine.id].name, len(mine.boundary)) == (c.kind, c.name, len(c.outline))
            assert shapely.Polygon(mine.boundary).area == pytest.approx(c.polygon.area, abs=1e-6)
    assert kinds == Counter(p.kind for p in alone.portals) and len(rooms) == len(alone.cells)


def _nearest(points: np.ndarray, to: np.ndarray) -> np.ndarray:
    """Each of ``points``' distance to the nearest of ``to`` (both ``(n, 3)``)."""
    return np.sqrt(((points[:, None, :] - to[None, :, :]) ** 2).sum(axis=2)).min(axis=1)


def test_a_turned_interiors_contents_stay_in_its_own_frame(baked: tuple[Path, dict[str, Any], Path], tmp_path: Path) -> None:
    """The contents of the turned office are the office alone's, byte for byte (cellmesh/3
    keeps its boxes, 27 kB rather than 68 kB placed), and the entrance says how to place them."""
    db, _, d = baked
    bake(d / "office.json", tmp_path / "office.db")
    with SceneReader.open(tmp_path / "office.db") as r:
        alone = {c: r.contents(c) for c in r.contents_info()}
    with SceneReader.open(db) as r:
        (e,) = r.entrances()
        rooms = r.rooms()
        got = {c - min(rooms): r.contents(c) for c in r.contents_info()}
    p = e.placement
    assert p is not None and p.cells == (min(rooms), max(rooms)) and abs(p.angle) > 0.01  # turned to the facade
    assert got == alone
    assert sum(map(len, got.values())) < 30_000


def test_placed_contents_match_the_contents_encoded_placed(baked: tuple[Path, dict[str, Any], Path]) -> None:
    """Decoded and placed by the entrance's placement, each cell's parts are those a crossing
    bake stored placed before (encoded after the move), within the codec's error."""
    from walkstream.server.bake.interior import interior_parts, room_contents
    from walkstream.server.bake.placement import Placement
    from walkstream.server.sources.interior import InteriorScene
    from walkstream.server.sources.read import read_source
    from walkstream.shared.codec.cellmesh import decode_cell_mesh, encode_cell_mesh
    from walkstream.shared.codec.planarmesh import area_tolerance, mesh_area

    db, _, d = baked
    scene = read_source(d / "office.json")
    assert isinstance(scene, InteriorScene)
    local = interior_parts(scene, d / "office.json")
    with SceneReader.open(db) as r:
        (e,) = r.entrances()
        offset = min(r.rooms())
        blobs = {c: r.contents(c) for c in r.contents_info()}
    p = e.placement
    assert p is not None
    turn = Placement(p.angle, p.shift, p.dz)
    exact = {cid: [(e, m, turn.xyz(v), t) for e, m, v, t in ps] for cid, ps in room_contents(scene, local.layout).items()}
    c, s = abs(np.cos(p.angle)), abs(np.sin(p.angle))
    # half a millimetre per coordinate in the interior's frame (turned: up to 0.5 (|c| + |s|) mm
    # in x and y), float32 rounding on top
    bound = np.array([0.5e-3 * (c + s), 0.5e-3 * (c + s), 0.5e-3]) + 1e-5
    parts = 0
    for cid, blob in blobs.items():
        new = p.place(decode_cell_mesh(blob, f"cell {cid}"))
        ps = [q for q in exact.get(cid - offset, []) if len(q[3])]
        was = decode_cell_mesh(encode_cell_mesh(ps), "placed before") if ps else None
        assert len(new.parts) == len(ps) == (len(was.parts) if was else 0)
        for a, b, q in zip(new.parts, was.parts if was else (), ps, strict=True):
            parts += 1
            assert (a.element, a.material) == (b.element, b.material) == (q[0], q[1])
            # every placed vertex is one of the part's own, moved, within the bound
            assert _nearest(a.positions.astype(np.float64), np.asarray(q[2], np.float64)).max() <= float(np.linalg.norm(bound))
            assert np.all(np.abs(a.bbox[0] - b.bbox[0]) <= bound + 0.5e-3)
            assert np.all(np.abs(a.bbox[1] - b.bbox[1]) <= bound + 0.5e-3)
            area = mesh_area(q[2], q[3])
            assert abs(mesh_area(a.positions, a.indices) - area) <= area_tolerance(q[2], q[3])
            assert abs(mesh_area(b.positions, b.indices) - area) <= area_tolerance(q[2], q[3])
            # the faces still face out: the same area facing each axis way as before
            assert np.allclose(_facing(a), _facing(b), atol=0.01 * max(area, 1.0))
    assert parts > 100


def _facing(part: Any) -> np.ndarray:
    """Area facing +x, -x, +y, -y, +z, -z."""
    t = part.positions.astype(np.float64)[part.indices.astype(np.int64)]
    n = 0.5 * np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    return np.concatenate([np.clip(n, 0, None).sum(axis=0), np.clip(-n, 0, None).sum(axis=0)])


def test_a_killed_then_stopped_crossing_bake_resumes_to_the_same_version(
    baked: tuple[Path, dict[str, Any], Path], monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """One driver for every scene: a crossing killed while it wrote its tables resumes, one
    stopped after a few cells resumes like a city, and its room contents and its street
    cells' PVS both go through the one chunk runner.  One work file through the three runs
    (each of the two interruptions alone cost a whole bake of the scene more)."""
    from walkstream.server.bake import chunks
    from walkstream.server.store import SceneWriter

    _, summary, d = baked
    out = tmp_path / "resumed" / "x.db"
    out.parent.mkdir()
    args = (d / "city.geojson", out)

    def killed(*_: Any) -> None:
        raise RuntimeError("killed")

    with monkeypatch.context() as m:
        m.setattr(SceneWriter, "add_portals", killed)  # after the city's tables, before the rooms'
        with pytest.raises(RuntimeError, match="killed"):
            bake(*args, settings=FAST, interior=d / "office.json", name="scene")
    assert Path(str(out) + ".partial").exists() and not out.exists()
    ran: list[str] = []
    run = chunks._run

    def spy(task: Any, *args: Any) -> Any:
        ran.append(task.__name__)
        return run(task, *args)

    monkeypatch.setattr(chunks, "_run", spy)
    assert bake(*args, settings=FAST, interior=d / "office.json", name="scene", max_cells=3) == {}
    assert ran == ["contents_task", "pvs_task"] and not out.exists()
    ran.clear()
    again = bake(*args, settings=FAST, interior=d / "office.json", name="scene")
    assert again["resumed_cells"] == 3 and ran == ["pvs_task"]  # the contents were kept
    assert again["version"] == summary["version"]


def test_a_crossing_on_a_dask_local_cluster_bakes_the_same_scene(baked: tuple[Path, dict[str, Any], Path], tmp_path: Path) -> None:
    _, summary, d = baked
    out = tmp_path / "dask" / "x.db"
    out.parent.mkdir()
    with local_cluster() as cluster:
        got = bake(d / "city.geojson", out, settings=FAST, interior=d / "office.json", name="scene",
                   scheduler=cluster.scheduler_address)
    assert got["version"] == summary["version"]


def test_one_graph_walks_every_scene_kind(baked: tuple[Path, dict[str, Any], Path]) -> None:
    """The same graph class routes a city (streets only), a crossing (streets, the entrance,
    rooms) and refuses what a scene does not have."""
    db, _, d = baked
    with SceneReader.open(d / "city.db") as r:
        city = scene_graph(r)
    with SceneReader.open(db) as r:
        both = scene_graph(r)
        rooms = r.rooms()
    a, b = city.streets.cells[0].centroid, city.streets.cells[-1].centroid
    assert np.array_equal(city.route(a, b)[:, :2], city.streets.plan(a, b).xy)
    with pytest.raises(RouteError, match="no rooms"):
        city.route(a, "0.c00 corridor")
    with pytest.raises(RouteError, match="no rooms"):
        _ = city.rooms
    (e,) = both.entrances
    floor = both.route(tuple(a), "0.c00 corridor")
    at_front = int(np.flatnonzero(np.all(np.isclose(floor[:, :2], e.front), axis=1))[0])
    assert np.allclose(floor[at_front + 1], e.threshold)  # from the street's front of the door to its threshold
    assert (floor[: at_front + 1, 2] == 0).all() and both.rooms.locate(*floor[-1] + [0, 0, 1.6]) in rooms
