"""The cell-contents codec (walkstream-cellmesh/1, /2, /3): round trips, its error bound, bounded decoding."""

from __future__ import annotations

import msgpack
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from walkstream.shared.codec.cellmesh import (
    CELLMESH_FORMAT,
    CELLMESH_V1,
    CELLMESH_V2,
    decode_cell_mesh,
    encode_cell_mesh,
    flat_normals,
    position_error_bound,
    raw_bytes,
)
from walkstream.shared.errors import CodecError


@st.composite
def parts(draw: st.DrawFn) -> list[tuple[int, int, np.ndarray, np.ndarray]]:
    n_parts = draw(st.integers(1, 5))
    scale = draw(st.sampled_from([0.01, 1.0, 40.0, 300.0]))
    centre = draw(st.sampled_from([0.0, 150.0, -2000.0]))
    out = []
    for _ in range(n_parts):
        n = draw(st.integers(3, 40))
        seed = draw(st.integers(0, 2**31 - 1))
        rng = np.random.default_rng(seed)
        pos = centre + rng.uniform(-scale, scale, (n, 3))
        tri = rng.integers(0, n, (draw(st.integers(1, 60)), 3))
        out.append((draw(st.integers(0, 10**9)), draw(st.integers(0, 255)), pos, tri))
    return out


@given(parts(), st.sampled_from(["best", "zlib", "lzma", "none"]))
@settings(max_examples=60, deadline=None)
def test_round_trip_within_the_stated_bound(ps: list, compress: str) -> None:
    blob = encode_cell_mesh(ps, compress=compress, version=1)
    cm = decode_cell_mesh(blob)
    allp = np.concatenate([p[2] for p in ps])
    bound = position_error_bound(np.ptp(allp, axis=0))
    f32 = 2.0**-24 * np.abs(allp).max(axis=0)  # float32 rounding of the decoded value
    assert len(cm.parts) == len(ps) and cm.nbytes == len(blob)
    for (element, material, pos, tri), got in zip(ps, cm.parts, strict=True):
        assert got.element == element and got.material == material
        assert np.array_equal(got.indices, tri)
        err = np.abs(got.positions.astype(np.float64) - pos).max(axis=0)
        assert np.all(err <= bound + f32 + 1e-12)
    assert cm.error_bound == pytest.approx(float(bound.max()))


def test_bound_is_half_a_step_of_16_bits() -> None:
    assert float(position_error_bound([65.535])[0]) == pytest.approx(0.0005)
    # a 30 m room: a quarter of a millimetre
    assert float(position_error_bound([30.0])[0]) < 0.00023


def test_it_is_smaller_than_raw_float32_on_a_real_looking_cell() -> None:
    # a room's walls, floor and some boxes: 40 boxes of 12 triangles
    from walkstream.server.sources.interiormesh import box_mesh

    rng = np.random.default_rng(1)
    rows = np.column_stack(
        [rng.uniform(0, 6, 40), rng.uniform(0, 4, 40), rng.uniform(0.05, 1.5, 40), rng.uniform(0.05, 1.0, 40),
         rng.uniform(0, 3, 40), np.zeros(40), rng.uniform(0.3, 2.5, 40)]
    )
    v, t = box_mesh(rows)
    blob = encode_cell_mesh([(7, 13, v, t)], version=1)
    assert len(blob) < 0.35 * raw_bytes(len(v), len(t))


def test_damaged_blobs_are_codec_errors() -> None:
    v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    blob = encode_cell_mesh([(1, 2, v, [[0, 1, 2]])], compress="zlib", version=1)
    for bad in (b"", b"Z", blob[:-5], b"Q" + blob[1:], b"N" + b"\x81\xa1x\x01", b"Z" + b"\x00" * 20):
        with pytest.raises(CodecError):
            decode_cell_mesh(bad)
    # a well-formed map whose index points past its vertices
    body = msgpack.unpackb(decode_cell_mesh.__globals__["_decompress"](blob, "x"), raw=False)
    assert body["format"] == CELLMESH_V1
    body["indices"] = bytes([2, 2, 2])  # zigzag varints of +1 +1 +1: indices 1, 2, 3
    with pytest.raises(CodecError, match="out of range"):
        decode_cell_mesh(b"N" + msgpack.packb(body, use_bin_type=True))
    with pytest.raises(CodecError, match="index out of range"):
        encode_cell_mesh([(1, 2, v, [[0, 1, 3]])])
    with pytest.raises(CodecError, match="non-finite"):
        encode_cell_mesh([(1, 2, np.full((3, 3), np.nan), [[0, 1, 2]])])


def test_flat_normals_of_a_box_point_outwards() -> None:
    from walkstream.server.sources.interiormesh import box_mesh

    v, t = box_mesh([[0, 0, 2, 2, 0, 0, 2]])
    tri = v[t]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    centre = tri.mean(axis=1)
    assert np.all(np.einsum("ij,ij->i", n, centre - np.array([0, 0, 1.0])) > 0)
    vn = flat_normals(v, t)
    assert np.allclose(np.linalg.norm(vn, axis=1), 1.0, atol=1e-6)


# ---- walkstream-cellmesh/2: planar polygons on a 1 mm grid


def _tri_points(pos: np.ndarray, idx: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """``(n, 3)`` points spread over a mesh's triangles (by area)."""
    c = np.asarray(pos, np.float64)[np.asarray(idx, np.int64)]
    area = 0.5 * np.linalg.norm(np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]), axis=1)
    k = rng.choice(len(c), n, p=area / area.sum())
    u, v = rng.uniform(0, 1, (2, n))
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    t = c[k]
    return t[:, 0] + u[:, None] * (t[:, 1] - t[:, 0]) + v[:, None] * (t[:, 2] - t[:, 0])


def _distance(points: np.ndarray, pos: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """``(n,)`` distance of each point to the nearest triangle (closest point: face or edges)."""
    c = np.asarray(pos, np.float64)[np.asarray(idx, np.int64)]  # (t, 3, 3)
    p = points[:, None, :]  # (n, 1, 3)
    a, b, cc = c[None, :, 0], c[None, :, 1], c[None, :, 2]
    n = np.cross(b - a, cc - a)
    nn = np.maximum(np.einsum("...i,...i", n, n), 1e-30)
    d = np.einsum("...i,...i", p - a, n) / nn
    q = p - d[..., None] * n  # projection on the plane
    inside = np.ones(q.shape[:2], bool)
    for s, e in ((a, b), (b, cc), (cc, a)):
        inside &= np.einsum("...i,...i", np.cross(e - s, q - s), n) >= -1e-12
    best = np.where(inside, np.abs(d) * np.sqrt(nn), np.inf)
    for s, e in ((a, b), (b, cc), (cc, a)):
        se = e - s
        t = np.clip(np.einsum("...i,...i", p - s, se) / np.maximum(np.einsum("...i,...i", se, se), 1e-30), 0, 1)
        best = np.minimum(best, np.linalg.norm(p - (s + t[..., None] * se), axis=-1))
    return best.min(axis=1)


def _same_surface(before: tuple, after, rng: np.random.Generator) -> None:
    from walkstream.shared.codec.planarmesh import area_tolerance, mesh_area

    _, _, pos, idx = before
    a0, a1 = mesh_area(pos, idx), mesh_area(after.positions, after.indices)
    assert abs(a1 - a0) <= area_tolerance(pos, idx)
    # covered sample points agree both ways, to the bound (0.5 mm a coordinate: 0.87 mm)
    assert _distance(_tri_points(pos, idx, 300, rng), after.positions, after.indices).max() < 0.9e-3
    assert _distance(_tri_points(after.positions, after.indices, 300, rng), pos, idx).max() < 0.9e-3
    # every decoded vertex is a corner of a triangle with area: none is left on another
    # triangle's edge alone (a T-junction, where a hairline crack can open)
    p, t = after.positions.astype(np.float64), after.indices.astype(np.int64)
    live = np.linalg.norm(np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]]), axis=1) > 1e-9
    assert len(np.unique(t[live])) == len(p)


def _grid_wall(nx: int, ny: int, hole: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """A 4 m x 3 m wall in the x-z plane cut into ``nx * ny`` quads (two triangles each),
    facing -y; with ``hole`` the middle quads are left out (a door opening)."""
    xs, zs = np.linspace(0.0, 4.0, nx + 1), np.linspace(0.0, 3.0, ny + 1)
    gx, gz = np.meshgrid(xs, zs, indexing="ij")
    pos = np.column_stack([gx.ravel() + 10.0, np.full(gx.size, 5.0), gz.ravel()])
    tris = []
    for i in range(nx):
        for j in range(ny):
            if hole and 0 < i < nx - 1 and 0 < j < ny - 1:
                continue
            v0, v1, v2, v3 = i * (ny + 1) + j, (i + 1) * (ny + 1) + j, (i + 1) * (ny + 1) + j + 1, i * (ny + 1) + j + 1
            tris += [[v0, v1, v2], [v0, v2, v3]]
    return pos, np.array(tris)


def test_v2_merges_a_clipped_wall_into_one_polygon_with_its_hole() -> None:
    rng = np.random.default_rng(3)
    pos, tri = _grid_wall(8, 6, hole=True)
    part = (42, 7, pos, tri)
    blob2, blob1 = encode_cell_mesh([part]), encode_cell_mesh([part], version=1)
    cm = decode_cell_mesh(blob2)
    assert msgpack.unpackb(decode_cell_mesh.__globals__["_decompress"](blob2, "x"))["format"] == CELLMESH_FORMAT
    got = cm.parts[0]
    assert (got.element, got.material) == (42, 7)
    assert got.triangles < len(tri) // 4  # 8 corners of the outline and the hole: 8 triangles
    assert len(blob2) < len(blob1)
    _same_surface(part, got, rng)
    # the faces still face -y (the winding is kept) and the normals are flat
    n = got.mesh().normals
    assert np.allclose(n, [0.0, -1.0, 0.0], atol=1e-6)
    assert cm.error_bound == pytest.approx(0.0005)


def test_v2_keeps_a_vertex_another_plane_of_the_part_uses() -> None:
    # two walls meeting at a corner; the first is cut at x=12 and so has a vertex on
    # the corner edge's mid-height that the second (one quad) has too: dropping it from
    # either would open a T-junction
    rng = np.random.default_rng(4)
    a_pos, a_tri = _grid_wall(2, 2)  # x 10..14, y = 5, z 0..3, vertex (14, 5, 1.5) on the edge
    b_pos = np.array([[14.0, 5.0, 0.0], [14.0, 8.0, 0.0], [14.0, 8.0, 3.0], [14.0, 5.0, 3.0], [14.0, 5.0, 1.5]])
    b_tri = np.array([[0, 1, 4], [1, 2, 4], [2, 3, 4]])
    pos = np.concatenate([a_pos, b_pos])
    tri = np.concatenate([a_tri, b_tri + len(a_pos)])
    got = decode_cell_mesh(encode_cell_mesh([(1, 1, pos, tri)])).parts[0]
    _same_surface((1, 1, pos, tri), got, rng)
    p = got.positions.astype(np.float64)
    on_edge = np.all(np.isclose(p, [14.0, 5.0, 1.5]), axis=1)
    assert on_edge.sum() == 2  # kept by both regions
    # and the middle vertices of the first wall that only it uses are gone
    assert not np.any(np.all(np.isclose(p, [12.0, 5.0, 1.5]), axis=1))


def test_v2_keeps_triangles_where_merging_is_unsafe() -> None:
    rng = np.random.default_rng(5)
    # overlapping coplanar triangles (their union is smaller than their sum) and a
    # non-planar fan: both come back as the same surface
    over = np.array([[0.0, 0, 0], [2, 0, 0], [0, 2, 0], [1, 0, 0], [3, 0, 0], [1, 2, 0]])
    fan = np.array([[0.0, 0, 1], [1, 0, 1.3], [1, 1, 1.1], [0, 1, 1.6], [0.5, 0.5, 2.0]])
    parts = [(1, 3, over, [[0, 1, 2], [3, 4, 5]]), (2, 3, fan, [[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]])]
    cm = decode_cell_mesh(encode_cell_mesh(parts))
    assert [p.triangles for p in cm.parts] == [2, 4]
    for before, after in zip(parts, cm.parts, strict=True):
        _same_surface((before[0], before[1], np.asarray(before[2]), np.asarray(before[3])), after, rng)


@given(parts())
@settings(max_examples=30, deadline=None)
def test_v2_random_soups_keep_their_surface(ps: list) -> None:
    from walkstream.shared.codec.planarmesh import area_tolerance, mesh_area

    cm = decode_cell_mesh(encode_cell_mesh(ps))
    assert len(cm.parts) == len(ps)
    for (element, material, pos, tri), got in zip(ps, cm.parts, strict=True):
        assert (got.element, got.material) == (element, material)
        q = np.rint(np.asarray(pos) / 0.001) * 0.001
        # every decoded vertex is an encoded vertex on the grid
        d = np.abs(got.positions.astype(np.float64)[:, None, :] - q[None]).max(axis=2).min(axis=1)
        assert np.all(d <= 2.0**-24 * np.abs(q).max() + 1e-9)
        assert abs(mesh_area(got.positions, got.indices) - mesh_area(pos, tri)) <= area_tolerance(pos, tri) + 1e-6 * (
            1 + np.abs(pos).max()
        ) ** 2 * len(tri)


def test_v2_bad_input_is_a_codec_error() -> None:
    pos, tri = _grid_wall(2, 2, hole=False)
    blob = encode_cell_mesh([(1, 2, pos, tri), (3, 4, pos + 1.0, tri)], compress="none", version=2)
    body = msgpack.unpackb(blob[1:], raw=False)
    assert body["format"] == CELLMESH_V2 and body["regions"] == bytes([1, 1])

    def bad(**change: object) -> None:
        b = dict(body, **change)
        with pytest.raises(CodecError) as exc:
            decode_cell_mesh(b"N" + msgpack.packb(b, use_bin_type=True))
        assert "\n" not in str(exc.value)

    bad(regions=bytes([1, 2]))  # a region more than the rings say
    bad(rings=bytes([0, 1]))  # a region without rings
    bad(ring_sizes=bytes([2] * (len(body["ring_sizes"]))))  # a ring of 2 vertices
    bad(ring_sizes=bytes([0xFF, 0xFF, 0x7F]) + body["ring_sizes"][1:])  # a ring over the limit
    bad(positions=body["positions"][:-3])  # truncated positions
    bad(positions=bytes([0xFF] * 9 + [0x01]) + body["positions"][10:])  # a position beyond the grid's range
    bad(parts=3)
    bad(materials=b"\x02")
    bad(extra=b"")
    bad(indices=b"\xff")
    bad(vertices="3")
    with pytest.raises(CodecError, match="version"):
        encode_cell_mesh([(1, 2, pos, tri)], version=5)
    with pytest.raises(CodecError, match="beyond"):
        encode_cell_mesh([(1, 2, pos + 2e9, tri)])


# ---- walkstream-cellmesh/4: the remaining triangles share their corners


def _handrail(n: int = 24, m: int = 12, z: float = 0.9) -> tuple[np.ndarray, np.ndarray]:
    """A bent tube (a handrail round a turn) as an exporter writes it: ``n * m * 2`` small
    triangles on no common plane, each with corners of its own (none shared)."""
    a = np.linspace(0.0, np.pi / 2, n + 1)[:, None]  # along the turn
    b = np.linspace(0.0, 2 * np.pi, m + 1)[None, :]  # round the tube
    b = b + 3.0 * a  # twisted (rings along a real rail's sweep do not line up): no quad is planar
    r = 1.0 + 0.025 * np.cos(b)
    grid = np.stack(np.broadcast_arrays(r * np.cos(a), r * np.sin(a), z + 0.025 * np.sin(b)), axis=-1)  # (n+1, m+1, 3)
    i, j = np.meshgrid(np.arange(n), np.arange(m), indexing="ij")
    v = lambda di, dj: (i + di) * (m + 1) + (j + dj)  # noqa: E731
    tri = np.concatenate([np.stack([v(0, 0), v(1, 0), v(1, 1)], -1), np.stack([v(0, 0), v(1, 1), v(0, 1)], -1)]).reshape(-1, 3)
    pts = grid.reshape(-1, 3)
    return pts[tri].reshape(-1, 3), np.arange(3 * len(tri)).reshape(-1, 3)


def test_v4_welds_a_curved_part_and_keeps_its_normals_flat() -> None:
    rng = np.random.default_rng(4)
    rail = _handrail()
    ps = [(7, 3, *rail), (8, 3, *_handrail(z=1.9)), (9, 4, *_grid_wall(2, 2))]
    blob = encode_cell_mesh(ps, compress="none")
    body = msgpack.unpackb(blob[1:], raw=False)
    assert body["format"] == CELLMESH_FORMAT == "walkstream-cellmesh/4"
    v3 = encode_cell_mesh(ps, compress="none", version=3)
    # a vertex per grid point, not per corner: the positions and indices shrink
    assert len(blob) < 0.6 * len(v3)
    assert len(encode_cell_mesh(ps)) < 0.8 * len(encode_cell_mesh(ps, version=3))
    cm = decode_cell_mesh(blob)
    for before, after in zip(ps, cm.parts, strict=True):
        _same_surface(before, after, rng)
        # facing the same way (a 5 cm tube on a 1 mm grid: its area to 2 %)
        assert np.allclose(_signed_areas(before[2], before[3]), _signed_areas(after.positions, after.indices), rtol=0.02)
    # every triangle has corners of its own again: each vertex normal is its face's
    got = cm.parts[0]
    c = got.positions.astype(np.float64)[got.indices.astype(np.int64)]
    fn = np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])
    fn /= np.linalg.norm(fn, axis=1, keepdims=True)
    # (to the plane groups' 1e-3: nearly flat pairs go as one quadrilateral; smoothing would turn them by ~0.3)
    assert np.allclose(got.mesh().normals[got.indices.astype(np.int64)], fn[:, None, :], atol=5e-3)
    # a version 3 blob of the same parts decodes to the same surface
    for before, after in zip(ps, decode_cell_mesh(v3).parts, strict=True):
        _same_surface(before, after, rng)


def test_v4_refuses_index_codes_out_of_range() -> None:
    blob = encode_cell_mesh([(7, 3, *_handrail(4, 4)), (8, 3, *_handrail(4, 4, z=2.0))], compress="none")
    body = msgpack.unpackb(blob[1:], raw=False)

    def bad(**change: object) -> None:
        with pytest.raises(CodecError, match="indices") as exc:
            decode_cell_mesh(b"N" + msgpack.packb(dict(body, **change), use_bin_type=True))
        assert "\n" not in str(exc.value)

    codes = bytearray(body["indices"])
    assert codes[0] == 0  # the first corner is a new vertex
    bad(indices=bytes([5]) + bytes(codes[1:]))  # a code reaching before the first vertex
    bad(indices=bytes([0] * len(codes)))  # every corner new: the first part takes the second's vertices
    last_new = len(codes) - 1 - codes[::-1].index(0)
    codes[last_new] = 1
    bad(indices=bytes(codes))  # the last vertex never brought in


# ---- walkstream-cellmesh/3: boxes and axis rectangles in their own fields

_BOX_FACES = np.array(  # a unit box's twelve triangles over its corners (bit 0: x, 1: y, 2: z), facing out
    [[0, 4, 6], [0, 6, 2], [1, 3, 7], [1, 7, 5], [0, 1, 5], [0, 5, 4],
     [2, 6, 7], [2, 7, 3], [0, 2, 3], [0, 3, 1], [4, 5, 7], [4, 7, 6]]
)


def _box(lo: np.ndarray, size: np.ndarray, drop: tuple[int, ...] = (), flip: bool = False) -> tuple:
    """``(positions (8, 3), triangles)`` of an axis-aligned box, without the faces in ``drop``
    (0..5: -x, +x, -y, +y, -z, +z) and wound inwards when ``flip``."""
    bits = (np.arange(8)[:, None] >> np.arange(3)) & 1
    pos = np.asarray(lo, np.float64) + bits * np.asarray(size, np.float64)
    tri = np.concatenate([_BOX_FACES[2 * f : 2 * f + 2] for f in range(6) if f not in drop])
    return pos, tri[:, ::-1] if flip else tri


def _signed_areas(pos: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """``(6,)`` the area facing +x, +y, +z and -x, -y, -z: a face turned round changes it."""
    c = np.asarray(pos, np.float64)[np.asarray(idx, np.int64)]
    n = 0.5 * np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])
    return np.concatenate([np.clip(n, 0, None).sum(axis=0), np.clip(n, None, 0).sum(axis=0)])


def test_v3_sends_a_box_as_six_numbers_and_keeps_its_faces_outwards() -> None:
    rng = np.random.default_rng(6)
    whole = _box([1.0, 2.0, 0.0], [1.2, 0.6, 0.75])
    open_top = _box([3.0, 2.0, 0.0], [0.45, 0.45, 0.9], drop=(5,))  # clipped by a cell's ceiling
    reveal = _box([5.0, 2.0, 0.0], [0.3, 0.3, 0.3], drop=(2, 3), flip=True)  # a window's opening
    floor = _grid_wall(1, 1)  # one rectangle
    ps = [(10, 4, *whole), (11, 4, *open_top), (12, 5, *reveal), (13, 6, *floor)]
    blob = encode_cell_mesh(ps, compress="none")
    body = msgpack.unpackb(blob[1:], raw=False)
    assert body["format"] == CELLMESH_FORMAT
    assert body["box_counts"] == bytes([1, 1, 1, 0]) and len(body["boxes"]) <= 3 * 12  # six varints a box
    assert body["box_faces"] == bytes([63, 31, 64 | 0b110011])  # all; no +z; inwards, no y faces
    assert body["rect_counts"] == bytes([0, 0, 0, 1]) and body["rect_kinds"] == bytes([2])  # facing -y
    assert body["positions"] == b"" and body["indices"] == b""
    cm = decode_cell_mesh(blob)
    for before, after in zip(ps, cm.parts, strict=True):
        _same_surface(before, after, rng)
        assert np.allclose(_signed_areas(before[2], before[3]), _signed_areas(after.positions, after.indices), atol=1e-6)
    # flat normals point out of the whole box (no vertex shared by two faces)
    got = cm.parts[0]
    centre = np.array([1.6, 2.3, 0.375])
    tri_c = got.positions[got.indices.astype(np.int64)].mean(axis=1)
    fn = got.mesh().normals[got.indices[:, 0]]
    assert np.all(np.einsum("ij,ij->i", fn, tri_c - centre) > 0)
    v2 = encode_cell_mesh(ps, compress="none", version=2)
    assert len(blob) < 0.75 * len(v2)
    # the older format still decodes to the same surface
    for before, after in zip(ps, decode_cell_mesh(v2).parts, strict=True):
        _same_surface(before, after, rng)


def test_v3_keeps_a_wall_vertex_a_box_corner_uses() -> None:
    # a desk against a wall cut in four: the wall's vertex (12, 5, 0) lies on its straight
    # bottom edge, and the desk's corner is there too: dropping it would be a T-junction
    wall_pos, wall_tri = _grid_wall(2, 2)
    desk_pos, desk_tri = _box([12.0, 4.0, 0.0], [1.0, 1.0, 0.75])
    pos = np.concatenate([wall_pos, desk_pos])
    tri = np.concatenate([wall_tri, desk_tri + len(wall_pos)])
    got = decode_cell_mesh(encode_cell_mesh([(1, 1, pos, tri)])).parts[0]
    _same_surface((1, 1, pos, tri), got, np.random.default_rng(7))
    p = got.positions.astype(np.float64)
    assert np.all(np.isclose(p, [12.0, 5.0, 0.0]), axis=1).sum() >= 3  # the wall's ring and two desk faces
    assert not np.any(np.all(np.isclose(p, [12.0, 5.0, 1.5]), axis=1))  # the wall's own middle: dropped


@given(st.integers(0, 2**31 - 1), st.integers(1, 6))
@settings(max_examples=25, deadline=None)
def test_v3_random_box_furniture_keeps_its_surface(seed: int, n: int) -> None:
    rng = np.random.default_rng(seed)
    ps = []
    for k in range(n):
        lo = rng.integers(-5000, 5000, 3) * 0.001 + rng.choice([0.0, 100.0])
        size = rng.integers(1, 2000, 3) * 0.001
        drop = tuple(rng.choice(6, rng.integers(0, 3), replace=False).tolist())
        pos, tri = _box(lo, size, drop, flip=bool(rng.integers(0, 4) == 0))
        if rng.integers(0, 2):  # another diagonal, another vertex order
            order = rng.permutation(8)
            pos, tri = pos[order], np.argsort(order)[tri]
        if rng.integers(0, 3) == 0:  # two boxes in one part, overlapping (a frame)
            p2, t2 = _box(lo + np.floor(size / 0.002) * 0.001, size, ())  # on the grid: no rounding
            pos, tri = np.concatenate([pos, p2]), np.concatenate([tri, t2 + 8])
        ps.append((k, k % 3, pos, tri))
    from walkstream.shared.codec.planarmesh import area_tolerance

    for before, after in zip(ps, decode_cell_mesh(encode_cell_mesh(ps)).parts, strict=True):
        _same_surface(before, after, rng)
        turned = _signed_areas(before[2], before[3]) - _signed_areas(after.positions, after.indices)
        assert np.abs(turned).max() <= area_tolerance(before[2], before[3])


def test_v3_bad_input_is_a_codec_error() -> None:
    ps = [(1, 2, *_box([0.0, 0, 0], [1.0, 1, 1])), (3, 4, *_box([2.0, 0, 0], [1.0, 1, 1], drop=(0,)))]
    ps += [(5, 6, *_grid_wall(1, 1))]
    blob = encode_cell_mesh(ps, compress="none")
    body = msgpack.unpackb(blob[1:], raw=False)
    assert body["box_counts"] == bytes([1, 1, 0]) and body["rect_counts"] == bytes([0, 0, 1])

    def bad(drop: tuple[str, ...] = (), **change: object) -> None:
        b = {k: v for k, v in dict(body, **change).items() if k not in drop}
        with pytest.raises(CodecError) as exc:
            decode_cell_mesh(b"N" + msgpack.packb(b, use_bin_type=True))
        assert "\n" not in str(exc.value)

    bad(rect_kinds=b"\x06")  # no such kind
    bad(rect_kinds=b"")  # a kind short
    bad(box_faces=b"\x3f\x40")  # a box of no faces
    bad(box_faces=b"\x3f\x80")  # an unknown bit
    bad(box_faces=b"\x3f")  # a box's faces missing
    bad(rects=body["rects"][:-1])  # truncated
    bad(boxes=body["boxes"][:-1] + b"\x00")  # a box of no size
    bad(boxes=body["boxes"][:3] + bytes([0xFF] * 9 + [0x01]) + body["boxes"][4:])  # beyond the grid
    bad(box_counts=bytes([2, 1, 0]))  # more boxes than sent
    bad(drop=("rect_counts",))  # rectangles without counts
    bad(drop=("boxes",))
    bad(format=CELLMESH_V2)  # /2 knows no boxes


def test_v3_pairs_overlapping_rectangles_that_cannot_merge() -> None:
    # a window frame's jamb and sill overlap in the frame's front plane: the union is
    # smaller than the sum, so version 2 keeps the four triangles; version 3 sends two
    # rectangles (their halves pair up), with the same surface
    jamb = np.array([[0.0, 0, 0], [0.06, 0, 0], [0.06, 0, 1.5], [0.0, 0, 1.5]])
    sill = np.array([[0.0, 0, 0], [1.4, 0, 0], [1.4, 0, 0.06], [0.0, 0, 0.06]])
    pos = np.concatenate([jamb, sill])
    tri = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    part = (9, 17, pos, tri)
    body2 = msgpack.unpackb(encode_cell_mesh([part], compress="none", version=2)[1:], raw=False)
    body3 = msgpack.unpackb(encode_cell_mesh([part], compress="none")[1:], raw=False)
    assert body2["triangles"] == bytes([4]) and body3["triangles"] == bytes([0])
    assert body3["rect_counts"] == bytes([2]) and body3["rect_kinds"] == bytes([2, 2])  # both face -y
    got = decode_cell_mesh(encode_cell_mesh([part])).parts[0]
    _same_surface(part, got, np.random.default_rng(8))
    assert np.allclose(_signed_areas(pos, tri), _signed_areas(got.positions, got.indices), atol=1e-6)


@pytest.mark.parametrize("version", [2, 3])
def test_a_cell_without_parts_round_trips(version: int) -> None:
    """An empty cell (nothing of the model inside it) encodes and decodes to no part,
    never a numpy error."""
    m = decode_cell_mesh(encode_cell_mesh([], version=version), "empty")
    assert m.parts == () and m.triangles == 0 and m.vertices == 0
