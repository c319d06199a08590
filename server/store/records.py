"""The rows a bake writes and a reader returns, the scene metadata, and their field checks."""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from walkstream.shared.areakinds import area_z
from walkstream.shared.codec import (
    encode_area,
    encode_building,
    encode_street,
)
from walkstream.shared.errors import StoreError
from walkstream.shared.records import AreaParams, BuildingParams, StreetParams
from walkstream.shared.roomwire import ContentsRef
from walkstream.shared.scene.placement import ContentsPlacement

try:  # advisory locks between processes; POSIX only
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None  # type: ignore[assignment]
from walkstream.server.store.schema import READABLE_VERSIONS

__all__ = [
    "SceneMeta",
    "ObjectRow",
    "ObjectInfo",
    "CellRow",
    "CellInfo",
    "RoomInfo",
    "PortalInfo",
    "StairInfo",
    "ContentsInfo",
    "StoreyInfo",
    "EntranceInfo",
    "MAX_PATH_BYTES",
    "finite_number",
    "row_index",
    "check_path_name",
    "parse_meta",
    "f64_array",
    "f64_blob",
]
_MAX_PATH_NAME = 200
MAX_PATH_BYTES = 64 << 20
"""Most bytes one recorded path's blob may take."""






# ---------------------------------------------------------------------------
# records
# ---------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class SceneMeta:
    """What the ``meta`` table says about a finished scene.

    ``origin`` is the CRS position of local (0, 0); ``version`` the first 16 hex
    digits of the content hash; ``settings_json`` the bake settings as canonical
    JSON (see :attr:`settings`).
    """

    schema_version: int
    name: str
    version: str
    crs: str
    origin: tuple[float, float]
    grammar_text: str
    grammar_version: str
    features: tuple[str, ...]
    settings_json: str
    bake_seconds: float
    created: str

    @property
    def settings(self) -> dict[str, Any]:
        """The bake settings (a fresh dict on each call)."""
        value: dict[str, Any] = json.loads(self.settings_json)
        return value

    @property
    def kind(self) -> str:
        """``crossing`` for a city with a building's interior joined at its entrance
        (the ``entrances`` feature), ``interior`` for a scene of rooms and portals,
        else ``city``."""
        if "entrances" in self.features:
            return "crossing"
        return "interior" if "rooms" in self.features else "city"


@dataclass(frozen=True, slots=True)
class ObjectRow:
    """One object as the bake hands it to :meth:`SceneWriter.add_objects`.

    ``bbox`` is ``(minx, miny, minz, maxx, maxy, maxz)`` in scene-local metres and
    ``tris`` the triangle counts of LOD 0, 1 and 2.
    """

    id: int
    kind: str
    params: bytes
    bbox: tuple[float, float, float, float, float, float]
    tris: tuple[int, int, int] = (0, 0, 0)

    @classmethod
    def of(
        cls,
        p: BuildingParams | StreetParams | AreaParams,
        *,
        tris: tuple[int, int, int] = (0, 0, 0),
        bbox: Sequence[float] | None = None,
        with_source_id: bool = True,
    ) -> ObjectRow:
        """Encode ``p`` and, unless given, derive its box from the footprint.

        The derived box spans z from 0 to ``p.top`` (the eaves, or a landmark's crown) for a building, 0 to 0 for
        a street piece and its kind's height for an area (kind ``"area"``); pass ``bbox`` when the grammar builds above the eaves.
        """
        bottom = 0.0
        if isinstance(p, BuildingParams):
            blob, kind, xy, top = (
                encode_building(p, with_source_id=with_source_id),
                "building",
                p.rings[0],
                p.top,
            )
        elif isinstance(p, AreaParams):
            blob, kind, xy = encode_area(p, with_source_id=with_source_id), "area", p.rings[0]
            bottom = top = area_z(p.kind)
        else:
            blob, kind, xy, top = (
                encode_street(p, with_source_id=with_source_id),
                p.kind,
                p.ring,
                0.0,
            )
        if bbox is None:
            if len(xy) == 0:
                raise StoreError(f"object {p.id}: no vertices, pass bbox explicitly")
            lo, hi = xy.min(axis=0), xy.max(axis=0)
            bbox = (float(lo[0]), float(lo[1]), bottom, float(hi[0]), float(hi[1]), float(top))
        b = tuple(float(v) for v in bbox)
        if len(b) != 6:
            raise StoreError(f"object {p.id}: bbox: expected 6 numbers, got {len(b)}")
        return cls(p.id, kind, blob, (b[0], b[1], b[2], b[3], b[4], b[5]), tris)


@dataclass(frozen=True, slots=True)
class ObjectInfo:
    """An object's kind, box ``(minx, miny, minz, maxx, maxy, maxz)`` and LOD triangle counts."""

    id: int
    kind: str
    bbox: tuple[float, float, float, float, float, float]
    tris: tuple[int, int, int]


@dataclass(frozen=True, slots=True)
class CellRow:
    """One view cell as the bake hands it to :meth:`SceneWriter.add_cells` (no PVS yet).

    ``boundary`` is the convex outline, ``(n, 2) float64`` local metres; ``zmin`` and
    ``zmax`` the height range of viewers in it; ``neighbours`` ``(m,)`` cell ids.
    """

    id: int
    kind: str
    boundary: NDArray[np.float64]
    zmin: float
    zmax: float
    neighbours: NDArray[np.int64]


@dataclass(frozen=True, slots=True)
class CellInfo:
    """A cell read back: :class:`CellRow` fields plus its PVS.

    ``pvs`` is ``(k,) int64`` ascending object ids and ``ach`` ``(k,) float64``
    their average coverage (sums to 1; both empty for a cell that sees nothing).
    """

    id: int
    kind: str
    boundary: NDArray[np.float64]
    zmin: float
    zmax: float
    neighbours: NDArray[np.int64]
    pvs: NDArray[np.int64]
    ach: NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class EntranceInfo:
    """A building's entrance in a crossing scene: ``portal`` (an id of the portals
    table) joins ``street`` (a city cell) to ``doorway`` (a room-model cell); the
    city object ``building`` is drawn as the contents of cell ``shell`` (the
    interior's outside: its outer walls, with the door, and its roof).  ``placement``:
    the interior's contents are stored in its own frame, moved into the city's by it
    (None: stored in the city's frame, as a crossing scene baked before keeps them)."""

    portal: int
    building: int
    street: int
    doorway: int
    shell: int
    placement: ContentsPlacement | None = None


def finite_number(x: object, what: str) -> float:
    """``x`` as a finite float, or a :class:`StoreError` naming ``what``."""
    try:
        v = float(x)  # type: ignore[arg-type]
    except (TypeError, ValueError) as exc:
        raise StoreError(f"{what}: expected a number, got {x!r:.40}") from exc
    if not math.isfinite(v):
        raise StoreError(f"{what}: expected a finite number, got {v}")
    return v


def row_index(x: object, what: str) -> int:
    """``x`` as a non-negative int64 (an id or count), or a :class:`StoreError` naming ``what``."""
    if isinstance(x, bool) or not isinstance(x, int | np.integer):
        raise StoreError(f"{what}: expected an integer, got {type(x).__name__}")
    v = int(x)
    if not 0 <= v < 2**63:
        raise StoreError(f"{what}: expected a non-negative int64, got {v}")
    return v


def check_path_name(name: object) -> str:
    """``name`` when it is a valid recorded path name (printable, not too long), else a :class:`StoreError`."""
    if not isinstance(name, str) or not 0 < len(name) <= _MAX_PATH_NAME:
        raise StoreError(f"path name: expected 1 to {_MAX_PATH_NAME} characters, got {name!r:.60}")
    if not name.isprintable():
        raise StoreError(f"path name {name!r:.60}: control characters are not allowed")
    return name


def parse_meta(raw: dict[str, Any], label: str) -> SceneMeta:
    """The :class:`SceneMeta` of a ``meta`` table's rows, checked (``label`` names the file in errors)."""
    try:
        if raw.get("app") != "walkstream":
            raise StoreError(f"{label}: meta table does not name walkstream")
        if raw["schema_version"] not in READABLE_VERSIONS:
            raise StoreError(
                f"{label}: schema version {raw['schema_version']}, this walkstream reads "
                f"versions {', '.join(map(str, READABLE_VERSIONS))}"
            )
        if raw.get("version") is None:
            raise StoreError(
                f"{label}: an unfinished bake (no content version); bake the scene again"
            )
        features = json.loads(raw["features"])
        if not isinstance(features, list) or not all(isinstance(f, str) for f in features):
            raise StoreError(f"{label}: meta 'features' is not a list of names")
        return SceneMeta(
            schema_version=int(raw["schema_version"]),
            name=str(raw["name"]),
            version=str(raw["version"]),
            crs=str(raw["crs"]),
            origin=(float(raw["origin_x"]), float(raw["origin_y"])),
            grammar_text=str(raw["grammar"]),
            grammar_version=str(raw["grammar_version"]),
            features=tuple(features),
            settings_json=str(raw["settings"]),
            bake_seconds=float(raw["bake_seconds"]),
            created=str(raw["created"]),
        )
    except KeyError as exc:
        raise StoreError(f"{label}: meta table lacks {exc.args[0]!r}") from exc
    except (TypeError, ValueError) as exc:
        raise StoreError(f"{label}: meta table damaged ({exc})") from exc


# ---------------------------------------------------------------------------
# interiors (schema version 2, features rooms / portals / meshes)
# ---------------------------------------------------------------------------


def f64_array(blob: bytes, cols: int, what: str) -> NDArray[np.float64]:
    """A float64 little-endian ``(n, cols)`` array stored as bytes, read-only."""
    if not isinstance(blob, bytes | bytearray | memoryview) or len(blob) % (8 * cols):
        raise StoreError(f"{what}: expected float64 rows of {cols}")
    a = np.frombuffer(bytes(blob), dtype="<f8").reshape(-1, cols).astype(np.float64)
    if not np.all(np.isfinite(a)):
        raise StoreError(f"{what}: non-finite values")
    a.flags.writeable = False
    return a


def f64_blob(a: object, cols: int, what: str) -> bytes:
    """A finite float64 array as little-endian ``(n, cols)`` bytes (see :func:`f64_array`)."""
    arr = np.asarray(a, dtype=np.float64).reshape(-1, cols)
    if not np.all(np.isfinite(arr)):
        raise StoreError(f"{what}: non-finite values")
    return arr.astype("<f8").tobytes()


@dataclass(frozen=True, slots=True)
class StoreyInfo:
    """A storey of an interior: its name and the height range of its cells."""

    id: int
    name: str
    zmin: float
    zmax: float


@dataclass(frozen=True, slots=True)
class RoomInfo:
    """An interior cell's room data: the room it is part of (``room`` is the source's
    key, ``None`` for a doorway or the outside), its storey (-1: outside) and its
    ``planes`` ``(k, 4)`` (inside where ``n . p + d <= 0``)."""

    cell: int
    name: str
    room: str | None
    storey: int
    planes: NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class PortalInfo:
    """A portal: ``polygon`` ``(k, 3)`` between cells ``a`` and ``b``; its kind, and
    where its two sides came from (``source``)."""

    id: int
    a: int
    b: int
    polygon: NDArray[np.float64]
    kind: str
    source: str
    name: str


@dataclass(frozen=True, slots=True)
class StairInfo:
    """A stair: the portal it climbs through, its lower and upper cell and its walking
    line ``path`` ``(k, 3)`` (floor points, bottom to top)."""

    id: int
    portal: int
    lower: int
    upper: int
    path: NDArray[np.float64]
    name: str


@dataclass(frozen=True)
class ContentsInfo(ContentsRef):
    """The sizes of one cell's contents as the database holds them: the wire's
    :class:`~walkstream.shared.roomwire.ContentsRef` and the cell they belong to."""

    cell: int = -1
