"""The cell-contents codec (walkstream-cellmesh/1): round trips, its error bound, bounded decoding."""

from __future__ import annotations

import msgpack
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from walkstream.shared.codec.cellmesh import (
    CELLMESH_FORMAT,
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
    blob = encode_cell_mesh(ps, compress=compress)
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
    blob = encode_cell_mesh([(7, 13, v, t)])
    assert len(blob) < 0.35 * raw_bytes(len(v), len(t))


def test_damaged_blobs_are_codec_errors() -> None:
    v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    blob = encode_cell_mesh([(1, 2, v, [[0, 1, 2]])], compress="zlib")
    for bad in (b"", b"Z", blob[:-5], b"Q" + blob[1:], b"N" + b"\x81\xa1x\x01", b"Z" + b"\x00" * 20):
        with pytest.raises(CodecError):
            decode_cell_mesh(bad)
    # a well-formed map whose index points past its vertices
    body = msgpack.unpackb(decode_cell_mesh.__globals__["_decompress"](blob, "x"), raw=False)
    assert body["format"] == CELLMESH_FORMAT
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
