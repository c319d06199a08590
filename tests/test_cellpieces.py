"""A cell's parts cut into pieces for culling: the same triangles, fewer drawn through a door."""

from __future__ import annotations

import math

import numpy as np
import pytest

from walkstream.shared.camera import camera, perspective
from walkstream.shared.codec.cellmesh import CellMesh, CellPart, encode_cell_mesh
from walkstream.shared.codec.cellpieces import (
    PIECE_TRIANGLES,
    cell_pieces,
    decode_cell_pieces,
    split_part,
)
from walkstream.shared.content.cellmesh import KIND
from walkstream.shared.partcull import cull_parts

SIZE = (160, 120)


def _helix(n: int, centre: tuple[float, float] = (6.0, 0.0), radius: float = 1.5) -> CellPart:
    """A curved stair's underside: ``n`` triangles winding up around ``centre``, a turn and a half."""
    a = np.linspace(0.0, 3.0 * math.pi, n // 2 + 1)
    z = np.linspace(0.0, 2.8, len(a))
    inner = np.stack([centre[0] + 0.3 * np.cos(a), centre[1] + 0.3 * np.sin(a), z], axis=1)
    outer = np.stack([centre[0] + radius * np.cos(a), centre[1] + radius * np.sin(a), z], axis=1)
    pos = np.concatenate([inner, outer])
    m = len(a)
    tri = [(i, m + i, m + i + 1) for i in range(m - 1)] + [(i, m + i + 1, i + 1) for i in range(m - 1)]
    return CellPart(7, 3, pos, np.array(tri[:n]))


def _soup(parts: list[CellPart] | tuple[CellPart, ...]) -> np.ndarray:
    """``(t, 9)`` every triangle's corners, sorted rows (the same surface whatever the indexing)."""
    rows = np.concatenate([np.asarray(p.positions)[np.asarray(p.indices, np.int64)].reshape(-1, 9) for p in parts])
    return rows[np.lexsort(rows.T[::-1])]


def test_a_part_is_cut_into_pieces_holding_its_triangles_once() -> None:
    part = _helix(1000)
    pieces = split_part(part, 128)
    assert len(pieces) >= 8
    assert all(0 < q.triangles <= 128 for q in pieces)
    assert all(q.element == 7 and q.material == 3 for q in pieces)
    np.testing.assert_array_equal(_soup(pieces), _soup([part]))  # each triangle once, winding kept
    lo, hi = part.bbox
    for q in pieces:  # each piece's box inside the part's, and far smaller for a helix
        qlo, qhi = q.bbox
        assert np.all(qlo >= lo) and np.all(qhi <= hi)
    assert max(float(np.prod(q.bbox[1] - q.bbox[0])) for q in pieces) < 0.5 * float(np.prod(hi - lo))
    # deterministic: the same cut every time (the client and its truth key the same pieces)
    again = split_part(part, 128)
    for a, b in zip(pieces, again, strict=True):
        np.testing.assert_array_equal(a.indices, b.indices)
        np.testing.assert_array_equal(a.positions, b.positions)


def test_small_parts_and_meshes_are_kept_as_they_are() -> None:
    small = _helix(PIECE_TRIANGLES)
    assert split_part(small) == [small]
    mesh = CellMesh((small,), (0.0, 0.0, 0.0), (1.0, 1.0, 1.0))
    assert cell_pieces(mesh) is mesh
    with pytest.raises(ValueError, match="max_triangles"):
        split_part(small, 0)


def test_the_content_kind_decodes_the_pieces_in_the_stored_order() -> None:
    big, box = _helix(900), _helix(20, centre=(0.0, 5.0))
    blob = encode_cell_mesh([(p.element, p.material, p.positions, p.indices) for p in (box, big)])
    got = KIND.decode(blob, "cell")
    np.testing.assert_array_equal(_soup(got.parts), _soup(decode_cell_pieces(blob, "cell").parts))
    assert got.parts[0].triangles == 20  # the small part first, as stored, then the pieces
    assert len(got.parts) >= 1 + math.ceil(900 / PIECE_TRIANGLES)
    assert all(p.triangles <= PIECE_TRIANGLES for p in got.parts)
    assert got.triangles == 920 and got.nbytes == len(blob)


def test_pieces_beyond_a_door_are_culled_and_none_that_a_door_shows() -> None:
    """A curved stair seen through a narrow door: the whole part's box meets the door's
    rectangle, so all of it was drawn; its pieces are drawn only near the door, and every
    triangle whose own box meets the door's rectangle is in a piece drawn."""
    part = _helix(1200)
    eye = np.array([0.0, 0.0, 1.6])
    view = camera(eye, 0.0, 0.0).astype(np.float64)
    proj = perspective(60.0, SIZE[0] / SIZE[1], 0.1, 100.0).astype(np.float64)
    door = {0: [(112, 30, 125, 90)]}  # the stair's right-hand edge
    whole = {0: (part.bbox[0][None], part.bbox[1][None])}
    assert cull_parts("portals", [0], whole, eye, view, proj, SIZE, vsas=door)[0].all()
    pieces = split_part(part)
    boxes = {0: (np.array([q.bbox[0] for q in pieces]), np.array([q.bbox[1] for q in pieces]))}
    kept = cull_parts("portals", [0], boxes, eye, view, proj, SIZE, vsas=door)[0]
    drawn = sum(q.triangles for q, k in zip(pieces, kept, strict=True) if k)
    assert 0 < drawn < 0.8 * part.triangles
    for q, k in zip(pieces, kept, strict=True):
        tri = np.asarray(q.positions, np.float64)[np.asarray(q.indices, np.int64)]
        each = {0: (tri.min(axis=1), tri.max(axis=1))}
        seen = cull_parts("portals", [0], each, eye, view, proj, SIZE, vsas=door)[0]
        assert k or not seen.any()
