"""The records of the HTTP API, defined once: the service encodes them, the client decodes them.

Every record is a frozen dataclass with :meth:`to_wire` (the plain structure the
service sends as msgpack or JSON, keys in a fixed order) and a bounded decoder for
the client, which reads untrusted bytes: every body is unpacked with hard limits
(:func:`~walkstream.shared.codec.unpack_bounded`) and checked field by field, so a
corrupt or hostile answer is a :class:`~walkstream.shared.errors.CodecError`, never
a crash.

Integer sequences below are ``[format, payload]`` pairs
(:func:`~walkstream.shared.codec.pack_ints`: a plain list in JSON, the smallest of
list, int16, int32 or zigzag varints in msgpack).

manifest
    ``{name, version, schema_version, crs, origin, bounds, features, grammar: {id,
    text}, viewpoints: [{name, x, y, z, yaw, cell}], paths, objects, cells, limits:
    {objects_per_request}, kind: city | interior | crossing, index: {origin, tile, shape,
    reach} | null, offers}``;
    ``index`` is the :class:`~walkstream.shared.cells.TileGrid` of the cell index,
    ``offers`` the optional parts of the API this server has (:data:`OFFERS`).
cell index (a tile, or the whole scene)
    ``{tile: [i, j] | null, ids, kind_names, kinds, zmin, zmax, counts, anchor,
    coords, degrees, adjacent}``: cell ids ascending (delta-coded), each cell's kind
    (an index into ``kind_names``), eye-height range (centimetres, delta-coded),
    convex outline (``counts`` vertices per cell; ``anchor`` the first vertex in
    centimetres, ``coords`` the x/y centimetre deltas chained over every outline)
    and neighbours (``degrees`` per cell, ``adjacent`` their ids, each minus the
    cell's own id).  Tracking the viewer needs nothing else: a client learns the
    cells ahead without a request per cell.
cell
    ``{id, kind, pvs, ach}``: what is the cell's own: the PVS ids ascending
    (delta-coded: the first id, then differences) and their ACH in units of
    1/65535 (:data:`~walkstream.shared.codec.ACH_UNITS`, summing to it exactly).
    Optional, kind-specific fields may follow; a decoder ignores keys it does not
    know, so a new field never breaks an older client (a cell's impostors, ``imp``:
    :mod:`walkstream.shared.impostorwire`).  A stream of records (the
    cells batch) is plain concatenated msgpack, one per asked id in the order asked.
locate
    ``{cell: id}`` or ``{cell: null, reason}``
object frame
    ``{id, kind, params: bin}`` (or ``mesh: bin`` for the ``lod2`` form); a stream of
    them is plain concatenated msgpack, one per asked id in the order asked.
start part
    one part of the start bundle: :mod:`walkstream.shared.startwire`.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from walkstream.shared.cells import TileGrid
from walkstream.shared.codec import ACH_UNITS, pack_ints, quantise_ach, unpack_bounded, unpack_ints
from walkstream.shared.content.registry import frame_keys
from walkstream.shared.errors import CodecError
from walkstream.shared.impostorwire import CellImpostors, impostors_from_wire
from walkstream.shared.records import Viewpoint, readonly
from walkstream.shared.scene.cellkinds import CELL_KINDS

__all__ = [
    "MSGPACK",
    "MAX_GRAMMAR_TEXT",
    "JSON",
    "MSGPACK_TYPES",
    "FRAME_KEYS",
    "OFFERS",
    "Manifest",
    "CellRecord",
    "CellIndex",
    "ObjectFrame",
    "decode_manifest",
    "decode_cell",
    "cell_from_wire",
    "decode_cell_index",
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

FRAME_KEYS: dict[str, str] = frame_keys()
"""The key of an object frame's payload, per form of the objects request (``params``:
``params``, ``lod2``: ``mesh``; from the content kinds, :mod:`walkstream.shared.content.registry`)."""

OFFERS: tuple[str, ...] = ("cell-index", "cells-batch", "start")
"""Optional parts of the API a manifest may list in ``offers``: the cell index
(``GET .../index/{i}/{j}``), cell records in batches (``POST .../cells``) and the
start bundle (``GET /v1/start``)."""

_MAX_MANIFEST = 4 << 20
#: the longest string a manifest may hold: the building grammar's text (the default
#: grammar is about 6 kB; a string bound of 4 kB once refused it, and the client then
#: never rebuilt a building)
MAX_GRAMMAR_TEXT = 1 << 16
_MAX_CELL = 8 << 20
_MAX_INDEX = 32 << 20
_MAX_INDEX_CELLS = 1 << 20
_MAX_INDEX_VERTICES = 1 << 24
_MAX_CM = 2**53


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
    """``city`` (view cells with a PVS, buildings from parameters), ``interior``
    (rooms and portals, cell contents as meshes) or ``crossing`` (both, joined at a
    building's entrance)."""
    index: TileGrid | None = None
    """The tiles of the cell index (None: the server has no cell index)."""
    offers: tuple[str, ...] = ()
    """Optional parts of the API the server has (names from :data:`OFFERS`)."""
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
            "index": None if self.index is None else _grid_to_wire(self.index),
            "offers": list(self.offers),
        }


def _grid_to_wire(g: TileGrid) -> dict[str, Any]:
    return {"origin": list(g.origin), "tile": g.tile_m, "shape": list(g.shape), "reach": g.reach_m}


def _grid_from_wire(obj: Any) -> TileGrid | None:
    if obj is None:
        return None
    from walkstream.shared.errors import InputError

    try:
        return TileGrid(
            origin=(float(obj["origin"][0]), float(obj["origin"][1])),
            tile_m=float(obj["tile"]),
            shape=(int(obj["shape"][0]), int(obj["shape"][1])),
            reach_m=float(obj["reach"]),
        )
    except InputError as exc:
        raise ValueError(str(exc)) from exc


@dataclass(frozen=True)
class CellRecord:
    """A view cell's own data as the API sends it: its PVS with the ACH of each object.

    The outline, height range and neighbours of every cell are in the cell index
    (:class:`CellIndex`).  ``nbytes``, ``etag`` and ``body`` are what the client
    received (its caches keep them); the service leaves them empty.
    """

    id: int
    kind: str
    pvs: NDArray[np.int64]
    """(k,) object ids, ascending."""
    ach: NDArray[np.float64]
    """(k,) average coverage of each PVS object (sums to 1 unless empty)."""
    nbytes: int = 0
    etag: str | None = None
    body: bytes = field(default=b"", repr=False)
    impostors: CellImpostors | None = None
    """The objects of the PVS the cell draws as impostors (a scene baked with
    ``--impostors``, a cell with some; None otherwise, and then the record is what it
    was before)."""
    far: NDArray[np.int64] | None = None
    """(f,) a city baked with ``--virtual-walls``: the objects the cell's ring of walls
    carries on its textures (not in :attr:`pvs`), ascending; the client streams them
    with the PVS and draws them as geometry while a ring texture in view has not
    arrived.  None: no ring (the record is what it was before)."""
    far_ach: NDArray[np.float64] | None = None
    """(f,) their coverage (sums to 1 unless empty)."""
    far_share: float = 0.0
    """Their share of the cell's whole coverage before the ring: the frame that draws
    them weighs :attr:`ach` by ``1 - far_share`` and :attr:`far_ach` by ``far_share``."""

    def __post_init__(self) -> None:
        # records are shared between caches and callers: nothing in them may change
        object.__setattr__(self, "pvs", readonly(np.asarray(self.pvs, np.int64).reshape(-1)))
        object.__setattr__(self, "ach", readonly(np.asarray(self.ach, np.float64).reshape(-1)))
        if self.far is not None:
            object.__setattr__(self, "far", readonly(np.asarray(self.far, np.int64).reshape(-1)))
            fa = np.zeros(len(self.far)) if self.far_ach is None else self.far_ach
            object.__setattr__(self, "far_ach", readonly(np.asarray(fa, np.float64).reshape(-1)))

    def streamed(self) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        """``((k + f,) ids, (k + f,) coverage)``: the objects the client streams for this
        cell, the PVS and then the ring's far field (:attr:`far`) weighed by its share."""
        if self.far is None or not len(self.far):
            return self.pvs, self.ach
        fa = np.asarray(self.far_ach, np.float64)
        return (np.concatenate([self.pvs, self.far]),
                np.concatenate([self.ach * (1.0 - self.far_share), fa * self.far_share]))

    def to_wire(self, *, compact: bool = True) -> dict[str, Any]:
        """The record as sent (``compact=False``: plain integer lists, for JSON)."""
        ids = np.asarray(self.pvs, dtype=np.int64)
        units = quantise_ach(self.ach) if len(ids) else np.zeros(0, np.int64)
        out: dict[str, Any] = {
            "id": self.id,
            "kind": self.kind,
            "pvs": pack_ints(np.diff(ids, prepend=0).tolist(), compact=compact),
            "ach": pack_ints(units.tolist(), compact=compact),
        }
        if self.impostors is not None:  # only then: a scene without impostors sends the very same bytes
            out["imp"] = self.impostors.to_wire()
        if self.far is not None:  # only then: a cell without a ring sends the very same bytes
            far = np.asarray(self.far, np.int64)
            out["far"] = pack_ints(np.diff(far, prepend=0).tolist(), compact=compact)
            fa = np.zeros(0) if self.far_ach is None else np.asarray(self.far_ach, np.float64)
            out["fach"] = pack_ints((quantise_ach(fa) if len(far) else np.zeros(0, np.int64)).tolist(), compact=compact)
            out["fsh"] = round(float(self.far_share) * ACH_UNITS)
        return out


@dataclass(frozen=True)
class CellIndex:
    """Outlines, height ranges and adjacency of the cells of one tile (or of a scene).

    Immutable per scene version, so a client keeps it as long as its cache allows.
    ``nbytes``, ``etag`` and ``body`` are what the client received; the service
    leaves them empty.

    Attributes
    ----------
    tile : (i, j) or None
        The tile of the scene's :class:`~walkstream.shared.cells.TileGrid`; None for
        the whole scene.
    ids : (n,) int64
        Cell ids, ascending.
    kinds : tuple of str
        Each cell's kind (:data:`~walkstream.shared.cells.CELL_KINDS`).
    zmin, zmax : (n,) float64
        Eye-height range of each cell, metres (centimetre precision on the wire).
    outlines : tuple of (m_i, 2) float64
        Convex outlines, scene-local metres (centimetre precision on the wire).
    neighbours : tuple of (k_i,) int64
        Ids of each cell's neighbours (some may lie in other tiles).
    """

    tile: tuple[int, int] | None
    ids: NDArray[np.int64]
    kinds: tuple[str, ...]
    zmin: NDArray[np.float64]
    zmax: NDArray[np.float64]
    outlines: tuple[NDArray[np.float64], ...]
    neighbours: tuple[NDArray[np.int64], ...]
    nbytes: int = 0
    etag: str | None = None
    body: bytes = field(default=b"", repr=False)

    def __post_init__(self) -> None:
        n = len(self.ids)
        object.__setattr__(self, "ids", readonly(np.asarray(self.ids, np.int64).reshape(-1)))
        object.__setattr__(self, "zmin", readonly(np.asarray(self.zmin, np.float64).reshape(-1)))
        object.__setattr__(self, "zmax", readonly(np.asarray(self.zmax, np.float64).reshape(-1)))
        object.__setattr__(
            self,
            "outlines",
            tuple(readonly(np.asarray(o, np.float64).reshape(-1, 2)) for o in self.outlines),
        )
        object.__setattr__(
            self,
            "neighbours",
            tuple(readonly(np.asarray(b, np.int64).reshape(-1)) for b in self.neighbours),
        )
        object.__setattr__(self, "kinds", tuple(str(k) for k in self.kinds))
        sizes = {
            len(self.kinds),
            len(self.zmin),
            len(self.zmax),
            len(self.outlines),
            len(self.neighbours),
        }
        if sizes != {n}:
            raise CodecError(f"cell index: {n} ids but fields of lengths {sorted(sizes)}")

    def __len__(self) -> int:
        return len(self.ids)

    def to_wire(self, *, compact: bool = True) -> dict[str, Any]:
        """The index as sent (``compact=False``: plain integer lists, for JSON)."""
        ids = np.asarray(self.ids, dtype=np.int64)
        names = sorted(
            set(self.kinds), key=lambda k: (CELL_KINDS.index(k) if k in CELL_KINDS else 99, k)
        )
        code = {k: i for i, k in enumerate(names)}
        counts = [len(o) for o in self.outlines]
        if counts:
            q = np.rint(np.concatenate(self.outlines) * 100.0).astype(np.int64)
            anchor = q[0].tolist()
            coords = np.diff(q, axis=0).reshape(-1).tolist()
        else:
            anchor, coords = [0, 0], []
        zmin = np.rint(np.asarray(self.zmin) * 100.0).astype(np.int64)
        zmax = np.rint(np.asarray(self.zmax) * 100.0).astype(np.int64)
        adjacent = [
            int(b) - int(c)
            for c, nb in zip(ids.tolist(), self.neighbours, strict=True)
            for b in nb.tolist()
        ]
        return {
            "tile": None if self.tile is None else list(self.tile),
            "ids": pack_ints(np.diff(ids, prepend=0).tolist(), compact=compact),
            "kind_names": names,
            "kinds": pack_ints([code[k] for k in self.kinds], compact=compact),
            "zmin": pack_ints(np.diff(zmin, prepend=0).tolist(), compact=compact),
            "zmax": pack_ints(np.diff(zmax, prepend=0).tolist(), compact=compact),
            "counts": pack_ints(counts, compact=compact),
            "anchor": anchor,
            "coords": pack_ints(coords, compact=compact),
            "degrees": pack_ints([len(nb) for nb in self.neighbours], compact=compact),
            "adjacent": pack_ints(adjacent, compact=compact),
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


@contextlib.contextmanager
def _fields(what: str) -> Iterator[None]:
    """Turn a missing or mistyped field of an unpacked record into a :class:`CodecError`."""
    try:
        yield
    except KeyError as exc:
        raise CodecError(f"{what}: missing field {exc}") from exc
    except (TypeError, ValueError, OverflowError) as exc:
        raise CodecError(f"{what}: {exc}") from exc


def _cumsum_ids(deltas: list[int], what: str, field: str, strict: bool) -> NDArray[np.int64]:
    """Ids from ``[first, d1, d2, ...]``: non-negative and ascending (strictly if ``strict``)."""
    d = np.asarray(deltas, dtype=np.int64)
    if len(d) and (d[0] < 0 or (d[1:] <= 0 if strict else d[1:] < 0).any()):
        raise CodecError(f"{what}: {field} are not ascending non-negative ids")
    if len(d) and int(np.abs(d).max()) >= 2**62 // max(1, len(d)):
        raise CodecError(f"{what}: {field}: ids out of range")
    out: NDArray[np.int64] = np.cumsum(d) if len(d) else np.zeros(0, np.int64)
    return out


def cell_from_wire(
    obj: Any, what: str, nbytes: int = 0, etag: str | None = None, body: bytes = b""
) -> CellRecord:
    """A :class:`CellRecord` from an unpacked record (one of a stream, or a whole body), checked."""
    if not isinstance(obj, dict):
        raise CodecError(f"{what}: expected a map")
    with _fields(what):
        cid = obj["id"]
        if type(cid) is not int or cid < 0:
            raise CodecError(f"{what}: id is not a non-negative integer")
        pvs = _cumsum_ids(unpack_ints(obj["pvs"], what, "pvs", 1 << 22), what, "pvs", strict=True)
        units = np.asarray(unpack_ints(obj["ach"], what, "ach", 1 << 22), dtype=np.int64)
        if len(units) != len(pvs):
            raise CodecError(f"{what}: {len(pvs)} pvs ids but {len(units)} ach values")
        if len(units) and ((units < 0).any() or (units > ACH_UNITS).any()):
            raise CodecError(f"{what}: ach units outside [0, {ACH_UNITS}]")
        kind = obj.get("kind", "")
        far, far_ach, share = _ring_far(obj, what)
        return CellRecord(
            id=cid,
            kind=str(kind),
            pvs=pvs,
            ach=units.astype(np.float64) / ACH_UNITS,
            nbytes=nbytes,
            etag=etag,
            body=bytes(body),
            impostors=impostors_from_wire(obj.get("imp"), what),
            far=far,
            far_ach=far_ach,
            far_share=share,
        )


def _ring_far(obj: dict[str, Any], what: str) -> tuple[NDArray[np.int64] | None, NDArray[np.float64] | None, float]:
    """A record's ring far field (:attr:`CellRecord.far`), checked; ``(None, None, 0)`` without one."""
    if "far" not in obj:
        return None, None, 0.0
    far = _cumsum_ids(unpack_ints(obj["far"], what, "far", 1 << 22), what, "far", strict=True)
    units = np.asarray(unpack_ints(obj.get("fach", []), what, "fach", 1 << 22), dtype=np.int64)
    share = obj.get("fsh", 0)
    if len(units) != len(far):
        raise CodecError(f"{what}: {len(far)} far ids but {len(units)} fach values")
    if (len(units) and ((units < 0).any() or (units > ACH_UNITS).any())) or type(share) is not int \
            or not 0 <= share <= ACH_UNITS:
        raise CodecError(f"{what}: far coverage or share outside [0, {ACH_UNITS}]")
    return far, units.astype(np.float64) / ACH_UNITS, share / ACH_UNITS


def _unpack_record(
    body: bytes, what: str, max_bytes: int, *, max_array_len: int, max_map_len: int
) -> Any:
    """Unpack a record whose binary fields may be as large as the record itself."""
    return unpack_bounded(
        body,
        what,
        max_bytes=max_bytes,
        max_array_len=max_array_len,
        max_map_len=max_map_len,
        max_bin_len=max_bytes,
    )


def decode_cell(body: bytes, what: str, etag: str | None = None) -> CellRecord:
    """Decode and check a cell record body (msgpack)."""
    obj = _unpack_record(body, what, _MAX_CELL, max_array_len=1 << 20, max_map_len=64)
    return cell_from_wire(obj, what, len(body), etag, body)


def decode_cell_index(body: bytes, what: str, etag: str | None = None) -> CellIndex:
    """Decode and check a cell index body (msgpack): sizes agree, outlines have >= 3 vertices."""
    obj = _unpack_record(body, what, _MAX_INDEX, max_array_len=1 << 24, max_map_len=32)
    if not isinstance(obj, dict):
        raise CodecError(f"{what}: expected a map")
    with _fields(what):
        tile_obj = obj["tile"]
        tile: tuple[int, int] | None = None
        if tile_obj is not None:
            if not (
                isinstance(tile_obj, list)
                and len(tile_obj) == 2
                and all(type(v) is int and v >= 0 for v in tile_obj)
            ):
                raise CodecError(f"{what}: tile is not [i, j]")
            tile = (tile_obj[0], tile_obj[1])
        ids = _cumsum_ids(
            unpack_ints(obj["ids"], what, "ids", _MAX_INDEX_CELLS), what, "ids", strict=True
        )
        n = len(ids)
        names = obj["kind_names"]
        if not isinstance(names, list) or not all(
            isinstance(k, str) and len(k) <= 64 for k in names
        ):
            raise CodecError(f"{what}: kind_names is not a list of names")
        codes = unpack_ints(obj["kinds"], what, "kinds", n)
        if len(codes) != n or any(not 0 <= c < len(names) for c in codes):
            raise CodecError(f"{what}: kinds: expected {n} indexes into kind_names")
        z = []
        for key in ("zmin", "zmax"):
            v = np.cumsum(np.asarray(unpack_ints(obj[key], what, key, n), dtype=np.int64))
            if len(v) != n or (len(v) and int(np.abs(v).max()) >= _MAX_CM):
                raise CodecError(f"{what}: {key}: expected {n} heights")
            z.append(v.astype(np.float64) / 100.0)
        counts = unpack_ints(obj["counts"], what, "counts", n)
        if len(counts) != n or any(c < 3 for c in counts) or sum(counts) > _MAX_INDEX_VERTICES:
            raise CodecError(f"{what}: counts: expected {n} outlines of >= 3 vertices")
        total = sum(counts)
        anchor = obj["anchor"]
        if not (
            isinstance(anchor, list)
            and len(anchor) == 2
            and all(type(a) is int and abs(a) < _MAX_CM for a in anchor)
        ):
            raise CodecError(f"{what}: anchor is not [x, y] in centimetres")
        d = unpack_ints(obj["coords"], what, "coords", 2 * _MAX_INDEX_VERTICES)
        if len(d) != 2 * max(0, total - 1):
            raise CodecError(
                f"{what}: coords: expected {2 * max(0, total - 1)} deltas, got {len(d)}"
            )
        outlines: tuple[NDArray[np.float64], ...] = ()
        if total:
            q = np.empty((total, 2), np.int64)
            q[0] = anchor
            q[1:] = np.asarray(d, dtype=np.int64).reshape(-1, 2)
            xy = np.cumsum(q, axis=0)
            if int(np.abs(xy).max()) >= _MAX_CM:
                raise CodecError(f"{what}: coords out of range")
            outlines = tuple(np.split(xy.astype(np.float64) / 100.0, np.cumsum(counts)[:-1]))
        degrees = unpack_ints(obj["degrees"], what, "degrees", n)
        if len(degrees) != n or any(k < 0 for k in degrees):
            raise CodecError(f"{what}: degrees: expected {n} counts")
        adjacent = unpack_ints(obj["adjacent"], what, "adjacent", _MAX_INDEX_VERTICES)
        if len(adjacent) != sum(degrees):
            raise CodecError(f"{what}: adjacent: expected {sum(degrees)} ids, got {len(adjacent)}")
        own = np.repeat(ids, degrees)
        nb = np.asarray(adjacent, dtype=np.int64) + own
        if len(nb) and (nb < 0).any():
            raise CodecError(f"{what}: adjacent: negative cell ids")
        neighbours = tuple(np.split(nb, np.cumsum(degrees)[:-1])) if n else ()
        return CellIndex(
            tile=tile,
            ids=ids,
            kinds=tuple(names[c] for c in codes),
            zmin=z[0],
            zmax=z[1],
            outlines=outlines,
            neighbours=neighbours,
            nbytes=len(body),
            etag=etag,
            body=bytes(body),
        )


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
        body, what, max_bytes=_MAX_MANIFEST, max_array_len=1 << 16, max_map_len=64, max_bin_len=0,
        max_str_len=MAX_GRAMMAR_TEXT,
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
            index=_grid_from_wire(m.get("index")),
            offers=tuple(str(o) for o in m.get("offers", ())),
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
