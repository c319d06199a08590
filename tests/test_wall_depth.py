"""A virtual wall's texture against what the eye sees through the wall (issue 28).

The trap: a texture rendered from its zone's sampling point is right for that point
only.  A viewer standing nearer the wall than the sampling point (a ring's regions are
tens of metres deep, its walls sampled from the region's middle) saw the texture
magnified about its foot on the wall: on the village's worst frame a far tower a tenth
of the frame off and a block of buildings pushed out of the frame.  Here one pillar
stands behind a wall; where it lands on the texture and where the client lays it are
checked against a ray-plane projection and a render from the eye itself, and so is
the texture drawn as a textured depth mesh (``benchmarks/walldepth.py``).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from walkstream.client.draw.quads import warped
from walkstream.shared.walls import EYE_HEIGHT, NO_WARP, WallSide, zone_slide, zone_warp

_TEXELS = 16  # per metre, both ways
_SIDE = WallSide(0, 0, (-6.0, 20.0), (6.0, 20.0), 0.0, 12.0, 0.0, 0.0, 0.0, 20.0, math.radians(10.0), 1, (0,))
"""A wall 12 m long and 12 m high, 20 m ahead of its one zone's sampling point (the origin)."""
_DEPTH = 10.0
"""How far behind the wall the pillar stands."""
_PILLAR = (2.5, 20.0 + _DEPTH - 0.5, 0.0, 3.5, 20.0 + _DEPTH + 0.5, 6.0)
"""A pillar 1 m square, 6 m high, centred 3 m right of the sampling line."""


def _on_wall(eye: np.ndarray, point: np.ndarray) -> tuple[float, float]:
    """Where the ray from ``eye`` to ``point`` meets the wall: metres from ``p0``, height."""
    t = (20.0 - eye[1]) / (point[1] - eye[1])
    hit = eye + (point - eye) * t
    return float(hit[0] - _SIDE.p0[0]), float(hit[2])


def _pillar(img: np.ndarray) -> tuple[float, float]:
    """The pillar on a wall image ``(h, w, 4)``: its middle column (metres from ``p0``, on
    the eye-height row) and the height of its top (on its middle column)."""
    row = int((_SIDE.z1 - EYE_HEIGHT) * _TEXELS)
    cols = np.flatnonzero(img[row, :, 3] > 127)
    assert len(cols), "the pillar is not on the image"
    mid = int(round(cols.mean()))
    rows = np.flatnonzero(img[:, mid, 3] > 127)
    return (cols.mean() + 0.5) / _TEXELS, _SIDE.z1 - rows.min() / _TEXELS


def _laid(tex: np.ndarray, warp: tuple[float, float, float]) -> np.ndarray:
    """The texture as the client lays it on the wall's quad (the quad's corners' texture
    coordinates from :func:`warped`, interpolated across it, the edge texels outside)."""
    c = warped(_SIDE.corners(), warp)
    uv = np.asarray(c, np.float64)[:, 3:] if np.shape(c) == (4, 5) else np.array([[0, 1], [1, 1], [1, 0], [0, 0.0]])
    h, w = tex.shape[:2]
    fx = (np.arange(w) + 0.5) / w
    fy = (np.arange(h) + 0.5) / h  # 0 at the top
    u = uv[3, 0] + fx * (uv[2, 0] - uv[3, 0])  # the top edge, left to right (the map is affine)
    v = uv[3, 1] + fy[:, None] * (uv[0, 1] - uv[3, 1])
    cols = np.clip(np.floor(u * w), 0, w - 1).astype(int)
    rows = np.clip(np.floor(v[:, 0] * h), 0, h - 1).astype(int)
    out: np.ndarray = tex[rows[:, None], cols[None, :]]
    return out


@pytest.mark.gl
def test_the_texture_laid_for_a_nearer_viewer_shows_what_it_sees_through_the_wall(gl: object) -> None:
    from walkstream.server.bake.wallrender import WallRenderer

    lo, hi = np.asarray(_PILLAR[:3]), np.asarray(_PILLAR[3:])
    corner = np.array([[(i >> k) & 1 for k in range(3)] for i in range(8)], np.float64)
    faces = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    quads = (lo + corner * (hi - lo))[np.array(faces)]
    tri = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])  # the box's 12 triangles
    width = int(_SIDE.length * _TEXELS)
    ren = WallRenderer([(1, tri, np.zeros(len(tri), np.uint8))], ctx=gl)
    eye = np.array([-1.5, 10.0, EYE_HEIGHT])  # 10 m from the wall, 1.5 m left of the sampling line
    try:
        tex = ren.render(_SIDE, 0, width)
        behind = ren.depth_behind(_SIDE, 0, width)
        seen = ren.render(_SIDE, 0, width, eye=eye)
        mesh = _depth_mesh_seen(gl, tex, behind, eye)
        dist, foot = _SIDE.view(eye).distance, float(eye[0] - _SIDE.p0[0])
        warp = tuple(float(g) for g in zone_warp(foot, eye[2], dist, 0, _SIDE.length, _SIDE.depth, EYE_HEIGHT, 0.5))
        drawn = _client_mesh_seen(gl, tex, behind, eye, warp)
    finally:
        ren.release()
    # the depth the texture carries: the pillar's front face 9.5 m behind the wall, nothing elsewhere
    on = np.repeat(np.repeat(tex[..., 3] > 250, 2, axis=0), 2, axis=1)
    assert np.median(behind[on]) == pytest.approx(_DEPTH - 0.5, abs=0.01) and np.isinf(behind[~on]).mean() > 0.99
    # a 16 x 16 depth mesh of it, drawn from the eye, shows the pillar where the eye sees it
    assert ((mesh[..., 3] > 127) != (seen[..., 3] > 127)).mean() < 0.005
    # the client's own (--wall-depth 16: stored, decoded, drawn by the quad renderer, its
    # warped quad where the mesh leaves holes) too; the texture laid flat on the quad does not
    assert ((drawn[..., 3] > 127) != (seen[..., 3] > 127)).mean() < 0.005
    assert ((tex[..., 3] > 127) != (seen[..., 3] > 127)).mean() > 0.01
    centre = np.array([3.0, 20.0 + _DEPTH, 0.0])
    top = np.array([3.0, 20.0 + _DEPTH - 0.5, 6.0])  # the top's near edge bounds it on the wall
    # the texture shows the pillar where the ray from the sampling point meets the wall
    sample = _SIDE.sample_point(0)
    assert _pillar(tex)[0] == pytest.approx(_on_wall(sample, centre + [0, 0, EYE_HEIGHT])[0], abs=1.5 / _TEXELS)
    assert _pillar(tex)[1] == pytest.approx(_on_wall(sample, top)[1], abs=1.5 / _TEXELS)
    # and the render from the eye where the eye's ray does
    want = (_on_wall(eye, centre + [0, 0, EYE_HEIGHT])[0], _on_wall(eye, top)[1])
    assert _pillar(seen) == pytest.approx(want, abs=1.5 / _TEXELS)
    # laid for the eye (as far behind the wall as the eye stands before it: the default
    # parallax share, one half), the texture shows the pillar where the eye sees it
    dist = _SIDE.view(eye).distance
    foot = float(eye[0] - _SIDE.p0[0])
    warp = tuple(float(g) for g in zone_warp(foot, eye[2], dist, 0, _SIDE.length, _SIDE.depth, EYE_HEIGHT, 0.5))
    assert _pillar(_laid(tex, warp)) == pytest.approx(want, abs=1.5 / _TEXELS)
    laid = _laid(tex, warp)[..., 3] > 127
    assert (laid != (seen[..., 3] > 127)).mean() < 0.002  # texel for texel, to the pillar's edges
    # slid along the wall alone (the wall's depth not counted), the eye 10 m from a wall
    # sampled from 20 m saw the pillar magnified, half a metre off and 1.3 times as tall
    slide = float(zone_slide(foot, 0, _SIDE.length, 0.5))
    off = _pillar(_laid(tex, (1.0, -slide, 0.0)))
    assert abs(off[0] - want[0]) > 0.4 and off[1] - EYE_HEIGHT > 1.2 * (want[1] - EYE_HEIGHT)
    assert _laid(tex, NO_WARP) is not tex and np.array_equal(_laid(tex, NO_WARP), tex)


def _depth_mesh_seen(gl: object, tex: np.ndarray, behind: np.ndarray, eye: np.ndarray) -> np.ndarray:
    """``tex`` with its depths ``behind`` as a 16 x 16 depth mesh (8-bit, the nearest
    depth at each vertex) drawn from ``eye`` (``benchmarks/walldepth.py``)."""
    from walkstream.benchmarks.walldepth import MeshDrawer, depth_mesh, quantised, vertex_depths
    from walkstream.shared.gl import Framebuffer
    from walkstream.shared.litimage import SUPERSAMPLE

    at = _SIDE.sample_point(0)
    inv = _SIDE.depth / (_SIDE.depth + np.minimum(behind.astype(np.float64), 1000.0))
    grid = quantised(vertex_depths(inv, 16, "nearest"), 8, _SIDE.depth / (_SIDE.depth + 1000.0))
    drawer = MeshDrawer(gl)
    fb = Framebuffer(gl, (tex.shape[1] * SUPERSAMPLE, tex.shape[0] * SUPERSAMPLE))
    try:
        pic, _ = drawer.draw(_SIDE, eye, at, depth_mesh(_SIDE, at, grid), tex, fb)
    finally:
        fb.release()
        drawer.release()
    return pic


def _client_mesh_seen(gl: object, tex: np.ndarray, behind: np.ndarray, eye: np.ndarray,
                      warp: tuple[float, ...]) -> np.ndarray:
    """``tex`` stored with its 16 x 16 depth grid (:mod:`walkstream.shared.walldepth`),
    decoded as the client does and drawn by its quad renderer from ``eye`` (the mesh, and
    the quad laid by ``warp`` in its holes), at the texture's resolution."""
    from walkstream.client.draw.quads import QuadRenderer, with_mesh
    from walkstream.server.bake.wallrender import off_axis
    from walkstream.shared.codec.image import encode_image
    from walkstream.shared.content.walltex import decode_walltex
    from walkstream.shared.gl import Framebuffer
    from walkstream.shared.litimage import SUPERSAMPLE, average_samples
    from walkstream.shared.walldepth import attach_depth, depth_mesh, encode_depth, vertex_depths

    inv = vertex_depths(behind, _SIDE.depth, 16)
    img = decode_walltex(attach_depth(encode_image(tex), encode_depth(inv)))
    assert img.depth is not None and np.abs(img.depth - inv).max() <= 0.5 / 255 + 1e-9
    assert np.array_equal(img, decode_walltex(encode_image(tex)))  # the image, as without a grid
    corners = with_mesh(warped(_SIDE.corners(), warp), depth_mesh(_SIDE, 0, img.depth))
    fb = Framebuffer(gl, (tex.shape[1] * SUPERSAMPLE, tex.shape[0] * SUPERSAMPLE))
    quads = QuadRenderer(gl)
    try:
        fb.use()
        fb.clear((0.0, 0.0, 0.0, 0.0))
        quads.draw([(corners, -1, img, 1.0)], off_axis(eye, _SIDE))
        assert quads.last_triangles == len(corners) // 3 < 2 + 2 * 16 * 16
        out: np.ndarray = average_samples(fb.read())
    finally:
        quads.release()
        fb.release()
    return out


def test_the_warp_is_the_slide_at_the_sampling_depth_and_exact_for_points_as_deep_as_the_share_says() -> None:
    w, xs = 3.0, 14.0
    for x in (7.0, 14.0, 30.0):
        for share in (0.0, 0.5, 0.8):
            k, along, up = zone_warp(5.1, 1.7, x, 1, w, xs, EYE_HEIGHT, share)
            if x == xs:  # the sampling point's distance: the slide along the wall, nothing else
                assert k == pytest.approx(1.0) and along == pytest.approx(-float(zone_slide(5.1, 1, w, share)))
            p = x * share / (1.0 - share)  # the depth the share is exact for
            for q, z in ((-20.0, 0.0), (3.0, 9.0), (40.0, 25.0)):
                sample, viewer = np.array([4.5, -xs, EYE_HEIGHT]), np.array([5.1, -x, 1.7])
                point = np.array([q, p, z])
                s_at = sample + (point - sample) * xs / (xs + p)  # on the wall plane (y = 0)
                v_at = viewer + (point - viewer) * x / (x + p)
                assert along + k * v_at[0] == pytest.approx(s_at[0]) and up + k * v_at[2] == pytest.approx(s_at[2])
    assert np.allclose(zone_warp(5.1, 1.7, 7.0, 1, w, xs, EYE_HEIGHT, 0.0), NO_WARP)  # share 0: fixed on the wall


def test_a_texture_with_a_depth_grid_is_drawn_as_its_mesh_over_its_warped_quad() -> None:
    from walkstream.client.walk.walls import DrawnWall, _triangles, wall_quads
    from walkstream.shared.walldepth import depth_mesh, with_depth

    side = WallSide(0, 0, (-6.0, 20.0), (6.0, 20.0), 0.0, 12.0, 0.0, 0.0, 0.0, 20.0, math.radians(10.0), 2, (5, 6))
    inv = np.full((9, 9), 20.0 / 1020.0)
    inv[4:6, 3:5] = 20.0 / 29.5  # something near behind the middle of the wall
    rgba = np.zeros((32, 32, 4), np.uint8)
    images = {5: with_depth(rgba, inv), 6: rgba}

    class Lane:
        def image(self, tid: int) -> object:
            return images[tid]

    own = _triangles(Lane(), side, 5, -1)
    mesh = depth_mesh(side, 0, inv)
    # the rows of cells at one depth merged: far fewer than 2 x 8 x 8
    assert own == 2 + len(mesh) // 3 and own < 2 + 64
    assert _triangles(Lane(), side, 6, -1) == 2 and _triangles(Lane(), side, 6, 5) == own
    wall = DrawnWall(0, 0, 0, 5, 1.0, side.corners(), rgba.nbytes, (0, 1), side_of=side, triangles=own)
    (corners, key, image, alpha), = wall_quads([wall], images.get)
    assert key == -6 and image is images[5] and alpha == 1.0 and corners.shape == (6 + len(mesh), 6)
    assert np.allclose(corners[6:], mesh) and np.allclose(corners[:6, :3], side.corners()[[0, 1, 2, 0, 2, 3]])
    # each vertex where the sampling point saw it: on its ray through the wall, at its depth
    at = side.sample_point(0)
    u, q = corners[6:, 3] / corners[6:, 5], corners[6:, 5]
    assert np.allclose(at[1] + (20.0 - at[1]) * q, corners[6:, 1])
    assert np.allclose(at[0] + (side.p0[0] + u * side.length - at[0]) * q, corners[6:, 0], atol=1e-3)
    # a texture without a grid is the quad as before
    flat = DrawnWall(0, 0, 1, 6, 1.0, side.corners(), rgba.nbytes, (0, 1), side_of=side)
    assert wall_quads([flat], images.get)[0][0].shape == (4, 3)


def test_a_depth_mesh_covers_its_wall_once_with_flat_blocks_merged() -> None:
    from walkstream.shared.walldepth import depth_mesh

    rng = np.random.default_rng(1)
    for g in (4, 8, 16):
        inv = np.full((g + 1, g + 1), 0.02)
        near = rng.random((g + 1, g + 1)) < 0.3
        inv[near] = rng.choice([0.5, 0.7], int(near.sum()))
        tri = depth_mesh(_SIDE, 0, inv).reshape(-1, 3, 6).astype(np.float64)
        uv = tri[..., 3:5] / tri[..., 5:6]  # where on the texture (and the wall) each corner is
        e1, e2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
        assert np.abs(e1[:, 0] * e2[:, 1] - e2[:, 0] * e1[:, 1]).sum() / 2 == pytest.approx(1.0)
        assert len(tri) < 2 * g * g
    # one depth everywhere: one quad
    assert len(depth_mesh(_SIDE, 0, np.full((9, 9), 0.02))) == 6


def test_the_wall_floor_counts_as_the_truth_and_lays_ideal_textures_unwarped() -> None:
    """``benchmarks/wallfloor.py``: the pieces of its arithmetic (the replay around it is a benchmark)."""
    from walkstream.benchmarks.wallfloor import (
        MAX_WIDTH,
        FloorRun,
        edge_mask,
        frame_width,
        ideal_quads,
        ring_holes,
        summarise,
        table,
        texture_id,
    )

    assert texture_id(-1) == 0 and texture_id(-1 - 41) == 41  # the client keys a texture -1 - id
    # 120 rows at 60 degrees: 120 / (2 tan 30°) = 103.9 pixels a metre at 1 m, 10.39 at 10 m
    p11 = 1.0 / math.tan(math.radians(30.0))
    assert frame_width(20.0, 10.0, p11, 120, 1.0) == 208  # a 20 m wall at 10 m: 207.8 pixels across
    assert frame_width(20.0, 10.0, p11, 120, 4.0) == 832
    assert frame_width(20.0, 0.0, p11, 120, 8.0) == MAX_WIDTH
    s = summarise([0.0, 0.005, 0.01, 0.02])  # at most 1 % counts as within
    assert s["wall1"] == 0.75 and s["median"] == pytest.approx(0.0075) and s["mean"] == pytest.approx(0.00875)
    assert math.isnan(summarise([])["wall1"])
    # a wall blending with its neighbour zone: two quads, both replaced, fresh negative keys, opacities kept
    corners = np.hstack([_SIDE.corners(), np.array([[0.1, 1.0], [0.9, 1.0], [0.9, 0.0], [0.1, 0.0]])])
    tex = np.zeros((4, 4, 4), np.uint8)
    quads = [(corners, -1 - 7, tex, 0.6), (corners, -1 - 8, tex, 0.3), (corners, -1 - 99, tex, 1.0)]
    ideal = np.full((8, 8, 4), 255, np.uint8)
    keys = iter([-100, -101])
    out = ideal_quads(quads, lambda t: ideal if t in (7, 8) else None, lambda: next(keys))
    assert [q[1] for q in out] == [-100, -101, -1 - 99] and [q[3] for q in out] == [0.6, 0.3, 1.0]
    assert out[0][0].shape == (4, 3) and out[0][2] is ideal  # laid on the quad as it is: no warp
    assert out[2][0] is corners and out[2][2] is tex  # a texture it has none for stays as drawn
    kept = ideal_quads(quads[:1], lambda t: ideal, lambda: -5, warp=True)
    assert kept[0][0].shape == (4, 5)
    # a ring 10 x 6 m (corner k + 1 to corner k, as the bake lays them): every box meeting it is a hole
    ring_corners = [(-5.0, -3.0), (5.0, -3.0), (5.0, 3.0), (-5.0, 3.0)]
    ring = [WallSide(4 * 3 + k, 0, ring_corners[(k + 1) % 4], ring_corners[k], 0.0, 10.0, 0.0, 0.0, 0.0, 3.0,
                     math.radians(10.0), 1, (k,)) for k in range(4)]
    boxes = np.array([[-1, -1, 0, 1, 1, 5],  # inside
                      [4, 2, 0, 7, 4, 5],  # across the corner
                      [5.5, -1, 0, 8, 1, 5],  # beyond the right wall
                      [6, 4, 0, 7, 5, 5]], np.float64)  # off the corner
    assert ring_holes(ring, np.array([10, 11, 12, 13]), boxes) == (10, 11)
    assert ring_holes(ring[:3], np.array([10]), boxes[:1]) == ()
    # edges: a pixel visibly different from a neighbour, both sides of the step
    pic = np.full((3, 4, 3), 200, np.uint8)
    pic[:, 2:] = 60
    assert edge_mask(pic).tolist() == [[False, True, True, False]] * 3
    # the table: a row a variant; the viewer's scale only when it was counted
    run = FloorRun(["today", "eye x1"], frames=[1, 2], wrong={"today": [0.02, 0.0], "eye x1": [0.005, 0.0]},
                   painted={"today": [0.1, 0.0], "eye x1": [0.1, 0.0]}, texels={"today": [4.0], "eye x1": [4.0]},
                   edges=[0.05, 0.0])
    text = table(run)
    assert "2 compared frames, 1 of them drawing a wall" in text and "viewer-scale" not in text
    assert "| today | 4.0 | 50.0 % |" in text and "| eye x1 | 4.0 | 100.0 % |" in text
