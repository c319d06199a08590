"""Axis-aligned boxes and rectangles of ``walkstream-cellmesh/3`` (:mod:`.planarmesh` uses them).

A box is six numbers (low corner, size) where its faces as rings were 24 vertices; a
rectangle in an axis plane with axis-parallel edges is a kind byte and five numbers.
Here: finding them among a part's triangles on the millimetre grid, and turning them
back into corners.  All integers are millimetre grid steps.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["find_boxes", "rect_pairs", "rect_ring", "box_corners", "rect_of", "rect_mesh", "box_rects", "group_rects", "Rect"]

_OTHER = np.array([[1, 2], [0, 2], [0, 1]])
"""The in-plane axes (increasing) of a face whose normal is along axis 0, 1, 2."""
_CCW = np.array([True, False, True])
"""Whether ``_OTHER[k]``'s corner order ``(0,0), (1,0), (1,1), (0,1)`` is counter-clockwise about ``+k``."""


def find_boxes(q: NDArray[np.int64], t: NDArray[np.int64]) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
    """The axis-aligned boxes among a part's triangles: ``(boxes (k, 6) lo and hi, (m,) in a box)``.

    A box is twelve triangles: on each of its six faces two halves of the face's rectangle
    (three of its corners each, the missing corners opposite) wound with the normal
    pointing out of the box.  Generated furniture, frames and glass are made of such
    boxes, and six numbers say what 24 ring vertices did.
    """
    faces = rect_pairs(q, t) if len(t) >= 12 else {}
    plus: dict[tuple[int, ...], list[int]] = {}
    for key in faces:
        if key[0] == 0 and key[1] == 1:
            plus.setdefault(key[3:], []).append(key[2])
    used = np.zeros(len(t), bool)
    boxes: list[tuple[int, ...]] = []
    for key in list(faces):
        if key[0] != 0 or key[1] != 0:
            continue
        x0, (y0, y1, z0, z1) = key[2], key[3:]
        for x1 in sorted(plus.get(key[3:], [])):
            if x1 <= x0:
                continue
            need = [key, (0, 1, x1, y0, y1, z0, z1), (1, 0, y0, x0, x1, z0, z1), (1, 1, y1, x0, x1, z0, z1),
                    (2, 0, z0, x0, x1, y0, y1), (2, 1, z1, x0, x1, y0, y1)]
            pairs = [faces.get(n) for n in need]
            if all(p is not None and not used[list(p)].any() for p in pairs):
                for p in pairs:
                    used[list(p)] = True  # type: ignore[arg-type]  # p is not None: checked above
                boxes.append((x0, y0, z0, x1, y1, z1))
                break
    return np.array(boxes, np.int64).reshape(-1, 6), used


def rect_pairs(q: NDArray[np.int64], t: NDArray[np.int64]) -> dict[tuple[int, ...], tuple[int, int]]:
    """Pairs of triangles ``t`` that are the two halves of a rectangle in an axis plane with
    axis-parallel edges (three of its corners each, the missing corners opposite, wound
    alike), by rectangle ``(axis, faces +axis, plane, a0, a1, b0, b1)`` (``a``, ``b`` the
    other axes in increasing order); each triangle in one pair at most."""
    c = q[t]  # (m, 3, 3)
    lo, hi = c.min(axis=1), c.max(axis=1)
    flat = lo == hi
    cand = np.flatnonzero(flat.sum(axis=1) == 1)
    if len(cand) < 2:
        return {}
    cc, lo, hi = c[cand], lo[cand], hi[cand]
    ax = np.argmax(flat[cand], axis=1)
    ab = _OTHER[ax]
    uv = np.take_along_axis(cc, ab[:, None, :], axis=2)  # (k, 3 corners, 2)
    l2, h2 = np.take_along_axis(lo, ab, axis=1), np.take_along_axis(hi, ab, axis=1)
    at_hi = uv == h2[:, None, :]
    code = 2 * at_hi[..., 0] + at_hi[..., 1]  # which rectangle corner each triangle corner is
    ok = (at_hi | (uv == l2[:, None, :])).all(axis=(1, 2))
    ok &= (code[:, 0] != code[:, 1]) & (code[:, 0] != code[:, 2]) & (code[:, 1] != code[:, 2])
    nz = np.cross(cc[:, 1] - cc[:, 0], cc[:, 2] - cc[:, 0])[np.arange(len(cand)), ax]
    keys = np.column_stack([ax, nz > 0, np.take_along_axis(lo, ax[:, None], axis=1)[:, 0], l2[:, 0], h2[:, 0], l2[:, 1], h2[:, 1]])
    halves: dict[tuple[int, ...], dict[int, int]] = {}
    faces: dict[tuple[int, ...], tuple[int, int]] = {}
    for key, miss, i in zip(map(tuple, keys[ok].tolist()), (6 - code[ok].sum(axis=1)).tolist(), cand[ok].tolist(), strict=True):
        if key in faces:
            continue
        h = halves.setdefault(key, {})
        if 3 - miss in h:  # the other half: its missing corner is the opposite one
            faces[key] = (h[3 - miss], i)
        else:
            h.setdefault(miss, i)
    return faces


def box_corners(boxes: NDArray[np.int64]) -> NDArray[np.int64]:
    """``(8 k, 3)`` the corners of boxes ``(k, 6)`` (``lo, hi``)."""
    pick = np.array([[i, j, k] for i in (0, 3) for j in (1, 4) for k in (2, 5)])
    return boxes[:, pick].reshape(-1, 3)


def rect_ring(key: tuple[int, ...]) -> NDArray[np.int64]:
    """``(4, 3)`` the corners of a :func:`rect_pairs` rectangle, counter-clockwise seen from its front."""
    ax, up, plane, a0, a1, b0, b1 = key
    lo = np.zeros(3, np.int64)
    lo[ax], lo[_OTHER[ax]] = plane, (a0, b0)
    return rect_mesh(np.array([2 * ax + up]), lo[None], np.array([[a1 - a0, b1 - b0]]))[0]


def rect_of(ring: NDArray[np.int64]) -> tuple[int, NDArray[np.int64], int, int] | None:
    """``(kind, lo (3,), extent a, extent b)`` when ``ring (4, 3)`` is a rectangle in an axis plane
    with axis-parallel edges (``kind = 2 * axis + (normal along +axis)``), else ``None``."""
    if len(ring) != 4:
        return None
    lo, hi = ring.min(axis=0), ring.max(axis=0)
    flat = lo == hi
    if flat.sum() != 1 or not ((ring == lo) | (ring == hi)).all():
        return None
    ax = int(np.argmax(flat))
    a, b = _OTHER[ax]
    # the four corners, each once, in turn round the rectangle (a diagonal step is no edge)
    code = 2 * (ring[:, a] == hi[a]) + (ring[:, b] == hi[b])
    if len(set(code.tolist())) != 4 or ((code ^ np.roll(code, -1)) == 3).any():
        return None
    e1, e2 = ring[1] - ring[0], ring[2] - ring[1]  # a convex turn: its sign is the face's
    turn = e1[(ax + 1) % 3] * e2[(ax + 2) % 3] - e1[(ax + 2) % 3] * e2[(ax + 1) % 3]
    return 2 * ax + int(turn > 0), lo, int(hi[a] - lo[a]), int(hi[b] - lo[b])


def rect_mesh(kind: NDArray[np.int64], lo: NDArray[np.int64], ext: NDArray[np.int64]) -> NDArray[np.int64]:
    """``(r, 4, 3)`` the corners of rectangles (kinds ``(r,)``, corners ``lo (r, 3)``, extents
    ``(r, 2)``) in the order whose triangles ``0 1 2, 0 2 3`` face the kind's way."""
    ax, up = kind // 2, kind % 2 == 1
    ab = _OTHER[ax]
    flip = (_CCW[ax] != up)[:, None]
    ca = np.where(flip, [0, 0, 1, 1], [0, 1, 1, 0])
    cb = np.where(flip, [0, 1, 1, 0], [0, 0, 1, 1])
    v = np.repeat(lo[:, None, :], 4, axis=1)
    rows, cols = np.arange(len(kind))[:, None], np.arange(4)[None]
    v[rows, cols, ab[:, :1]] += ca * ext[:, :1]
    v[rows, cols, ab[:, 1:]] += cb * ext[:, 1:]
    return v


def box_rects(boxes: NDArray[np.int64]) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """The six faces of boxes ``(k, 6)`` (``lo, size``) as rectangles ``(kinds, lo, extents)``, box after box."""
    lo, s = boxes[:, :3], boxes[:, 3:]
    z = np.zeros_like(s[:, 0])
    shift = np.stack([z, s[:, 0], z, s[:, 1], z, s[:, 2]], axis=1)  # (k, 6): + faces move along their axis
    ax = np.repeat(np.arange(3), 2)
    flo = np.repeat(lo[:, None, :], 6, axis=1)
    flo[:, np.arange(6), ax] += shift
    ext = s[:, _OTHER[ax]]  # (k, 6, 2)
    return np.tile(np.arange(6), len(boxes)), flo.reshape(-1, 3), ext.reshape(-1, 2)


Rect = tuple[int, int, int, int, int, int]
"""A rectangle: ``(kind, x, y, z, extent a, extent b)`` (:func:`rect_of`)."""


def _face(box: tuple[int, ...], f: int, inward: bool) -> Rect:
    """Face ``f`` (0..5: -x, +x, -y, +y, -z, +z) of ``box`` ``(x0, y0, z0, x1, y1, z1)`` as a
    rectangle, facing out of the box or, when ``inward``, into it."""
    ax, top = f // 2, f % 2
    lo = list(box[:3])
    lo[ax] = box[3 + ax] if top else box[ax]
    a, b = _OTHER[ax]
    return (2 * ax + (top ^ int(inward)), lo[0], lo[1], lo[2], box[3 + a] - box[a], box[3 + b] - box[b])


def group_rects(rects: list[Rect]) -> tuple[list[tuple[int, ...]], list[Rect]]:
    """Rectangles that are faces of one box, as that box: ``(boxes, the other rectangles)``.

    A box here is ``(x0, y0, z0, x1, y1, z1, faces)``: ``faces`` bits 0..5 say which of
    its faces (-x, +x, -y, +y, -z, +z) there are, bit 6 that they face into the box (a
    window's reveals).  It needs two opposite faces; a clipped wall (its four long faces)
    or a reveal (four faces round the opening) is six numbers and a byte where its
    rectangles were five numbers and a kind each.
    """
    index = {r: i for i, r in enumerate(rects)}
    # the faces a box could pair with: by axis, way and extent (the plane comes second)
    far: dict[tuple[int, ...], list[int]] = {}
    for r in rects:
        ax = r[0] // 2
        a, b = _OTHER[ax]
        far.setdefault((r[0], r[1 + a], r[1 + b], r[4], r[5]), []).append(r[1 + ax])
    used = [False] * len(rects)
    boxes: list[tuple[int, ...]] = []
    for i, r in enumerate(rects):
        if used[i]:
            continue
        ax = r[0] // 2
        a, b = _OTHER[ax]
        inward = r[0] % 2 == 1  # a face towards +axis at the low side faces into its box
        c0 = r[1 + ax]
        for c1 in sorted(c for c in far.get((r[0] ^ 1, r[1 + a], r[1 + b], r[4], r[5]), []) if c > c0):
            lo = [r[1], r[2], r[3]]
            hi = [lo[0], lo[1], lo[2]]
            hi[ax], hi[a], hi[b] = c1, lo[a] + r[4], lo[b] + r[5]
            box = (*lo, *hi)
            faces = [index.get(_face(box, f, inward)) for f in range(6)]
            k0, k1 = faces[2 * ax], faces[2 * ax + 1]
            if k0 is None or k1 is None or used[k0] or used[k1]:
                continue
            mask = 0
            for f, k in enumerate(faces):
                if k is not None and not used[k]:
                    used[k] = True
                    mask |= 1 << f
            boxes.append((*box, mask | (64 if inward else 0)))
            break
    return boxes, [r for r, u in zip(rects, used, strict=True) if not u]
