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
room (interior cell record)
    ``{id, kind, name, room, storey, outline, zmin, zmax, planes, portals: [{id, kind,
    polygon, cell}], neighbours, contents: {triangles, vertices, parts, bytes,
    raw_bytes, max_error}}``
topology (an interior's topological file, Mulloni et al.)
    ``{storeys: [{id, name, zmin, zmax}], cells: [{id, kind, name, storey, outline,
    zmin, zmax, planes, triangles, bytes}], portals: [{id, kind, cells, polygon}],
    stairs: [{portal, lower, upper, path}]}``
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
    "PortalRef",
    "ContentsRef",
    "RoomRecord",
    "Topology",
    "decode_room",
    "decode_topology",
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
    kind: str = "city"
    """``city`` (view cells with a PVS, buildings from parameters) or ``interior``
    (rooms and portals, cell contents as meshes)."""
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
            "kind": self.kind,
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
            kind=str(m.get("kind", "city")),
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


# --------------------------------------------------------------------------- interiors

_MAX_ROOM = 4 << 20
_MAX_TOPOLOGY = 64 << 20


def _rows(x: Any, cols: int, what: str, min_rows: int = 0) -> NDArray[np.float64]:
    a = _floats(x, what)
    if a.size == 0 and min_rows == 0:
        return np.zeros((0, cols))
    if a.ndim != 2 or a.shape[1] != cols or len(a) < min_rows:
        raise CodecError(f"{what}: expected an (n >= {min_rows}, {cols}) array, got shape {a.shape}")
    return a


def _int(x: Any, what: str) -> int:
    if type(x) is not int:
        raise CodecError(f"{what}: expected an integer, got {type(x).__name__}")
    return int(x)


@dataclass(frozen=True)
class PortalRef:
    """A portal of an interior cell as its record gives it: the portal's id and kind,
    its polygon ``(k, 3)`` and the cell on its other side."""

    id: int
    kind: str
    polygon: NDArray[np.float64]
    cell: int

    def __post_init__(self) -> None:
        object.__setattr__(self, "polygon", readonly(np.asarray(self.polygon, np.float64).reshape(-1, 3)))

    def to_wire(self) -> dict[str, Any]:
        """The portal as sent."""
        return {"id": self.id, "kind": self.kind, "polygon": self.polygon.tolist(), "cell": self.cell}


@dataclass(frozen=True)
class ContentsRef:
    """What a cell's contents weigh: triangles, vertices, parts, encoded bytes, the same
    mesh's raw float32 bytes, and the encoding's largest position error (metres)."""

    triangles: int
    vertices: int
    parts: int
    nbytes: int
    raw_bytes: int
    max_error: float

    def to_wire(self) -> dict[str, Any]:
        """The sizes as sent."""
        return {
            "triangles": self.triangles,
            "vertices": self.vertices,
            "parts": self.parts,
            "bytes": self.nbytes,
            "raw_bytes": self.raw_bytes,
            "max_error": self.max_error,
        }


@dataclass(frozen=True)
class RoomRecord:
    """An interior cell as the API sends it (``GET .../rooms/{id}``).

    ``outline`` ``(n, 2)`` is convex, ``planes`` ``(k, 4)`` its plane set (a point is
    in the cell when ``n . p + d <= 0`` for every row; empty for the outside cell,
    which nobody is located in); ``portals`` each lead to one other cell;
    ``contents`` says what ``GET .../rooms/{id}/contents`` weighs.
    """

    id: int
    kind: str
    name: str
    room: str | None
    storey: int
    outline: NDArray[np.float64]
    zmin: float
    zmax: float
    planes: NDArray[np.float64]
    portals: tuple[PortalRef, ...]
    neighbours: tuple[int, ...]
    contents: ContentsRef
    nbytes: int = 0
    etag: str | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "outline", readonly(np.asarray(self.outline, np.float64).reshape(-1, 2)))
        object.__setattr__(self, "planes", readonly(np.asarray(self.planes, np.float64).reshape(-1, 4)))

    def to_wire(self) -> dict[str, Any]:
        """The record as sent."""
        return {
            "id": self.id,
            "kind": self.kind,
            "name": self.name,
            "room": self.room,
            "storey": self.storey,
            "outline": self.outline.tolist(),
            "zmin": self.zmin,
            "zmax": self.zmax,
            "planes": self.planes.tolist(),
            "portals": [p.to_wire() for p in self.portals],
            "neighbours": list(self.neighbours),
            "contents": self.contents.to_wire(),
        }


def _contents_ref(c: Any, what: str) -> ContentsRef:
    if not isinstance(c, dict):
        raise CodecError(f"{what}: contents is not a map")
    return ContentsRef(
        _int(c["triangles"], f"{what}: triangles"),
        _int(c["vertices"], f"{what}: vertices"),
        _int(c["parts"], f"{what}: parts"),
        _int(c["bytes"], f"{what}: bytes"),
        _int(c["raw_bytes"], f"{what}: raw_bytes"),
        float(c["max_error"]),
    )


def decode_room(body: bytes, what: str, etag: str | None = None) -> RoomRecord:
    """Decode and check an interior cell record body (msgpack)."""
    obj = unpack_bounded(body, what, max_bytes=_MAX_ROOM, max_array_len=1 << 16, max_map_len=16, max_bin_len=0)
    if not isinstance(obj, dict):
        raise CodecError(f"{what}: expected a map")
    try:
        portals = []
        for k, p in enumerate(obj["portals"]):
            if not isinstance(p, dict):
                raise CodecError(f"{what}: portals[{k}] is not a map")
            portals.append(
                PortalRef(_int(p["id"], f"{what}: portals[{k}].id"), str(p["kind"]),
                          _rows(p["polygon"], 3, f"{what}: portals[{k}].polygon", 3),
                          _int(p["cell"], f"{what}: portals[{k}].cell"))
            )
        room = obj["room"]
        return RoomRecord(
            id=_int(obj["id"], f"{what}: id"),
            kind=str(obj["kind"]),
            name=str(obj["name"]),
            room=None if room is None else str(room),
            storey=_int(obj["storey"], f"{what}: storey"),
            outline=_rows(obj["outline"], 2, f"{what}: outline", 3),
            zmin=float(obj["zmin"]),
            zmax=float(obj["zmax"]),
            planes=_rows(obj["planes"], 4, f"{what}: planes"),
            portals=tuple(portals),
            neighbours=tuple(_int(n, f"{what}: neighbours") for n in obj["neighbours"]),
            contents=_contents_ref(obj["contents"], what),
            nbytes=len(body),
            etag=etag,
        )
    except KeyError as exc:
        raise CodecError(f"{what}: missing field {exc}") from exc
    except (TypeError, ValueError) as exc:
        raise CodecError(f"{what}: {exc}") from exc


@dataclass(frozen=True)
class Topology:
    """An interior's topological file (Mulloni et al.): everything a client needs to
    build the visibility graph without loading any cell's contents.

    ``storeys`` are ``(id, name, zmin, zmax)``; ``cells`` the records of every cell
    without their portals (``portals`` lists each portal once, with both cells);
    ``stairs`` are ``(portal, lower, upper, path (k, 3))``.
    """

    storeys: tuple[tuple[int, str, float, float], ...]
    cells: tuple[RoomRecord, ...]
    portals: tuple[tuple[int, str, int, int, NDArray[np.float64]], ...]
    stairs: tuple[tuple[int, int, int, NDArray[np.float64]], ...]
    nbytes: int = 0

    def to_wire(self) -> dict[str, Any]:
        """The topology as sent."""
        return {
            "storeys": [{"id": i, "name": n, "zmin": a, "zmax": b} for i, n, a, b in self.storeys],
            "cells": [
                {
                    "id": c.id,
                    "kind": c.kind,
                    "name": c.name,
                    "storey": c.storey,
                    "outline": c.outline.tolist(),
                    "zmin": c.zmin,
                    "zmax": c.zmax,
                    "planes": c.planes.tolist(),
                    "triangles": c.contents.triangles,
                    "bytes": c.contents.nbytes,
                }
                for c in self.cells
            ],
            "portals": [
                {"id": i, "kind": k, "cells": [a, b], "polygon": np.asarray(pg).tolist()}
                for i, k, a, b, pg in self.portals
            ],
            "stairs": [
                {"portal": p, "lower": lo, "upper": up, "path": np.asarray(pa).tolist()}
                for p, lo, up, pa in self.stairs
            ],
        }


def decode_topology(body: bytes, what: str) -> Topology:
    """Decode and check a topology body (msgpack)."""
    obj = unpack_bounded(body, what, max_bytes=_MAX_TOPOLOGY, max_array_len=1 << 20, max_map_len=16, max_bin_len=0)
    if not isinstance(obj, dict):
        raise CodecError(f"{what}: expected a map")
    try:
        storeys = tuple(
            (_int(s["id"], f"{what}: storey"), str(s["name"]), float(s["zmin"]), float(s["zmax"]))
            for s in obj["storeys"]
        )
        portals = []
        ends: dict[int, list[PortalRef]] = {}
        for k, p in enumerate(obj["portals"]):
            a, b = (_int(v, f"{what}: portals[{k}].cells") for v in p["cells"])
            poly = _rows(p["polygon"], 3, f"{what}: portals[{k}].polygon", 3)
            pid = _int(p["id"], f"{what}: portals[{k}].id")
            portals.append((pid, str(p["kind"]), a, b, poly))
            ends.setdefault(a, []).append(PortalRef(pid, str(p["kind"]), poly, b))
            ends.setdefault(b, []).append(PortalRef(pid, str(p["kind"]), poly, a))
        cells = []
        for k, c in enumerate(obj["cells"]):
            cid = _int(c["id"], f"{what}: cells[{k}].id")
            refs = tuple(ends.get(cid, ()))
            cells.append(
                RoomRecord(
                    id=cid, kind=str(c["kind"]), name=str(c["name"]), room=None,
                    storey=_int(c["storey"], f"{what}: cells[{k}].storey"),
                    outline=_rows(c["outline"], 2, f"{what}: cells[{k}].outline", 3),
                    zmin=float(c["zmin"]), zmax=float(c["zmax"]),
                    planes=_rows(c["planes"], 4, f"{what}: cells[{k}].planes"),
                    portals=refs, neighbours=tuple(sorted({r.cell for r in refs})),
                    contents=ContentsRef(_int(c["triangles"], what), 0, 0, _int(c["bytes"], what), 0, 0.0),
                )
            )
        stairs = tuple(
            (_int(s["portal"], what), _int(s["lower"], what), _int(s["upper"], what),
             _rows(s["path"], 3, f"{what}: stair path", 2))
            for s in obj["stairs"]
        )
        return Topology(storeys, tuple(cells), tuple(portals), stairs, nbytes=len(body))
    except KeyError as exc:
        raise CodecError(f"{what}: missing field {exc}") from exc
    except (TypeError, ValueError) as exc:
        raise CodecError(f"{what}: {exc}") from exc
