"""Streaming meshes instead of parameters: shared.codec.encode_mesh/decode_mesh and
the server's ``POST .../objects?form=lod2`` (what ``--stream meshes`` compares)."""

from __future__ import annotations

import asyncio
import base64
import io
from collections.abc import Callable, Iterator
from typing import Any

import httpx
import msgpack
import numpy as np
import pytest
from fastapi import FastAPI
from hypothesis import given, settings
from hypothesis import strategies as st
from scenes import CityDb, build_city_db

from walkstream.server.service.main import create_app
from walkstream.server.sources.citygen import generate_city
from walkstream.server.sources.geojson import load_geojson_dict
from walkstream.server.sources.scene import SourceScene
from walkstream.shared.buildings import build_lod, build_lods
from walkstream.shared.codec import (
    MESH_FORMAT,
    decode_mesh,
    decode_object,
    encode_building,
    encode_mesh,
)
from walkstream.shared.errors import CodecError
from walkstream.shared.lsystem.grammar import parse_grammar
from walkstream.shared.records import BuildingParams, Mesh, StreetParams
from walkstream.shared.streets import build_street

# ---------------------------------------------------------------------------
# codec
# ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def city_src() -> SourceScene:
    return load_geojson_dict(generate_city(200.0, 1), name="city")


def assert_same_mesh(got: Mesh, want: Mesh, normal_atol: float = 1e-3) -> None:
    assert np.array_equal(got.positions, want.positions)
    assert np.array_equal(got.indices, want.indices)
    assert np.array_equal(got.materials, want.materials)
    # normals are recomputed from float32 positions: the same up to float rounding
    np.testing.assert_allclose(got.normals, want.normals, rtol=0, atol=normal_atol)


def test_building_meshes_round_trip(city_src: SourceScene) -> None:
    for b in city_src.buildings[:12]:
        for lod, want in enumerate(build_lods(b)):
            data = encode_mesh(want)
            rec = msgpack.unpackb(data)
            assert rec["format"] == MESH_FORMAT
            # flat faces: nothing beyond positions, indices and per-triangle materials
            assert "normals" not in rec and "vertex_materials" not in rec, (b.id, lod)
            assert len(rec["materials"]) == want.triangles
            assert rec["index_bytes"] == (1 if len(want.positions) <= 256 else 2)
            assert_same_mesh(decode_mesh(data), want)


def test_street_meshes_round_trip_exactly(city_src: SourceScene) -> None:
    for s in city_src.streets:
        want = build_street(s)
        got = decode_mesh(encode_mesh(want))
        assert_same_mesh(got, want, normal_atol=0.0)


def test_index_width_follows_the_vertex_count() -> None:
    n = 70_000
    pos = np.zeros((n, 3))
    pos[:, 0] = np.arange(n)
    pos[1::2, 1] = 1.0
    tris = np.column_stack([np.arange(n - 2), np.arange(1, n - 1), np.arange(2, n)])
    tris[1::2] = tris[1::2, ::-1]  # keep one winding so the strip is flat and consistent
    mesh = Mesh(pos, np.tile([0.0, 0.0, 1.0], (n, 1)), tris)
    data = encode_mesh(mesh)
    assert msgpack.unpackb(data)["index_bytes"] == 4
    got = decode_mesh(data)
    assert np.array_equal(got.indices, mesh.indices)
    small = Mesh(pos[:300], np.tile([0.0, 0.0, 1.0], (300, 1)), tris[:298])
    assert msgpack.unpackb(encode_mesh(small))["index_bytes"] == 2


def test_empty_mesh_round_trips() -> None:
    empty = Mesh(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)))
    got = decode_mesh(encode_mesh(empty))
    assert got.triangles == 0 and len(got.positions) == 0


def test_what_cannot_be_recomputed_is_sent() -> None:
    # a tetrahedron with shared vertices and smooth (radial) normals, and a triangle
    # whose corners have different materials: neither survives the compact form
    pos = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], np.float64)
    tris = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    nrm = pos - pos.mean(axis=0)
    nrm /= np.linalg.norm(nrm, axis=1)[:, None]
    mesh = Mesh(pos, nrm, tris, np.array([1, 2, 3, 4], np.uint8))
    data = encode_mesh(mesh)
    rec = msgpack.unpackb(data)
    assert "normals" in rec and "vertex_materials" in rec and "materials" not in rec
    assert_same_mesh(decode_mesh(data), mesh, normal_atol=0.0)


def test_meshes_are_much_larger_than_parameters(city_src: SourceScene) -> None:
    mesh_bytes = [len(encode_mesh(build_lod(b, 2))) for b in city_src.buildings]
    param_bytes = [len(encode_building(b)) for b in city_src.buildings]
    ratio = sum(mesh_bytes) / sum(param_bytes)
    assert ratio > 100, ratio  # about 1500 for this city
    assert min(m / p for m, p in zip(mesh_bytes, param_bytes, strict=True)) > 10


def _good() -> dict[str, Any]:
    pos = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    return {
        "format": MESH_FORMAT,
        "vertices": 3,
        "positions": pos.tobytes(),
        "index_bytes": 1,
        "indices": bytes([0, 1, 2]),
        "materials": bytes([4]),
    }


Mutation = Callable[[dict[str, Any]], Any]

_BAD: list[tuple[str, Mutation, str]] = [
    ("not a map", lambda r: [1, 2], "expected a map"),
    ("format", lambda r: {**r, "format": "obj"}, "format"),
    ("unknown field", lambda r: {**r, "colour": b"x"}, "unknown field 'colour'"),
    ("no positions", lambda r: {k: v for k, v in r.items() if k != "positions"}, "positions"),
    ("short positions", lambda r: {**r, "positions": r["positions"][:-4]}, "positions"),
    ("positions type", lambda r: {**r, "positions": [0.0] * 9}, "positions"),
    (
        "nan position",
        lambda r: {**r, "positions": np.array([np.nan] * 9, np.float32).tobytes()},
        "positions: not finite",
    ),
    (
        "inf position",
        lambda r: {**r, "positions": np.array([np.inf] * 9, np.float32).tobytes()},
        "positions: not finite",
    ),
    ("vertices type", lambda r: {**r, "vertices": "3"}, "vertices"),
    ("vertices negative", lambda r: {**r, "vertices": -1}, "vertices"),
    ("vertices huge", lambda r: {**r, "vertices": 2**40}, "vertices"),
    ("index out of range", lambda r: {**r, "indices": bytes([0, 1, 3])}, "out of range"),
    ("partial triangle", lambda r: {**r, "indices": bytes([0, 1])}, "indices"),
    ("index width", lambda r: {**r, "index_bytes": 3}, "index_bytes"),
    ("index width type", lambda r: {**r, "index_bytes": True}, "index_bytes"),
    ("materials length", lambda r: {**r, "materials": bytes([1, 2])}, "materials"),
    (
        "both materials",
        lambda r: {**r, "vertex_materials": bytes(3)},
        "exactly one of materials",
    ),
    ("short normals", lambda r: {**r, "normals": bytes(12)}, "normals"),
    (
        "nan normals",
        lambda r: {**r, "normals": np.full(9, np.nan, np.float32).tobytes()},
        "normals: not finite",
    ),
]


@pytest.mark.parametrize(
    ("mutate", "needle"), [(m, n) for _, m, n in _BAD], ids=[b[0] for b in _BAD]
)
def test_malformed_meshes_name_the_field(mutate: Mutation, needle: str) -> None:
    assert isinstance(decode_mesh(msgpack.packb(_good())), Mesh)
    with pytest.raises(CodecError, match=f"mesh of 7: .*{needle}"):
        decode_mesh(msgpack.packb(mutate(_good())), "mesh of 7")


def test_truncated_and_trailing_bytes(city_src: SourceScene) -> None:
    data = encode_mesh(build_lod(city_src.buildings[0], 2))
    for cut in (0, 1, 10, len(data) // 2, len(data) - 1):
        with pytest.raises(CodecError):
            decode_mesh(data[:cut])
    with pytest.raises(CodecError, match="trailing"):
        decode_mesh(data + b"\x00")
    with pytest.raises(CodecError, match="expected bytes"):
        decode_mesh("text")  # type: ignore[arg-type]


@settings(max_examples=200, deadline=None, derandomize=True, database=None)
@given(data=st.binary(max_size=300), flips=st.lists(st.integers(0, 10_000), max_size=8))
def test_random_bytes_only_raise_codec_errors(data: bytes, flips: list[int]) -> None:
    good = bytearray(msgpack.packb(_good()))
    for f in flips:
        good[f % len(good)] ^= 1 + f % 255
    for blob in (data, bytes(good)):
        try:
            decode_mesh(blob)
        except CodecError:
            pass


# ---------------------------------------------------------------------------
# server: POST /v1/scenes/{scene}/objects?form=lod2
# ---------------------------------------------------------------------------


class Client:
    """A synchronous face on ``httpx.AsyncClient`` over the ASGI app (one event loop)."""

    def __init__(self, app: FastAPI) -> None:
        self.loop = asyncio.new_event_loop()
        self.http = httpx.AsyncClient(
            transport=httpx.ASGITransport(app=app), base_url="http://testserver"
        )

    def request(self, method: str, url: str, **kwargs: Any) -> httpx.Response:
        return self.loop.run_until_complete(self.http.request(method, url, **kwargs))

    def close(self) -> None:
        self.loop.run_until_complete(self.http.aclose())
        self.loop.close()


@pytest.fixture(scope="module")
def city(tmp_path_factory: pytest.TempPathFactory) -> CityDb:
    return build_city_db(tmp_path_factory.mktemp("mesh") / "tiny.db", size=160.0, k=10)


@pytest.fixture(scope="module")
def client(city: CityDb) -> Iterator[Client]:
    app = create_app([city.path])
    c = Client(app)
    yield c
    c.close()
    app.state.scenes.close()


def post(
    client: Client, city: CityDb, ids: list[int], form: str | None, **kw: Any
) -> httpx.Response:
    params = {} if form is None else {"form": form}
    return client.request(
        "POST", f"/v1/scenes/{city.name}/objects", json={"ids": ids}, params=params, **kw
    )


def frames(r: httpx.Response) -> list[dict[str, Any]]:
    assert r.status_code == 200, r.text
    assert r.headers["content-type"] == "application/msgpack"
    return list(msgpack.Unpacker(io.BytesIO(r.content), raw=False))


def test_lod2_meshes_match_local_rebuilds(client: Client, city: CityDb) -> None:
    rng = np.random.default_rng(5)
    ids = [int(i) for i in rng.permutation(city.object_ids)[:25]]
    ids += [ids[0], ids[3]]  # repeats are sent again, in place
    r = post(client, city, ids, "lod2")
    got = frames(r)
    assert r.headers["x-object-count"] == str(len(ids))
    assert [f["id"] for f in got] == ids
    assert all(set(f) == {"id", "kind", "mesh"} for f in got)
    # rebuild locally from the parameters with the grammar of the manifest
    m = client.request("GET", f"/v1/scenes/{city.name}")
    grammar = parse_grammar(msgpack.unpackb(m.content)["grammar"]["text"])
    params = {f["id"]: f for f in frames(post(client, city, ids, "params"))}
    kinds = set()
    for f in got:
        p = decode_object(params[f["id"]]["params"])
        assert f["kind"] == params[f["id"]]["kind"]
        kinds.add(type(p))
        want = build_lod(p, 2, grammar) if isinstance(p, BuildingParams) else build_street(p)
        assert_same_mesh(decode_mesh(f["mesh"], f"mesh of {f['id']}"), want)
    assert kinds == {BuildingParams, StreetParams}
    # a second request is served from the frame cache, byte for byte
    assert post(client, city, ids, "lod2").content == r.content


def test_params_form_is_the_default_and_unchanged(client: Client, city: CityDb) -> None:
    ids = list(city.object_ids[:8])
    default = post(client, city, ids, None)
    assert post(client, city, ids, "params").content == default.content
    assert all(set(f) == {"id", "kind", "params"} for f in frames(default))
    # the mesh frames of the same objects are far larger
    meshes = post(client, city, ids, "lod2")
    assert len(meshes.content) > 20 * len(default.content)


def test_lod2_json(client: Client, city: CityDb) -> None:
    ids = list(city.object_ids[:6])[::-1]
    rm = post(client, city, ids, "lod2")
    rj = post(client, city, ids, "lod2", headers={"accept": "application/json"})
    assert rj.status_code == 200 and rj.headers["content-type"] == "application/json"
    items = rj.json()
    assert [o["id"] for o in items] == ids
    assert all(set(o) == {"id", "kind", "mesh"} for o in items)
    assert [base64.b64decode(o["mesh"]) for o in items] == [f["mesh"] for f in frames(rm)]


def test_unknown_form_is_a_422_naming_it(client: Client, city: CityDb) -> None:
    r = post(client, city, [city.object_ids[0]], "lod9")
    assert r.status_code == 422 and r.headers["content-type"] == "application/json"
    body = r.json()
    assert "lod9" in body["error"] and "lod2" in body["error"]
    assert body["detail"]["form"] == "lod9"


def test_lod2_unknown_ids_and_empty(client: Client, city: CityDb) -> None:
    r = post(client, city, [city.object_ids[0], 10**12], "lod2")
    assert r.status_code == 404 and str(10**12) in r.json()["error"]
    r = post(client, city, [], "lod2")
    assert r.status_code == 200 and r.content == b""


def test_form_is_documented(client: Client, city: CityDb) -> None:
    spec = client.request("GET", "/openapi.json").json()
    op = spec["paths"]["/v1/scenes/{scene}/objects"]["post"]
    (form,) = [p for p in op["parameters"] if p["name"] == "form"]
    assert form["in"] == "query" and not form.get("required", False)
    assert "lod2" in form["description"] and form["schema"]["default"] == "params"
    assert "form=lod2" in spec["info"]["description"]
