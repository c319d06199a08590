"""Per-scene state of the service and the FastAPI dependencies that hand it out.

Everything a request needs is prepared when the app starts or on the first request
that needs it, so that answering costs about as much as serving a static file:

* each database is opened read-only with :class:`~walkstream.server.store.reader.SceneReader` (which
  validates it) and every cell is read once, which builds the
  :class:`~walkstream.shared.cells.CellLocator`, keeps every cell's outline, height
  range and neighbours (the cell index needs them) and decodes every PVS, so a
  damaged file stops the start;
* the cell index is cut into square tiles (:func:`fit_tile_grid`: one tile for a
  small scene, else tiles of about :data:`CELLS_PER_TILE` cells), each cell in the
  tile holding the mean of its vertices;
* the manifest is encoded at start-up in both representations (msgpack and JSON);
* cell records, index tiles and recorded paths are encoded on first use and kept
  in a byte-bounded LRU;
* the start bundle (:mod:`walkstream.server.service.startbundle`) is assembled from
  those same encoded bodies;
* object frames (see :mod:`walkstream.server.service.routers`) are encoded on first use and kept in a
  second byte-bounded LRU; which ids exist and their kinds are known from start-up,
  so an unknown id is answered without touching the database;
* an interior scene also gets an :class:`~walkstream.server.service.interiors.InteriorState`
  (its topology, room records and cell contents), and its cells are located in 3D;
* LOD2 mesh frames (``form=lod2``, for the client's ``--stream meshes`` comparison)
  are built from the parameters with the scene's grammar (parsed once per scene) on
  first use, in a worker thread, and kept in the same frame LRU under separate keys.

A scene version is immutable, so nothing cached for it ever needs invalidating.  A
recorded path or a new bake replaces the file with a *new* version (written beside it,
renamed over it): :meth:`~walkstream.server.service.registry.SceneRegistry.get` notices the new file (checked at most once
per :data:`~walkstream.server.service.registry.RECHECK_S`) and serves the new version from then on, with new ETags; a file
that cannot be loaded leaves the old version served and is reported in the log."""

from __future__ import annotations

import base64
import gzip
import logging
import math
import os
import threading
from collections.abc import Callable, Iterable, Sequence
from typing import Any, Literal, cast

import numpy as np
from numpy.typing import NDArray

from walkstream.server.service.http import (
    Encoded,
    Rep,
    dump_msgpack,
    encode,
    etag_for,
)
from walkstream.server.service.interiors import InteriorState
from walkstream.server.service.lru import LRU
from walkstream.server.store import CellInfo, SceneReader
from walkstream.shared.areas import build_flat
from walkstream.shared.buildings import build_lod
from walkstream.shared.cells import CellLocator, TileGrid
from walkstream.shared.codec import decode_object, encode_mesh, unpack_bounded
from walkstream.shared.content.impostor import KIND as IMPOSTOR
from walkstream.shared.content.mesh import KIND as MESH
from walkstream.shared.content.params import KIND as PARAMS
from walkstream.shared.content.registry import by_form, object_forms
from walkstream.shared.content.walltex import KIND as WALLTEX
from walkstream.shared.errors import ApiError, CodecError, DatabaseDamagedError, StoreError
from walkstream.shared.impostorwire import CellImpostors, ImpostorRow
from walkstream.shared.lsystem.grammar import Grammar, parse_grammar
from walkstream.shared.pathcodec import PATH_Q_MEDIA, encode_path_q, head_path_q
from walkstream.shared.paths import RecordedPath
from walkstream.shared.records import BuildingParams
from walkstream.shared.walls import WallSide, ring_cell, walls_wire
from walkstream.shared.wire import (
    MSGPACK,
    OFFERS,
    CellIndex,
    CellRecord,
    Manifest,
    ObjectFrame,
    locate_answer,
)

log = logging.getLogger(__name__)

__all__ = [
    "MAX_IDS",
    "CELLS_PER_TILE",
    "Form",
    "OBJECT_FORMS",
    "fit_tile_grid",
    "Scene",
]


MAX_IDS = 1000
"""Most object ids one ``POST .../objects`` may ask for (more: 413)."""

Form = Literal["params", "lod2"]
"""What an object frame carries: the stored parameters, or the rebuilt LOD2 mesh (the
forms of the object content kinds, :func:`~walkstream.shared.content.registry.object_forms`)."""

OBJECT_FORMS: tuple[Form, ...] = cast(tuple[Form, ...], object_forms())
"""The forms ``POST .../objects?form=`` accepts, one per object content kind; ``params``
is the default."""

CELLS_PER_TILE = 32
"""About this many cells per tile of the cell index (a scene with fewer has one tile)."""

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


def fit_tile_grid(
    outlines: Sequence[NDArray[np.float64]], cells_per_tile: int = CELLS_PER_TILE
) -> tuple[TileGrid, NDArray[np.int64]]:
    """The tiles of a scene's cell index and the tile of each cell.

    One tile covers the scene when it has at most ``cells_per_tile`` cells; else the
    tile side (a multiple of 10 m) gives about that many cells per tile on average
    over the cells' bounding box.  A cell belongs to the tile holding the mean of its
    vertices; the grid's ``reach_m`` is how far any outline pokes out of its tile.

    Parameters
    ----------
    outlines : sequence of (m_i, 2) float
        The cells' outlines, scene-local metres.
    cells_per_tile : int
        Target number of cells per tile.

    Returns
    -------
    grid : TileGrid
    tiles : (n, 2) int64
        Tile ``(i, j)`` of each cell.
    """
    n = len(outlines)
    if n == 0:
        return TileGrid((0.0, 0.0), 1.0, (1, 1), 0.0), np.zeros((0, 2), np.int64)
    pts = np.concatenate([np.asarray(o, np.float64).reshape(-1, 2) for o in outlines])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    w, h = float(hi[0] - lo[0]), float(hi[1] - lo[1])
    side = max(w, h, 1.0)
    if n > cells_per_tile:
        side = min(side, max(10.0, math.ceil(math.sqrt(max(w, 1.0) * max(h, 1.0) * cells_per_tile / n) / 10.0) * 10.0))
    shape = (max(1, math.ceil(w / side - 1e-9)), max(1, math.ceil(h / side - 1e-9)))
    centres = np.stack([np.asarray(o, np.float64).reshape(-1, 2).mean(axis=0) for o in outlines])
    grid0 = TileGrid((float(lo[0]), float(lo[1])), side, shape, 0.0)
    tiles = grid0.tiles_of(centres)
    reach = 0.0
    counts = [len(np.asarray(o).reshape(-1, 2)) for o in outlines]
    owner = np.repeat(tiles, counts, axis=0)
    x0 = lo[0] + owner[:, 0] * side
    y0 = lo[1] + owner[:, 1] * side
    dx = np.maximum(np.maximum(x0 - pts[:, 0], pts[:, 0] - (x0 + side)), 0.0)
    dy = np.maximum(np.maximum(y0 - pts[:, 1], pts[:, 1] - (y0 + side)), 0.0)
    reach = float(np.hypot(dx, dy).max()) + 0.01  # centimetre rounding on the wire
    return TileGrid((float(lo[0]), float(lo[1])), side, shape, reach), tiles


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
        # every outline, height range and (existing) neighbour, for the cell index
        self.boundaries: dict[int, NDArray[np.float64]] = {c.id: c.boundary for c in cells}
        self._z: dict[int, tuple[float, float]] = {c.id: (c.zmin, c.zmax) for c in cells}
        # a neighbour the database has no cell for is left out: nobody walks into it
        self._neighbours: dict[int, NDArray[np.int64]] = {
            c.id: np.array([n for n in c.neighbours.tolist() if n in self.boundaries], np.int64)
            for c in cells
        }
        # interior cells stack storeys: located in 3D, the outside never (see their kinds);
        # a street cell of a crossing scene holds a point at any height
        self.locator = CellLocator.of_kinds(
            [c.id for c in cells], [c.kind for c in cells], [c.boundary for c in cells],
            [[c.zmin, c.zmax] for c in cells],
        )
        inside = cells
        if meta.kind == "crossing":
            rooms = reader.rooms()
            inside = [c for c in cells if c.id in rooms]
        self.kind: str = meta.kind
        self.interior: InteriorState | None = (
            InteriorState(reader, inside) if meta.kind in ("interior", "crossing") else None
        )
        self.grid, tiles = fit_tile_grid([c.boundary for c in cells])
        self.tile_cells: dict[tuple[int, int], list[int]] = {}
        """Tile -> ids of its cells, ascending."""
        self.cell_tile: dict[int, tuple[int, int]] = {}
        """Cell id -> the tile of the cell index that holds it."""
        for c, (i, j) in zip(cells, tiles.tolist(), strict=True):
            self.tile_cells.setdefault((i, j), []).append(c.id)
            self.cell_tile[c.id] = (i, j)
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
            index=self.grid,
            offers=OFFERS,
        ).to_wire()
        self.manifest_viewpoints = vps
        self.manifest: dict[Rep, Encoded] = {
            rep: encode(manifest, rep, self.version, "manifest") for rep in ("msgpack", "json")
        }
        self._bodies = LRU(_BODY_CACHE_BYTES)
        self._frames = LRU(_FRAME_CACHE_BYTES)
        self._grammar_text = meta.grammar_text
        self._grammar: Grammar | None = None
        self._grammar_lock = threading.Lock()
        self.impostor_ids: frozenset[int] = frozenset(reader.impostor_info())
        """The impostor images the scene has (empty when baked without ``--impostors``)."""
        self.has_walls = reader.has_walls()
        """Whether the scene was baked with textured virtual walls (``--virtual-walls``)."""
        self.wall_texture_ids: frozenset[int] = frozenset(reader.wall_texture_info())
        """The wall textures the scene has (empty without walls)."""
        sides = [WallSide.from_row(r, "stored wall").to_row(compact=True) for r in reader.wall_sides()] \
            if self.has_walls else []
        self.ring_sides: dict[int, list[list[float | int]]] = {}
        """A city's ring walls by the cell they ring (``ring_cell`` of the portal): what
        ``GET .../walls?cells=...`` answers (a walk asks for the rings of the cells it
        comes to, not for every side before it starts)."""
        for row in sides:
            self.ring_sides.setdefault(ring_cell(int(row[0])), []).append(row)
        self.walls: dict[Rep, Encoded] = {
            rep: encode(walls_wire(sides), rep, self.version, "walls") for rep in ("msgpack", "json")
        } if self.has_walls else {}
        """Every wall side (``WallSide.to_row(compact=True)`` lists) in each representation
        (empty without walls)."""
        self.walls_gzip: Encoded | None = Encoded(
            gzip.compress(self.walls["msgpack"].content, 9, mtime=0), self.walls["msgpack"].media_type,
            etag_for(self.version, "walls", "msgpack-gzip")) if self.has_walls else None
        """The msgpack sides gzip-compressed (``Content-Encoding: gzip`` when the request
        accepts it: a hall's 600 sides are about 6 kB so, 70 kB not)."""
        self._payloads: dict[str, Callable[[int, bytes], bytes]] = {
            PARAMS.name: lambda _oid, blob: blob,
            MESH.name: self._lod2_mesh,
        }
        """Object content kind -> its frame's payload from the stored bytes (see :attr:`payload_kinds`)."""

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
            raise DatabaseDamagedError(f"{label}: damaged database ({exc})") from exc
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

        The record is ``{id, kind, pvs, ach}`` (:class:`~walkstream.shared.wire.CellRecord`):
        what is the cell's own; outlines and neighbours are in the cell index.
        """
        enc = self.cached_cell(cid, rep)
        if enc is None:
            c = self.reader.cell(cid)
            far = self.reader.ring_far(cid)
            record = CellRecord(id=c.id, kind=c.kind, pvs=c.pvs, ach=c.ach, impostors=self._impostor_rows(cid),
                                far=None if far is None else far[0], far_ach=None if far is None else far[1],
                                far_share=0.0 if far is None else far[2])
            enc = encode(record.to_wire(compact=rep == "msgpack"), rep, self.version, f"cell-v2:{cid}")
            self._bodies.put(("cell", cid, rep), enc, len(enc.content))
        return enc

    def _impostor_rows(self, cid: int) -> CellImpostors | None:
        """Cell ``cid``'s impostors with each object's box and the bake's D and A (None
        for a cell without impostors or a scene baked without them)."""
        if not self.impostor_ids:
            return None
        rows = self.reader.cell_impostors(cid)
        if not rows:
            return None
        info = self.reader.object_info(r[0] for r in rows)
        st = self.reader.meta.settings["impostors"]
        return CellImpostors(float(st["distance"]), math.radians(float(st["error_deg"])), tuple(
            ImpostorRow(oid, level, az0, n_az, el0, n_el, info[oid].bbox, tuple(images))
            for oid, level, az0, n_az, el0, n_el, *images in rows
        ), st.get("projection", "ortho") == "perspective")

    def cached_wall_texture(self, tid: int) -> Encoded | None:
        """Wall texture ``tid`` if it is cached (no database access)."""
        value: Encoded | None = self._bodies.get(("walltex", tid))
        return value

    def wall_texture(self, tid: int) -> Encoded:
        """Wall texture ``tid`` (a known one) as stored: immutable, its ETag naming the scene
        version and the texture (reads the database on a cache miss)."""
        enc = self.cached_wall_texture(tid)
        if enc is None:
            media, data = self.reader.wall_textures([tid])[tid]
            enc = Encoded(data, media, etag_for(self.version, f"walltex:{tid}", WALLTEX.name))
            self._bodies.put(("walltex", tid), enc, len(data))
        return enc

    def has_impostor(self, image: int) -> bool:
        """Whether the scene has impostor image ``image``."""
        return image in self.impostor_ids

    def cached_impostor(self, image: int) -> Encoded | None:
        """Impostor image ``image`` if it is cached (no database access)."""
        value: Encoded | None = self._bodies.get(("impostor", image))
        return value

    def impostor(self, image: int) -> Encoded:
        """Impostor image ``image`` (a known one) as stored: immutable, its ETag naming the
        scene version and the image (reads the database on a cache miss)."""
        enc = self.cached_impostor(image)
        if enc is None:
            media, data = self.reader.impostor_images([image])[image]
            enc = Encoded(data, media, etag_for(self.version, f"impostor:{image}", IMPOSTOR.name))
            self._bodies.put(("impostor", image), enc, len(data))
        return enc

    def cells(self, ids: Sequence[int]) -> list[bytes]:
        """The msgpack records of cells ``ids`` (known ids), in the order asked.

        Reads the database for those not cached: call it from a worker thread.
        """
        return [self.cell(i, "msgpack").content for i in ids]

    def unknown_cells(self, ids: Iterable[int]) -> list[int]:
        """The ids (first occurrence, in order) the scene has no cell for."""
        return list(dict.fromkeys(i for i in ids if i not in self.boundaries))

    # -- cell index -----------------------------------------------------------

    def has_tile(self, i: int, j: int) -> bool:
        """Whether ``(i, j)`` is a tile of the grid (it may hold no cell)."""
        return 0 <= i < self.grid.shape[0] and 0 <= j < self.grid.shape[1]

    def index(self, tile: tuple[int, int] | None, rep: Rep) -> Encoded:
        """The encoded cell index of ``tile`` (None: the whole scene); no database access."""
        key = ("index", tile, rep)
        enc: Encoded | None = self._bodies.get(key)
        if enc is None:
            if tile is None:
                ids = sorted(self.boundaries)
            else:
                ids = self.tile_cells.get(tile, [])
            record = CellIndex(
                tile=tile,
                ids=np.array(ids, np.int64),
                kinds=tuple(self.cell_kinds[c] for c in ids),
                zmin=np.array([self._z[c][0] for c in ids]),
                zmax=np.array([self._z[c][1] for c in ids]),
                outlines=tuple(self.boundaries[c] for c in ids),
                neighbours=tuple(self._neighbours[c] for c in ids),
            )
            name = "index" if tile is None else f"index:{tile[0]}:{tile[1]}"
            enc = encode(record.to_wire(compact=rep == "msgpack"), rep, self.version, name)
            self._bodies.put(key, enc, len(enc.content))
        return enc

    # -- locate --------------------------------------------------------------

    def locate(self, x: float, y: float, rep: Rep, z: float | None = None) -> Encoded:
        """``{cell: id}`` for the cell containing ``(x, y)`` (and height ``z`` in an
        interior, where the storey's height range decides), or ``{cell: null, reason}``."""
        answer = locate_answer(self.locator.locate(x, y, z))
        tag = f"locate:{x!r}:{y!r}" + ("" if z is None else f":{z!r}")
        return encode(answer, rep, self.version, tag)

    # -- paths ---------------------------------------------------------------

    def cached_path(self, name: str, rep: Rep | Literal["q1"]) -> Encoded | None:
        """The encoded path ``name`` if it is cached (``q1``: the compact encoding)."""
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

    def path_q(self, name: str) -> Encoded:
        """Recorded path ``name`` in the compact encoding (``walkstream-path-q/1``)."""
        enc = self.cached_path(name, "q1")
        if enc is None:
            p = RecordedPath.from_msgpack(self.path(name, "msgpack").content, f"path {name!r}")
            enc = Encoded(encode_path_q(p), PATH_Q_MEDIA, etag_for(self.version, f"path:{name}", "q1"))
            self._bodies.put(("path", name, "q1"), enc, len(enc.content))
        return enc

    def path_head_q(self, name: str, seconds: float) -> Encoded | None:
        """The first ``seconds`` of path ``name``, compact, decoding exactly as the whole
        compact path's first samples (:func:`~walkstream.shared.pathcodec.head_path_q`);
        None when that is the whole path."""
        enc: Encoded | None = self._bodies.get(key := ("path", name, f"q1head:{seconds!r}"))
        if enc is None and (blob := head_path_q(self.path_q(name).content, seconds, f"path {name!r}")):
            enc = Encoded(blob, PATH_Q_MEDIA, etag_for(self.version, f"pathhead:{name}:{seconds!r}", "q1"))
            self._bodies.put(key, enc, len(enc.content))
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
        the scene's grammar, street pieces and areas with :func:`~walkstream.shared.areas.build_flat`).
        Runs a database query, and for ``lod2`` real geometry work: call it from a
        worker thread.
        """
        kind = by_form(form)
        make = self._payloads[kind.name]
        out: dict[int, bytes] = {}
        for oid, blob in self.reader.content_blobs(kind.name, ids).items():
            payload = make(oid, blob)
            frame = dump_msgpack(ObjectFrame(oid, self.kinds[oid], payload, form).to_wire())
            self._frames.put(oid if form == "params" else (form, oid), frame, len(frame))
            out[oid] = frame
        missing = [i for i in ids if i not in out]
        if missing:
            raise ApiError(f"scene {self.name!r}: no object {missing[0]}", status=404, detail={"ids": missing})
        return out

    @property
    def payload_kinds(self) -> frozenset[str]:
        """The object content kinds whose frames this scene can make."""
        return frozenset(self._payloads)

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
            raise DatabaseDamagedError(f"{self.reader.path}: damaged database ({exc})") from exc
        if isinstance(p, BuildingParams):
            return encode_mesh(build_lod(p, 2, self.grammar()))
        return encode_mesh(build_flat(p, 2))


# ---------------------------------------------------------------------------
# all scenes
# ---------------------------------------------------------------------------
