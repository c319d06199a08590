"""View cells: street cells (Marvie et al.), grid cells (m-LOMA), locating, viewpoints."""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Sequence

import numpy as np
import pytest
import shapely
from teamdata import team_data

from walkstream.server.bake.cells import make_cells
from walkstream.server.bake.gridcells import grid_cells
from walkstream.server.bake.streetcells import street_cells
from walkstream.server.bake.viewcell import ViewCell, cell_locator, cell_polygons
from walkstream.server.bake.viewpoints import viewpoints
from walkstream.server.sources.citygen import generate_city
from walkstream.server.sources.geojson import load_geojson, load_geojson_dict
from walkstream.server.sources.scene import SourceScene
from walkstream.shared.errors import InputError
from walkstream.shared.records import BuildingParams, StreetParams

# --------------------------------------------------------------------------- helpers


def building(bid: int, x0: float, y0: float, x1: float, y1: float) -> BuildingParams:
    ring = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], dtype=np.float64)
    return BuildingParams(
        id=bid, rings=(ring,), neighbour_heights=(np.zeros(4),), floors=3, floor_height=3.0
    )


def scene_of(
    buildings: Sequence[BuildingParams] = (), streets: Sequence[StreetParams] = ()
) -> SourceScene:
    return SourceScene("test", "EPSG:32633", (0.0, 0.0), tuple(buildings), tuple(streets))


def street(sid: int, kind: str, geom: shapely.Polygon, width: float = 10.0) -> StreetParams:
    return StreetParams(id=sid, kind=kind, ring=np.asarray(geom.exterior.coords)[:-1], width=width)


def signed_area(r: np.ndarray) -> float:
    x, y = (r - r[0]).T
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def assert_valid_partition(cells: list[ViewCell], nav: shapely.Geometry) -> None:
    """Convex, CCW, disjoint cells whose union is the navigation space ``nav``."""
    assert [c.id for c in cells] == list(range(len(cells)))
    polys = cell_polygons(cells)
    for c, p in zip(cells, polys, strict=True):
        assert signed_area(c.polygon) > 0, f"cell {c.id} is not counter-clockwise"
        assert p.is_valid
        assert abs(p.convex_hull.area - p.area) <= 1e-6 * p.area, f"cell {c.id} is not convex"
        assert not c.polygon.flags.writeable
    i, j = shapely.STRtree(polys).query(polys, predicate="intersects")
    keep = i < j
    overlap = shapely.area(shapely.intersection(polys[i[keep]], polys[j[keep]]))
    assert overlap.max(initial=0.0) < 1e-6
    union = shapely.union_all(polys)
    assert abs(union.area - nav.area) <= 1e-3 * nav.area
    assert shapely.symmetric_difference(union, nav).area <= 1e-3 * nav.area


def connected(cells: list[ViewCell]) -> bool:
    seen = {0}
    todo = deque([0])
    while todo:
        for n in cells[todo.popleft()].neighbours:
            if n not in seen:
                seen.add(n)
                todo.append(n)
    return len(seen) == len(cells)


def assert_symmetric(cells: list[ViewCell]) -> None:
    for c in cells:
        assert c.id not in c.neighbours
        for n in c.neighbours:
            assert c.id in cells[n].neighbours


def nav_space(scene: SourceScene) -> shapely.Geometry:
    return shapely.union_all([shapely.Polygon(s.ring) for s in scene.streets])


# --------------------------------------------------------------------------- street cells


@pytest.fixture(scope="module")
def city350() -> SourceScene:
    return load_geojson_dict(generate_city(350, 1))


@pytest.fixture(scope="module")
def cells350(city350: SourceScene) -> list[ViewCell]:
    return street_cells(city350)


def test_street_cells_partition_the_navigation_space(
    city350: SourceScene, cells350: list[ViewCell]
) -> None:
    assert {c.kind for c in cells350} == {"crossroad", "street", "square"}
    assert_valid_partition(cells350, nav_space(city350))
    assert all((c.zmin, c.zmax) == (1.5, 2.0) for c in cells350)


@pytest.mark.parametrize("max_length", [40.0, 25.0])
def test_street_cells_respect_max_length(city350: SourceScene, max_length: float) -> None:
    cells = street_cells(city350, max_length=max_length)
    src = [s for s in city350.streets if s.kind == "street"]
    src_polys = np.array([shapely.Polygon(s.ring) for s in src], dtype=object)
    tree = shapely.STRtree(src_polys)
    for c in cells:
        if c.kind != "street":
            continue
        p = shapely.Polygon(c.polygon)
        hits = tree.query(p, predicate="intersects")
        parent = hits[np.argmax(shapely.area(shapely.intersection(p, src_polys[hits])))]
        # the street's long axis: long side of its minimum rotated rectangle
        rect = np.asarray(shapely.minimum_rotated_rectangle(src_polys[parent]).exterior.coords)
        e1, e2 = rect[1] - rect[0], rect[2] - rect[1]
        axis = e1 if np.hypot(*e1) >= np.hypot(*e2) else e2
        t = c.polygon @ (axis / np.hypot(*axis))
        assert t.max() - t.min() <= max_length + 1e-6
    # a shorter limit only cuts more
    assert sum(c.kind == "street" for c in cells) >= sum(
        c.kind == "street" for c in street_cells(city350)
    )


def test_crossroads_are_whole_cells_separate_from_streets(
    city350: SourceScene, cells350: list[ViewCell]
) -> None:
    crossroads = [shapely.Polygon(s.ring) for s in city350.streets if s.kind == "crossroad"]
    xcells = [shapely.Polygon(c.polygon) for c in cells350 if c.kind == "crossroad"]
    assert len(xcells) == len(crossroads)
    for x in crossroads:
        assert any(shapely.symmetric_difference(x, c).area < 1e-6 for c in xcells)
    other = cell_polygons([c for c in cells350 if c.kind != "crossroad"])
    inter = shapely.area(shapely.intersection(other[:, None], np.array(crossroads)[None, :]))
    assert inter.max() < 1e-6
    # crossroads lead into streets, not straight into other crossroads
    for c in cells350:
        if c.kind == "crossroad":
            assert c.neighbours
            assert all(cells350[n].kind != "crossroad" for n in c.neighbours)


def test_street_cell_graph_is_connected_and_symmetric(cells350: list[ViewCell]) -> None:
    assert_symmetric(cells350)
    assert connected(cells350)
    # a street cell in the middle of a long street has one neighbour on each end
    assert any(c.kind == "street" and len(c.neighbours) == 2 for c in cells350)


def test_street_cells_are_deterministic(city350: SourceScene, cells350: list[ViewCell]) -> None:
    again = street_cells(load_geojson_dict(generate_city(350, 1)))
    assert len(again) == len(cells350)
    for a, b in zip(again, cells350, strict=True):
        assert (a.id, a.kind, a.neighbours) == (b.id, b.kind, b.neighbours)
        np.testing.assert_array_equal(a.polygon, b.polygon)
    kinds = [c.kind for c in cells350]
    assert kinds == sorted(kinds, key=["crossroad", "street", "square"].index)


def test_street_cells_of_a_700m_city() -> None:
    scene = load_geojson_dict(generate_city(700, 1))
    t0 = time.perf_counter()
    cells = street_cells(scene)
    assert time.perf_counter() - t0 < 10.0
    assert len(cells) > 300
    assert_valid_partition(cells, nav_space(scene))
    assert connected(cells)


def test_non_convex_square_and_overlapping_streets() -> None:
    # an L-shaped square, two crossing buffered streets (no crossroad given) and a
    # crossroad overlapping one street's end
    l_square = shapely.Polygon([(0, 0), (60, 0), (60, 20), (20, 20), (20, 70), (0, 70)])
    s1 = shapely.LineString([(-100, -20), (100, -20)]).buffer(5, cap_style="flat")
    s2 = shapely.LineString([(40, -80), (40, -5)]).buffer(6, cap_style="flat")
    bend = shapely.LineString([(80, 30), (120, 30), (120, 90)]).buffer(
        4, cap_style="flat", join_style="mitre"
    )
    xroad = shapely.box(95, -30, 110, -10)
    scene = scene_of(
        streets=[
            street(10, "square", l_square),
            street(11, "street", s1),
            street(12, "street", s2),
            street(13, "street", bend),
            street(14, "crossroad", xroad),
        ]
    )
    cells = street_cells(scene, max_length=30)
    assert_valid_partition(cells, nav_space(scene))
    squares = shapely.union_all([shapely.Polygon(c.polygon) for c in cells if c.kind == "square"])
    assert abs(squares.area - l_square.area) < 1e-6
    crossroad_cells = [c for c in cells if c.kind == "crossroad"]
    assert len(crossroad_cells) == 1
    assert (
        shapely.symmetric_difference(shapely.Polygon(crossroad_cells[0].polygon), xroad).area < 1e-6
    )
    assert_symmetric(cells)


def test_street_mode_without_streets_raises() -> None:
    scene = scene_of(buildings=[building(0, 0, 0, 20, 20)])
    with pytest.raises(InputError, match="no street"):
        make_cells(scene, "street")
    with pytest.raises(InputError, match="no street"):
        street_cells(scene)
    assert {c.kind for c in make_cells(scene)} == {"grid"}  # auto falls back to grid
    with pytest.raises(InputError, match="mode"):
        make_cells(scene, "rooms")


def test_make_cells_auto_picks_streets(city350: SourceScene, cells350: list[ViewCell]) -> None:
    auto = make_cells(city350)
    assert [c.kind for c in auto] == [c.kind for c in cells350]
    assert {c.kind for c in make_cells(city350, "grid")} == {"grid"}


@pytest.mark.parametrize(
    "kwargs",
    [
        {"max_length": 0},
        {"max_length": float("nan")},
        {"height_range": (2.0, 1.5)},
        {"eye_height": 3.0},
    ],
)
def test_street_cells_reject_bad_parameters(city350: SourceScene, kwargs: dict) -> None:
    with pytest.raises(InputError):
        street_cells(city350, **kwargs)


# --------------------------------------------------------------------------- grid cells


@pytest.fixture(scope="module")
def two_buildings() -> SourceScene:
    # 3 x 2 squares of 40 m over (0, 0)-(120, 80): the south-west square is fully
    # built, the south-east one 90 % built (10 % free < 15 %), the others free
    return scene_of(buildings=[building(0, 0, 0, 40, 40), building(1, 80, 0, 120, 36)])


@pytest.fixture(scope="module")
def grid4(two_buildings: SourceScene) -> list[ViewCell]:
    return grid_cells(two_buildings, bbox=(0, 0, 120, 80))


def test_grid_skips_built_squares(grid4: list[ViewCell]) -> None:
    assert [c.kind for c in grid4] == ["grid"] * 4
    lower_left = [tuple(c.polygon.min(axis=0)) for c in grid4]
    assert lower_left == [(40, 0), (0, 40), (40, 40), (80, 40)]
    for c in grid4:
        assert signed_area(c.polygon) == pytest.approx(1600.0)
        assert (c.zmin, c.zmax) == (1.5, 2.0)


def test_grid_neighbours_are_4_connected(grid4: list[ViewCell]) -> None:
    assert [c.neighbours for c in grid4] == [(2,), (2,), (0, 1, 3), (2,)]


def test_grid_min_free_and_default_bbox(two_buildings: SourceScene) -> None:
    # with a lower threshold the 90 % built square is kept as well
    assert len(grid_cells(two_buildings, bbox=(0, 0, 120, 80), min_free=0.05)) == 5
    # default bbox = the buildings' (0, 0)-(120, 40): one row, only the middle is free
    cells = grid_cells(two_buildings)
    assert [tuple(c.polygon.min(axis=0)) for c in cells] == [(40, 0)]
    with pytest.raises(InputError):
        grid_cells(two_buildings, bbox=(0, 0, 0, 10))
    with pytest.raises(InputError):
        grid_cells(two_buildings, min_free=1.5)
    with pytest.raises(InputError):
        grid_cells(scene_of())


def test_vienna_grid_in_a_2km_bbox() -> None:
    scene = load_geojson(team_data("vienna", "blocks.geojson"))
    assert not scene.streets
    t0 = time.perf_counter()
    cells = make_cells(scene, bbox=(-1000, -1000, 1000, 1000))
    elapsed = time.perf_counter() - t0
    assert elapsed < 5.0  # about 0.1 s here; generous for slow CI machines
    assert {c.kind for c in cells} == {"grid"}
    assert 1000 <= len(cells) <= 2500  # 50 x 50 squares, the fully built blocks dropped
    assert_symmetric(cells)
    vps = viewpoints(cells, scene)
    loc = cell_locator(cells)
    for v in vps:
        assert loc.locate(v.x, v.y) == v.cell


# --------------------------------------------------------------------------- locator


def test_locate_inside_boundary_outside(grid4: list[ViewCell]) -> None:
    loc = cell_locator(grid4)
    assert loc.locate(60.0, 20.0) == 0
    assert loc.locate(100.0, 60.0) == 3
    # on the edge between cells 0 and 2, and on the corner of cells 0, 1, 2: lowest id
    assert loc.locate(60.0, 40.0) == 0
    assert loc.locate(40.0, 40.0) == 0
    assert loc.locate(80.0, 60.0) == 2
    # within 1e-6 m of a cell counts as inside it
    assert loc.locate(60.0, -5e-7) == 0
    assert loc.locate(60.0, -1e-4) is None
    assert loc.locate(20.0, 20.0) is None  # the fully built square
    assert loc.locate(500.0, 500.0) is None


def test_locate_many_agrees_with_locate(grid4: list[ViewCell], cells350: list[ViewCell]) -> None:
    rng = np.random.default_rng(7)
    for cells, lo, hi in ((grid4, -10, 130), (cells350, -180, 180)):
        loc = cell_locator(cells)
        pts = rng.uniform(lo, hi, size=(400, 2))
        # add the cells' vertices: points shared by several cells
        pts = np.concatenate([pts, np.concatenate([c.polygon for c in cells])[:200]])
        many = loc.locate_many(pts)
        assert many.dtype == np.int64 and many.shape == (len(pts),)
        single = [loc.locate(float(x), float(y)) for x, y in pts]
        assert many.tolist() == [-1 if s is None else s for s in single]
        # brute force: the lowest id among the cells within 1e-6 m
        polys = cell_polygons(cells)
        d = shapely.distance(shapely.points(pts)[:, None], polys[None, :])
        within = d <= 1e-6
        expect = np.where(within.any(axis=1), np.argmax(within, axis=1), -1)
        np.testing.assert_array_equal(many, expect)
        assert (many >= 0).any() and (many == -1).any()
    assert cell_locator(grid4).locate_many(np.zeros((0, 2))).shape == (0,)


def test_locate_street_cell_boundary(cells350: list[ViewCell]) -> None:
    loc = cell_locator(cells350)
    c = next(c for c in cells350 if c.kind == "crossroad" and len(c.neighbours) >= 4)
    n = c.neighbours[0]
    shared = shapely.intersection(
        shapely.Polygon(c.polygon).boundary, shapely.Polygon(cells350[n].polygon).buffer(1e-6)
    )
    mid = shapely.line_interpolate_point(shared, 0.5, normalized=True)
    assert loc.locate(mid.x, mid.y) == min(c.id, n)
    x, y = c.centroid
    assert loc.locate(x, y) == c.id


# --------------------------------------------------------------------------- viewpoints


def test_viewpoints_of_street_cells(city350: SourceScene, cells350: list[ViewCell]) -> None:
    vps = viewpoints(cells350, city350, count=4)
    assert len(vps) == 4
    assert len({v.name for v in vps}) == 4
    loc = cell_locator(cells350)
    footprints = [shapely.Polygon(b.rings[0], b.rings[1:]) for b in city350.buildings]
    pts = np.array([(v.x, v.y) for v in vps])
    for v in vps:
        assert loc.locate(v.x, v.y) == v.cell
        assert cells350[v.cell].kind == "crossroad"
        assert v.z == pytest.approx(1.7)
        assert -np.pi <= v.yaw <= np.pi
        # it looks along a street: no building within 30 m straight ahead
        ray = shapely.LineString([(v.x, v.y), (v.x + 30 * np.cos(v.yaw), v.y + 30 * np.sin(v.yaw))])
        assert not any(ray.intersects(f) for f in footprints)
    # spread over the scene, not bunched together
    d = np.linalg.norm(pts[:, None] - pts[None, :], axis=2)
    assert d[np.triu_indices(4, 1)].min() > 50.0
    assert viewpoints(cells350, city350, count=4) == vps


def test_viewpoints_of_grid_cells(two_buildings: SourceScene, grid4: list[ViewCell]) -> None:
    vps = viewpoints(grid4, two_buildings, count=10)
    assert 1 <= len(vps) <= len(grid4)
    loc = cell_locator(grid4)
    for v in vps:
        assert loc.locate(v.x, v.y) == v.cell
        assert not any(
            shapely.Polygon(b.rings[0]).covers(shapely.Point(v.x, v.y))
            for b in two_buildings.buildings
        )
    with pytest.raises(InputError):
        viewpoints([], two_buildings)
    with pytest.raises(InputError):
        viewpoints(grid4, two_buildings, count=0)
