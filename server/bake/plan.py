"""What the one bake driver is given: a scene's database header, its cells by kind, its tables and walks.

Every scene kind (a city, an interior, a crossing of both) is turned into a
:class:`BakePlan` by its planner (:func:`~.pipeline.city_plan`,
:func:`~.interior.interior_plan`, :func:`~.crossing.crossing_plan`); the driver
(:func:`~.driver.drive`) then bakes the cells by their kind, whatever the scene:

- :class:`PvsCells`, cells seen through a baked PVS (street, crossroad, square and
  grid cells): their PVS and ACH rendered in chunks (:func:`~.workers.pvs_task`);
- :class:`RoomCells`, cells seen through portals (room, doorway and outside cells):
  their contents clipped in chunks (:func:`~.roomcontents.contents_task`) and
  encoded; their portals are written with the plan's tables;
- :class:`ImpostorCells` (a city baked with ``--impostors``): after the PVS, the
  impostor images its PVS cells need (:mod:`~.impostorplan`), rendered and encoded
  in chunks (:func:`~.impostorrender.impostor_task`).

- :class:`FieldCells`, cells grown over a dense visibility field (sections), or
  street and grid cells sampled from it (``--sampling field``): the field rendered
  in blocks (:func:`~.workers.field_task`, resumed block by block), then the
  planner's ``grow`` makes the cells (sections) and their PVS from it, before the
  tables are written.

A planner does the cheap work (reading, cells, placement, the walking graphs); the
chunked work, the database and resuming are the driver's.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from walkstream.server.bake.field import FieldLattice, PointSets
from walkstream.server.bake.impostorsettings import ImpostorSettings
from walkstream.server.bake.roomcontents import Part
from walkstream.server.bake.roomlayout import RoomLayout
from walkstream.server.bake.settings import BakeSettings
from walkstream.server.bake.viewcell import ViewCell
from walkstream.server.bake.wallplan import WallPlan, WallSettings
from walkstream.server.sources.interior import InteriorScene
from walkstream.server.sources.scene import SourceScene
from walkstream.server.store import SceneWriter
from walkstream.shared.arrays import F64, I64
from walkstream.shared.paths import RecordedPath

__all__ = ["BakePlan", "FieldCells", "ImpostorCells", "PvsCells", "RingCells", "RoomCells", "Say", "Walk", "settings_key"]

Say = Callable[[str], None]
"""A one-line message about the bake's stages."""

Walk = tuple[RecordedPath, str]
"""A default walk and the line said when it is recorded."""


@dataclass
class PvsCells:
    """Cells seen through a baked PVS: ``cells`` rendered in ``scene`` under ``settings``;
    ``key`` names the scene and settings (a worker keeps its renderer while it stays)."""

    scene: SourceScene
    settings: BakeSettings
    cells: list[ViewCell]
    key: str


@dataclass
class RoomCells:
    """Cells seen through portals: an interior's cells and their contents.

    ``layout`` is the interior in its own frame (the contents are clipped to its
    cells there); ``place`` turns the contents so found into the scene's frame (the
    identity for an interior alone); ``offset`` is added to every cell id in the
    scene; ``cellmesh_version`` picks the contents codec.
    """

    scene: InteriorScene
    layout: RoomLayout
    offset: int = 0
    place: Callable[[dict[int, list[Part]]], dict[int, list[Part]]] = lambda parts: parts
    cellmesh_version: int = 4
    walls: WallSettings | None = None
    """With ``--virtual-walls``: their settings (the layout already holds the ``wall`` portals)."""
    wall_plan: WallPlan | None = None
    """The walls' sides, textures and crossing objects (:func:`~.wallplan.plan_walls`)."""


@dataclass
class FieldCells:
    """Cells grown over a dense visibility field (sections, :mod:`~.sections`).

    The driver renders the field of ``lattice`` in ``scene`` under ``settings``
    (``key`` names the scene and the field's settings: the folder its blocks are kept
    in) and hands it to ``grow``, which makes the cells (the plan's ``write_tables``
    and ``walks`` then see them) and returns each cell's ``(id, pvs, ach)``.
    """

    scene: SourceScene
    settings: BakeSettings
    lattice: FieldLattice
    key: str
    grow: Callable[[PointSets], list[tuple[int, I64, F64]]]
    cells: list[ViewCell] = field(default_factory=list)
    """Street or grid cells sampled from the field (``--sampling field``,
    :mod:`~.fieldsampling`), known before it; empty for sections (grown from it)."""


@dataclass
class ImpostorCells:
    """The impostor images of a city's PVS cells: ``settings`` (D, A, S, N, codec), the
    buildings' stored ``boxes`` and LOD2 triangles ``tris2`` by object id; ``key``
    names the scene (a worker keeps its renderer while it stays)."""

    scene: SourceScene
    settings: ImpostorSettings
    boxes: dict[int, tuple[float, float, float, float, float, float]]
    tris2: dict[int, int]
    key: str


@dataclass
class RingCells:
    """The rings of textured virtual walls around a city's cells (``--virtual-walls`` on
    a city, :mod:`~.ringwalls`): ``settings``, every object's stored ``boxes`` by id,
    the bake's ``view_distance``; ``key`` names the scene (a worker keeps its renderer
    while it stays)."""

    scene: SourceScene
    settings: WallSettings
    boxes: dict[int, tuple[float, float, float, float, float, float]]
    view_distance: float
    key: str


@dataclass
class BakePlan:
    """A scene to bake (see the module docstring).

    Attributes
    ----------
    name, crs, origin, grammar_text, grammar_version, features, settings:
        The database header (:meth:`~walkstream.server.store.SceneWriter.create`);
        ``settings`` identifies the input, so a work file with equal ones resumes.
    pvs, rooms, field:
        The scene's cells by kind (any may be None).
    impostors:
        The impostor images of the PVS cells (None: a bake without ``--impostors``).
    rings:
        The rings of virtual walls around the city's cells whose PVS is large (None: a
        bake without ``--virtual-walls``).
    write_tables:
        Writes everything but the PVS and the contents: objects, cells, viewpoints,
        rooms, portals, stairs, entrances (on resume again: the writer's upserts keep
        every stored PVS).
    walks:
        The default walks, in the order they are stored, made after the cells.
    summary:
        What the bake adds to the database's summary.
    """

    name: str
    crs: str
    origin: tuple[float, float]
    grammar_text: str
    grammar_version: str
    features: list[str]
    settings: dict[str, Any]
    pvs: PvsCells | None
    rooms: RoomCells | None
    write_tables: Callable[[SceneWriter], None]
    walks: Callable[[Say], list[Walk]]
    summary: dict[str, Any] = field(default_factory=dict)
    field: FieldCells | None = None
    impostors: ImpostorCells | None = None
    rings: RingCells | None = None


def settings_key(settings: dict[str, Any]) -> str:
    """A short name of a bake's settings (:attr:`PvsCells.key`)."""
    return hashlib.sha256(repr(sorted(settings.items())).encode()).hexdigest()[:16]
