"""The documented shapes of the API, for OpenAPI and ``/docs``.

The handlers send pre-encoded bytes (the records of :mod:`walkstream.shared.wire`);
these pydantic models only describe them.  ``tests/test_server.py`` checks that each
documented record has exactly the fields the wire record sends.
"""

from __future__ import annotations

from typing import Annotated, Any

from pydantic import BaseModel, Field

from walkstream.server.service.scenes import MAX_IDS
from walkstream.shared.codec.cellbatch import CELLBATCH_MAX_CELLS
from walkstream.shared.wire import JSON, MSGPACK

MAX_INT64 = 2**63 - 1
"""Largest object id (SQLite integers are signed 64-bit)."""


__all__ = [
    "ErrorOut",
    "error_doc",
    "HealthOut",
    "SceneRef",
    "GrammarOut",
    "ViewpointOut",
    "LimitsOut",
    "TileGridOut",
    "Manifest",
    "LocateOut",
    "CellOut",
    "CellIndexOut",
    "StartPartOut",
    "ObjectsIn",
    "PortalRefOut",
    "ContentsOut",
    "RoomOut",
    "StoreyOut",
    "TopoCellOut",
    "TopoPortalOut",
    "StairOut",
    "TopologyOut",
    "CellsIn",
    "ContentsIn",
    "MAX_INT64",
    "ERRORS",
    "both",
]




class ErrorOut(BaseModel):
    """Every error: a message and a machine-readable detail."""

    error: str
    detail: Any = None


class HealthOut(BaseModel):
    """Health: ``ok`` and the number of scenes served."""

    status: str
    scenes: int


class SceneRef(BaseModel):
    """A served scene: its name (used in URLs) and version (content hash)."""

    name: str
    version: str


class GrammarOut(BaseModel):
    """The building grammar the scene's objects are meant for."""

    id: str
    text: str


class ViewpointOut(BaseModel):
    """A named start position in scene-local metres; ``yaw`` in radians."""

    name: str
    x: float
    y: float
    z: float
    yaw: float
    cell: int | None


class LimitsOut(BaseModel):
    """Request limits a client must respect."""

    objects_per_request: int


class TileGridOut(BaseModel):
    """The square tiles of the cell index (``GET .../index/{i}/{j}``)."""

    origin: list[float] = Field(description="south-west corner of tile (0, 0), local metres")
    tile: float = Field(description="side of a tile, metres")
    shape: list[int] = Field(description="tiles along x and y")
    reach: float = Field(
        description="largest distance from a cell's outline to its tile's square: a point "
        "lies only in cells of the tiles within this distance"
    )


class Manifest(BaseModel):
    """What a client needs to start walking a scene."""

    name: str
    version: str
    schema_version: int
    crs: str
    origin: list[float] = Field(description="CRS position of local (0, 0)")
    bounds: list[float] = Field(description="minx, miny, minz, maxx, maxy, maxz in local metres")
    features: list[str]
    grammar: GrammarOut
    viewpoints: list[ViewpointOut]
    paths: list[str] = Field(description="names of the recorded paths")
    objects: int
    cells: int
    limits: LimitsOut
    kind: str = Field(description="city or interior")
    index: TileGridOut | None = Field(description="tiles of the cell index; null without one")
    offers: list[str] = Field(
        description="optional parts of the API this server has: cell-index, cells-batch, start"
    )


class LocateOut(BaseModel):
    """The cell containing a position, or ``cell: null`` with the reason."""

    cell: int | None
    reason: str | None = None


IntsOut = list[Any]
"""An integer sequence ``[format, payload]`` (shared.codec.pack_ints): in JSON always
``[0, [int, ...]]``; in msgpack format 1 (int16), 2 (int32) or 3 (zigzag varints)
carry ``bin`` payloads."""


class ImpostorsOut(BaseModel):
    """What a cell draws as impostors: the bake's distance and error bound, one row per building."""

    d: int = Field(description="D: a listed building is at least this far from every point of the cell, centimetres")
    a: int = Field(description="A: the angular error bound, microradians")
    rows: list[list[int]] = Field(
        description="[object, level, az0, n_az, el0, n_el, minx, miny, minz, maxx, maxy, maxz, image ids...]: "
        "the box in centimetres; image j * n_az + i is the one of azimuth bin (az0 + i) mod 8 * 2**level "
        "and elevation bin el0 + j"
    )


class CellOut(BaseModel):
    """A view cell's own data: its PVS and the ACH of each object (outlines are in the index)."""

    id: int
    kind: str
    pvs: IntsOut = Field(
        description="PVS object ids ascending, delta-coded (the first id, then differences)"
    )
    ach: IntsOut = Field(
        description="average coverage of each PVS object in units of 1/65535, summing to 65535"
    )
    imp: ImpostorsOut | None = Field(
        default=None,
        description="only in a scene baked with --impostors, for a cell with impostors (see docs/formats.md)",
    )
    far: IntsOut | None = Field(
        default=None,
        description="only in a city baked with --virtual-walls, for a cell with a ring of walls: the objects "
        "its ring's textures carry, ids ascending, delta-coded (drawn as geometry while a texture is missing)",
    )
    fach: IntsOut | None = Field(default=None, description="their coverage in units of 1/65535, summing to 65535")
    fsh: int | None = Field(default=None, description="their share of the cell's whole coverage, units of 1/65535")


class CellIndexOut(BaseModel):
    """Outlines, height ranges and neighbours of the cells of one tile (or of the scene)."""

    tile: list[int] | None = Field(description="[i, j], or null for the whole scene")
    ids: IntsOut = Field(description="cell ids ascending, delta-coded")
    kind_names: list[str]
    kinds: IntsOut = Field(description="each cell's kind, an index into kind_names")
    zmin: IntsOut = Field(description="eye-height range bottoms, centimetres, delta-coded")
    zmax: IntsOut = Field(description="eye-height range tops, centimetres, delta-coded")
    counts: IntsOut = Field(description="vertices of each cell's convex outline")
    anchor: list[int] = Field(description="first vertex of the first outline, centimetres")
    coords: IntsOut = Field(
        description="x/y centimetre deltas of every further vertex, chained over all outlines"
    )
    degrees: IntsOut = Field(description="number of neighbours of each cell")
    adjacent: IntsOut = Field(description="neighbour ids, each minus its cell's own id")


class StartPartOut(BaseModel):
    """One part of a start bundle: the body its own endpoint sends, with that body's ETag."""

    part: str = Field(description="pathhead (interiors, asked with head), path, topology (interiors), contents (interiors), cell, record (a cell record whose objects the bundle does not all bring), index, manifest or objects")
    etag: str | None
    body: Any = Field(description="msgpack: the body's bytes; JSON: the body's JSON form")


class PortalRefOut(BaseModel):
    """A portal of an interior cell: its polygon and the cell on its other side."""

    id: int
    kind: str = Field(description="door, window, opening, virtual, split, void or stair")
    polygon: list[list[float]] = Field(description="(k, 3) scene-local metres")
    cell: int


class ContentsOut(BaseModel):
    """What a cell's contents weigh."""

    triangles: int
    vertices: int
    parts: int
    bytes: int = Field(description="encoded bytes of .../contents")
    raw_bytes: int = Field(description="the same mesh as float32 positions and uint32 indices")
    max_error: float = Field(description="largest position error of the encoding, metres")


class RoomOut(BaseModel):
    """An interior cell: plane set, convex outline, height range, portals, neighbours."""

    id: int
    kind: str = Field(description="room, doorway or outside")
    name: str
    room: str | None = Field(description="the source's room key (None for doorways and the outside)")
    storey: int
    outline: list[list[float]] = Field(description="(n, 2) convex outline, local metres")
    zmin: float
    zmax: float
    planes: list[list[float]] = Field(description="(k, 4) nx, ny, nz, d: inside where n . p + d <= 0")
    portals: list[PortalRefOut]
    neighbours: list[int]
    contents: ContentsOut


class StoreyOut(BaseModel):
    """A storey and the height range of its cells."""

    id: int
    name: str
    zmin: float
    zmax: float


class TopoCellOut(BaseModel):
    """A cell in the topology (its portals are listed once, in ``portals``)."""

    id: int
    kind: str
    name: str
    storey: int
    outline: list[list[float]]
    zmin: float
    zmax: float
    planes: list[list[float]]
    triangles: int
    bytes: int


class TopoPortalOut(BaseModel):
    """A portal with the two cells it joins."""

    id: int
    kind: str
    cells: list[int]
    polygon: list[list[float]]


class StairOut(BaseModel):
    """A stair: the portal it climbs through, its cells and walking line (floor points)."""

    portal: int
    lower: int
    upper: int
    path: list[list[float]]


class TopologyOut(BaseModel):
    """An interior's topological file: storeys, cells, portals, stairs."""

    storeys: list[StoreyOut]
    cells: list[TopoCellOut]
    portals: list[TopoPortalOut]
    stairs: list[StairOut]


class ObjectsIn(BaseModel):
    """The objects to send, in the order to send them."""

    ids: list[Annotated[int, Field(ge=0, le=MAX_INT64)]] = Field(max_length=MAX_IDS)


class CellsIn(BaseModel):
    """The cells whose records to send, in the order to send them."""

    ids: list[Annotated[int, Field(ge=0, le=MAX_INT64)]] = Field(max_length=MAX_IDS)


class ContentsIn(BaseModel):
    """The interior cells whose contents to send, each once, in the order to send them."""

    ids: list[Annotated[int, Field(ge=0, le=MAX_INT64)]] = Field(
        max_length=CELLBATCH_MAX_CELLS, json_schema_extra={"uniqueItems": True}
    )


CONTENTS_BATCH_BODY: dict[str, Any] = {
    "required": True,
    "content": {
        JSON: {"schema": ContentsIn.model_json_schema()},
        MSGPACK: {"schema": ContentsIn.model_json_schema()},
    },
}
"""The OpenAPI request body of a contents batch (rooms' contents, impostor images): a
:class:`ContentsIn` as JSON or msgpack (the route reads the body itself)."""


def error_doc(description: str) -> dict[str, Any]:
    return {"model": ErrorOut, "description": description}


ERRORS: dict[int | str, dict[str, Any]] = {
    404: error_doc("unknown scene, cell, tile, path, viewpoint or object, or rooms of a city (named in the error)"),
    422: error_doc("a malformed parameter"),
}


def both(description: str) -> dict[int | str, dict[str, Any]]:
    # the JSON schema comes from response_model; msgpack carries the same structure
    return {
        200: {"description": description, "content": {MSGPACK: {}}},
        304: {"description": "not modified (If-None-Match matched the ETag)"},
    }
