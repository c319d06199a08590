"""Per-scene state of the service and the FastAPI dependencies that hand it out.

Everything a request needs is prepared when the app starts or on the first request
that needs it, so that answering costs about as much as serving a static file:

* each database is opened read-only with :class:`~walkstream.server.store.reader.SceneReader` (which
  validates it) and every cell is read once, which builds the
  :class:`~walkstream.shared.cells.CellLocator`, keeps every cell boundary (neighbour records
  need them) and decodes every PVS, so a damaged file stops the start;
* the manifest is encoded at start-up in both representations (msgpack and JSON);
* cell records and recorded paths are encoded on first use and kept in a
  byte-bounded LRU;
* object frames (see :mod:`walkstream.server.service.routers`) are encoded on first use and kept in a
  second byte-bounded LRU; which ids exist and their kinds are known from start-up,
  so an unknown id is answered without touching the database;
* an interior scene also gets an :class:`~walkstream.server.service.interiors.InteriorState`
  (its topology, room records and cell contents), and its cells are located in 3D;
* LOD2 mesh frames (``form=lod2``, for the client's ``--stream meshes`` comparison)
  are built from the parameters with the scene's grammar (parsed once per scene) on
  first use, in a worker thread, and kept in the same frame LRU under separate keys.

A scene is immutable (a recorded path makes a *new* scene version in a new file), so
nothing cached here ever needs invalidating; a restart serves the new version."""

from __future__ import annotations

import base64
import math
import os
import threading
from collections.abc import Iterable, Sequence
from typing import Any, Literal, cast

import numpy as np
from numpy.typing import NDArray

from walkstream.server.service.http import (
    Encoded,
    Rep,
    _digest,
    dump_json,
    dump_msgpack,
    encode,
    etag_for,
)
from walkstream.server.service.interiors import InteriorState
from walkstream.server.service.lru import LRU
from walkstream.server.store import CellInfo, SceneReader
from walkstream.shared.buildings import build_lod
from walkstream.shared.cells import LOCATABLE_KINDS, CellLocator
from walkstream.shared.codec import decode_object, encode_mesh, unpack_bounded
from walkstream.shared.errors import ApiError, CodecError, StoreError
from walkstream.shared.lsystem.grammar import Grammar, parse_grammar
from walkstream.shared.records import BuildingParams
from walkstream.shared.streets import build_street
from walkstream.shared.wire import (
    MSGPACK,
    CellRecord,
    Manifest,
    ObjectFrame,
    locate_answer,
)

__all__ = ["MAX_IDS", "Form", "OBJECT_FORMS", "Scene", "SceneRegistry"]


MAX_IDS = 1000
"""Most object ids one ``POST .../objects`` may ask for (more: 413)."""

Form = Literal["params", "lod2"]
"""What an object frame carries: the stored parameters, or the rebuilt LOD2 mesh."""

OBJECT_FORMS: tuple[Form, ...] = ("params", "lod2")
"""The forms ``POST .../objects?form=`` accepts; ``params`` is the default."""

# LRU budgets per scene: enough for every cell and object of a large city, small
# enough that several scenes fit in one worker
_BODY_CACHE_BYTES = 64 << 20
_FRAME_CACHE_BYTES = 128 << 20
# a recorded path larger than this is not decoded for the JSON representation
_MAX_PATH_JSON_BYTES = 8 << 20


# ---------------------------------------------------------------------------
# one scene
# ---------------------------------------------------------------------------


def _jsonable(obj: Any) -> Any:
    """A decoded msgpack value made JSON-able: bytes as base64, non-finite floats as None."""
    if isinstance(obj, bytes):
        return {"base64": base64.b64encode(obj).decode("ascii")}
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, list | tuple):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    return obj


class Scene:
    """One scene database as the service serves it; see the module docstring.

    Build with :meth:`load`.  Thread-safe: the database reader has a connection
    pool and the caches are locked.
    """

    def __init__(
        self,
        reader: SceneReader,
        cells: Sequence[CellInfo],
        kinds: dict[int, str],
        path_names: Sequence[str],
    ) -> None:
        """Private: use :meth:`load`."""
        meta = reader.meta
        self.reader = reader
        self.name: str = meta.name
        self.version: str = meta.version
        self.kinds = kinds
        """Object id -> kind, for every object of the scene."""
        self.path_names = frozenset(path_names)
        self.cell_kinds: dict[int, str] = {c.id: c.kind for c in cells}
        # every outline, for the neighbour entries of cell records
        self.boundaries: dict[int, NDArray[np.float64]] = {c.id: c.boundary for c in cells}
        # interiors stack storeys: their cells are located in 3D, the outside never
        locatable = [c for c in cells if c.kind in LOCATABLE_KINDS]
        zranges = [[c.zmin, c.zmax] for c in locatable] if meta.kind == "interior" else None
        self.locator = CellLocator([c.id for c in locatable], [c.boundary for c in locatable], zranges)
        self.kind: str = meta.kind
        self.interior: InteriorState | None = InteriorState(reader, cells) if meta.kind == "interior" else None
        b = reader.bounds()
        vps = reader.viewpoints()
        manifest = Manifest(
            name=meta.name,
            version=meta.version,
            schema_version=meta.schema_version,
            crs=meta.crs,
            origin=meta.origin,
            bounds=tuple(b),
            features=tuple(meta.features),
            grammar_id=meta.grammar_version,
            grammar_text=meta.grammar_text,
            viewpoints=tuple(vps),
            paths=tuple(sorted(path_names)),
            objects=len(kinds),
            cells=len(cells),
            max_ids=MAX_IDS,
            kind=meta.kind,
        ).to_wire()
        self.manifest: dict[Rep, Encoded] = {
            rep: encode(manifest, rep, self.version, "manifest") for rep in ("msgpack", "json")
        }
        self._bodies = LRU(_BODY_CACHE_BYTES)
        self._frames = LRU(_FRAME_CACHE_BYTES)
        self._grammar_text = meta.grammar_text
        self._grammar: Grammar | None = None
        self._grammar_lock = threading.Lock()

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> Scene:
        """Open, validate and index a scene database.

        Raises
        ------
        StoreError
            Missing, not a scene database, another schema version, unfinished,
            damaged (every page is checked, every cell decoded), or a scene name
            that cannot be part of a URL.  The message names the file.
        """
        reader = SceneReader.open(path, check=True)
        label = os.fspath(path)
        try:
            name = reader.meta.name
            if not name or "/" in name or not name.isprintable():
                raise StoreError(f"{label}: scene name {name!r:.60} cannot be part of a URL")
            cells = list(reader.cells())
            info = reader.object_info(reader.object_ids().tolist())
            kinds = {oid: i.kind for oid, i in info.items()}
            return cls(reader, cells, kinds, reader.path_names())
        except CodecError as exc:
            reader.close()
            raise StoreError(f"{label}: damaged database ({exc})") from exc
        except BaseException:
            reader.close()
            raise

    def close(self) -> None:
        """Close the database (idempotent)."""
        self.reader.close()

    # -- cells ---------------------------------------------------------------

    def has_cell(self, cid: int) -> bool:
        """Whether the scene has cell ``cid``."""
        return cid in self.boundaries

    def cached_cell(self, cid: int, rep: Rep) -> Encoded | None:
        """The encoded record of cell ``cid`` if it is cached (no database access)."""
        value: Encoded | None = self._bodies.get(("cell", cid, rep))
        return value

    def cell(self, cid: int, rep: Rep) -> Encoded:
        """The encoded record of cell ``cid`` (reads the database on a cache miss).

        The record is ``{id, kind, boundary, zmin, zmax, neighbours: [{id,
        boundary}], pvs, ach}``; a neighbour id the database has no cell for is left
        out (nobody can walk into it).
        """
        enc = self.cached_cell(cid, rep)
        if enc is None:
            c = self.reader.cell(cid)
            record = CellRecord(
                id=c.id,
                kind=c.kind,
                boundary=c.boundary,
                zmin=c.zmin,
                zmax=c.zmax,
                # a neighbour the database has no cell for is left out: nobody walks into it
                neighbours={
                    n: self.boundaries[n] for n in c.neighbours.tolist() if n in self.boundaries
                },
                pvs=c.pvs,
                ach=c.ach,
            ).to_wire()
            enc = encode(record, rep, self.version, f"cell:{cid}")
            self._bodies.put(("cell", cid, rep), enc, len(enc.content))
        return enc

    # -- locate --------------------------------------------------------------

    def locate(self, x: float, y: float, rep: Rep, z: float | None = None) -> Encoded:
        """``{cell: id}`` for the cell containing ``(x, y)`` (and height ``z`` in an
        interior, where the storey's height range decides), or ``{cell: null, reason}``."""
        answer = locate_answer(self.locator.locate(x, y, z))
        tag = f"locate:{x!r}:{y!r}" + ("" if z is None else f":{z!r}")
        return encode(answer, rep, self.version, tag)

    # -- paths ---------------------------------------------------------------

    def cached_path(self, name: str, rep: Rep) -> Encoded | None:
        """The encoded path ``name`` if it is cached."""
        value: Encoded | None = self._bodies.get(("path", name, rep))
        return value

    def path(self, name: str, rep: Rep) -> Encoded:
        """Recorded path ``name``: the stored msgpack bytes as they are, or as JSON.

        The JSON representation is ``{"name", "data"}`` with ``data`` the decoded
        msgpack (bytes as ``{"base64": ...}``); a blob that is not msgpack (or too
        large to decode) is given as ``{"name", "base64"}`` instead.
        """
        enc = self.cached_path(name, rep)
        if enc is not None:
            return enc
        blob = self.reader.path_blob(name)
        tag = f"path:{name}"
        if rep == "msgpack":
            enc = Encoded(blob, MSGPACK, etag_for(self.version, tag, rep))
        else:
            try:
                data = unpack_bounded(
                    blob,
                    f"path {name!r}",
                    max_bytes=_MAX_PATH_JSON_BYTES,
                    max_array_len=len(blob),
                    max_map_len=len(blob),
                    max_str_len=len(blob),
                    max_bin_len=len(blob),
                )
                body: dict[str, Any] = {"name": name, "data": _jsonable(data)}
            except (CodecError, RecursionError):
                body = {"name": name, "base64": base64.b64encode(blob).decode("ascii")}
            enc = encode(body, rep, self.version, tag)
        self._bodies.put(("path", name, rep), enc, len(enc.content))
        return enc

    # -- objects -------------------------------------------------------------

    def unknown_ids(self, ids: Iterable[int]) -> list[int]:
        """The ids (first occurrence, in order) the scene has no object for."""
        seen: dict[int, None] = {}
        for i in ids:
            if i not in self.kinds:
                seen[i] = None
        return list(seen)

    def cached_frames(
        self, ids: Sequence[int], form: Form = "params"
    ) -> tuple[dict[int, bytes], list[int]]:
        """``(frames found in the cache by id, ids not cached, without repeats)``."""
        if form == "params":
            found, missing = self._frames.get_many(ids)
            return cast(dict[int, bytes], found), cast(list[int], missing)
        # mesh frames live in the same LRU under (form, id) keys
        got, absent = self._frames.get_many((form, i) for i in ids)
        return (
            {cast(tuple[str, int], k)[1]: v for k, v in got.items()},
            [cast(tuple[str, int], k)[1] for k in absent],
        )

    def load_frames(self, ids: Sequence[int], form: Form = "params") -> dict[int, bytes]:
        """Read and encode the frames of ``ids`` (known ids) and cache them.

        A ``params`` frame is the msgpack map ``{"id": int, "kind": str, "params":
        bin}``; a ``lod2`` frame is ``{"id", "kind", "mesh": bin}`` with the object's
        LOD2 mesh encoded by :func:`~walkstream.shared.codec.encode_mesh` (buildings rebuilt with
        the scene's grammar, street pieces with :func:`~walkstream.shared.streets.build_street`).
        Runs a database query, and for ``lod2`` real geometry work: call it from a
        worker thread.
        """
        params = self.reader.object_params(ids)
        out: dict[int, bytes] = {}
        for oid, blob in params.items():
            payload = blob if form == "params" else self._lod2_mesh(oid, blob)
            frame = dump_msgpack(ObjectFrame(oid, self.kinds[oid], payload, form).to_wire())
            self._frames.put(oid if form == "params" else (form, oid), frame, len(frame))
            out[oid] = frame
        missing = [i for i in ids if i not in out]
        if missing:
            raise ApiError(f"scene {self.name!r}: no object {missing[0]}", status=404, detail={"ids": missing})
        return out

    def grammar(self) -> Grammar:
        """The scene's building grammar, parsed on first use (once per scene)."""
        with self._grammar_lock:
            if self._grammar is None:
                self._grammar = parse_grammar(self._grammar_text)
            return self._grammar

    def _lod2_mesh(self, oid: int, blob: bytes) -> bytes:
        """The encoded LOD2 mesh of object ``oid`` from its stored parameters."""
        try:
            p = decode_object(blob, f"scene {self.name!r}: object {oid}")
        except CodecError as exc:
            # stored bytes, not the request, are at fault: a server-side error
            raise StoreError(f"{self.reader.path}: damaged database ({exc})") from exc
        if isinstance(p, BuildingParams):
            return encode_mesh(build_lod(p, 2, self.grammar()))
        return encode_mesh(build_street(p, 2))


# ---------------------------------------------------------------------------
# all scenes
# ---------------------------------------------------------------------------


class SceneRegistry:
    """The scenes a service serves, by name."""

    def __init__(self, scenes: Sequence[Scene]) -> None:
        """Private: use :meth:`open`."""
        self.scenes: dict[str, Scene] = {s.name: s for s in sorted(scenes, key=lambda s: s.name)}
        listing = [{"name": s.name, "version": s.version} for s in self.scenes.values()]
        # the list changes only when the service restarts with other files: validated
        # with the ETag on every use rather than cached for a year
        tag = _digest(dump_json(listing))
        self.listing: dict[Rep, Encoded] = {
            rep: encode(listing, rep, tag, "scenes") for rep in ("msgpack", "json")
        }

    @classmethod
    def open(cls, paths: Sequence[str | os.PathLike[str]]) -> SceneRegistry:
        """Open and validate every database; all or nothing.

        Raises
        ------
        StoreError
            No path, a database that cannot be served (see :meth:`Scene.load`), or
            two databases with the same scene name.
        """
        if not paths:
            raise StoreError("no scene database given")
        scenes: list[Scene] = []
        where: dict[str, str] = {}
        try:
            for p in paths:
                s = Scene.load(p)
                scenes.append(s)
                if s.name in where:
                    raise StoreError(
                        f"{os.fspath(p)}: scene name {s.name!r} is already served from "
                        f"{where[s.name]}; each scene needs its own name"
                    )
                where[s.name] = os.fspath(p)
        except BaseException:
            for s in scenes:
                s.close()
            raise
        return cls(scenes)

    def get(self, name: str) -> Scene:
        """The scene called ``name``.

        Raises
        ------
        ApiError
            404 naming the scene and listing the known ones.
        """
        scene = self.scenes.get(name)
        if scene is None:
            raise ApiError(
                f"unknown scene {name!r:.80}",
                status=404,
                detail={"scene": name, "known": list(self.scenes)},
            )
        return scene

    def close(self) -> None:
        """Close every database."""
        for s in self.scenes.values():
            s.close()
