"""Part of the frame step ``visible``: textured virtual walls, which are closed and which texture each shows.

On an interior baked with ``--virtual-walls`` the walk holds every wall side
(:class:`~walkstream.shared.walls.WallSide`, fetched once at the start).  Each frame,
before the portal walk (:func:`frame_walls`):

- each side facing the viewer gives its zone and texture weight
  (:meth:`~walkstream.shared.walls.WallSide.view`): 1 beyond the blend zone, 0 nearer
  than ``x_T`` (or above or below the eye-height band, or behind the wall), linear
  between;
- its zone's texture is wanted from the image lane (the impostors' lane, kind
  ``walltex``, through the one request scheduler, needed now);
- a side at weight 1 whose texture is held **closes** its portal: the portal walk
  stops there (:attr:`~walkstream.client.stream.rooms.RoomStreamer.closed`) and the
  wall is drawn as one textured quad; a side between 0 and 1 leaves the portal open
  (the next cell drawn as geometry) and its texture is drawn over it at that opacity
  (the blend zone); a side whose texture has not arrived leaves the portal open: the
  cell behind is drawn as geometry (or is past the fog), never a hole;
- the quads kept are those of walls on the sides of the cells the walk reaches, so
  a wall two cells away is drawn only when its cell is (:func:`drawn_walls`);
- with ``--wall-parallax R`` (0.5 by default) each texture slides along its wall by ``R``
  times the viewer's offset from its zone's sampling line
  (:func:`~walkstream.shared.walls.zone_slide`), and shrinks or grows about the
  viewer's foot on the wall as the viewer stands nearer or farther than the sampling
  point (:func:`~walkstream.shared.walls.zone_warp`): what stands behind the wall moves
  on the screen as parallax moves it, not as the wall does, two zones' textures agree
  at their border, where they blend, and a viewer near a wall sampled from far does not
  see what is behind it magnified.

With ``config.virtual_walls`` off, or a scene without walls, nothing is closed and
the frame is what it was.

**Outdoors** (a city baked with ``--virtual-walls``: a ring of walls around each
street cell whose PVS was large, :mod:`walkstream.server.bake.ringwalls`; the rings
fetched as the walk comes to their cells, :class:`~walkstream.client.stream.ringsides.RingSides`,
merged by :func:`add_ring_sides`, a ringed cell whose ring is not in yet drawing its
whole far field), each frame (:func:`ring_walls`) draws the walls of the current cell's ring, each with its zone's
texture (blended with the next zone's near a border, as indoors); their textures are
wanted now for the walls in view (sooner than those behind the viewer), ahead for the
zones the eye moves into, and for the rings the walker enters next from where it
enters them (:mod:`~walkstream.client.walk.ringahead`).  The far field is no longer in the cell's geometry PVS, but the
cell's record lists it apart (:attr:`~walkstream.shared.wire.CellRecord.far`, streamed
with the PVS: a city's objects are a few parameters each): while a ring wall in view
has no texture yet, the frame draws that far field as geometry
(:attr:`~walkstream.client.walk.state.Frame.ring_far`), never a hole, and the perfect
frame needs it built as it needs the PVS.  Only a scene baked before the far field was
stored shows the sky there, and then the missing texture is missing content
(:attr:`~walkstream.client.walk.state.Frame.wall_missing`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from walkstream.client.draw.quads import Quad, cross_fade, with_mesh
from walkstream.client.walk.ringahead import ring_textures_ahead, ring_zones_ahead
from walkstream.client.walk.scene import WalkScene
from walkstream.client.walk.state import Frame, WalkState
from walkstream.shared.frustum import frustum_cull
from walkstream.shared.walldepth import depth_mesh, mesh_triangles
from walkstream.shared.walls import (
    NO_WARP,
    WallSide,
    WallTable,
    WallWarp,
    ring_cell,
    zone_mix,
    zone_warp,
)

__all__ = [
    "RING_BEHIND_NEED_S", "WALL_AHEAD_S", "WALL_MIX_NEED_S", "DrawnWall", "drawn_walls", "frame_walls", "ring_walls",
    "add_ring_sides", "wall_mesh", "wall_quads", "want_wall_textures",
]


@dataclass(frozen=True)
class DrawnWall:
    """One wall side a frame draws: its portal, side, zone, texture, opacity and quad
    (``(4, 3)`` bottom-left, bottom-right, top-right, top-left as the viewer faces it),
    and the texture's bytes.  ``image`` is the texture id (the quads' common key)."""

    portal: int
    side: int
    zone: int
    image: int
    alpha: float
    corners: NDArray[np.float64]
    nbytes: int
    cells: tuple[int, int]
    """``(the viewer's side cell, the hidden cell)``."""
    mix_image: int = -1
    """The texture of the neighbour zone blended in near a zone border (-1: none;
    :func:`~walkstream.shared.walls.zone_mix`)."""
    mix: float = 0.0
    """Its share (0 to 0.5): the wall shows ``(1 - mix)`` of its own zone's texture
    and ``mix`` of the neighbour's, at :attr:`alpha`."""
    warps: tuple[WallWarp, WallWarp] = (NO_WARP, NO_WARP)
    """How its own texture and the neighbour's are laid on the wall: slid with the viewer's
    offset from each zone's sampling line and scaled with its distance against the
    sampling point's (:func:`~walkstream.shared.walls.zone_warp`, ``--wall-parallax``)."""
    side_of: WallSide | None = None
    """The side drawn: a texture with a depth grid (``--wall-depth``) is drawn as its
    depth mesh (:func:`wall_mesh`) over the warped quad."""
    triangles: int = 2
    """Triangles the wall draws: its quad's two, and its textures' depth meshes'."""


WALL_AHEAD_S = (0.5, 1.0, 1.5, 2.0, 3.0, 4.5, 6.0)
"""Horizons (seconds) at which the eye moved on at its velocity wants its walls'
textures too, each at that need: the next zone's texture is in before the viewer
walks into it (a zone is about a metre wide at A = 10 degrees on an 8 m grid)."""


WALL_MIX_NEED_S = 0.5
"""The need (seconds) a neighbour zone's texture is asked for at when the viewer nears
its border and it is not held: after the textures needed now (without it the wall
swaps its texture at the border, it is never open)."""


RING_BEHIND_NEED_S = 0.5
"""The need (seconds) of a ring wall's texture out of view (the viewer turns to it):
after those in view."""


def _warps(table: WallTable, k: int, eye: NDArray[np.float64], foot: float, distance: float, zone: int,
           mix_zone: int, share: float) -> tuple[WallWarp, WallWarp]:
    """How side ``k``'s own zone's texture and the neighbour's blended in are laid on it
    for a viewer at ``eye`` (module docs)."""
    if share <= 0.0:
        return (NO_WARP, NO_WARP)
    got = zone_warp(foot, float(eye[2]), distance, np.array([zone, max(mix_zone, 0)]), table.width[k],
                    table.depth[k], table.eye_z[k], share)
    own = (float(got[0, 0]), float(got[0, 1]), float(got[0, 2]))
    other = (float(got[1, 0]), float(got[1, 1]), float(got[1, 2])) if mix_zone >= 0 else NO_WARP
    return (own, other)


def wall_mesh(image: Any, side: WallSide, tid: int) -> NDArray[np.float32] | None:
    """The depth mesh of texture ``tid`` of ``side`` (its decoded ``image`` carrying a depth
    grid, ``--wall-depth``: :class:`~walkstream.shared.walldepth.WallImage`), built once
    and kept on the image; None for a texture without one."""
    inv = getattr(image, "depth", None)
    if inv is None or tid not in side.textures:
        return None
    mesh: NDArray[np.float32] | None = getattr(image, "mesh", None)
    if mesh is None:
        mesh = depth_mesh(side, side.textures.index(tid), inv)
        image.mesh = mesh
    return mesh


def _triangles(lane: Any, side: WallSide, tid: int, mix_tid: int) -> int:
    """Triangles a wall draws (:attr:`DrawnWall.triangles`): the quad's two and the depth
    meshes of its texture and the neighbour's blended in."""
    out = 2 + mesh_triangles(wall_mesh(lane.image(tid), side, tid))
    if mix_tid >= 0:
        out += mesh_triangles(wall_mesh(lane.image(mix_tid), side, mix_tid))
    return out


def _meshed(lane: Any, side: WallSide, tid: int, mix_tid: int, seen: bool) -> tuple[WallSide | None, int]:
    """:attr:`DrawnWall.side_of` and :attr:`DrawnWall.triangles` of a wall: a wall out
    of the view draws its quad alone (off the screen either way; its depth meshes'
    triangles would take the frame's budget for nothing)."""
    return (side, _triangles(lane, side, tid, mix_tid)) if seen else (None, 2)


def add_ring_sides(scene: WalkScene, sides: Sequence[WallSide]) -> None:
    """Add ring walls that arrived (:class:`~walkstream.client.stream.ringsides.RingSides`)
    to ``scene``: its :attr:`~.scene.WalkScene.walls` (each side once), each ringed
    cell's indices, the portals' cells, the table and the quads' boxes."""
    have = {(s.portal, s.side) for s in scene.walls}
    new = tuple(s for s in sides if (s.portal, s.side) not in have)
    if not new:
        return
    scene.walls = (*scene.walls, *new)
    rings: dict[int, list[int]] = {}
    for k, s in enumerate(scene.walls):
        rings.setdefault(ring_cell(s.portal), []).append(k)
    scene.wall_rings = {c: tuple(v) for c, v in rings.items()}
    scene.wall_cells = {s.portal: (ring_cell(s.portal), -1) for s in scene.walls}
    scene.wall_table = WallTable(scene.walls)
    corners = np.array([s.corners() for s in scene.walls], np.float64).reshape(-1, 4, 3)
    scene.wall_boxes = np.stack([corners.min(axis=1), corners.max(axis=1)], axis=1)


def ring_walls(w: WalkState, f: Frame) -> list[DrawnWall]:
    """Outdoors: the walls of the current street cell's ring drawn with their textures
    (see the module docstring); sets the frame's ``wall_due`` and ``wall_missing`` and
    wants the textures now and ahead from the lane."""
    lane, city = w.scene.wall_images, w.scene.streets
    f.wall_due = f.wall_missing = 0
    f.ring_far = f.far_all = False
    f.far_walls = ()
    if lane is None or city is None or not w.config.virtual_walls:
        return []
    street = -1 if f.street is None else int(f.street)
    loader = w.scene.ring_sides
    if loader is not None:  # the rings of the cells the walk comes to: this one's first
        route = city.need_records
        loader.want([street, *sorted(route, key=route.__getitem__)])
        rec = city.cells.get(street)
        if street >= 0 and not loader.held(street) and rec is not None and rec.far is not None:
            f.ring_far = f.far_all = True  # its ring not in yet: the whole far field, never a hole
    table = w.scene.wall_table
    if table is None or not w.scene.wall_rings:
        return []
    sides = w.scene.walls
    ring = list(w.scene.wall_rings.get(street, ()))
    eye = np.asarray(f.eye, np.float64).reshape(3)
    velocity = np.zeros(2)
    if w.config.prefetch:
        velocity = np.asarray(city.velocity, np.float64).reshape(2)
    moving = float(np.linalg.norm(velocity)) > 1e-3
    horizons = WALL_AHEAD_S if moving else ()
    eyes = np.array([eye, *[eye + np.array([*(velocity * t), 0.0]) for t in horizons]])
    zones, dist, weights = table.views(eyes)
    wants: dict[int, float] = {}

    def want(tid: int, need: float) -> None:
        if not lane.held(tid) and need < wants.get(tid, np.inf):
            wants[tid] = need

    boxes = w.scene.wall_boxes

    def in_view(walls: list[int], moved: NDArray[np.float64]) -> NDArray[np.bool_]:
        """Which of ``walls`` the view shows from the eye moved by ``moved`` ``(3,)``
        (looking the same way): the textures ahead are those of walls the walker will
        see, not of the wall behind it (half the textures asked for were never drawn)."""
        if boxes is None or not walls:
            return np.ones(len(walls), bool)
        shift = np.eye(4)
        shift[:3, 3] = -np.asarray(moved, np.float64)[:3]
        return frustum_cull(boxes[walls, 0], boxes[walls, 1], np.asarray(f.vp, np.float64) @ shift)

    out: list[DrawnWall] = []
    rec = city.cells.get(street)
    has_far = rec is not None and rec.far is not None
    if ring:
        seen = in_view(ring, np.zeros(3))
        foot = table.along_of(eye)[0]
        mix_zone, mix_share = zone_mix(foot, table.width, table.zones, w.config.wall_zone_blend)
        for j, k in enumerate(ring):
            if weights[0, k] <= 0.0:
                continue
            s = sides[k]
            zone = int(zones[0, k])
            tid = s.textures[zone]
            if not lane.held(tid):
                if has_far:  # the far field behind it drawn as geometry instead: never a hole
                    if seen[j]:
                        f.ring_far = True
                        f.far_walls += ((*s.p0, *s.p1),)
                else:
                    f.wall_due += int(seen[j])
                    f.wall_missing += int(seen[j])
                want(tid, 0.0 if seen[j] else RING_BEHIND_NEED_S)
                continue
            f.wall_due += int(seen[j])
            mix_tid, mix = -1, 0.0
            if mix_zone[k] >= 0:  # near a zone border: the neighbour's texture blended in
                nb = s.textures[int(mix_zone[k])]
                if lane.held(nb):
                    mix_tid, mix = nb, float(mix_share[k])
                else:
                    want(nb, WALL_MIX_NEED_S)
            img = lane.image(tid)
            out.append(DrawnWall(s.portal, s.side, zone, tid, float(weights[0, k]), s.corners(),
                                 int(getattr(img, "nbytes", 0)), (street, -1), mix_tid, mix,
                                 _warps(table, k, eye, float(foot[k]), float(dist[0, k]), zone, int(mix_zone[k]),
                                        w.config.wall_parallax), *_meshed(lane, s, tid, mix_tid, bool(seen[j]))))
        # the zones the eye walks into along its ring (the walker may turn: ring_zones_ahead)
        ring_zones_ahead(table, sides, ring, eye, eyes[1:], horizons, in_view, want)
    if w.config.prefetch:  # the rings the walker enters next, where it enters them
        ring_textures_ahead(table, sides, w.scene.wall_rings, f.street, eye, velocity, city.need_records,
                            city.cellmap.outlines, WALL_AHEAD_S, in_view, want)
    lane.want(wants)
    return out


def frame_walls(w: WalkState, f: Frame) -> list[DrawnWall]:
    """The wall sides facing the viewer with a texture to show (held), and which portals
    close; sets ``rooms.closed`` (the walls held: the walk drawn), ``rooms.due_closed``
    (every wall at weight 1: the walk as baked, whose cells are needed now) and the
    frame's :attr:`~walkstream.client.walk.state.Frame.wall_wants`: the missing textures
    now and those the eye will see ahead (:data:`WALL_AHEAD_S`) at their need times
    (asked for by :func:`want_wall_textures` once the walk is known)."""
    rooms, lane = w.scene.rooms, w.scene.wall_images
    sides, table = w.scene.walls, w.scene.wall_table
    f.wall_wants = []
    if rooms is None:
        return []
    if lane is None or not sides or table is None or not w.config.virtual_walls:
        rooms.closed = frozenset()
        rooms.due_closed = frozenset()
        return []
    eye = np.asarray(f.eye, np.float64).reshape(3)
    view = np.asarray(f.view, np.float64)
    moving = w.config.prefetch and (
        float(np.linalg.norm(rooms.velocity()[:2])) > 1e-3 or rooms.turning())
    horizons = WALL_AHEAD_S if moving else ()
    # the eye and view ahead: moved on at its velocity, and turned on while it turns (a
    # walker turning at a corner sees walls no frame has shown yet; their textures go
    # out before the turn shows them)
    ahead = [rooms.view_ahead(eye, view, t) for t in horizons]
    eyes = np.array([eye, *[e for e, _ in ahead]])
    zones, dist, weights = table.views(eyes)
    wanted: list[tuple[int, int, float]] = []
    out: list[DrawnWall] = []
    closed: set[int] = set()
    due: set[int] = set()
    portals = w.scene.wall_cells
    # only the walls in view ask for their textures (now and ahead, looking the same
    # way); one behind the viewer is asked for when the viewer turns to it
    boxes = w.scene.wall_boxes

    def in_view(vp: NDArray[np.float64]) -> NDArray[np.bool_]:
        return frustum_cull(boxes[:, 0], boxes[:, 1], vp) if boxes is not None else np.ones(len(sides), bool)

    seen = in_view(f.vp)
    to_eye = np.asarray(f.vp, np.float64) @ np.linalg.inv(view)  # the projection
    band = w.config.wall_zone_blend
    foot = table.along_of(eye)[0]
    mix_zone, mix_share = zone_mix(foot, table.width, table.zones, band)
    for k in np.flatnonzero(weights[0] > 0.0).tolist():
        s = sides[k]
        zone = int(zones[0, k])
        tid = s.textures[zone]
        a, b = portals[s.portal]
        cells = (a, b) if s.side == 0 else (b, a)
        held = lane.held(tid)
        if weights[0, k] >= 1.0:
            due.add(s.portal)
        if not held:
            if seen[k]:
                wanted.append((tid, cells[0], 0.0))
            continue  # not here yet: the portal stays open (geometry), never a hole
        img = lane.image(tid)
        mix_tid, mix = -1, 0.0
        if mix_zone[k] >= 0:  # near a zone border: the neighbour's texture blended in
            nb = s.textures[int(mix_zone[k])]
            if lane.held(nb):
                mix_tid, mix = nb, float(mix_share[k])
            elif seen[k]:
                wanted.append((nb, cells[0], WALL_MIX_NEED_S))
        out.append(DrawnWall(s.portal, s.side, zone, tid, float(weights[0, k]), s.corners(),
                             int(getattr(img, "nbytes", 0)), cells, mix_tid, mix,
                             _warps(table, k, eye, float(foot[k]), float(dist[0, k]), zone, int(mix_zone[k]),
                                    w.config.wall_parallax), *_meshed(lane, s, tid, mix_tid, bool(seen[k]))))
        if weights[0, k] >= 1.0:
            closed.add(s.portal)
    for h, t in enumerate(horizons, start=1):
        seen_h = seen | in_view(to_eye @ ahead[h - 1][1])
        for k in np.flatnonzero((weights[h] > 0.0) & seen_h).tolist():
            s = sides[k]
            tid = s.textures[int(zones[h, k])]
            if not lane.held(tid):
                a, b = portals[s.portal]
                wanted.append((tid, a if s.side == 0 else b, float(t)))
    f.wall_wants = wanted
    rooms.closed = frozenset(closed)
    rooms.due_closed = frozenset(due)
    return out


def want_wall_textures(w: WalkState, f: Frame, cells: Sequence[int]) -> None:
    """Want the textures of the frame's walls (:func:`frame_walls`) on the sides of
    ``cells`` (the walk as baked: those its walk reaches), and those ahead on the sides
    of those cells and of the cells one portal beyond them (the cell the viewer walks
    into next): every wall in the hall faces the viewer from somewhere, and asking for
    all of them filled the link with textures of walls no frame draws."""
    lane, rooms = w.scene.wall_images, w.scene.rooms
    if lane is None or rooms is None:
        return
    now = set(cells)
    near = now | {n for c in now if c in rooms.cells for n in rooms.cells[c].neighbours}
    wanted: dict[int, float] = {}
    for tid, cell, need in f.wall_wants:
        if cell in (now if need <= 0.0 else near) and need < wanted.get(tid, np.inf):
            wanted[tid] = need
    lane.want(wanted)


def drawn_walls(walls: list[DrawnWall], visible: list[int]) -> list[DrawnWall]:
    """The walls on the viewer's side of a visible cell (those the walk reaches)."""
    seen = set(visible)
    return [d for d in walls if d.cells[0] in seen]


def wall_quads(walls: Sequence[DrawnWall], image: Callable[[int], Any]) -> list[Quad]:
    """The quads of a frame's walls (``image(id)`` the decoded RGBA of a texture), each
    keyed by its texture id turned negative: impostor images and wall textures share
    the quad renderer's textures without colliding.  A texture with a depth grid
    (``--wall-depth``) is its depth mesh over its warped quad, one item
    (:func:`~walkstream.client.draw.quads.with_mesh`).

    A wall with a neighbour zone blended in (:attr:`DrawnWall.mix` ``m`` at opacity
    ``a``) is two quads, its own texture at ``a (1 - m) / (1 - a m)`` and then the
    neighbour's over it at ``a m``: drawn "over" (premultiplied) that is exactly
    ``a ((1 - m) own + m neighbour) + (1 - a) behind``, for opaque textures."""
    out: list[Quad] = []
    for d in walls:
        rgba = image(d.image)
        if rgba is None:
            continue
        other = image(d.mix_image) if d.mix_image >= 0 and d.mix > 0.0 else None
        quads = cross_fade(d.corners, -1 - d.image, rgba, -1 - d.mix_image, other, d.alpha, d.mix, d.warps)
        if d.side_of is not None:  # a texture with a depth grid: its mesh over its warped quad
            for n, q in enumerate(quads):
                mesh = wall_mesh(q[2], d.side_of, d.image if n == 0 else d.mix_image)
                if mesh is not None:
                    quads[n] = (with_mesh(q[0], mesh), q[1], q[2], q[3])
        out += quads
    return out
