"""A cell's decoded parts cut into pieces of at most :data:`PIECE_TRIANGLES` triangles: the units the client culls.

A stored part is one element's piece in one cell (:class:`~walkstream.shared.codec.cellmesh.CellPart`),
and the client culls parts by their boxes against the portal walk's visible screen areas
(:func:`~walkstream.shared.partcull.cull_parts`).  A part of thousands of triangles --
a curved stair (2,146 triangles on FZK-Haus), a round gable window (1,792), a wall
cabinet -- is drawn whole as soon as its box touches a door's rectangle by a pixel,
while what the walker sees of it is a corner or nothing: on FZK-Haus's tour, such parts
made the frames draw up to eleven times the triangles truly visible.  Cut into spatially
coherent pieces (median cuts of the triangles' centroids across the longest axis, each
piece's box its own), a piece beyond a door's edge is left out and the rest is drawn.

The cut is made after decoding, not in the bake: the stored blob keeps the element as
one part (cut parts would cost about 16 % more bytes on FZK-Haus, duplicated corners
and broken runs of the codec), and every reader of contents that culls or compares --
the client's streamers, its ground truth, the portal benchmarks -- decodes through
:func:`decode_cell_pieces` (the ``cellmesh`` content kind's decoder), so the truth keys
the same pieces the client culls.  The cut is deterministic (a function of the decoded
part alone); a piece keeps its element id and material, and its triangles keep their
stored order and winding, so the picture is unchanged.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from walkstream.shared.codec.cellmesh import CellMesh, CellPart, decode_cell_mesh

__all__ = ["PIECE_TRIANGLES", "split_part", "cell_pieces", "decode_cell_pieces"]

#: Triangles per piece, at most: a part over this is cut.  256 keeps boxes and
#: rectangles (12 triangles) and most walls whole; on FZK-Haus's tour it brought
#: tightness p95 from 9.5 to 3.2 pose by pose with 59 more parts (225 -> 284).
PIECE_TRIANGLES = 256


def _groups(centroids: NDArray[np.float64], max_triangles: int) -> list[NDArray[np.int64]]:
    """Triangle index groups of at most ``max_triangles``: median cuts across the longest
    axis of their ``(m, 3)`` centroids, in order along the cuts (low side first)."""
    out: list[NDArray[np.int64]] = []
    stack = [np.arange(len(centroids))]
    while stack:
        sel = stack.pop()
        if len(sel) <= max_triangles:
            out.append(np.sort(sel))  # the stored order within a piece
            continue
        c = centroids[sel]
        axis = int(np.argmax(c.max(axis=0) - c.min(axis=0)))
        order = np.argsort(c[:, axis], kind="stable")
        half = len(sel) // 2
        stack.append(sel[order[half:]])
        stack.append(sel[order[:half]])
    return out


def split_part(part: CellPart, max_triangles: int = PIECE_TRIANGLES) -> list[CellPart]:
    """``part`` as pieces of at most ``max_triangles`` triangles (itself when it has no more).

    Each piece holds the corners its triangles use, re-indexed; the union of the
    pieces' triangles is the part's, each once.
    """
    if max_triangles < 1:
        raise ValueError(f"max_triangles must be at least 1, got {max_triangles}")
    idx = np.asarray(part.indices, np.int64)
    if len(idx) <= max_triangles:
        return [part]
    pos = np.asarray(part.positions)
    centroids = pos[idx].astype(np.float64).mean(axis=1)
    pieces = []
    for sel in _groups(centroids, max_triangles):
        tri = idx[sel]
        used, inverse = np.unique(tri, return_inverse=True)
        pieces.append(CellPart(part.element, part.material, pos[used], inverse.reshape(-1, 3)))
    return pieces


def cell_pieces(mesh: CellMesh, max_triangles: int = PIECE_TRIANGLES) -> CellMesh:
    """``mesh`` with every part over ``max_triangles`` triangles cut into pieces, in place of
    the part (the other parts unchanged, in their order)."""
    if all(p.triangles <= max_triangles for p in mesh.parts):
        return mesh
    parts = tuple(q for p in mesh.parts for q in split_part(p, max_triangles))
    return CellMesh(parts, mesh.lo, mesh.extent, nbytes=mesh.nbytes, grid=mesh.grid)


def decode_cell_pieces(blob: bytes, what: str = "cell mesh") -> CellMesh:
    """:func:`~walkstream.shared.codec.cellmesh.decode_cell_mesh`, then :func:`cell_pieces`:
    the contents as the client culls and the truth compares them."""
    return cell_pieces(decode_cell_mesh(blob, what))
