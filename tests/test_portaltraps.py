"""Portal culling on the traps of real buildings: each a small IFC model written here.

Every model is baked as a user's file would be; the bake's cells, portals and stairs
are checked, and so is the culling against the id truth of the whole building
(:class:`portalscene.PortalScene`): at every door, opening and stair
(:func:`portalscene.walk_every_door`), on a grid of eyes in every room cell looking
eight ways (level, up and down), and at the poses the trap is about.  Nothing the
truth shows may be culled: a miss along a ray that leaves the cells other than
through a portal (a ``leak``) counts too.

The traps: a door in a wall that two spaces share unevenly, a space whose boundary
does not reach the floor or the ceiling, an element that lies in no space, a stair
that joins three storeys, a void (atrium) through two storeys, the eye exactly on a
stair's landing, and spaces that overlap.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from ifcmodels import IfcBuilder
from portalscene import EYE, PortalScene, walk_every_door

from walkstream.server.bake import bake
from walkstream.server.store import SceneReader

pytestmark = pytest.mark.gl
pytest.importorskip("ifcopenshell", reason="the ifc extra (make test installs it)")

Pose = tuple[np.ndarray, float, float]
T = 0.2  # wall thickness
H = 2.8  # room height


def _box(x0: float, y0: float, x1: float, y1: float) -> list[tuple[float, float]]:
    return [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]


def _shell(b: IfcBuilder, s: Any, x1: float, y1: float, z0: float, h: float = H) -> list[Any]:
    """Four outer walls around ``(0, 0)-(x1, y1)`` (centred on the outline's edge)."""
    o = _box(-T / 2, -T / 2, x1 + T / 2, y1 + T / 2)
    return [b.wall(s, o[i], o[(i + 1) % 4], T, z0, h) for i in range(4)]


def _baked(tmp_path: Path, model: IfcBuilder) -> tuple[Path, np.ndarray]:
    """The model baked, and its scene's origin (the file's coordinates of local 0, 0)."""
    src = model.write(tmp_path / "trap.ifc")
    bake(src, tmp_path / "trap.db")
    with SceneReader.open(tmp_path / "trap.db") as r:
        origin = np.array([*r.meta.origin, 0.0])
    return tmp_path / "trap.db", origin


def _grid(scene: PortalScene, step: float = 1.5, margin: float = 0.35) -> Iterator[Pose]:
    """Eyes 1.6 m up on a grid over every room cell (its outline shrunk by ``margin``),
    looking eight ways, level and 0.7 rad up or down in turn."""
    yaws = [k * math.pi / 4 for k in range(8)]
    n = 0
    for c in scene.topology.cells:
        if c.kind != "room" or not len(c.planes):
            continue
        lo, hi = c.outline.min(axis=0) + margin, c.outline.max(axis=0) - margin
        xs = np.arange(lo[0], hi[0] + 1e-9, step) if hi[0] > lo[0] else np.array([0.5 * (lo[0] + hi[0])])
        ys = np.arange(lo[1], hi[1] + 1e-9, step) if hi[1] > lo[1] else np.array([0.5 * (lo[1] + hi[1])])
        for x in xs.tolist():
            for y in ys.tolist():
                for yaw in yaws:
                    n += 1
                    yield np.array([x, y, c.zmin + EYE]), yaw, (0.0, 0.7, -0.7)[n % 3]


def _misses(scene: PortalScene, poses: Iterable[Pose]) -> tuple[int, list[tuple[list[float], float, float, int]]]:
    """Frames compared, and every frame with a culled pixel the truth shows (pinholes apart)."""
    frames, bad = 0, []
    for eye, yaw, pitch in poses:
        got = scene.frame(np.asarray(eye, float), yaw, pitch)
        if got is None:
            continue
        frames += 1
        chk = got[0]
        real = chk.missed_pixels - chk.pinholes
        if real > 0:
            bad.append(([float(v) for v in eye], yaw, pitch, real))
    return frames, bad


def _conservative(baked: tuple[Path, np.ndarray], gl_ctx: Any, extra: Iterable[Pose] = (),
                  step: float = 1.5) -> PortalScene:
    """Culling at every door, on the grid and at ``extra`` (eyes in the file's
    coordinates) culls nothing the truth shows; returns the scene (released by the caller)."""
    db, origin = baked
    extra = [(np.asarray(e, float) - origin, yaw, pitch) for e, yaw, pitch in extra]
    _ = gl_ctx.error  # an error an earlier test left pending is not this scene's
    scene = PortalScene(db, gl_ctx)
    try:
        doors = walk_every_door(scene)
        assert doors["missed"] == 0 and doors["leaks"] == 0, doors
        frames, bad = _misses(scene, [*_grid(scene, step), *extra])
        # one lone pixel where two cells' pieces of one wall meet (a depth tie at their
        # seam that the pinhole rule does not name) is allowed on 1 % of frames
        ties = [b for b in bad if b[3] == 1]
        assert frames >= 20 and len(bad) == len(ties) <= 0.01 * frames, (frames, bad[:8], len(bad))
    except BaseException:
        scene.release()
        raise
    return scene


def _kinds(scene: PortalScene) -> dict[str, int]:
    out: dict[str, int] = {}
    for _pid, kind, *_ in scene.topology.portals:
        out[kind] = out.get(kind, 0) + 1
    return out


# --------------------------------------------------------------------------- the traps


def test_a_door_in_a_wall_two_spaces_share_unevenly(tmp_path: Path, gl_ctx: Any) -> None:
    """One room on the west side of a wall, two on the east; the south-east space stops
    30 cm short of the wall (as exporters draw spaces to a lining), the north-east one
    reaches it; a door from the west room into each."""
    b = IfcBuilder()
    s = b.storey("ground", 0.0)
    b.space("West", s, _box(0, 0, 4, 6), 0.0, H)
    b.space("North-east", s, _box(4.2, 3.1, 8, 6), 0.0, H)
    b.space("South-east", s, _box(4.5, 0, 8, 2.9), 0.0, H)
    _shell(b, s, 8, 6, 0.0)
    mid = b.wall(s, (4.1, 0), (4.1, 6), T, 0.0, H)
    b.wall(s, (4.2, 3.0), (8, 3.0), T, 0.0, H)
    b.opening(s, mid, (4.1, 1.5), (0, 1), 0.9, T + 0.02, 0.0, 2.1, "door")
    b.opening(s, mid, (4.1, 4.5), (0, 1), 0.9, T + 0.02, 0.0, 2.1, "door")
    b.slab(s, _box(-T / 2, -T / 2, 8 + T / 2, 6 + T / 2), 0.0)
    b.slab(s, _box(-T / 2, -T / 2, 8 + T / 2, 6 + T / 2), H + 0.2)
    b.furniture(s, _box(6.5, 0.5, 7.5, 1.5), 0.0, 1.0, "cupboard")
    baked = _baked(tmp_path, b)
    # the eye in the south-east room's gap before the wall, and in the doorway, looking west and east
    extra = [(np.array([x, 1.5, EYE]), yaw, 0.0) for x in (4.3, 4.4, 4.6, 3.8) for yaw in (0.0, math.pi, 2.0, -2.0)]
    scene = _conservative(baked, gl_ctx, extra, step=1.2)
    try:
        rooms = {c.id: c for c in scene.topology.cells if c.kind == "room"}
        assert len(rooms) == 3
        # each door is a doorway cell between the west room and one east room
        assert _kinds(scene).get("door", 0) >= 4, _kinds(scene)
    finally:
        scene.release()


def test_a_space_that_does_not_reach_floor_or_ceiling(tmp_path: Path, gl_ctx: Any) -> None:
    """Two storeys whose spaces float: the ground's from 0.3 to 2.2 m under a ceiling at
    2.8 m, the upper's from 3.6 to 5.0 m above a floor at 3.0 m; the cells still run
    from floor to floor (what lies under or over a space is its room's)."""
    b = IfcBuilder()
    g = b.storey("ground", 0.0)
    u = b.storey("upper", 3.0)
    for s, z0, zs, hs in ((g, 0.0, 0.3, 1.9), (u, 3.0, 3.6, 1.4)):
        b.space("A", s, _box(0, 0, 4, 5), zs, hs)
        b.space("B", s, _box(4.2, 0, 9, 5), zs, hs)
        _shell(b, s, 9, 5, z0)
        mid = b.wall(s, (4.1, 0), (4.1, 5), T, z0, H)
        b.opening(s, mid, (4.1, 2.5), (0, 1), 0.9, T + 0.02, z0, z0 + 2.1, "door")
        b.slab(s, _box(-T / 2, -T / 2, 9 + T / 2, 5 + T / 2), z0)
        b.furniture(s, _box(6, 1, 7, 2), z0, 0.25, "low table")  # under the floating space
        b.furniture(s, _box(6, 3, 7, 4), z0 + 2.5, 0.25, "hanging lamp")  # over it
    b.slab(u, _box(-T / 2, -T / 2, 9 + T / 2, 5 + T / 2), 6.0)
    baked = _baked(tmp_path, b)
    low = [(np.array([2.0, 2.5, z0 + EYE]), 0.0, p) for z0 in (0.0, 3.0) for p in (-0.9, 0.0, 0.9)]
    scene = _conservative(baked, gl_ctx, low)
    try:
        for c in scene.topology.cells:
            if c.kind == "room":
                assert c.zmin in (0.0, 3.0) and c.zmax in (3.0, 6.0), (c.zmin, c.zmax)
    finally:
        scene.release()


def test_an_element_that_lies_in_no_space(tmp_path: Path, gl_ctx: Any) -> None:
    """Two rooms with a hall between them that has no space (a column stands in it), a
    door from each room into the hall, and a cabinet standing in a room's wall niche
    outside its space: the hall is seen through a door and the room beyond it through
    both, and the cabinet from its room."""
    b = IfcBuilder()
    s = b.storey("ground", 0.0)
    b.space("West", s, _box(0, 0, 4, 5), 0.0, H)
    b.space("East", s, _box(6.2, 0, 10, 5), 0.0, H)
    _shell(b, s, 10, 5, 0.0)
    w1 = b.wall(s, (4.1, 0), (4.1, 5), T, 0.0, H)
    w2 = b.wall(s, (6.1, 0), (6.1, 5), T, 0.0, H)
    b.opening(s, w1, (4.1, 2.5), (0, 1), 1.0, T + 0.02, 0.0, 2.1, "door")
    b.opening(s, w2, (6.1, 2.0), (0, 1), 1.0, T + 0.02, 0.0, 2.1, "door")
    b.furniture(s, _box(5.0, 3.5, 5.4, 3.9), 0.0, H, "column")
    b.furniture(s, _box(-0.05, 4.0, 0.4, 4.9), 0.0, 1.8, "cabinet")  # pokes into the outer wall
    b.slab(s, _box(-T / 2, -T / 2, 10 + T / 2, 5 + T / 2), 0.0)
    b.slab(s, _box(-T / 2, -T / 2, 10 + T / 2, 5 + T / 2), H + 0.2)
    baked = _baked(tmp_path, b)
    # from the west room through its door, across the hall, through the east door
    extra = [(np.array([x, y, EYE]), yaw, 0.0) for x in (1.0, 3.0, 3.6) for y in (1.5, 2.5, 3.5)
             for yaw in (0.0, 0.3, -0.3, 0.6)]
    scene = _conservative(baked, gl_ctx, extra)
    scene.release()


def _stair_core(b: IfcBuilder, storeys: list[Any], size: tuple[float, float], holes: dict[int, list[Any]]) -> None:
    """Rooms over the whole plan on every storey, outer walls and slabs with holes."""
    x1, y1 = size
    for k, s in enumerate(storeys):
        z0 = 3.0 * k
        b.space(f"Hall {k}", s, _box(0, 0, x1, y1), z0, H)
        _shell(b, s, x1, y1, z0)
        outer = _box(-T / 2, -T / 2, x1 + T / 2, y1 + T / 2)
        b.slab(s, outer, z0, holes=holes.get(k, []))
        b.furniture(s, _box(x1 - 2, y1 - 1.5, x1 - 1, y1 - 0.5), z0, 1.0, f"desk {k}")
    b.slab(storeys[-1], _box(-T / 2, -T / 2, x1 + T / 2, y1 + T / 2), 3.0 * len(storeys))


def test_a_stair_that_joins_three_storeys(tmp_path: Path, gl_ctx: Any) -> None:
    """One straight ``IfcStair`` from the ground floor to the second (6 m in 32 steps)
    through holes in both floors above: the bake records a walkable stair between each
    pair of storeys it passes, and the walk climbs it all the way."""
    b = IfcBuilder()
    storeys = [b.storey(n, 3.0 * k) for k, n in enumerate(("ground", "first", "second"))]
    _stair_core(b, storeys, (16, 6), {1: [_box(3.0, 1.0, 14.5, 2.2)], 2: [_box(8.5, 1.0, 14.5, 2.2)]})
    b.stair(storeys[0], (1.5, 1.6), (14.3, 1.6), 1.0, 0.0, 6.0, steps=32)
    baked = _baked(tmp_path, b)
    scene = PortalScene(baked[0], gl_ctx)
    try:
        st = scene.topology.stairs
        cells = {c.id: c for c in scene.topology.cells}
        joined = sorted((cells[lo].zmin, cells[up].zmin) for _p, lo, up, _path in st)
        assert joined == [(0.0, 3.0), (3.0, 6.0)], joined
        for _p, lo, up, path in st:
            p = np.asarray(path)
            # each piece rises from its lower storey's floor to its upper one's
            assert p[0, 2] <= cells[lo].zmin + 0.3 and abs(p[-1, 2] - cells[up].zmin) < 0.3, (p[0], p[-1])
    finally:
        scene.release()
    scene = _conservative(baked, gl_ctx, step=2.0)
    scene.release()


def test_a_void_through_two_storeys(tmp_path: Path, gl_ctx: Any) -> None:
    """An atrium: one space on the ground floor rising through three storeys, holes in
    the two floors above it, rooms around it on every storey; seen from its floor
    looking up, and from the rooms above looking down into it."""
    b = IfcBuilder()
    storeys = [b.storey(n, 3.0 * k) for k, n in enumerate(("ground", "first", "second"))]
    x1, y1 = 12.0, 10.0
    atrium = _box(4, 3, 8, 7)
    for k, s in enumerate(storeys):
        z0 = 3.0 * k
        ring = [(0, 0), (x1, 0), (x1, y1), (0, y1)]
        # the storey's room is the plan less the atrium (an outline with a hole is two parts here)
        b.space(f"South {k}", s, _box(0, 0, x1, 3), z0, H)
        b.space(f"North {k}", s, _box(0, 7, x1, y1), z0, H)
        b.space(f"West {k}", s, _box(0, 3, 4, 7), z0, H)
        b.space(f"East {k}", s, _box(8, 3, x1, 7), z0, H)
        _shell(b, s, x1, y1, z0)
        outer = _box(-T / 2, -T / 2, x1 + T / 2, y1 + T / 2)
        b.slab(s, outer, z0, holes=[atrium] if k else [])
        b.furniture(s, _box(1, 1, 2, 2), z0, 1.0, f"desk {k}")
        b.furniture(s, [(5.5, 4.5), (6.5, 4.5), (6.5, 5.5), (5.5, 5.5)], z0, 0.5, f"plant {k}") if k == 0 else None
        del ring
    b.space("Atrium", storeys[0], atrium, 0.0, 8.8)
    b.slab(storeys[-1], _box(-T / 2, -T / 2, x1 + T / 2, y1 + T / 2), 9.0)
    baked = _baked(tmp_path, b)
    up = [(np.array([6.0, 5.0, EYE]), yaw, 1.2) for yaw in (0.0, 1.6, 3.1, -1.6)]
    down = [(np.array([x, y, z + EYE]), yaw, -0.9) for z in (3.0, 6.0)
            for (x, y, yaw) in ((3.5, 5.0, 0.0), (6.0, 2.5, math.pi / 2), (8.5, 5.0, math.pi), (6.0, 7.5, -math.pi / 2))]
    scene = _conservative(baked, gl_ctx, up + down, step=2.0)
    try:
        kinds = _kinds(scene)
        assert kinds.get("void", 0) >= 2, kinds
    finally:
        scene.release()


def test_the_eye_exactly_on_a_stairs_landing(tmp_path: Path, gl_ctx: Any) -> None:
    """A stair of two flights with a half landing at 1.4 m in a well that the ground
    storey's stair space spans: the eye 1.6 m over the landing is exactly at the upper
    floor's height (3.0 m), on the plane that parts the two storeys' cells."""
    b = IfcBuilder()
    g = b.storey("ground", 0.0)
    u = b.storey("upper", 3.0)
    rooms = _box(0, 0, 6, 5)
    well = _box(6.2, 0, 10, 5)
    b.space("Hall", g, rooms, 0.0, H)
    b.space("Landing", u, rooms, 3.0, H)
    b.space("Stair", g, well, 0.0, 5.8)
    for s, z0 in ((g, 0.0), (u, 3.0)):
        _shell(b, s, 10, 5, z0, 3.0)  # up to the next floor: the well has no slab to close the gap
    mid = b.wall(g, (6.1, 0), (6.1, 5), T, 0.0, 5.8)
    b.opening(g, mid, (6.1, 4.2), (0, 1), 0.9, T + 0.02, 0.0, 2.1, "door")
    b.opening(u, mid, (6.1, 0.8), (0, 1), 0.9, T + 0.02, 3.0, 5.1, "door")
    b.slab(g, _box(-T / 2, -T / 2, 10 + T / 2, 5 + T / 2), 0.0)
    b.slab(u, _box(-T / 2, -T / 2, 6.1, 5 + T / 2), 3.0)
    b.slab(u, _box(6.1, -T / 2, 10 + T / 2, 1.6), 3.0)  # the upper landing over the well's south end
    b.slab(u, _box(-T / 2, -T / 2, 10 + T / 2, 5 + T / 2), 6.0)
    b.flights(g, [((7.0, 1.8), (7.0, 3.8), 0.0, 1.4, 8), ((9.2, 3.8), (9.2, 1.8), 1.4, 1.6, 8)],
              [(_box(6.4, 3.8, 9.8, 4.8), 1.4)], 1.0)
    baked = _baked(tmp_path, b)
    on = [(np.array([x, 4.3, 1.4 + EYE]), yaw, p) for x in (7.0, 8.1, 9.2)
          for yaw in (0.0, math.pi / 2, math.pi, -math.pi / 2) for p in (0.0, -0.6, 0.6)]
    scene = _conservative(baked, gl_ctx, on, step=1.5)
    try:
        assert len(scene.topology.stairs) == 1
        # the eye on the landing is in a cell (on the plane, in both storeys' cells)
        from walkstream.shared.roomview import cell_of

        held = scene.ids[np.flatnonzero(cell_of(scene.planes, np.array([8.1, 4.3, 3.0]) - baked[1]))]
        assert len(held) >= 1
    finally:
        scene.release()


def test_spaces_that_overlap(tmp_path: Path, gl_ctx: Any) -> None:
    """Two spaces that overlap by 0.8 m across the wall between them (each drawn to the
    far face of the wall and beyond), and a small space lying wholly inside a larger one
    (a meeting box in an open office)."""
    b = IfcBuilder()
    s = b.storey("ground", 0.0)
    b.space("West", s, _box(0, 0, 5.0, 5), 0.0, H)
    b.space("East", s, _box(4.2, 0, 10, 5), 0.0, H)
    b.space("Box", s, _box(7, 3, 9, 4.5), 0.0, H)
    _shell(b, s, 10, 5, 0.0)
    mid = b.wall(s, (4.6, 0), (4.6, 5), T, 0.0, H)
    b.opening(s, mid, (4.6, 1.5), (0, 1), 0.9, T + 0.02, 0.0, 2.1, "door")
    boxw = b.wall(s, (7, 2.9), (9, 2.9), T, 0.0, 2.2)  # the meeting box's low front wall
    b.opening(s, boxw, (8.0, 2.9), (1, 0), 0.9, T + 0.02, 0.0, 2.0, "door")
    b.slab(s, _box(-T / 2, -T / 2, 10 + T / 2, 5 + T / 2), 0.0)
    b.slab(s, _box(-T / 2, -T / 2, 10 + T / 2, 5 + T / 2), H + 0.2)
    b.furniture(s, _box(1, 3.5, 2, 4.5), 0.0, 0.8, "table")
    baked = _baked(tmp_path, b)
    extra = [(np.array([x, y, EYE]), yaw, 0.0) for x in (4.3, 4.6, 4.9) for y in (1.5, 3.5)
             for yaw in (0.0, math.pi, 1.0, -1.0)]
    scene = _conservative(baked, gl_ctx, extra, step=1.2)
    scene.release()
