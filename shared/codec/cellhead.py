"""A cell's *head*: the pieces a first view draws, and the boxes of the pieces it does not.

The start bundle of an interior brings the contents of every cell the first view
sees, and a frame is perfect only when each of them is in memory.  But a view sees
little of some cells: from FZK-Haus's start room, the outside cell (8.0 kB stored,
112 pieces) shows 13 pieces through the windows, 523 of its 8,216 triangles.  A head
sends those pieces first and the rest of the cell after the other cells' heads, so
the first frame waits for what it draws, not for the whole building's shell.

A head is a contents part with one more field (``walkstream-cellbatch/1`` part, see
:mod:`~walkstream.shared.codec.cellbatch`)::

    {"cell": id, "etag": str, "body": bin, "missing": bin}

``body`` is a ``walkstream-cellmesh`` blob of the pieces drawn (each at most
:data:`~walkstream.shared.codec.cellpieces.PIECE_TRIANGLES` triangles, in the order
:func:`~walkstream.shared.codec.cellpieces.decode_cell_pieces` gives the whole cell's
pieces); ``missing`` says where the others go, as varints: the number of pieces of
the whole cell, the number missing, then per missing piece the difference of its
index to the previous one's (the first: the index plus one) and its box in whole
centimetres, the low corner rounded down and the high corner up (so the box holds the
piece), as zigzag differences to the previous box's low corner, then the extent.

:func:`decode_cell_head` gives a :class:`~walkstream.shared.codec.cellmesh.CellMesh`
of the whole cell's length whose missing pieces are *stand-ins*: a part with no
triangle whose corners are the box's, element ``-1``; ``missing`` lists their
indices.  A stand-in has the piece's key ``(cell, index)``, so the client culls it
by its box like any piece: a frame whose culling keeps a stand-in is waiting for the
cell (not perfect, and its pixels are not counted as culled); one whose culling drops
every stand-in draws every piece it would draw with the whole cell, and the ground
truth checks that it hides nothing.  The cell's whole blob follows in the same stream
and replaces the head.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from walkstream.shared.codec.cellmesh import CellMesh, CellPart, decode_cell_mesh, encode_cell_mesh
from walkstream.shared.codec.cellpieces import PIECE_TRIANGLES
from walkstream.shared.codec.varint import decode_varints, encode_varints, unzigzag, zigzag
from walkstream.shared.errors import CodecError

__all__ = ["STAND_IN_ELEMENT", "encode_cell_head", "decode_cell_head", "stand_in"]

STAND_IN_ELEMENT = -1
"""The element id of a missing piece's stand-in."""

_CM = 100.0
_MAX_PIECES = 1 << 16


def stand_in(lo: ArrayLike, hi: ArrayLike) -> CellPart:
    """A missing piece's stand-in: no triangle, its corners the eight of the box ``lo``,
    ``hi`` (3,) (so that a turned placement keeps a box that holds the piece)."""
    a, b = np.asarray(lo, np.float64).reshape(3), np.asarray(hi, np.float64).reshape(3)
    pick = np.array([[i & 1, (i >> 1) & 1, (i >> 2) & 1] for i in range(8)], bool)
    return CellPart(STAND_IN_ELEMENT, 0, np.where(pick, b, a), np.zeros((0, 3), np.uint32))


def encode_cell_head(pieces: CellMesh, keep: ArrayLike) -> tuple[bytes, bytes]:
    """``(body, missing)`` of the head of a cell decoded as ``pieces`` that keeps the
    pieces where ``keep`` ``(n,)`` bool is true.

    Raises
    ------
    CodecError
        ``keep`` not one flag per piece, a piece over
        :data:`~walkstream.shared.codec.cellpieces.PIECE_TRIANGLES` triangles, or none kept.
    """
    k = np.asarray(keep, bool).reshape(-1)
    n = len(pieces.parts)
    if len(k) != n:
        raise CodecError(f"cell head: {len(k)} flags for {n} pieces")
    if not k.any():
        raise CodecError("cell head: no piece kept")
    if any(p.triangles > PIECE_TRIANGLES for p in pieces.parts):
        raise CodecError(f"cell head: a piece over {PIECE_TRIANGLES} triangles (not cut as the client cuts)")
    body = encode_cell_mesh([(p.element, p.material, p.positions, p.indices)
                             for p, kk in zip(pieces.parts, k.tolist(), strict=True) if kk])
    idx = np.flatnonzero(~k)
    boxes = [pieces.parts[i].bbox for i in idx.tolist()]
    lo = np.floor(np.array([b[0] for b in boxes]).reshape(-1, 3) * _CM).astype(np.int64)
    hi = np.ceil(np.array([b[1] for b in boxes]).reshape(-1, 3) * _CM).astype(np.int64)
    dlo = np.diff(lo, axis=0, prepend=np.zeros((1, 3), np.int64))
    rows = np.column_stack([np.diff(idx, prepend=-1), zigzag(dlo.reshape(-1)).reshape(-1, 3).astype(np.int64),
                            hi - lo]) if len(idx) else np.zeros((0, 7), np.int64)
    missing = encode_varints(np.concatenate([[n, len(idx)], rows.reshape(-1)]).astype(np.uint64))
    return body, missing


def decode_cell_head(body: bytes, missing: bytes, what: str = "cell head") -> CellMesh:
    """The head as the whole cell's pieces, each missing one a :func:`stand_in`
    (``CellMesh.missing`` lists their indices).

    Raises
    ------
    CodecError
        A damaged body or ``missing``, or counts that do not add up.
    """
    head = decode_cell_mesh(body, what)
    v = decode_varints(missing, f"{what}: missing")
    if len(v) < 2:
        raise CodecError(f"{what}: missing holds no counts")
    n, m = int(v[0]), int(v[1])
    if not 0 < m < n <= _MAX_PIECES or len(v) != 2 + 7 * m:
        raise CodecError(f"{what}: missing says {m} of {n} pieces in {len(v)} numbers")
    if n - m != len(head.parts) or any(p.triangles > PIECE_TRIANGLES for p in head.parts):
        raise CodecError(f"{what}: {len(head.parts)} pieces drawn, expected {n - m} of at most "
                         f"{PIECE_TRIANGLES} triangles")
    rows = v[2:].reshape(m, 7).astype(np.int64)
    idx = np.cumsum(rows[:, 0]) - 1
    if rows[0, 0] < 1 or np.any(rows[1:, 0] < 1) or idx[-1] >= n:
        raise CodecError(f"{what}: missing piece indices out of order or past {n}")
    lo = np.cumsum(unzigzag(rows[:, 1:4].reshape(-1).astype(np.uint64)).reshape(m, 3), axis=0)
    hi = lo + rows[:, 4:7]
    parts: list[CellPart] = []
    kept = iter(head.parts)
    gone = dict(zip(idx.tolist(), range(m), strict=True))
    for i in range(n):
        j = gone.get(i)
        parts.append(next(kept) if j is None else stand_in(lo[j] / _CM, hi[j] / _CM))
    return CellMesh(tuple(parts), head.lo, head.extent, nbytes=head.nbytes, grid=head.grid,
                    missing=tuple(idx.tolist()))

