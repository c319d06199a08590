"""An interior start bundle's first view: which cells go as heads, and whether as one pack.

The start bundle brings the contents of every cell the client's view sees from the
path's first pose (:meth:`~walkstream.server.service.interiors.InteriorState.first_view`),
and the walk's first perfect frame waits for all of them.  Two ways to send them, the
one costing fewer bytes chosen:

- *Part by part* in the answer's gzip stream, each cell in its cheaper form there
  (:mod:`~walkstream.server.service.contentsform`), a cell the first pose sees in part
  as its head (:mod:`~walkstream.server.service.firstheads`) where that head is at most
  :data:`~walkstream.server.service.firstheads.HEAD_SHARE` of the stored blob and of the
  whole cell's cost in the stream.
- *One pack* (:mod:`~walkstream.shared.codec.contentspack`, asked for with the heads):
  every cell inflated, in cell-id order, in one LZMA dictionary (its meshes field by
  field where that is smaller), a cell as its head where the head
  inflated is at most ``HEAD_SHARE`` of the cell inflated (what each costs in the
  pack's dictionary).

Either way the heads' cells follow whole, part by part, after the first view.
duplex.ifc at 160x120 (ten cells down five doorways): part by part 19.7 kB with two
heads; one pack with three (its cell 4, 22 kB inflated, seen in part: a 7.9 kB head)
15.9 kB one part after the other, 15.4 kB field by field in cell-id order.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Sequence

import numpy as np
from numpy.typing import ArrayLike

from walkstream.server.service.contentsform import STREAM_LEVEL, ContentsStream
from walkstream.server.service.firstheads import HEAD_SHARE, first_heads, wholes_order
from walkstream.server.service.interiors import InteriorState
from walkstream.shared.codec.contentspack import pack_parts
from walkstream.shared.roomview import RoomView

__all__ = ["first_view_contents"]


def first_view_contents(
    interior: InteriorState, cells: list[int], pose: tuple[ArrayLike, float, float], view: RoomView, *,
    heads: bool, inflate: bool, pack: bool, first: Collection[int] | None = None,
    lead: Sequence[tuple[ArrayLike, float, float]] = (),
) -> tuple[list[int], list[bytes], int]:
    """The start bundle's ``contents``: the cell ids its parts name, in order, the
    frames that carry them (one per id, or a pack first in place of one per cell of
    ``cells``), and how many of those frames carry the view from ``pose`` (the pack, or
    the parts of ``first``, which lead ``cells``).

    Parameters
    ----------
    cells:
        The first view's cells (:meth:`InteriorState.first_view`).
    pose:
        The path's first pose ``(eye (3,), yaw, pitch)``.
    heads:
        Cells ``pose`` sees in part may go as heads first, whole after the others.
    inflate:
        The answer is gzip-compressed: each part in the form that costs it fewer bytes
        in the stream (else as stored).
    pack:
        The client reads packs: the first view may go as one.
    first:
        Of ``cells``, those ``pose`` itself sees (None: all).  Only they may go in the
        pack, whose cells all arrive with its last byte; the cells of the poses the walk
        leads to follow it part by part, so that the first frame does not wait for them
        (with the first view's virtual walls closed, the first pose sees one cell of a
        hall and the lead's cells would hold it back).
    lead:
        Where the path leads after ``pose`` (:func:`~walkstream.server.service.startbundle.room_lead`):
        the heads' cells follow whole in the order the walk needs them whole there
        (:func:`~walkstream.server.service.firstheads.wholes_order`; none: in ``cells``' order).
    """
    every = first_heads(interior, cells, pose, view, share=math.inf) if heads else {}
    stored = {c: len(interior.contents(c).content) for c in every}
    hd = {c: h for c, h in every.items() if len(h[0]) + len(h[1]) <= HEAD_SHARE * stored[c]}
    # part by part: in a gzip answer, each cell in the form that costs it fewer bytes there
    stream = ContentsStream(STREAM_LEVEL) if inflate else None
    frames: list[bytes] = []
    later: list[int] = []
    for cid in cells:
        whole_forms = interior.contents_forms(cid, inflate)
        head_forms = interior.head_forms(cid, *hd[cid], inflate) if cid in hd else []
        cheap = bool(head_forms) and (
            stream is None or stream.cost(*head_forms) <= HEAD_SHARE * stream.cost(*whole_forms))
        if cheap:
            frames.append(head_forms[0] if stream is None else stream.cheaper(*head_forms))
            later.append(cid)
        else:
            frames.append(whole_forms[0] if stream is None else stream.cheaper(*whole_forms))
    order = list(cells)
    inpack = [c for c in cells if first is None or c in first]
    seen = len(inpack)
    if pack and inpack:
        packed, pack_heads = _pack(interior, inpack, every)
        alone = ContentsStream(STREAM_LEVEL) if stream is not None else None
        cost = alone.feed(packed) if alone is not None else len(packed)
        rest = [c for c in cells if c not in set(inpack)]
        after = [interior.contents_part(cid, inflate, alone) for cid in rest]
        if alone is None:
            cost += int(np.sum([len(f) for f in after]))
        else:
            cost = alone.nbytes
        if cost < (stream.nbytes if stream is not None else int(np.sum([len(f) for f in frames]))):
            frames, later, stream, order = [packed, *after], pack_heads, alone, [*sorted(inpack), *rest]
            seen = 1
    if lead and len(later) > 1:
        later = wholes_order(interior, later, [pose, *lead], view)
    frames += [interior.contents_part(cid, inflate, stream) for cid in later]
    return [*order, *later], frames, seen


def _pack(interior: InteriorState, cells: list[int],
          every: dict[int, tuple[bytes, bytes]]) -> tuple[bytes, list[int]]:
    """The pack of ``cells`` inflated, in cell-id order, and those of them in it as heads
    (of ``every``, each head's inflated form at most :data:`HEAD_SHARE` of its cell's).

    In id order since the bake numbers a storey's cells one after the other and alike
    cells sit nearer in the dictionary (the duplex's first view 103 bytes smaller than
    in the order the view reaches them); the client draws once all of them are in."""
    parts: list[bytes] = []
    heads: list[int] = []
    for cid in sorted(cells):
        whole = interior.contents_forms(cid, True)[0]
        head = interior.head_forms(cid, *every[cid], True)[0] if cid in every else None
        if head is not None and len(head) <= HEAD_SHARE * len(whole):
            parts.append(head)
            heads.append(cid)
        else:
            parts.append(whole)
    return pack_parts(parts), heads
