"""Which cells of an interior's first view go as heads, and the heads themselves.

The start bundle's first view holds every cell the client's view sees from the path's
first pose (:meth:`~walkstream.server.service.interiors.InteriorState.first_view`).
A cell of which that view draws few pieces goes first as a *head*
(:mod:`~walkstream.shared.codec.cellhead`): the pieces the client's culling keeps from
that pose and the boxes of the others; its whole blob follows after every cell's
first part.  The server culls as the client does -- the compact topology as the
client decodes it, the same portal walk, the same pieces
(:func:`~walkstream.shared.codec.cellpieces.decode_cell_pieces`) and the same box test
(:func:`~walkstream.shared.partcull.cull_parts`) -- but the client does not trust it:
it culls the stand-ins of the missing pieces with every frame, and a frame that keeps
one waits for the cell.

FZK-Haus at 160x120 (the outside cell: 13 of 112 pieces drawn from the start room):
the first view's parts 20.0 -> 13.3 kB on the link (gzip), the first perfect frame 3.20 -> 2.36 s.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.server.service.interiors import InteriorState
from walkstream.shared.camera import camera
from walkstream.shared.codec.cellhead import encode_cell_head
from walkstream.shared.codec.cellmesh import CellMesh
from walkstream.shared.codec.cellpieces import decode_cell_pieces
from walkstream.shared.errors import CodecError
from walkstream.shared.partcull import cull_parts
from walkstream.shared.portals import cull_portals
from walkstream.shared.roomview import RoomView, room_projection

__all__ = ["HEAD_SHARE", "first_heads", "wholes_order"]

HEAD_SHARE = 0.7
"""A cell goes as a head only when its head (pieces and boxes) is at most this share
of its stored blob, and (in a gzip answer) costs at most this share of the whole
cell's bytes in the answer's stream where it would go: the whole blob follows anyway,
so a head that saves little costs bytes twice."""


def first_heads(
    interior: InteriorState, cells: Sequence[int], pose: tuple[ArrayLike, float, float], view: RoomView,
    share: float = HEAD_SHARE,
) -> dict[int, tuple[bytes, bytes]]:
    """The heads ``{cell: (body, missing)}`` of those of ``cells`` that the view from
    ``pose`` (``(eye (3,), yaw, pitch)``) sees only in part, each at most ``share`` of
    its stored blob (see :data:`HEAD_SHARE`; ``inf``: every one)."""
    out: dict[int, tuple[bytes, bytes]] = {}
    for c, (pieces, keep) in _kept(interior, cells, pose, view).items():
        if keep.all() or not keep.any():
            continue
        stored = interior.contents(c).content
        body, missing = encode_cell_head(pieces, keep)
        if len(body) + len(missing) <= share * len(stored):
            out[c] = (body, missing)
    return out


def wholes_order(
    interior: InteriorState, cells: Sequence[int], poses: Sequence[tuple[ArrayLike, float, float]], view: RoomView,
) -> list[int]:
    """``cells`` (the heads' cells, whose whole blobs follow the first view) in the order
    the walk needs them whole: by the first of ``poses`` (``poses[0]`` the heads' pose,
    then where the path leads) whose view keeps a piece of the cell that the view from
    ``poses[0]`` does not; cells no pose needs whole keep their order, last.

    A walk that turns in its first seconds needs first the cell it turns towards: the
    FZK-Haus tour, bending round the stair, looks out of the start room's window at the
    outside cell's pieces its head lacks before it needs the start room whole."""
    first = {c: keep for c, (_p, keep) in _kept(interior, cells, poses[0], view).items()}
    when = {c: len(poses) for c in cells}
    for i, pose in enumerate(poses[1:], start=1):
        for c, (_p, keep) in _kept(interior, [c for c in cells if when[c] == len(poses)], pose, view).items():
            had = first.get(c)
            if had is None or had.shape != keep.shape or (keep & ~had).any():
                when[c] = i
    return sorted(cells, key=lambda c: when[c])


def _kept(
    interior: InteriorState, cells: Sequence[int], pose: tuple[ArrayLike, float, float], view: RoomView,
) -> dict[int, tuple[CellMesh, NDArray[np.bool_]]]:
    """Of ``cells``, those the view from ``pose`` reaches, each with its pieces and which
    of them the client's culling keeps from there (a damaged blob is left out: it goes
    whole, and the client says so)."""
    graph, locator = interior.view_model
    eye = np.asarray(pose[0], np.float64).reshape(3)
    cur = locator.locate(eye)
    if cur is None:
        return {}
    proj = room_projection(view.fov_deg, view.size, view.fog_m)
    v = camera(eye, float(pose[1]), float(pose[2])).astype(np.float64)
    pc = cull_portals(graph, cur, eye, v, proj, view.size, fog_m=view.fog_m, max_depth=view.max_depth)
    out: dict[int, tuple[CellMesh, NDArray[np.bool_]]] = {}
    for c in cells:
        if c not in pc.vsas:
            continue
        try:
            pieces = decode_cell_pieces(interior.contents(c).content, f"contents of cell {c}")
        except CodecError:
            continue
        boxes = {c: (np.array([p.bbox[0] for p in pieces.parts]).reshape(-1, 3),
                     np.array([p.bbox[1] for p in pieces.parts]).reshape(-1, 3))}
        keep = cull_parts("portals", [c], boxes, eye, v, proj, view.size, vsas=pc.vsas, fog_m=view.fog_m)[c]
        out[c] = (pieces, np.asarray(keep, dtype=bool))
    return out
