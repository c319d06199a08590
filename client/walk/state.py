"""The frame loop's state: what lasts the whole walk (:class:`WalkState`) and what one frame found (:class:`Frame`).

Each step of :mod:`.loop` reads the walk's state and the frame so far and adds its
own findings to the frame; nothing else passes between the steps.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Hashable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from walkstream.client.clock import Clock
from walkstream.client.config import ReplayConfig
from walkstream.client.draw.allocate import Allocation
from walkstream.client.draw.budget import BudgetController
from walkstream.client.report.framelog import FrameLogBuilder
from walkstream.client.stream.predict import MotionPredictor
from walkstream.client.truth.recorder import TruthRecorder
from walkstream.client.walk.figures import WalkFrames
from walkstream.client.walk.objects import PvsObjects
from walkstream.client.walk.scene import WalkScene
from walkstream.shared.codec.cellmesh import CellMesh
from walkstream.shared.paths import RecordedPath
from walkstream.shared.records import Mesh

__all__ = ["WalkState", "Frame"]


@dataclass
class WalkState:
    """What the frame loop keeps from frame to frame."""

    config: ReplayConfig
    clock: Clock
    path: RecordedPath
    """The path walked: its head while :attr:`path_pending`, then the whole path."""
    scene: WalkScene
    device: Any
    """The simulated device (a cost model) or the ``gl`` one."""
    renderer: Any
    """The GL renderer, or None (a simulated device without snapshots)."""
    proj: NDArray[np.float64]
    t_start: float
    bytes_down: Callable[[], int]
    frames: WalkFrames
    recorder: TruthRecorder | None = None
    """The ground-truth recorder (``truth_every``), of every scene kind."""
    controller: BudgetController | None = None
    predictor: MotionPredictor = field(default_factory=MotionPredictor)
    objects: PvsObjects = field(default_factory=PvsObjects)
    builder: FrameLogBuilder = field(default_factory=FrameLogBuilder)
    snapshots: list[Path] = field(default_factory=list)
    spikes: list[bool] = field(default_factory=list)
    boxes: dict[int, tuple[NDArray[np.float64], NDArray[np.float64]]] = field(default_factory=dict)
    """Per loaded room cell, its parts' boxes."""
    part_triangles: dict[int, NDArray[np.int64]] = field(default_factory=dict)
    """Per loaded room cell, its parts' triangles (kept with :attr:`boxes`)."""
    meshes: dict[tuple[int, int], Mesh] = field(default_factory=dict)
    """Room parts made into meshes for the renderer, by ``(cell, part)``."""
    boxed: dict[int, CellMesh] = field(default_factory=dict)
    """Per loaded room cell, the contents :attr:`boxes` and :attr:`meshes` were made from
    (a cell's head is replaced by the whole cell: both are made again)."""
    frame: int = 0
    path_pending: bool = False
    """:attr:`path` is the path's head; the whole path replaces it when it arrives."""
    indoors: bool = False
    """The portal model holds the eye (the last room kept on a threshold)."""
    stepped: bool = False
    """The cost step (``cost_step_at_s``) was applied."""
    planned: float = -math.inf
    """Clock time of the last look ahead through an entrance."""
    seen: list[int] = field(default_factory=list)
    """The rooms the last look ahead through an entrance saw."""
    from_entrance: list[int] | None = None
    """The rooms seen from the entrance's street cell (once)."""
    door: NDArray[np.float64] | None = None
    """The entrance door's centre."""
    indoor_fog: float = 0.0
    """The rooms' default fog (the lever starts from it each frame)."""
    impostors_shown: dict[int, Any] = field(default_factory=dict)
    """The impostors the last frame drew, by building
    (:class:`~walkstream.client.walk.impostors.DrawnImpostor`): the fade starts from them."""
    impostors_old: dict[int, tuple[Any, float]] = field(default_factory=dict)
    blend_lods: dict[int, int] = field(default_factory=dict)
    """The geometry's LOD of each building whose image was blending over it the last
    frame (:func:`~walkstream.client.walk.impostors.hold_blend_lods` keeps it)."""
    lod_since: dict[int, tuple[int, float]] = field(default_factory=dict)
    """Per object drawn, its last LOD and the walk time it fell to it (``-inf`` where
    it rose to it or was first drawn at it; :mod:`~walkstream.client.walk.lodhold`)."""
    lod_budgets: deque[tuple[float, int]] = field(default_factory=deque)
    """Of the last frames, ``(walk time, value)``, ascending in both: the value the
    objects' share is below the frame's budget (:func:`~walkstream.client.walk.lodhold.held_budget`)."""
    impostor_rows: dict[int, tuple[Any, Any]] = field(default_factory=dict)
    """Per building the last frame drew as an image, its row and the record that listed it
    (:class:`~walkstream.shared.impostorwire.ImpostorRow`,
    :class:`~walkstream.shared.impostorwire.CellImpostors`): its blend by distance runs on
    where the next cell does not list it (:func:`~walkstream.client.walk.impostors.frame_impostors`)."""
    """Per building crossing into another image: the image it showed before and that
    image's share, falling from 1 to 0 over the fade."""
    facades: Any = None
    """Facade textures held and being baked (:class:`~walkstream.client.walk.facades.FacadeState`;
    None: boxes drawn plain)."""
    impostors_wt: float = -math.inf
    """Walk time of the last frame that chose impostors (-inf: none yet)."""

    @property
    def size(self) -> tuple[int, int]:
        """The frame's size in pixels."""
        return self.config.size


@dataclass
class Frame:
    """What one frame's steps found, in step order."""

    t: float
    """Clock time of the frame's start."""
    wt: float
    """Walk time."""
    eye: NDArray[np.float64]
    view: NDArray[np.float64]
    vp: NDArray[np.float64]
    # -- locate
    street: int | None = None
    """The street cell the city streamer located (None: none, or no street cells)."""
    room: int | None = None
    """The room cell the rooms' locator keeps (None: none, or no room cells)."""
    held: bool = False
    """The room's planes hold the eye."""
    # -- wants
    ahead: list[int] = field(default_factory=list)
    """Rooms to fetch before the entrance's door."""
    # -- visible
    rooms_seen: list[int] = field(default_factory=list)
    """What the rooms' streamer returned: visible cells (foreign ones too) and the shown."""
    room_cells: list[int] = field(default_factory=list)
    """Visible room cells (their contents drawn or waited for)."""
    default_room_cells: list[int] = field(default_factory=list)
    """Visible room cells at the default fog (the frame's quality counts them)."""
    shown: list[int] = field(default_factory=list)
    """Room cells drawn besides the portal walk's (an entrance's shell from the street)."""
    pvs_cells: list[int] = field(default_factory=list)
    """Street cells whose PVS is visible."""
    fog: float = math.inf
    """The fog in force."""
    t_cull: float = 0.0
    """``time.thread_time`` at the start of the rooms' culling (its CPU, not the wall clock
    a loaded machine stretches)."""
    # -- allocate
    loaded: dict[int, CellMesh] = field(default_factory=dict)
    masks: dict[int, NDArray[np.bool_]] = field(default_factory=dict)
    heads_clear: set[int] = field(default_factory=set)
    """Loaded cells that are still heads (:mod:`~walkstream.shared.codec.cellhead`) whose
    missing pieces' stand-ins this frame's culling drops at the default fog: a head not
    here is waiting for its cell."""
    budget: int = 0
    alloc: Allocation | None = None
    """The objects' LODs (None: no street cells, nothing to allocate)."""
    triangles: int = 0
    drawn: int = 0
    """Room parts, objects and impostors drawn."""
    impostors: list[Any] = field(default_factory=list)
    """The impostors drawn (:class:`~walkstream.client.walk.impostors.DrawnImpostor`)."""
    facades: list[Any] = field(default_factory=list)
    """The boxes drawn with facade textures (:class:`~walkstream.client.draw.facades.FacadeSet`)."""
    facade_quads: list[Any] = field(default_factory=list)
    """Their faces turned to the eye as quads (:data:`~walkstream.client.draw.quads.Quad`)."""
    facade_bake: int = 0
    """LOD2 triangles the frame drew baking facade textures (charged to it)."""
    walls: list[Any] = field(default_factory=list)
    """The virtual walls drawn as textures (:class:`~walkstream.client.walk.walls.DrawnWall`)."""
    wall_wants: list[tuple[int, int, float]] = field(default_factory=list)
    """Wall textures not held that the eye sees now or ahead: ``(texture id, the
    viewer's side cell, need s)``; those near the walk are asked for
    (:func:`~walkstream.client.walk.walls.want_wall_textures`)."""
    wall_due: int = 0
    """Outdoors: the ring walls in view whose texture the frame needs (the perfect frame
    needs them as it needs the PVS: the far field left the geometry for them)."""
    wall_missing: int = 0
    """Of :attr:`wall_due`, those whose texture is not held yet."""
    ring_far: bool = False
    """Outdoors: a ring wall in view has no texture yet and the cell's record lists what
    its ring carries: the frame draws that far field as geometry (it joins the frame's
    PVS, so the perfect frame needs it built), never a hole."""
    far_walls: tuple[tuple[float, float, float, float], ...] = ()
    """Those walls' ends ``(x0, y0, x1, y1)`` (the hidden space to the left of ``p0 ->
    p1``): the far field's objects behind one of them are drawn."""
    far_all: bool = False
    """Outdoors: the current cell's ring has not arrived yet
    (:class:`~walkstream.client.stream.ringsides.RingSides`): its whole far field is
    drawn as geometry."""
    # -- draw
    snap: bool = False
    keys: list[Hashable] = field(default_factory=list)
    frame_time: float = 0.0
    # -- measure
    perfect: bool = False
    """Everything the frame's model makes visible was in and built (the frame log's perfect frame)."""

    @property
    def lods(self) -> NDArray[np.integer[Any]]:
        """The objects' LODs (-1: not drawn)."""
        return np.zeros(0, np.int8) if self.alloc is None else self.alloc.lod
