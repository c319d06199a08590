"""The scene database: one SQLite file per baked scene.

The modules: :mod:`.schema` (tables, header, content hash), :mod:`.records` (rows
and scene metadata), :mod:`.files` (atomic files, locks), :mod:`.writer`
(:class:`SceneWriter`), :mod:`.reader` (:class:`SceneReader`), :mod:`.edit`
(recorded paths written into a finished scene).

The bake writes it with :class:`SceneWriter`, the server reads it with
:class:`SceneReader`, and recorded paths are added with :func:`write_path`.

Layout (schema version :data:`SCHEMA_VERSION`; versions :data:`READABLE_VERSIONS` are read)
----------------------------------------------------------------------------------
``meta(key, value)``
    ``app`` (``"walkstream"``), ``schema_version``, ``name``, ``version`` (content
    hash), ``crs``, ``origin_x``, ``origin_y``, ``grammar``, ``grammar_version``,
    ``features`` (JSON list), ``settings`` (JSON), ``settings_hash``,
    ``bake_seconds``, ``created``.
``objects(id, kind, params, minx, miny, minz, maxx, maxy, maxz, tris0, tris1, tris2)``
    ``params`` is :func:`~walkstream.shared.codec.encode_building` / ``encode_street`` output,
    streamed to clients as is; ``tris*`` are the triangle counts of LOD 0-2.
``cells(id, kind, boundary, zmin, zmax, neighbours, pvs, done)``
    ``boundary`` is :func:`~walkstream.shared.codec.encode_polygon` of the convex ``(n, 2)``
    outline, ``neighbours`` :func:`~walkstream.shared.codec.encode_ids`, ``pvs``
    :func:`~walkstream.shared.codec.encode_pvs`.
``viewpoints(name, x, y, z, yaw, cell)`` and ``paths(name, data)``.

Interiors (version 2): the features ``rooms`` (tables ``rooms(cell, name, room, storey,
planes)`` and ``storeys(id, name, zmin, zmax)``), ``portals`` (``portals(id, cell_a,
cell_b, polygon, kind, source, name)`` and ``stairs(id, portal, lower, upper, path,
name)``) and ``meshes`` (``contents(cell, data, triangles, vertices, parts, raw_bytes,
max_error)``, the ``walkstream-cellmesh/2 or /1`` blob of each cell); an interior has no
objects and an empty PVS per cell.  Version 1 files (cities baked before interiors
existed) are read as they are.  A crossing scene (a city with an interior) adds the
feature ``entrances``: ``entrances(portal, building, street, doorway, shell)`` and
``placements(portal, angle, x, y, dz, first, last)``, the move of the contents of cells
``first .. last`` from the interior's own frame into the city's (a crossing scene baked
before has no ``placements``: its contents are stored moved).

Optional tables are declared once in :data:`OPTIONAL_TABLES`, keyed by the feature
name that needs them, and only created for scenes that list that feature.  The file
carries SQLite ``application_id`` :data:`APPLICATION_ID` and ``user_version``
:data:`SCHEMA_VERSION` so a foreign or newer file is refused from its 100-byte
header alone.

Atomicity: the bake writes ``<path>.partial`` (WAL, one small transaction per
cell, so a killed bake loses at most the cell it was on and can resume), and
:meth:`SceneWriter.finish` vacuums it into a fresh, self-contained file that
replaces ``path`` with ``os.replace``.  :func:`write_path` copies, edits and
replaces likewise.  Nothing ever modifies a finished file in place, which is
what lets readers open it ``immutable``."""

from walkstream.server.store.edit import write_path
from walkstream.server.store.reader import SceneReader
from walkstream.server.store.records import (
    CellInfo,
    CellRow,
    ContentsInfo,
    EntranceInfo,
    ObjectInfo,
    ObjectRow,
    PortalInfo,
    RoomInfo,
    SceneMeta,
    StairInfo,
    StoreyInfo,
)
from walkstream.server.store.schema import (
    APPLICATION_ID,
    OBJECT_KINDS,
    OPTIONAL_TABLES,
    READABLE_VERSIONS,
    SCHEMA_VERSION,
)
from walkstream.server.store.writer import SceneWriter

__all__ = [
    "SCHEMA_VERSION",
    "READABLE_VERSIONS",
    "APPLICATION_ID",
    "OBJECT_KINDS",
    "OPTIONAL_TABLES",
    "SceneMeta",
    "ObjectRow",
    "ObjectInfo",
    "CellRow",
    "CellInfo",
    "StoreyInfo",
    "RoomInfo",
    "PortalInfo",
    "StairInfo",
    "ContentsInfo",
    "EntranceInfo",
    "SceneWriter",
    "SceneReader",
    "write_path",
]
