"""A cell's head (``shared/codec/cellhead.py``): the pieces a first view draws and the
boxes of the others, in the start bundle before the whole cell."""

from __future__ import annotations

import numpy as np
import pytest

from walkstream.shared.codec.cellhead import STAND_IN_ELEMENT, decode_cell_head, encode_cell_head
from walkstream.shared.codec.cellmesh import CellMesh, CellPart
from walkstream.shared.codec.varint import encode_varints
from walkstream.shared.errors import CodecError


def _box(element: int, lo: tuple[float, float, float], size: float) -> CellPart:
    """A closed box of 12 triangles (a piece of its own)."""
    c = np.array([[i & 1, (i >> 1) & 1, (i >> 2) & 1] for i in range(8)], np.float64) * size + np.asarray(lo)
    t = [[0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6], [0, 1, 4], [1, 5, 4],
         [2, 6, 3], [3, 6, 7], [0, 4, 2], [2, 4, 6], [1, 3, 5], [3, 7, 5]]
    return CellPart(element, 3 + element % 5, np.round(c, 3), np.asarray(t, np.uint32))


def _cell(n: int) -> CellMesh:
    parts = tuple(_box(10 + k, (0.37 * k, -1.113 * (k % 3), 0.05 * k), 0.2 + 0.01 * k) for k in range(n))
    return CellMesh(parts, (0.0, 0.0, 0.0), (1.0, 1.0, 1.0))


def test_a_head_keeps_the_pieces_drawn_at_their_places_and_boxes_the_others() -> None:
    cell = _cell(9)
    keep = np.array([1, 0, 0, 1, 1, 0, 1, 0, 0], bool)
    body, missing = encode_cell_head(cell, keep)
    head = decode_cell_head(body, missing, "head")
    assert len(head.parts) == 9 and head.missing == (1, 2, 5, 7, 8)
    for k, (p, q) in enumerate(zip(cell.parts, head.parts, strict=True)):
        lo, hi = p.bbox
        hlo, hhi = q.bbox
        if keep[k]:  # the piece itself, at its index (the key the truth and the culling share)
            assert (q.element, q.material, q.triangles) == (p.element, p.material, 12)
            assert np.allclose(hlo, lo, atol=1e-3) and np.allclose(hhi, hi, atol=1e-3)
        else:  # a stand-in: no triangle, a box that holds the piece, within a centimetre
            assert q.element == STAND_IN_ELEMENT and q.triangles == 0
            assert np.all(hlo <= lo + 1e-9) and np.all(hhi >= hi - 1e-9)
            assert np.all(lo - hlo < 0.0100001) and np.all(hhi - hi < 0.0100001)


def test_bad_heads_are_one_line_codec_errors() -> None:
    cell = _cell(4)
    with pytest.raises(CodecError, match="3 flags for 4 pieces"):
        encode_cell_head(cell, [True, False, True])
    with pytest.raises(CodecError, match="no piece kept"):
        encode_cell_head(cell, [False] * 4)
    body, missing = encode_cell_head(cell, [True, False, True, False])
    for bad, says in [
        (b"", "no counts"),
        (encode_varints(np.array([4, 2, 2, 0, 0, 0, 1, 1, 1], np.uint64)), "in 9 numbers"),
        (encode_varints(np.array([5, 2] + [1, 0, 0, 0, 1, 1, 1] * 2, np.uint64)), "pieces drawn, expected 3"),
        (encode_varints(np.array([4, 2] + [2, 0, 0, 0, 1, 1, 1] + [3, 0, 0, 0, 1, 1, 1], np.uint64)), "past 4"),
        (encode_varints(np.array([4, 2] + [2, 0, 0, 0, 1, 1, 1] + [0, 0, 0, 0, 1, 1, 1], np.uint64)), "out of order"),
    ]:
        with pytest.raises(CodecError, match=says) as e:
            decode_cell_head(body, bad, "head of cell 7")
        assert "\n" not in str(e.value) and "head of cell 7" in str(e.value)
    assert decode_cell_head(body, missing).missing == (1, 3)
