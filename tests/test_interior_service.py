"""Interiors through the database, the service, the client and the command line.

One small generated office (two storeys), baked once per module; a city database
of schema version 1 (the format every city had before interiors), made by hand.
"""

from __future__ import annotations

import asyncio
import json
import sqlite3
from contextlib import closing
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
from scenes import build_city_db

from walkstream.cli import main
from walkstream.client.clock import RealClock
from walkstream.client.net.api import SceneClient
from walkstream.server.bake import bake
from walkstream.server.service import models
from walkstream.server.service.main import create_app
from walkstream.server.sources.interiorgen import InteriorPlan, write_interior
from walkstream.server.store import SceneReader
from walkstream.shared.codec.cellmesh import decode_cell_mesh
from walkstream.shared.roomwire import (
    ContentsRef,
    PortalRef,
    RoomRecord,
    Topology,
    decode_room,
    decode_topology,
)
from walkstream.shared.wire import decode_manifest


@pytest.fixture(scope="module")
def office(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("svc")
    write_interior(d / "office.json", InteriorPlan(storeys=2, length=16, width=14, seed=5))
    bake(d / "office.json", d / "office.db")
    return d / "office.db"


def _get(app: Any, url: str, **headers: str) -> httpx.Response:
    async def go() -> httpx.Response:
        async with httpx.AsyncClient(transport=httpx.ASGITransport(app=app), base_url="http://t") as c:
            return await c.get(url, headers=headers)

    return asyncio.run(go())


def test_manifest_names_the_kind_and_only_the_features_used(office: Path, tmp_path: Path) -> None:
    app = create_app([office])
    m = decode_manifest(_get(app, "/v1/scenes/office").content, "m")
    assert m.kind == "interior" and m.features == ("rooms", "portals", "meshes")
    assert m.objects == 0 and m.grammar_text == "" and "tour" in m.paths
    city = build_city_db(tmp_path / "city.db")
    mc = decode_manifest(_get(create_app([city.path]), f"/v1/scenes/{city.name}").content, "m")
    assert mc.kind == "city" and "portals" not in mc.features


def test_topology_rooms_and_immutable_contents(office: Path) -> None:
    app = create_app([office])
    r = _get(app, "/v1/scenes/office/topology")
    assert r.status_code == 200 and "immutable" in r.headers["cache-control"]
    topo = decode_topology(r.content, "t")
    with SceneReader.open(office) as db:
        assert len(topo.cells) == len(list(db.cells())) and len(topo.portals) == len(db.portals())
        assert len(topo.stairs) == len(db.stairs()) == 1
    room = next(c for c in topo.cells if c.kind == "room")
    rec = decode_room(_get(app, f"/v1/scenes/office/rooms/{room.id}").content, "r")
    assert rec.id == room.id and len(rec.planes) == len(rec.outline) + 2
    assert rec.portals and all(p.cell in rec.neighbours for p in rec.portals)
    assert all(len(p.polygon) >= 3 for p in rec.portals)
    first = _get(app, f"/v1/scenes/office/rooms/{room.id}/contents")
    assert first.headers["content-type"] == "application/vnd.walkstream.cellmesh"
    assert "immutable" in first.headers["cache-control"]
    cm = decode_cell_mesh(first.content)
    assert cm.triangles == rec.contents.triangles and len(first.content) == rec.contents.nbytes
    again = _get(app, f"/v1/scenes/office/rooms/{room.id}/contents", **{"If-None-Match": first.headers["etag"]})
    assert again.status_code == 304 and again.content == b""
    assert _get(app, "/v1/scenes/office/rooms/99999").status_code == 404
    assert _get(app, "/v1/scenes/office/rooms/99999/contents").status_code == 404


def test_locate_in_3d_picks_the_storey(office: Path) -> None:
    app = create_app([office])
    with SceneReader.open(office) as db:
        storeys = db.storeys()
        stair = db.stairs()[0]
        lower = next(c for c in db.cells() if c.id == stair.lower)
        x, y = np.asarray(lower.boundary).mean(axis=0)
    ids = []
    for z in (storeys[0].zmin + 1.6, storeys[1].zmin + 1.6):
        ans = json.loads(_get(app, f"/v1/scenes/office/locate?x={x}&y={y}&z={z}", accept="application/json").text)
        ids.append(ans["cell"])
    assert ids[0] == stair.lower and ids[1] == stair.upper
    # far above the building: in no cell (and never in the outside cell)
    ans = json.loads(_get(app, f"/v1/scenes/office/locate?x={x}&y={y}&z=100", accept="application/json").text)
    assert ans["cell"] is None


def test_a_city_has_no_rooms(tmp_path: Path) -> None:
    city = build_city_db(tmp_path / "city.db")
    app = create_app([city.path])
    r = _get(app, f"/v1/scenes/{city.name}/topology")
    assert r.status_code == 404 and "city" in r.json()["error"]
    assert _get(app, f"/v1/scenes/{city.name}/rooms/0/contents").status_code == 404


def test_documented_shapes_match_the_interior_records() -> None:
    sq = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]])
    poly = np.array([[0.0, 0, 0], [1, 0, 0], [1, 0, 2]])
    rec = RoomRecord(3, "room", "A", "key", 0, sq, 0.0, 3.0, np.zeros((5, 4)),
                     (PortalRef(1, "door", poly, 4),), (4,), ContentsRef(10, 8, 2, 300, 216, 1e-4))
    wire = rec.to_wire()
    assert list(wire) == list(models.RoomOut.model_fields)
    assert list(wire["portals"][0]) == list(models.PortalRefOut.model_fields)
    assert list(wire["contents"]) == list(models.ContentsOut.model_fields)
    topo = Topology(((0, "g", 0.0, 3.0),), (rec,), ((1, "door", 3, 4, poly),), ((1, 3, 4, poly),)).to_wire()
    assert list(topo) == list(models.TopologyOut.model_fields)
    assert list(topo["cells"][0]) == list(models.TopoCellOut.model_fields)
    assert list(topo["portals"][0]) == list(models.TopoPortalOut.model_fields)
    assert list(topo["stairs"][0]) == list(models.StairOut.model_fields)
    assert list(topo["storeys"][0]) == list(models.StoreyOut.model_fields)
    back = decode_topology(__import__("msgpack").packb(topo), "t")
    assert back.cells[0].portals[0].cell == 4


def test_the_client_reads_an_interior(office: Path) -> None:
    app = create_app([office])

    async def go() -> tuple[Any, ...]:
        async with httpx.AsyncClient(transport=httpx.ASGITransport(app=app), base_url="http://t") as c:
            api = SceneClient(c, RealClock(), "office")
            topo = await api.topology()
            cid = next(x.id for x in topo.cells if x.kind == "room")
            return topo, await api.room(cid), await api.contents(cid)

    topo, rec, cm = asyncio.run(go())
    assert rec.contents.triangles == cm.triangles > 0
    assert sum(c.contents.triangles for c in topo.cells) > cm.triangles


def test_old_city_databases_keep_working(tmp_path: Path) -> None:
    """A schema version 1 file, exactly as cities were stored before interiors."""
    city = build_city_db(tmp_path / "v1.db")
    with closing(sqlite3.connect(city.path)) as c:
        c.executescript(
            "CREATE TABLE cells_v1(id INTEGER PRIMARY KEY, kind TEXT NOT NULL CHECK (kind IN "
            "('crossroad', 'street', 'square', 'grid', 'room')), boundary BLOB NOT NULL, "
            "zmin REAL NOT NULL, zmax REAL NOT NULL, neighbours BLOB NOT NULL, pvs BLOB, "
            "done INTEGER NOT NULL DEFAULT 0);"
            "INSERT INTO cells_v1 SELECT * FROM cells; DROP TABLE cells; ALTER TABLE cells_v1 RENAME TO cells;"
            "UPDATE meta SET value = 1 WHERE key = 'schema_version'; PRAGMA user_version = 1;"
        )
        c.commit()
    with SceneReader.open(city.path, check=True) as r:
        s = r.summary()
        assert s["schema_version"] == 1 and s["kind"] == "city" and s["portals"] == 0
        assert r.rooms() == {} and r.portals() == [] and r.storeys() == []
    app = create_app([city.path])
    m = decode_manifest(_get(app, f"/v1/scenes/{city.name}").content, "m")
    assert m.kind == "city" and m.schema_version == 1
    first = next(iter(city.pvs))
    assert _get(app, f"/v1/scenes/{city.name}/cells/{first}").status_code == 200


def test_replay_walks_the_tour_end_to_end(office: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    report = tmp_path / "rep"
    code = main(["replay", str(office), "--path", "tour", "--device", "desktop2003", "--duration", "40s",
                 "--report", str(report), "--json"])
    assert code == 0
    s = json.loads((report / "report.json").read_text())
    assert s["kind"] == "interior" and s["frames"] > 900
    assert s["cells_entered"] >= 3 and s["visible_cells_mean"] >= 1
    assert s["perfect_frame_ratio"] > 0.9 and s["triangles_mean"] > 0
    # each cell fetched once; batches carry several cells per request
    assert s["redownloads"] == 0 and 0 < s["contents_requests"] < s["cells_fetched"]
    assert (report / "index.html").exists()
    capsys.readouterr()


def test_replay_draws_the_interior_on_gl(office: Path, tmp_path: Path, gl: object) -> None:
    report = tmp_path / "gl"
    assert main(["replay", str(office), "--path", "tour", "--device", "gl", "--duration", "6s",
                 "--snapshot-every", "50", "--report", str(report), "--no-plots"]) == 0
    s = json.loads((report / "report.json").read_text())
    assert s["triangles_mean"] > 100 and s["frames"] > 100
    frames = sorted((report / "frames").glob("*.png"))
    assert frames
    import matplotlib.image

    img = matplotlib.image.imread(frames[-1])
    assert img.std() > 0.02  # walls, floor and furniture, not an empty sky


def test_cli_record_inspect_map_and_cutaway(office: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], gl: object) -> None:
    db = tmp_path / "o.db"
    db.write_bytes(office.read_bytes())
    with SceneReader.open(db) as r:
        rooms = sorted({ri.name for ri in r.rooms().values() if ri.room is not None})
    a = next(n for n in rooms if n.startswith("0.") and "office" in n)
    b = next(n for n in rooms if n.startswith("1.") and "corridor" in n)
    assert main(["path", "record", str(db), "up", "--from-room", a, "--to-room", b]) == 0
    assert "recorded path 'up'" in capsys.readouterr().out
    with SceneReader.open(db) as r:
        from walkstream.shared.paths import RecordedPath

        up = RecordedPath.from_msgpack(r.path_blob("up"))
        assert up.speed_kmh == 4.0 and up.xyz[0, 2] == pytest.approx(1.6) and up.xyz[-1, 2] == pytest.approx(3.4 + 1.6)
    assert main(["path", "record", str(db), "x", "--from-room", "nowhere", "--to-room", b]) == 2
    err = capsys.readouterr().err
    assert "no room named 'nowhere'" in err and "Traceback" not in err
    assert main(["path", "record", str(db), "y", "--from", "0,0"]) == 2
    capsys.readouterr()
    png = tmp_path / "map.png"
    assert main(["inspect", str(db), "--json", "--map", str(png)]) == 0
    got = json.loads(capsys.readouterr().out)
    assert got["kind"] == "interior" and got["portals"] > 0 and got["paths"] == 2
    assert png.read_bytes()[:4] == b"\x89PNG"
    cut = tmp_path / "cut.png"
    assert main(["cutaway", str(db), "--storey", "1", "-o", str(cut)]) == 0
    assert cut.read_bytes()[:4] == b"\x89PNG" and "triangles" in capsys.readouterr().out


def test_generate_and_bench_interiors_cli(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "office.json"
    assert main(["generate", "interior", "--storeys", "1", "--size", "12x9", "-o", str(out), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["storeys"] == 1 and summary["rooms"] >= 3
    assert main(["generate", "interior", "--preset", "nope", "-o", str(out)]) == 2
    capsys.readouterr()
    from ifcmodels import two_rooms_model

    ifc = two_rooms_model(tmp_path / "two.ifc")
    assert main(["bench", "interiors", "--ifc", str(ifc), "--presets", "--out", str(tmp_path / "b")]) == 0
    table = capsys.readouterr().out
    assert "two.ifc" in table and "B/cell mean" in table and "max err mm" in table


def test_a_database_baked_with_cellmesh_1_keeps_working(office: Path, tmp_path: Path) -> None:
    # a database baked before walkstream-cellmesh/2: the service serves its blobs as they
    # are and the client decodes them; the same cells in /2 cover the same area
    from walkstream.server.bake.pipeline import bake_interior
    from walkstream.server.sources.read import read_source
    from walkstream.shared.codec.cellmesh import CELLMESH_FORMAT, CELLMESH_V1
    from walkstream.shared.codec.planarmesh import mesh_area

    src = office.parent / "office.json"
    old = tmp_path / "old.db"
    bake_interior(read_source(src), src, old, cellmesh_version=1)  # type: ignore[arg-type]
    with SceneReader.open(old) as db_old, SceneReader.open(office) as db_new:
        assert db_old.meta.settings["cellmesh"] == CELLMESH_V1
        assert db_new.meta.settings["cellmesh"] == CELLMESH_FORMAT
        cid = next(c.id for c in db_old.cells() if c.kind == "room")
        new = decode_cell_mesh(db_new.contents(cid))
        # no decoded vertex is left only in flat triangles (a T-junction with its neighbour)
        for c in db_new.cells():
            for part in decode_cell_mesh(db_new.contents(c.id)).parts:
                p, t = part.positions.astype(np.float64), part.indices.astype(np.int64)
                live = np.linalg.norm(np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]]), axis=1) > 1e-9
                assert len(np.unique(t[live])) == len(p), (c.id, part.element)
    served = _get(create_app([old]), f"/v1/scenes/old/rooms/{cid}/contents")
    assert served.status_code == 200
    cm = decode_cell_mesh(served.content)
    assert cm.grid == 0.0 and new.grid == 0.001 and cm.triangles >= new.triangles
    for a, b in zip(cm.parts, new.parts, strict=True):
        assert a.element == b.element
        assert mesh_area(a.positions, a.indices) == pytest.approx(mesh_area(b.positions, b.indices), rel=1e-3, abs=1e-4)
