"""Tests of walkstream.server.bake.visibility and .samples: ID-buffer PVS and ACH of a view cell, and its sample points."""

from __future__ import annotations

from collections.abc import Iterator

import moderngl
import numpy as np
import pytest
import shapely

from walkstream.server.bake.idpack import meshes_for_scene
from walkstream.server.bake.samples import (
    bake_points,
    boundary_points,
    dense_points,
    height_levels,
    reference_points,
    region_points,
    sample_points,
    split_points,
)
from walkstream.server.bake.visibility import VisibilityRenderer, pvs_from_counts
from walkstream.server.sources.scene import SourceScene
from walkstream.shared.buildings import build_lod
from walkstream.shared.errors import InputError, RenderError
from walkstream.shared.records import BuildingParams, Mesh, StreetParams
from walkstream.shared.streets import build_street

# The scene: a viewer cell (10 x 10 m around the origin) south of a long, high wall
# (y = 10..11) with a 6 m gap at x = -3..3.  Ids name what each object is for.
WALL_WEST, WALL_EAST = 1, 2
HIDDEN = 3  # behind the wall, off to the east: no line of sight from the cell
THROUGH_GAP = 4  # behind the gap: seen through it
BEHIND_VIEWER = 5  # south of the cell, large and close
FAR_SOUTH = 6  # south-east, small and far, not hidden by anything
STREET = 7  # the ground under the cell (seen by the downward cube face only)
BEYOND = 8  # farther than the view distance
VIEW_DISTANCE = 300.0

CELL = np.array([[-5.0, -5.0], [5.0, -5.0], [5.0, 5.0], [-5.0, 5.0]])


def rect(x0: float, y0: float, x1: float, y1: float) -> np.ndarray:
    return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], dtype=np.float64)


def block(oid: int, x0: float, y0: float, x1: float, y1: float, height: float) -> BuildingParams:
    """A box-shaped building: one floor of ``height`` metres."""
    return BuildingParams(
        oid, (rect(x0, y0, x1, y1),), (np.zeros(4),), floors=1, floor_height=height
    )


BUILDINGS = (
    block(WALL_WEST, -100.0, 10.0, -3.0, 11.0, 20.0),
    block(WALL_EAST, 3.0, 10.0, 100.0, 11.0, 20.0),
    block(HIDDEN, 40.0, 20.0, 44.0, 22.0, 5.0),
    block(THROUGH_GAP, -6.0, 30.0, 6.0, 32.0, 5.0),
    block(BEHIND_VIEWER, -3.0, -22.0, 3.0, -20.0, 4.0),
    block(FAR_SOUTH, 40.0, -80.0, 42.0, -78.0, 2.0),
    block(BEYOND, -20.0, -420.0, 20.0, -400.0, 60.0),
)
STREETS = (StreetParams(STREET, "street", rect(-6.0, -6.0, 6.0, 6.0), 12.0),)
SCENE = SourceScene("wall", "local", (0.0, 0.0), BUILDINGS, STREETS)


def footprint_tree(buildings: tuple[BuildingParams, ...]) -> shapely.STRtree:
    return shapely.STRtree([shapely.Polygon(b.rings[0], b.rings[1:]) for b in buildings])


@pytest.fixture(params=[True, False], ids=["cull", "nocull"])
def renderer(request: pytest.FixtureRequest, gl: moderngl.Context) -> Iterator[VisibilityRenderer]:
    """The wall scene at 64 x 64 per face, with and without back-face culling."""
    meshes, ids = meshes_for_scene(SCENE, 0)
    with VisibilityRenderer(
        meshes,
        ids,
        resolution=64,
        view_distance=VIEW_DISTANCE,
        ctx=gl,
        cull_back_faces=request.param,
    ) as r:
        yield r


def cell_pvs(r: VisibilityRenderer, points: np.ndarray) -> dict[int, float]:
    ids, pixels = r.cell_counts(points)
    pvs, ach = pvs_from_counts(ids, pixels)
    return dict(zip(pvs.tolist(), ach.tolist(), strict=True))


def test_wall_scene_pvs(renderer: VisibilityRenderer) -> None:
    pts = sample_points(CELL, 1.6, 3.0, footprints=footprint_tree(BUILDINGS))
    assert pts.shape == (8, 3)
    pvs = cell_pvs(renderer, pts)
    assert HIDDEN not in pvs  # behind the wall
    assert THROUGH_GAP in pvs  # through the gap
    assert BEHIND_VIEWER in pvs  # the cube faces look backwards too
    assert STREET in pvs  # ... and down
    assert {WALL_WEST, WALL_EAST, FAR_SOUTH} <= set(pvs)
    assert BEYOND not in pvs  # farther than the view distance
    assert sum(pvs.values()) == pytest.approx(1.0)
    assert all(0.0 < a <= 1.0 for a in pvs.values())
    # bigger and closer covers more of the screen on average
    assert pvs[BEHIND_VIEWER] > pvs[FAR_SOUTH]
    assert pvs[WALL_EAST] > pvs[THROUGH_GAP]


def test_occlusion_is_what_hides_them(gl: moderngl.Context) -> None:
    pts = sample_points(CELL, 1.6, 3.0)
    no_wall = SourceScene("open", "local", (0.0, 0.0), BUILDINGS[2:], STREETS)
    closed = block(WALL_WEST, -100.0, 10.0, 100.0, 11.0, 20.0)  # the wall without its gap
    no_gap = SourceScene("closed", "local", (0.0, 0.0), (closed, *BUILDINGS[2:]), STREETS)
    for scene, seen in ((no_wall, True), (no_gap, False)):
        meshes, ids = meshes_for_scene(scene, 0)
        with VisibilityRenderer(
            meshes, ids, resolution=64, view_distance=VIEW_DISTANCE, ctx=gl
        ) as r:
            pvs = cell_pvs(r, pts)
        assert (HIDDEN in pvs) is seen and (THROUGH_GAP in pvs) is seen
        assert BEHIND_VIEWER in pvs


def test_view_distance_limits_the_pvs(gl: moderngl.Context) -> None:
    meshes, ids = meshes_for_scene(SCENE, 0)
    pts = sample_points(CELL, 1.6, 3.0)
    with VisibilityRenderer(meshes, ids, resolution=32, view_distance=1000.0, ctx=gl) as r:
        assert BEYOND in cell_pvs(r, pts)  # big enough to be seen once in range
    with VisibilityRenderer(meshes, ids, resolution=32, view_distance=50.0, ctx=gl) as r:
        pvs = cell_pvs(r, pts)
    assert BEYOND not in pvs and FAR_SOUTH not in pvs
    assert BEHIND_VIEWER in pvs


def test_counts_are_exact_and_tiles_do_not_bleed(gl: moderngl.Context) -> None:
    # A slab 10 m east of the eye spanning exactly the 90-degree +x face: it fills that
    # face's res x res pixels and nothing in the neighbouring faces or tiles.
    res = 32
    slab = block(9, 10.0, -10.0, 10.5, 10.0, 20.0)
    with VisibilityRenderer([build_lod(slab, 0)], [9], resolution=res, ctx=gl) as r:
        ids, pixels = r.cell_counts(np.array([[0.0, 0.0, 10.0], [0.0, 0.0, 10.0]]))
    assert ids.tolist() == [9]
    assert pixels.tolist() == [2 * res * res]


def test_cell_inside_buildings_has_empty_pvs(gl: moderngl.Context) -> None:
    big = block(11, -50.0, -50.0, 50.0, 50.0, 10.0)
    meshes, ids = meshes_for_scene(SCENE, 0)
    pts = sample_points(CELL, 1.6, 3.0, footprints=footprint_tree((big,)))
    assert pts.shape == (0, 3)
    with VisibilityRenderer(meshes, ids, resolution=16, ctx=gl) as r:
        got_ids, pixels = r.cell_counts(pts)
    assert got_ids.shape == (0,) and pixels.shape == (0,)
    pvs, ach = pvs_from_counts(got_ids, pixels)
    assert pvs.dtype == np.int64 and ach.dtype == np.float64
    assert len(pvs) == 0 and len(ach) == 0
    assert len(dense_points(CELL, 1.6, 3.0, 20, footprints=footprint_tree((big,)))) == 0


def test_sample_points_inside_cell_and_outside_footprints() -> None:
    # An L-shaped cell with one building over its south-west corner and one inside it.
    cell = np.array([[0, 0], [30, 0], [30, 10], [10, 10], [10, 30], [0, 30]], dtype=np.float64)
    blds = (block(1, -5.0, -5.0, 4.0, 4.0, 10.0), block(2, 20.0, 2.0, 25.0, 6.0, 10.0))
    tree = footprint_tree(blds)
    margin = 0.3
    pts = sample_points(cell, 1.5, 4.0, margin=margin, footprints=tree, centre=True)
    assert pts.shape == (10, 3)
    assert pts[:4, 2].tolist() == [1.5] * 4 and pts[4:8, 2].tolist() == [4.0] * 4
    assert pts[8:, 2].tolist() == [1.5, 4.0]
    poly = shapely.Polygon(cell)
    p = shapely.points(pts[:, :2])
    # inside the cell by the margin (allow for the buffer's polygonal arcs)
    assert np.all(shapely.contains(poly, p))
    assert np.all(shapely.distance(poly.exterior, p) >= margin * 0.98)
    for b in blds:
        fp = shapely.Polygon(b.rings[0])
        assert not np.any(shapely.intersects(fp, p))
        assert np.all(shapely.distance(fp, p) >= margin * 0.98)
    # the south-west corner moved out of the building, as close as it can
    assert shapely.distance(shapely.Point(pts[0, :2]), shapely.box(-5, -5, 4, 4)) == pytest.approx(
        margin, abs=0.02
    )


def test_sample_points_without_footprints_hug_the_corners() -> None:
    pts = sample_points(CELL, 1.0, 2.0, margin=0.5)
    assert pts.shape == (8, 3)
    np.testing.assert_allclose(np.abs(pts[:, :2]), 4.5, atol=1e-9)
    # a cell thinner than two margins still gets points inside it
    thin = rect(0.0, 0.0, 20.0, 0.4)
    t = sample_points(thin, 1.0, 1.0, margin=0.3)
    assert t.shape == (8, 3)
    assert np.all(shapely.contains(shapely.Polygon(thin), shapely.points(t[:, :2])))


def test_dense_points_spread_and_deterministic() -> None:
    tree = footprint_tree((block(1, -2.0, -2.0, 2.0, 2.0, 5.0),))
    a = dense_points(CELL, 1.5, 3.5, 50, levels=3, footprints=tree)
    b = dense_points(CELL, 1.5, 3.5, 50, levels=3, footprints=tree)
    np.testing.assert_array_equal(a, b)
    assert a.shape == (150, 3)
    assert sorted(set(a[:, 2].tolist())) == [1.5, 2.5, 3.5]
    p = shapely.points(a[:, :2])
    assert np.all(shapely.contains(shapely.Polygon(CELL), p))
    assert not np.any(shapely.intersects(shapely.box(-2, -2, 2, 2), p))
    # spread: every quadrant of the cell gets some
    quadrants = {(bool(x > 0), bool(y > 0)) for x, y in a[:, :2]}
    assert len(quadrants) == 4


def test_results_are_deterministic(renderer: VisibilityRenderer, gl: moderngl.Context) -> None:
    pts = sample_points(CELL, 1.6, 3.0, centre=True)
    first = renderer.cell_counts(pts)
    again = renderer.cell_counts(pts)
    meshes, ids = meshes_for_scene(SCENE, 0)
    with VisibilityRenderer(
        meshes,
        ids,
        resolution=64,
        view_distance=VIEW_DISTANCE,
        ctx=gl,
        cull_back_faces=renderer.cull_back_faces,
        max_points_per_pass=3,  # several passes must add up to the same counts
    ) as other:
        third = other.cell_counts(pts)
    for got in (again, third):
        np.testing.assert_array_equal(first[0], got[0])
        np.testing.assert_array_equal(first[1], got[1])


def test_shared_ids_add_up_and_empty_meshes_are_ignored(gl: moderngl.Context) -> None:
    a = build_lod(block(0, 5.0, -1.0, 6.0, 1.0, 3.0), 0)
    b = build_lod(block(0, -6.0, -1.0, -5.0, 1.0, 3.0), 0)
    empty = Mesh(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)))
    eye = np.array([[0.0, 0.0, 1.5]])
    with VisibilityRenderer([a, b, empty], [3, 3, 4], resolution=32, ctx=gl) as r:
        ids, pixels = r.cell_counts(eye)
    with VisibilityRenderer([a], [3], resolution=32, ctx=gl) as r:
        _, single = r.cell_counts(eye)
    assert ids.tolist() == [3]
    assert pixels[0] == 2 * single[0]  # symmetric: both halves cover the same


def test_pvs_from_counts() -> None:
    pvs, ach = pvs_from_counts([4, 2, 9], [30, 10, 2], threshold=2)
    assert pvs.tolist() == [4, 2]
    np.testing.assert_allclose(ach, [0.75, 0.25])
    e_ids, e_ach = pvs_from_counts([], [])
    assert e_ids.shape == (0,) and e_ach.shape == (0,)
    with pytest.raises(InputError):
        pvs_from_counts([1, 2], [3])


def test_meshes_for_scene_lists_every_object() -> None:
    meshes, ids = meshes_for_scene(SCENE, 2)
    assert ids.tolist() == [b.id for b in BUILDINGS] + [STREET]
    assert ids.dtype == np.int64
    assert meshes[-1].triangles == build_street(STREETS[0]).triangles
    assert meshes[0].triangles == build_lod(BUILDINGS[0], 2).triangles


def test_bad_input_and_release(gl: moderngl.Context) -> None:
    meshes, ids = meshes_for_scene(SCENE, 0)
    with pytest.raises(InputError):
        VisibilityRenderer(meshes, ids[:-1], ctx=gl)
    with pytest.raises(InputError):
        VisibilityRenderer(meshes, ids, near=10.0, view_distance=5.0, ctx=gl)
    r = VisibilityRenderer(meshes, ids, resolution=8, ctx=gl)
    with pytest.raises(InputError):
        r.cell_counts(np.zeros((2, 2)))
    with pytest.raises(InputError):
        r.cell_counts(np.array([[0.0, 0.0, np.nan]]))
    r.release()
    r.release()  # idempotent
    with pytest.raises(RenderError):
        r.cell_counts(np.zeros((1, 3)))
    with pytest.raises(InputError):
        sample_points(CELL, 3.0, 1.0)
    with pytest.raises(InputError):
        sample_points(np.zeros((2, 2)), 1.0, 2.0)


def test_empty_scene(gl: moderngl.Context) -> None:
    with VisibilityRenderer([], [], resolution=8, ctx=gl) as r:
        ids, pixels = r.cell_counts(np.zeros((1, 3)))
    assert ids.shape == (0,) and pixels.shape == (0,)


def test_merging_draw_ranges_never_draws_out_of_range_objects(gl: moderngl.Context) -> None:
    # Boxes within reach (radius 40 m) and boxes just beyond the view distance (100 m)
    # but at a depth < 100 m in their cube face, interleaved around the eye: however the
    # draw ranges are merged, the far ones must stay out and the counts must not change.
    angles = np.radians(np.arange(0.0, 360.0, 15.0))
    meshes: list[Mesh] = []
    ids: list[int] = []
    for k, a in enumerate(angles):
        radius = 40.0 if k % 2 == 0 else 104.0
        x, y = radius * np.cos(a), radius * np.sin(a)
        meshes.append(build_lod(block(k, x - 1, y - 1, x + 1, y + 1, 12.0), 0))
        ids.append(k)
    eye = np.array([[0.0, 0.0, 1.7]])
    results = []
    for gap in (0, 10**9):
        with VisibilityRenderer(
            meshes, ids, resolution=64, view_distance=100.0, ctx=gl, merge_gap=gap
        ) as r:
            results.append(r.cell_counts(eye))
    assert results[0][0].tolist() == list(range(0, len(angles), 2))
    np.testing.assert_array_equal(results[0][0], results[1][0])
    np.testing.assert_array_equal(results[0][1], results[1][1])


def test_fallback_without_multi_draw_gives_the_same_counts(gl: moderngl.Context) -> None:
    # OpenGL < 4.3 (e.g. macOS) has no glMultiDrawElementsIndirect: one draw per range.
    meshes, ids = meshes_for_scene(SCENE, 0)
    pts = sample_points(CELL, 1.6, 3.0, centre=True)
    got = []
    for multi in (True, False):
        with VisibilityRenderer(
            meshes, ids, resolution=32, view_distance=VIEW_DISTANCE, ctx=gl
        ) as r:
            r._multi_draw = multi
            got.append(r.cell_counts(pts))
    np.testing.assert_array_equal(got[0][0], got[1][0])
    np.testing.assert_array_equal(got[0][1], got[1][1])


def test_boundary_points_follow_the_outline_inside_and_out_of_buildings() -> None:
    # a 60 m x 10 m street cell with one building over its south-west corner
    cell = rect(0.0, 0.0, 60.0, 10.0)
    blds = (block(1, -5.0, -5.0, 4.0, 4.0, 10.0),)
    tree = footprint_tree(blds)
    pts = boundary_points(cell, 1.5, 2.0, spacing=20.0, margin=0.3, footprints=tree)
    # corners and the long edges cut into 3 pieces: 4 + 2 * 2 points, one height (0.5 m range)
    assert pts.shape == (8, 3) and set(pts[:, 2].tolist()) == {2.0}
    p = shapely.points(pts[:, :2])
    poly = shapely.Polygon(cell)
    assert np.all(shapely.contains(poly, p))
    assert np.all(shapely.distance(poly.exterior, p) >= 0.3 * 0.98)
    assert not np.any(shapely.intersects(shapely.Polygon(blds[0].rings[0]), p))
    # along each long edge the points are at most the spacing apart (plus the margin)
    south = np.sort(pts[pts[:, 1] < 5, 0])
    assert len(south) == 4 and np.diff(south).max() <= 20.0 + 1e-6
    # a finer spacing gives more points; more height range gives more heights
    assert len(boundary_points(cell, 1.5, 2.0, spacing=5.0)) > len(pts)
    tall = boundary_points(cell, 0.0, 3.0, spacing=20.0, height_step=1.5)
    assert sorted(set(tall[:, 2].tolist())) == [0.0, 1.5, 3.0] and len(tall) == 3 * 8
    # the centre; points pulled into one place are kept once
    assert len(boundary_points(cell, 1.5, 2.0, centre=True)) == len(pts) + 1
    tiny = boundary_points(rect(0.0, 0.0, 0.5, 0.5), 1.5, 2.0)
    assert len(tiny) == 1
    # no free space: no points
    assert boundary_points(CELL, 1.5, 2.0, footprints=footprint_tree((block(9, -9.0, -9.0, 9.0, 9.0, 5.0),))).shape == (0, 3)


def test_bake_points_and_levels_check_their_input() -> None:
    np.testing.assert_array_equal(bake_points(CELL, 1.0, 2.0, sampling="corners"), sample_points(CELL, 1.0, 2.0))
    np.testing.assert_array_equal(bake_points(CELL, 1.0, 2.0, sampling="boundary"), boundary_points(CELL, 1.0, 2.0))
    np.testing.assert_array_equal(bake_points(CELL, 1.0, 2.0), region_points(CELL, 1.0, 2.0))
    assert height_levels(1.5, 2.0, 1.0).tolist() == [2.0]
    for bad in (
        lambda: bake_points(CELL, 1.0, 2.0, sampling="random"),
        lambda: boundary_points(CELL, 1.0, 2.0, spacing=0.0),
        lambda: boundary_points(CELL, 1.0, 2.0, height_step=-1.0),
        lambda: boundary_points(CELL, 2.0, 1.0),
    ):
        with pytest.raises(InputError):
            bad()


def test_reference_points_cover_the_cell_and_its_heights() -> None:
    a = reference_points(CELL, 1.0, 3.0, 64, seed=3)
    np.testing.assert_array_equal(a, reference_points(CELL, 1.0, 3.0, 64, seed=3))
    assert a.shape == (64, 3)
    # one point per slice of the height range
    slices = np.floor((a[:, 2] - 1.0) / 2.0 * 64).astype(int)
    assert sorted(slices.tolist()) == list(range(64))
    assert {(bool(x > 0), bool(y > 0)) for x, y in a[:, :2]} == {(True, True), (True, False), (False, True), (False, False)}
    # not where the bake samples
    b = boundary_points(CELL, 1.0, 3.0)
    assert np.min(np.hypot(*(a[:, None, :2] - b[None, :, :2]).transpose(2, 0, 1))) > 1e-6


def test_no_frustum_culling_gives_the_same_counts(gl: moderngl.Context) -> None:
    meshes, ids = meshes_for_scene(SCENE, 2)
    pts = sample_points(CELL, 1.5, 2.0, centre=True)
    with VisibilityRenderer(meshes, ids, resolution=48, view_distance=VIEW_DISTANCE, ctx=gl) as a:
        got = a.cell_counts(pts)
    with VisibilityRenderer(meshes, ids, resolution=48, view_distance=VIEW_DISTANCE, ctx=gl, frustum_cull=False) as b:
        ref = b.cell_counts(pts)
    for x, y in zip(got, ref, strict=True):
        np.testing.assert_array_equal(x, y)
    assert BEYOND not in ref[0].tolist()


def test_region_points_cover_the_outline_the_inside_and_both_heights() -> None:
    square = rect(0.0, 0.0, 60.0, 60.0)
    pts = region_points(square, 1.5, 2.0, spacing=20.0)
    ring = boundary_points(square, 1.5, 2.0, spacing=20.0)
    # the outline points first, then the inside grid
    np.testing.assert_array_equal(pts[: len(ring), :2], ring[:, :2])
    inner = pts[len(ring) :, :2]
    assert len(inner) >= 4
    assert np.all(shapely.contains_xy(shapely.Polygon(square).buffer(-10.0 + 1e-6), inner[:, 0], inner[:, 1]))
    gap = np.hypot(*(inner[:, None, :] - ring[None, :, :2]).transpose(2, 0, 1)).min(axis=1)
    assert gap.min() >= 10.0 - 1e-6
    # both ends of the height range, alternating along the points
    assert pts[:, 2].tolist()[:4] == [2.0, 1.5, 2.0, 1.5]
    assert set(pts[:, 2].tolist()) == {1.5, 2.0}
    np.testing.assert_array_equal(pts, region_points(square, 1.5, 2.0, spacing=20.0))
    # a short street cell: the outline only; a long one: a row down its middle too
    assert len(region_points(rect(0.0, 0.0, 30.0, 10.0), 1.5, 2.0)) == len(boundary_points(rect(0.0, 0.0, 30.0, 10.0), 1.5, 2.0))
    long_street = region_points(rect(0.0, 0.0, 60.0, 10.0), 1.5, 2.0)
    assert long_street[8:, 1].tolist() == [5.0, 5.0, 5.0]
    # a tall range samples every point at every level; inside buildings, nothing
    tall = region_points(square, 0.0, 3.0, spacing=20.0, height_step=1.5)
    assert sorted(set(tall[:, 2].tolist())) == [0.0, 1.5, 3.0] and len(tall) == 3 * len(pts)
    assert region_points(CELL, 1.5, 2.0, footprints=footprint_tree((block(9, -9.0, -9.0, 9.0, 9.0, 5.0),))).shape == (0, 3)
    # and out of buildings
    blds = (block(1, 25.0, 25.0, 35.0, 35.0, 10.0),)
    with_bld = region_points(square, 1.5, 2.0, spacing=20.0, footprints=footprint_tree(blds))
    assert not np.any(shapely.intersects(shapely.Polygon(blds[0].rings[0]).buffer(0.29), shapely.points(with_bld[:, :2])))
    np.testing.assert_array_equal(bake_points(square, 1.5, 2.0, sampling="region"), pts)


def test_the_edge_pass_adds_an_object_thinner_than_a_pixel_and_drops_nothing(gl: moderngl.Context) -> None:
    # a flat strip 2 m deep lying on the ground 100 m north: from 1.7 m up it is a band
    # 0.02 degrees high, far below one 16 px pixel (5.6 degrees)
    sliver = StreetParams(99, "street", rect(-30.0, 100.0, 30.0, 102.0), 2.0)
    scene = SourceScene("sliver", "local", (0.0, 0.0), BUILDINGS[:2] + BUILDINGS[3:], (sliver,))
    meshes, ids = meshes_for_scene(scene, 0)
    eye = np.array([[0.0, 0.0, 1.7]])
    got = {}
    for edge in (False, True):
        with VisibilityRenderer(meshes, ids, resolution=16, view_distance=VIEW_DISTANCE, ctx=gl, edge_pass=edge) as r:
            got[edge] = dict(zip(*(a.tolist() for a in r.cell_counts(eye)), strict=True))
    assert 99 not in got[False] and got[True].get(99, 0) >= 1
    # the fill's counts stand; the edges only add objects the fill did not see
    assert {k: got[True][k] for k in got[False]} == got[False]
    assert HIDDEN not in got[True]


def test_point_counts_give_each_points_own_view(gl: moderngl.Context) -> None:
    meshes, ids = meshes_for_scene(SCENE, 0)
    # west of the wall's gap and in front of it: only the second sees through it
    pts = np.array([[-4.0, -4.0, 1.7], [0.0, 4.0, 1.7], [4.0, -4.0, 1.7]])
    with VisibilityRenderer(meshes, ids, resolution=32, view_distance=VIEW_DISTANCE, ctx=gl) as r:
        total = r.cell_counts(pts)
        i, px, seen = r.point_counts(pts)
        alone = [r.cell_counts(p[None])[0] for p in pts]
    np.testing.assert_array_equal(i, total[0])
    np.testing.assert_array_equal(px, total[1])
    for a, b in zip(seen, alone, strict=True):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(np.unique(np.concatenate(seen)), i)


def test_split_points_go_between_views_that_differ() -> None:
    square = rect(0.0, 0.0, 40.0, 40.0)
    pts = np.array([[1.0, 1.0, 2.0], [21.0, 1.0, 1.5], [39.0, 39.0, 2.0]])
    same, other = np.array([1, 2, 3]), np.array([1, 7, 8])
    # the first two differ (Jaccard distance 0.8) and are neighbours; the third is too far
    got = split_points(pts, [same, other, other], square, differ=0.5, max_gap=25.0)
    np.testing.assert_allclose(got, [[11.0, 1.0, 1.75]])
    assert len(split_points(pts, [same, same, other], square, differ=0.5, max_gap=25.0)) == 0
    assert len(split_points(pts, [same, other, other], square, differ=0.9, max_gap=25.0)) == 0
    # not closer than min_gap to a point sampled already; moved out of buildings
    assert len(split_points(pts, [same, other, other], square, differ=0.5, max_gap=25.0, min_gap=11.0)) == 0
    blds = (block(1, 9.0, -1.0, 13.0, 3.0, 10.0),)
    moved = split_points(pts, [same, other, other], square, differ=0.5, max_gap=25.0, footprints=footprint_tree(blds))
    assert len(moved) == 1 and not shapely.intersects(shapely.Polygon(blds[0].rings[0]), shapely.points(moved[0, :2]))
    with pytest.raises(InputError):
        split_points(pts, [same], square, differ=0.5, max_gap=25.0)


def test_the_thin_pass_adds_an_object_under_a_pixel_and_nothing_hidden(gl: moderngl.Context) -> None:
    # the trap: a strip 2 m deep on the ground 100 m north, seen through the wall's gap
    # from 1.7 m up, is a band 0.02 degrees high, far below one 64 px pixel (1.4
    # degrees): the fill misses it at every pixel centre; a small box far behind the
    # wall (under a pixel too; the wall's foot 5 pixels below it) stays hidden, with
    # the occluders shrunk by a pixel too; nothing the fill counted changes
    sliver = StreetParams(99, "street", rect(-30.0, 100.0, 30.0, 102.0), 2.0)
    tucked = block(98, 120.0, 150.0, 120.5, 150.5, 0.5)  # behind the east wall, under a pixel, 20 degrees off the gap
    scene = SourceScene("sliver", "local", (0.0, 0.0), BUILDINGS[:2] + BUILDINGS[3:] + (tucked,), (sliver,))
    meshes, ids = meshes_for_scene(scene, 0)
    eye = np.array([[0.0, 0.0, 1.7], [2.0, -3.0, 1.5]])
    got = {}
    for thin, depth in ((0.0, False), (2.0, False), (2.0, True)):
        with VisibilityRenderer(meshes, ids, resolution=64, view_distance=VIEW_DISTANCE, ctx=gl, thin_pass=thin,
                                thin_depth=depth) as r:
            got[thin, depth] = dict(zip(*(a.tolist() for a in r.cell_counts(eye)), strict=True))
            each = r.each_point_counts(eye)
            _, _, seen = r.point_counts(eye)
    plain = got[0.0, False]
    assert 99 not in plain
    for key in ((2.0, False), (2.0, True)):  # with or without the occluders shrunk by a pixel
        assert got[key].get(99, 0) >= 1
        assert {k: got[key][k] for k in plain} == plain
        assert HIDDEN not in got[key] and 98 not in got[key]
    # per point the same objects: the thin pass feeds split_points and the field alike
    assert 99 in set(np.concatenate(seen).tolist())
    assert 99 in set(np.concatenate([e[0] for e in each]).tolist())
    # ... and the box is added where the wall does not stand (it is hidden, not ignored)
    open_scene = SourceScene("open", "local", (0.0, 0.0), (tucked,), (sliver,))
    m2, i2 = meshes_for_scene(open_scene, 0)
    with VisibilityRenderer(m2, i2, resolution=64, view_distance=VIEW_DISTANCE, ctx=gl, thin_pass=2.0) as r:
        assert 98 in r.cell_counts(eye)[0].tolist()
    with pytest.raises(InputError, match="thin_pass"):
        VisibilityRenderer(meshes, ids, thin_pass=-1.0, ctx=gl)
