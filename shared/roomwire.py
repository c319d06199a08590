"""The API's records of interiors: a room cell's record and an interior's topology.

What :mod:`walkstream.shared.wire` is for cities, this is for interiors (Mulloni et
al.'s topological file); the service encodes them, the client decodes them, bounded.

room (interior cell record)
    ``{id, kind, name, room, storey, outline, zmin, zmax, planes, portals: [{id, kind,
    polygon, cell}], neighbours, contents: {triangles, vertices, parts, bytes,
    raw_bytes, max_error}}``
topology (an interior's topological file, Mulloni et al.)
    ``{storeys: [{id, name, zmin, zmax}], cells: [{id, kind, name, storey, outline,
    zmin, zmax, planes, triangles, bytes}], portals: [{id, kind, cells, polygon}],
    stairs: [{portal, lower, upper, path}]}``
packed topology (``walkstream-topology/1+gzip``, :data:`TOPOLOGY_PACKED_MEDIA`)
    the topology's msgpack body, gzip-compressed: the same record for a seventh of
    the bytes on a generated office (57.6 kB -> 7.9 kB), so a walk on a slow link
    starts sooner; :func:`decode_topology_packed` inflates it bounded.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from walkstream.shared.codec import unpack_bounded
from walkstream.shared.codec.bounded import inflate_bounded
from walkstream.shared.errors import CodecError
from walkstream.shared.records import readonly
from walkstream.shared.scene.placement import ContentsPlacement

__all__ = [
    "PortalRef",
    "ContentsRef",
    "RoomRecord",
    "Topology",
    "decode_room",
    "decode_topology",
    "decode_topology_packed",
    "TOPOLOGY_PACKED_MEDIA",
    "Entrance",
    "decode_entrances",
]

TOPOLOGY_PACKED_MEDIA = "application/vnd.walkstream.topology+gzip"
"""Media type of the packed topology (``walkstream-topology/1+gzip``)."""

_MAX_ROOM = 4 << 20
_MAX_TOPOLOGY = 64 << 20


def _rows(x: Any, cols: int, what: str, min_rows: int = 0) -> NDArray[np.float64]:
    try:
        a = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise CodecError(f"{what}: expected numbers") from exc
    if not np.all(np.isfinite(a)):
        raise CodecError(f"{what}: non-finite values")
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


def decode_topology_packed(body: bytes, what: str) -> Topology:
    """Decode a packed topology body (gzip of the msgpack topology), inflating at most
    the topology's bound; its ``nbytes`` is the packed size (what crossed the link)."""
    raw = inflate_bounded(body, what, _MAX_TOPOLOGY, "gzip body", wbits=31)
    t = decode_topology(raw, what)
    return Topology(t.storeys, t.cells, t.portals, t.stairs, nbytes=len(body))


@dataclass(frozen=True)
class Entrance:
    """A building's entrance in a crossing scene as the API sends it (``GET .../entrances``).

    ``portal`` joins the city cell ``street`` to the room cell ``doorway``; the city
    object ``building`` (named by street PVS) is drawn as the contents of the room cell
    ``shell`` (the interior's outside: its outer walls with the door, and its roof),
    never from its own parameters (they are a stand-in inside the shell).
    ``placement``, when sent, says that the contents of the interior's cells are in the
    interior's own frame and how to move them into the scene's (None: they are in the
    scene's frame already, as a crossing scene baked before stores them).
    """

    portal: int
    building: int
    street: int
    doorway: int
    shell: int
    placement: ContentsPlacement | None = None

    def to_wire(self) -> dict[str, Any]:
        """The entrance as sent (``placement`` only when there is one)."""
        out: dict[str, Any] = {"portal": self.portal, "building": self.building, "street": self.street,
                               "doorway": self.doorway, "shell": self.shell}
        if self.placement is not None:
            out["placement"] = self.placement.to_wire()
        return out


def decode_entrances(body: bytes, what: str) -> tuple[Entrance, ...]:
    """Decode and check a crossing scene's entrances (msgpack: a list of maps)."""
    obj = unpack_bounded(body, what, max_bytes=1 << 20, max_array_len=1 << 16, max_map_len=8, max_bin_len=0)
    if not isinstance(obj, list):
        raise CodecError(f"{what}: expected a list")
    out = []
    for k, e in enumerate(obj):
        if not isinstance(e, dict):
            raise CodecError(f"{what}: [{k}] is not a map")
        try:
            ids = [_int(e[f], f"{what}: [{k}].{f}") for f in ("portal", "building", "street", "doorway", "shell")]
        except KeyError as exc:
            raise CodecError(f"{what}: [{k}] has no {exc.args[0]!r}") from None
        placed = e.get("placement")
        out.append(Entrance(ids[0], ids[1], ids[2], ids[3], ids[4],
                            None if placed is None else ContentsPlacement.from_wire(placed, f"{what}: [{k}].placement")))
    return tuple(out)
