"""The documented shapes of the API, for OpenAPI and ``/docs``.

The handlers send pre-encoded bytes (the records of :mod:`walkstream.shared.wire`);
these pydantic models only describe them.  ``tests/test_server.py`` checks that each
documented record has exactly the fields the wire record sends.
"""

from __future__ import annotations

from typing import Annotated, Any

from pydantic import BaseModel, Field

from walkstream.server.service.scenes import MAX_IDS
from walkstream.shared.wire import MSGPACK

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
    "Manifest",
    "LocateOut",
    "NeighbourOut",
    "CellOut",
    "ObjectsIn",
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


class LocateOut(BaseModel):
    """The cell containing a position, or ``cell: null`` with the reason."""

    cell: int | None
    reason: str | None = None


class NeighbourOut(BaseModel):
    """An adjacent cell and its boundary."""

    id: int
    boundary: list[list[float]]


class CellOut(BaseModel):
    """A view cell: convex boundary, eye-height range, neighbours, PVS and ACH."""

    id: int
    kind: str
    boundary: list[list[float]] = Field(description="(n, 2) convex outline, local metres")
    zmin: float
    zmax: float
    neighbours: list[NeighbourOut]
    pvs: list[int] = Field(description="ids of the potentially visible objects, ascending")
    ach: list[float] = Field(description="average coverage of each PVS object; sums to 1")


class ObjectsIn(BaseModel):
    """The objects to send, in the order to send them."""

    ids: list[Annotated[int, Field(ge=0, le=MAX_INT64)]] = Field(max_length=MAX_IDS)



def error_doc(description: str) -> dict[str, Any]:
    return {"model": ErrorOut, "description": description}


ERRORS: dict[int | str, dict[str, Any]] = {
    404: error_doc("unknown scene, cell, path or object (named in the error)"),
    422: error_doc("a malformed parameter"),
}


def both(description: str) -> dict[int | str, dict[str, Any]]:
    # the JSON schema comes from response_model; msgpack carries the same structure
    return {
        200: {"description": description, "content": {MSGPACK: {}}},
        304: {"description": "not modified (If-None-Match matched the ETag)"},
    }
