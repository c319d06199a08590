"""The records of the HTTP API, defined once: the service encodes them, the client decodes them.

Every record is a frozen dataclass with :meth:`to_wire` (the plain structure the
service sends as msgpack or JSON, keys in a fixed order) and a bounded decoder for
the client, which reads untrusted bytes: every body is unpacked with hard limits
(:func:`~walkstream.shared.codec.unpack_bounded`) and checked field by field, so a
corrupt or hostile answer is a :class:`~walkstream.shared.errors.CodecError`, never
a crash.

manifest
    ``{name, version, schema_version, crs, origin, bounds, features, grammar: {id,
    text}, viewpoints: [{name, x, y, z, yaw, cell}], paths, objects, cells, limits:
    {objects_per_request}}``
cell
    ``{id, kind, boundary, zmin, zmax, neighbours: [{id, boundary}], pvs, ach}``
locate
    ``{cell: id}`` or ``{cell: null, reason}``
object frame
    ``{id, kind, params: bin}`` (or ``mesh: bin`` for the ``lod2`` form); a stream of
    them is plain concatenated msgpack, one per asked id in the order asked.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

import numpy as np
from numpy.typing import NDArray

from walkstream.shared.codec import unpack_bounded
from walkstream.shared.errors import CodecError
from walkstream.shared.records import Viewpoint, readonly

__all__ = [
    "MSGPACK",
    "JSON",
    "MSGPACK_TYPES",
    "FRAME_KEYS",
    "Manifest",
    "CellRecord",
    "ObjectFrame",
    "decode_manifest",
    "decode_cell",
    "decode_frame",
    "locate_answer",
    "decode_locate",
    "decode_scene_list",
]

MSGPACK = "application/msgpack"
"""Media type of every msgpack body (the default representation)."""
JSON = "application/json"
"""Media type of the JSON representation and of every error."""
MSGPACK_TYPES = frozenset({MSGPACK, "application/x-msgpack", "application/vnd.msgpack"})
"""Media types accepted as msgpack in ``Accept`` and ``Content-Type``."""

FRAME_KEYS: dict[str, str] = {"params": "params", "lod2": "mesh"}
"""The key of an object frame's payload, per form of the objects request."""

_MAX_MANIFEST = 4 << 20
_MAX_CELL = 8 << 20


@dataclass(frozen=True)
class Manifest:
    """What a client needs to start walking a scene.

    ``etag`` and ``body`` are what the client received (kept for its disk cache);
    the service leaves them empty.
    """

    name: str
    version: str
    schema_version: int
    crs: str
    origin: tuple[float, float]
    """CRS position of local (0, 0)."""
    bounds: tuple[float, ...]
    """``minx, miny, minz, maxx, maxy, maxz`` in local metres."""
    features: tuple[str, ...]
    grammar_id: str
    grammar_text: str
    viewpoints: tuple[Viewpoint, ...]
    paths: tuple[str, ...]
    """Names of the recorded paths."""
    objects: int
    cells: int
    max_ids: int
    """Most object ids one objects request may ask for."""
    etag: str | None = None
    body: bytes = field(default=b"", repr=False)

    def to_wire(self) -> dict[str, Any]:
        """The manifest as sent."""
        return {
            "name": self.name,
            "version": self.version,
            "schema_version": self.schema_version,
            "crs": self.crs,
            "origin": list(self.origin),
            "bounds": list(self.bounds),
            "features": list(self.features),
            "grammar": {"id": self.grammar_id, "text": self.grammar_text},
            "viewpoints": [
                {"name": v.name, "x": v.x, "y": v.y, "z": v.z, "yaw": v.yaw, "cell": v.cell}
                for v in self.viewpoints
            ],
            "paths": list(self.paths),
            "objects": self.objects,
            "cells": self.cells,
            "limits": {"objects_per_request": self.max_ids},
        }


@dataclass(frozen=True)
class CellRecord:
    """A view cell as the API sends it.

    ``nbytes``, ``etag`` and ``body`` are what the client received (its cache keeps
    them); the service leaves them empty.
    """

    id: int
    kind: str
    boundary: NDArray[np.float64]
    """(n, 2) convex outline, scene-local metres."""
    zmin: float
    zmax: float
    neighbours: Mapping[int, NDArray[np.float64]]
    """Neighbour id -> its (m, 2) outline."""
    pvs: NDArray[np.int64]
    ach: NDArray[np.float64]
    nbytes: int = 0
    etag: str | None = None
    body: bytes = field(default=b"", repr=False)

    def __post_init__(self) -> None:
        # records are shared between caches and callers: nothing in them may change
        object.__setattr__(self, "boundary", readonly(np.asarray(self.boundary, np.float64)))
        object.__setattr__(self, "pvs", readonly(np.asarray(self.pvs, np.int64)))
        object.__setattr__(self, "ach", readonly(np.asarray(self.ach, np.float64)))
        frozen = {int(n): readonly(np.asarray(b, np.float64)) for n, b in self.neighbours.items()}
        object.__setattr__(self, "neighbours", MappingProxyType(frozen))

    def to_wire(self) -> dict[str, Any]:
        """The record as sent: outlines as nested lists of floats."""
        return {
            "id": self.id,
            "kind": self.kind,
            "boundary": np.asarray(self.boundary, dtype=np.float64).tolist(),
            "zmin": self.zmin,
            "zmax": self.zmax,
            "neighbours": [
                {"id": n, "boundary": np.asarray(b, dtype=np.float64).tolist()}
                for n, b in self.neighbours.items()
            ],
            "pvs": np.asarray(self.pvs).tolist(),
            "ach": np.asarray(self.ach, dtype=np.float64).tolist(),
        }


@dataclass(frozen=True, slots=True)
class ObjectFrame:
    """One object of a stream: its id, kind and payload (parameters, or an encoded mesh)."""

    id: int
    kind: str
    payload: bytes
    form: str
    """``params`` or ``lod2``."""
    nbytes: int = 0
    """Bytes of the frame on the wire (the client fills it in)."""

    def to_wire(self) -> dict[str, Any]:
        """The frame as sent."""
        return {"id": self.id, "kind": self.kind, FRAME_KEYS[self.form]: self.payload}


def locate_answer(cell: int | None) -> dict[str, Any]:
    """The answer to ``locate``: ``{cell: id}``, or ``{cell: null, reason}`` outside every cell."""
    return {"cell": None, "reason": "outside every cell"} if cell is None else {"cell": cell}


# --------------------------------------------------------------------------- decoding


def _floats(x: Any, what: str, shape_cols: int | None = None) -> NDArray[np.float64]:
    try:
        a = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise CodecError(f"{what}: expected numbers") from exc
    if not np.all(np.isfinite(a)):
        raise CodecError(f"{what}: non-finite values")
    if shape_cols is not None and (a.ndim != 2 or a.shape[1] != shape_cols or len(a) < 3):
        raise CodecError(f"{what}: expected an (n >= 3, {shape_cols}) array, got shape {a.shape}")
    return a


def decode_cell(body: bytes, what: str, etag: str | None = None) -> CellRecord:
    """Decode and check a cell record body (msgpack)."""
    obj = unpack_bounded(
        body, what, max_bytes=_MAX_CELL, max_array_len=1 << 20, max_map_len=16, max_bin_len=0
    )
    if not isinstance(obj, dict):
        raise CodecError(f"{what}: expected a map")
    try:
        cid = obj["id"]
        if type(cid) is not int:
            raise CodecError(f"{what}: id is not an integer")
        boundary = _floats(obj["boundary"], f"{what}: boundary", 2)
        neighbours: dict[int, NDArray[np.float64]] = {}
        for k, n in enumerate(obj["neighbours"]):
            if not isinstance(n, dict) or type(n.get("id")) is not int:
                raise CodecError(f"{what}: neighbours[{k}] is not {{id, boundary}}")
            neighbours[n["id"]] = _floats(n["boundary"], f"{what}: neighbours[{k}]", 2)
        pvs_list = obj["pvs"]
        if not isinstance(pvs_list, list) or any(type(i) is not int for i in pvs_list):
            raise CodecError(f"{what}: pvs is not a list of integers")
        pvs = np.asarray(pvs_list, dtype=np.int64).reshape(-1)
        ach = _floats(obj["ach"], f"{what}: ach").reshape(-1)
        if len(ach) != len(pvs):
            raise CodecError(f"{what}: {len(pvs)} pvs ids but {len(ach)} ach values")
        if np.any(ach < 0):
            raise CodecError(f"{what}: negative ach")
        kind = obj.get("kind", "")
        return CellRecord(
            id=cid,
            kind=str(kind),
            boundary=boundary,
            zmin=float(obj["zmin"]),
            zmax=float(obj["zmax"]),
            neighbours=neighbours,
            pvs=pvs,
            ach=ach,
            nbytes=len(body),
            etag=etag,
            body=bytes(body),
        )
    except KeyError as exc:
        raise CodecError(f"{what}: missing field {exc}") from exc
    except (TypeError, ValueError) as exc:
        raise CodecError(f"{what}: {exc}") from exc


def _viewpoint(v: Any) -> Viewpoint:
    cell = v["cell"]
    if cell is not None and type(cell) is not int:
        raise TypeError(f"viewpoint cell {cell!r:.40} is not an integer")
    return Viewpoint(
        str(v["name"]), float(v["x"]), float(v["y"]), float(v["z"]), float(v["yaw"]), cell
    )


def decode_manifest(body: bytes, what: str, etag: str | None = None) -> Manifest:
    """Decode and check a manifest body (msgpack)."""
    m = unpack_bounded(
        body, what, max_bytes=_MAX_MANIFEST, max_array_len=1 << 16, max_map_len=64, max_bin_len=0
    )
    if not isinstance(m, dict):
        raise CodecError(f"{what}: expected a map")
    try:
        grammar = m["grammar"]
        return Manifest(
            name=str(m["name"]),
            version=str(m["version"]),
            schema_version=int(m.get("schema_version", 0)),
            crs=str(m["crs"]),
            origin=(float(m["origin"][0]), float(m["origin"][1])),
            bounds=tuple(float(v) for v in m["bounds"]),
            features=tuple(str(f) for f in m["features"]),
            grammar_id=str(grammar["id"]),
            grammar_text=str(grammar["text"]),
            viewpoints=tuple(_viewpoint(v) for v in m.get("viewpoints", ())),
            paths=tuple(str(p) for p in m["paths"]),
            objects=int(m["objects"]),
            cells=int(m["cells"]),
            max_ids=max(1, int(m["limits"]["objects_per_request"])),
            etag=etag,
            body=bytes(body),
        )
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        raise CodecError(f"{what}: bad or missing field ({exc})") from exc


def decode_frame(obj: Any, expected_id: int, form: str, nbytes: int, what: str) -> ObjectFrame:
    """Check one unpacked frame of an object stream: the id asked for, a kind, the payload."""
    key = FRAME_KEYS.get(form, "mesh")
    if (
        not isinstance(obj, dict)
        or obj.get("id") != expected_id
        or not isinstance(obj.get("kind"), str)
        or not isinstance(obj.get(key), bytes)
    ):
        raise CodecError(f"{what}: not {{id: {expected_id}, kind, {key}}}")
    return ObjectFrame(expected_id, obj["kind"], obj[key], form, nbytes)


def decode_locate(body: bytes, what: str) -> int | None:
    """The cell id of a ``locate`` answer (``None`` outside every cell)."""
    obj = unpack_bounded(body, what, max_map_len=4, max_bin_len=0)
    if not isinstance(obj, Mapping) or "cell" not in obj:
        raise CodecError(f"{what}: expected {{cell}}")
    c = obj["cell"]
    if c is not None and type(c) is not int:
        raise CodecError(f"{what}: cell is not an integer")
    return c


def decode_scene_list(body: bytes, what: str = "scene list") -> list[str]:
    """The scene names of a scene list, sorted."""
    obj = unpack_bounded(body, what, max_array_len=1 << 12, max_map_len=8)
    if not isinstance(obj, list) or not all(isinstance(s, dict) and "name" in s for s in obj):
        raise CodecError(f"{what}: expected a list of {{name, version}}")
    return sorted(str(s["name"]) for s in obj)
