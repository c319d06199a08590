"""Objects' boxes: stand-ins for the city objects a first view does not draw.

A city frame is perfect when every object of its cell's PVS that it would draw has
arrived and is rebuilt.  Until an object arrives the client does not know where it
stands, so it must wait for the whole PVS, though the frame's frustum drops half of
it.  The city start bundle therefore sends, after the objects of the first view, the
boxes of the first cell's other objects (part ``boxes``): the client culls each
missing object's box with every frame, and one whose box the frustum drops is not
waited for.  The ground truth still compares every object the frame shows.

The body is varints: the number of boxes, then per box the difference of its object
id to the previous one's (ids ascending; the first: the id itself), its low corner in
whole metres rounded down as zigzag differences to the previous box's low corner, and
its extent in metres from the low corner to the high corner rounded up (so the box
holds the object's; about 9 bytes a box, against 15 in decimetres).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.shared.codec.varint import decode_varints, encode_varints, unzigzag, zigzag
from walkstream.shared.errors import CodecError

__all__ = ["MAX_BOXES", "ObjectBoxes", "as_sent", "encode_object_boxes", "decode_object_boxes"]

MAX_BOXES = 1 << 16
"""The most boxes one body may hold."""

_UNITS_PER_M = 1.0


@dataclass(frozen=True)
class ObjectBoxes:
    """Objects' boxes: ``ids`` ``(n,) int64`` ascending, ``lo`` and ``hi`` ``(n, 3)``
    float64 scene-local metres; ``nbytes`` what the part cost on the wire."""

    ids: NDArray[np.int64]
    lo: NDArray[np.float64]
    hi: NDArray[np.float64]
    nbytes: int = 0


def as_sent(lo: ArrayLike, hi: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The boxes ``lo``, ``hi`` ``(n, 3)`` as :func:`decode_object_boxes` will give them:
    each corner rounded outward to the body's unit (the sender culls with these, so the
    objects it leaves to boxes are those the receiver's frustum test drops)."""
    a = np.floor(np.asarray(lo, np.float64).reshape(-1, 3) * _UNITS_PER_M) / _UNITS_PER_M
    b = np.ceil(np.asarray(hi, np.float64).reshape(-1, 3) * _UNITS_PER_M) / _UNITS_PER_M
    return a, b


def encode_object_boxes(ids: ArrayLike, lo: ArrayLike, hi: ArrayLike) -> bytes:
    """The body of boxes ``lo``, ``hi`` ``(n, 3)`` of objects ``ids`` ``(n,)`` (any order;
    sent by ascending id, each widened outward to whole metres).

    Raises
    ------
    CodecError
        Shapes that differ, a repeated or negative id, a box not finite or inside out,
        more than :data:`MAX_BOXES`.
    """
    i = np.asarray(ids, np.int64).reshape(-1)
    a = np.asarray(lo, np.float64).reshape(-1, 3)
    b = np.asarray(hi, np.float64).reshape(-1, 3)
    if not len(i) == len(a) == len(b) or len(i) > MAX_BOXES:
        raise CodecError(f"object boxes: {len(i)} ids, {len(a)} low and {len(b)} high corners (at most {MAX_BOXES})")
    if len(i) and (i.min() < 0 or len(np.unique(i)) != len(i)):
        raise CodecError("object boxes: ids must be distinct and >= 0")
    if not (np.isfinite(a).all() and np.isfinite(b).all() and (b >= a).all()):
        raise CodecError("object boxes: a box not finite or inside out")
    order = np.argsort(i, kind="stable")
    i, a, b = i[order], a[order], b[order]
    qlo = np.floor(a * _UNITS_PER_M).astype(np.int64)
    ext = np.ceil(b * _UNITS_PER_M).astype(np.int64) - qlo
    dlo = np.diff(qlo, axis=0, prepend=np.zeros((1, 3), np.int64))
    rows = np.column_stack([np.diff(i, prepend=0), zigzag(dlo.reshape(-1)).reshape(-1, 3).astype(np.int64), ext])
    return encode_varints(np.concatenate([[len(i)], rows.reshape(-1)]).astype(np.uint64))


def decode_object_boxes(body: bytes, what: str = "object boxes", nbytes: int = 0) -> ObjectBoxes:
    """The boxes of a body :func:`encode_object_boxes` wrote.

    Raises
    ------
    CodecError
        A damaged body: counts that do not add up, ids not ascending.
    """
    v = decode_varints(body, what)
    if len(v) < 1 or int(v[0]) > MAX_BOXES or len(v) != 1 + 7 * int(v[0]):
        raise CodecError(f"{what}: {len(v)} numbers do not hold the boxes they count")
    n = int(v[0])
    rows = v[1:].reshape(n, 7)
    if n and (np.any(rows[1:, 0] == 0) or np.any(rows[:, 0] > np.uint64(1 << 62))):
        raise CodecError(f"{what}: ids not ascending")
    ids = np.cumsum(rows[:, 0].astype(np.int64))
    lo = np.cumsum(unzigzag(rows[:, 1:4].reshape(-1)).reshape(n, 3), axis=0)
    if n and np.any(rows[:, 4:7] > np.uint64(1 << 40)):
        raise CodecError(f"{what}: a box too large")
    hi = lo + rows[:, 4:7].astype(np.int64)
    return ObjectBoxes(ids, lo / _UNITS_PER_M, hi / _UNITS_PER_M, nbytes)
