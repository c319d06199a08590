"""The indices of the triangles that stay triangles in cell contents version 4 (``walkstream-cellmesh/4``).

Each part's kept triangles have one vertex per grid point (``planarmesh``); their
indices go as **high-water codes** over all parts at once: 0 for the next vertex not
used before (vertices come in the order the triangles first use them), else
``h + 1 - i`` with ``h`` the highest index used so far.  A part's triangles go breadth
first across shared edges (:func:`by_neighbours`) when that takes fewer varint bytes
(:func:`coded_size`) than their own order: neighbours reuse recent vertices, so their
codes stay small.  The order of triangles changes nothing drawn.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from walkstream.shared.codec.varint import encode_varints, zigzag
from walkstream.shared.errors import CodecError

__all__ = ["by_neighbours", "coded_size", "from_high_water_codes", "high_water_codes"]


def coded_size(q: NDArray[np.int64], t: NDArray[np.int64]) -> int:
    """Bytes of version 4's varints (position steps, high-water codes) for triangles ``t``
    over grid points ``q``, before compression: how the encoder picks an order."""
    used, first = np.unique(t.reshape(-1), return_index=True)
    order = used[np.argsort(first)]
    remap = np.full(len(q), -1, np.int64)
    remap[order] = np.arange(len(order))
    steps = np.diff(q[order], axis=0, prepend=np.zeros((1, 3), np.int64))
    codes = high_water_codes([remap[t].reshape(-1)], [len(order)], [len(t)])
    return len(encode_varints(zigzag(steps.T.reshape(-1)))) + len(encode_varints(codes))


def by_neighbours(t: NDArray[np.int64]) -> NDArray[np.int64]:
    """``(m, 3)`` triangles ``t`` reordered breadth first across shared edges (a
    triangle's neighbours follow it), so that version 4's high-water codes stay small; the
    order of triangles changes nothing drawn."""
    m = len(t)
    if m < 3:
        return t
    e = np.sort(np.stack([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]], axis=1).reshape(-1, 2), axis=1)
    _, edge = np.unique(e, axis=0, return_inverse=True)
    edge = edge.reshape(-1)
    owner = np.repeat(np.arange(m), 3)
    by_edge = np.argsort(edge, kind="stable")
    starts = np.searchsorted(edge[by_edge], np.arange(int(edge.max()) + 2))
    sharing = [owner[by_edge[a:b]].tolist() for a, b in zip(starts[:-1].tolist(), starts[1:].tolist(), strict=True)]
    edges = edge.reshape(m, 3).tolist()
    seen = bytearray(m)
    order: list[int] = []
    for s in range(m):
        if seen[s]:
            continue
        seen[s] = 1
        queue = [s]
        head = 0
        while head < len(queue):
            i = queue[head]
            head += 1
            for g in edges[i]:
                for j in sharing[g]:
                    if not seen[j]:
                        seen[j] = 1
                        queue.append(j)
        order.extend(queue)
    return t[np.asarray(order, np.int64)]


def high_water_codes(idx: list[NDArray[np.int64]], vcount: list[int], tcount: list[int]) -> NDArray[np.uint64]:
    """Version 4's kept-triangle indices: 0 for a vertex not used before (vertices come in
    the order the triangles first use them), else how far back it is, ``h + 1 - i`` with
    ``h`` the highest index used so far; over all parts at once (each part's vertices
    follow the previous part's, every one of them used)."""
    nv = np.asarray(vcount, np.int64)
    g = np.concatenate(idx) + np.repeat(np.cumsum(nv) - nv, np.asarray(tcount, np.int64) * 3) if idx else np.zeros(0, np.int64)
    if not len(g):
        return np.zeros(0, np.uint64)
    high = np.concatenate([[-1], np.maximum.accumulate(g)[:-1]])
    return np.where(g == high + 1, 0, high + 1 - g).astype(np.uint64)


def from_high_water_codes(
    code: NDArray[np.int64], vcount: NDArray[np.int64], tcount: NDArray[np.int64], what: str
) -> NDArray[np.int64]:
    """``(3 * triangles,)`` each part's local kept-triangle indices from :func:`high_water_codes`'s codes.

    Raises
    ------
    CodecError
        A code reaching before the first vertex, a part using another part's vertices or
        leaving one of its own unused.
    """
    fresh = np.cumsum(code == 0)  # vertices met so far, this one included
    g = np.where(code == 0, fresh - 1, fresh - code)
    if len(g) and int(g.min()) < 0:
        raise CodecError(f"{what}: indices: a code before the first vertex")
    part = np.repeat(np.arange(len(tcount)), tcount * 3)
    v0 = np.cumsum(vcount) - vcount
    local = g - v0[part]
    if len(local) and (int(local.min()) < 0 or bool(np.any(local >= vcount[part]))):
        raise CodecError(f"{what}: indices: a part's index out of its range")
    if int(fresh[-1] if len(fresh) else 0) != int(vcount[tcount > 0].sum()):
        raise CodecError(f"{what}: indices: kept vertices unused")
    return local
