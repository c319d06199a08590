"""Walks through an interior keep a body's clearance from the walls and the furniture,
and turn on the spot.

A generated two-storey office (small, with a stair) is planned without baking its
contents: the tour is sampled every few centimetres and checked against each room
cell's walls (its outline less the walkable portals in it) and against every piece of
furniture on its floor.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import shapely
import trimesh

from walkstream.server.bake.floorroute import FloorRoutes, walkable_floor
from walkstream.server.bake.interior import STANDING, InteriorParts, floor_obstacles, interior_parts
from walkstream.server.bake.roomnav import CLEARANCE, RoomGraph, walk_path
from walkstream.server.bake.rooms import room_layout
from walkstream.server.sources.interiorfile import load_interior, load_interior_dict
from walkstream.server.sources.interiorgen import InteriorPlan, generate_interior, write_interior
from walkstream.shared.pathcodec import decode_path_q, encode_path_q
from walkstream.shared.paths import wrap_angle

_WALKABLE = ("door", "opening", "virtual", "split")
_FURNITURE = frozenset({"furniture", "column"})


@pytest.fixture(scope="module")
def office(tmp_path_factory: pytest.TempPathFactory) -> InteriorParts:
    src = tmp_path_factory.mktemp("roomwalk") / "office.json"
    write_interior(src, InteriorPlan(storeys=2, length=24, width=14, seed=11))
    return interior_parts(load_interior(src), src)


def _walls(ip: InteriorParts, cid: int) -> shapely.Geometry:
    """A room cell's walls: its outline less the walkable portals it has."""
    ring = shapely.LinearRing(ip.graph.cells[cid].outline)
    holes = [shapely.LineString(p.polygon[:, :2]).buffer(0.02) for p in ip.layout.portals
             if p.kind in _WALKABLE and cid in (p.a, p.b)]
    return ring.difference(shapely.union_all(holes)) if holes else ring


def test_the_tour_keeps_its_clearance_from_every_wall(office: InteriorParts) -> None:
    g, walk = office.graph, office.walk
    assert len(office.layout.stairs) >= 1 and walk.xyz[:, 2].max() > 3.0  # it climbs a stair
    xyz = walk.sample(np.arange(0.0, walk.duration, 0.02))[0]
    ids = g.locator.locate_many(np.column_stack([xyz[:, :2], xyz[:, 2] - 1.0]))
    assert (ids >= 0).all()
    seen = 0
    for cid in np.unique(ids).tolist():
        if g.cells[cid].kind != "room":
            continue
        d = shapely.distance(_walls(office, cid), shapely.points(xyz[ids == cid, :2]))
        assert d.min() >= CLEARANCE - 1e-6, (g.cells[cid].name, float(d.min()))
        seen += int((ids == cid).sum())
    assert seen > 0.8 * len(xyz)


def test_the_tour_walks_around_the_furniture(office: InteriorParts, tmp_path_factory: pytest.TempPathFactory) -> None:
    src = tmp_path_factory.getbasetemp() / "roomwalk0" / "office.json"
    feet = floor_obstacles(load_interior(src), kinds=_FURNITURE)
    assert len(feet) > 20  # desks, chairs, shelves, tables, benches
    walk = office.walk
    xyz = walk.sample(np.arange(0.0, walk.duration, 0.02))[0]
    pts = shapely.points(xyz[:, :2])
    floor = xyz[:, 2] - 1.6
    near = [float(shapely.distance(o.footprint, pts[np.abs(floor - o.bottom) < 1.0]).min(initial=np.inf))
            for o in feet]
    # every piece: never walked through, passed at a body's half-width at least
    assert min(near) >= CLEARANCE - 1e-6


def test_a_leg_bends_around_a_table_and_is_refused_where_furniture_closes_the_room() -> None:
    room = shapely.box(0.0, 0.0, 8.0, 4.0)
    table = shapely.box(3.0, 1.0, 5.0, 3.0)
    routes = FloorRoutes(walkable_floor(room, [table], CLEARANCE))
    a, b = np.array([1.0, 2.0]), np.array([7.0, 2.0])
    leg = routes.route(a, b)
    assert leg is not None and len(leg) == 4  # around two of the table's grown corners
    line = shapely.LineString(leg)
    assert line.distance(table) >= CLEARANCE - 1e-6
    assert line.length == pytest.approx(2 * np.hypot(2.0 - CLEARANCE, 1.0 + CLEARANCE) + 2.0 + 2 * CLEARANCE, rel=1e-6)
    assert routes.route(a, np.array([1.0, 3.0])).shape == (2, 2)  # a clear line stays straight
    # a shelf wall to wall parts the room: no walk joins its two ends
    shelf = shapely.box(3.9, 0.0, 4.1, 4.0)
    parted = FloorRoutes(walkable_floor(room, [shelf], CLEARANCE))
    assert parted.route(a, b) is None


@pytest.mark.parametrize("seed", [11, 3, 5, 7])
def test_generated_doors_are_not_blocked_by_furniture(seed: int) -> None:
    # seed 11 put a corridor bench in front of a door: the walk had to cross it; seeds
    # 5 and 7 a bench or a plant across the corridor from the stairwell door's leaf
    scene = load_interior_dict(generate_interior(InteriorPlan(storeys=3, seed=seed)))
    feet = floor_obstacles(scene, kinds=_FURNITURE)
    doors = [o for o in scene.openings if o.kind == "door"]
    assert len(doors) > 30
    for d in doors:
        reach = 0.5 * d.depth + 0.6  # a step beyond the wall on either side
        line = shapely.LineString([d.centre[:2] - reach * d.normal, d.centre[:2] + reach * d.normal])
        near = [o for o in feet if abs(o.bottom - d.zmin) < 0.5]
        assert min(o.footprint.distance(line) for o in near) >= CLEARANCE - 1e-6, d.key
    for e in scene.elements:
        if e.key.endswith("stair/leaf"):  # in the corridor: a walker passes between it and the furniture
            leaf = shapely.MultiPoint(e.vertices[:, :2]).convex_hull
            near = [o for o in feet if abs(o.bottom - e.vertices[:, 2].min()) < 0.5]
            # a body's width with its clearance on both sides, the grown corners' mitres
            # included (0.58 and 0.67 m closed the corridor on seeds 7 and 5)
            assert min(o.footprint.distance(leaf) for o in near) >= 3 * CLEARANCE, e.key


def test_the_tour_keeps_its_headroom_by_the_stair(office: InteriorParts, tmp_path_factory: pytest.TempPathFactory) -> None:
    # it walked under the stair to the stairwell's middle, between the flights (0.2 m
    # apart) through the half landing, and up a flight under the solid one above it
    scene = load_interior(tmp_path_factory.getbasetemp() / "roomwalk0" / "office.json")
    tris = np.concatenate([e.soup for e in scene.elements if e.kind in ("stair", "slab", "railing")])
    lo, hi = tris.min(axis=1), tris.max(axis=1)
    walk = office.walk
    xyz = walk.sample(np.arange(0.0, walk.duration, 0.05))[0]
    near = np.all((lo[None] <= xyz[:, None] + CLEARANCE) & (hi[None] >= xyz[:, None] - CLEARANCE), axis=2)
    eyes, which = np.nonzero(near)
    assert len(np.unique(eyes)) > 20  # it does pass the stair and climbs it
    closest = trimesh.triangles.closest_point(tris[which], xyz[eyes])
    # the eye keeps a body's half-width from the stair, its railings and the slab's edge over it
    assert np.linalg.norm(closest - xyz[eyes], axis=1).min() >= CLEARANCE - 0.03


def test_sharp_turns_are_made_on_the_spot_with_stairs_in_the_walk(office: InteriorParts) -> None:
    walk = office.walk
    turn = np.abs(wrap_angle(np.diff(walk.yaw)))
    moved = np.linalg.norm(np.diff(walk.xyz, axis=0)[:, :2], axis=1) > 1e-6
    assert (turn > np.radians(120)).sum() == 0  # split into steps of at most 90 degrees
    assert not (moved & (turn > np.radians(60))).any()  # a sharp turn stands still
    on_spot = ~moved & (turn > np.radians(45))
    assert on_spot.sum() >= 2  # the tour's U-turns in rooms
    # the compact path keeps every one of them turning the same way
    back = decode_path_q(encode_path_q(walk))
    assert np.array_equal(np.sign(wrap_angle(np.diff(walk.yaw))[on_spot]),
                          np.sign(wrap_angle(np.diff(back.yaw))[on_spot]))


def test_walk_path_keeps_a_u_turn_before_a_stair() -> None:
    # along a corridor, back, then up a ramp: the U-turn is two standing quarter turns
    floor = np.array([[0, 0, 0], [6, 0, 0], [2, 0, 0], [2, 4, 0], [2, 8, 3], [2, 10, 3]], float)
    p = walk_path("u", floor)
    at = np.flatnonzero(np.all(np.abs(p.xyz[:, :2] - [6, 0]) < 1e-9, axis=1))
    assert len(at) == 3  # arrive, a quarter turn, another: standing
    assert np.abs(wrap_angle(p.yaw[at[-1]] - p.yaw[at[0]])) == pytest.approx(np.pi)
    z = p.sample(np.linspace(0, p.duration, 200))[0][:, 2]
    assert z.min() == pytest.approx(1.6) and z.max() == pytest.approx(4.6)


def _leaf_doc() -> dict[str, object]:
    """Two rooms, a door between them near the south end whose leaf swings 90 degrees
    into the deep east room, across the diagonal from the door to the room's middle."""
    wall = {"thickness": 0.15, "storey": 0, "exterior": False, "openings": []}
    return {
        "format": "walkstream-interior", "version": 1, "name": "leaf", "crs": None, "slab": 0.25,
        "storeys": [{"name": "0", "elevation": 0.0, "height": 3.0}],
        "rooms": [{"id": "a", "name": "west", "storey": 0, "outline": [[0, 0], [4, 0], [4, 4], [0, 4]]},
                  {"id": "b", "name": "east", "storey": 0, "outline": [[4.15, 0], [8, 0], [8, 8], [4.15, 8]]}],
        "walls": [{**wall, "id": "ab", "from": [4.075, 0], "to": [4.075, 4],
                   "openings": [{"id": "d", "kind": "door", "offset": 1.2, "width": 0.9, "sill": 0.0,
                                 "head": 2.1, "swing": -1}]}],
        "slabs": [], "stairs": [], "furniture": [],
    }


def test_a_walk_keeps_its_clearance_from_a_door_leaf_swung_into_the_room(tmp_path: Path) -> None:
    scene = load_interior_dict(_leaf_doc())
    leaf = next(e for e in scene.elements if e.key == "d/leaf")
    foot = shapely.MultiPoint(leaf.vertices[:, :2]).convex_hull
    layout = room_layout(scene)
    rooms = {c.name: c.id for c in layout.cells if c.kind == "room"}

    def walked(kinds: frozenset[str]) -> np.ndarray:
        g = RoomGraph(layout.cells, layout.portals, layout.stairs, floor_obstacles(scene, kinds=kinds))
        p = walk_path("w", g.route(rooms["west"], rooms["east"]))
        return p.sample(np.arange(0.0, p.duration, 0.02))[0]

    # without the doors as obstacles the diagonal to the room's middle grazes the leaf
    assert shapely.distance(foot, shapely.points(walked(frozenset({"furniture"}))[:, :2])).min() < CLEARANCE
    xyz = walked(STANDING)
    assert shapely.distance(foot, shapely.points(xyz[:, :2])).min() >= CLEARANCE - 1e-6
    assert xyz[-1, 0] > foot.bounds[2] + 0.5  # and it still gets to the east room's middle
