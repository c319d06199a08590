"""The first portal walk, kept as the reference the faster walk is checked against.

:func:`cull_portals_reference` is :func:`~walkstream.shared.portals.cull_portals`
as merged for issue 14 (a FIFO walk over Python ints, the portals projected in lazy
waves above ``_PROJECT_ALL`` directed portals).  The walk that replaced it must give
exactly the same cells, VSAs and depths in the same order (tests/test_portalwalk.py),
and ``walkstream bench portals`` times both side by side.  It lives with the benchmarks, not in the client: nothing the client runs calls it.
"""

from __future__ import annotations

import math
import time
from collections import deque
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.shared.errors import InputError
from walkstream.shared.portalgraph import PortalGraph
from walkstream.shared.portals import PortalCull, box_distance
from walkstream.shared.screenrects import clipped_rects, corner_secant, ndc_pixels

__all__ = ["cull_portals_reference", "rects_reference"]

#: Directed portals up to which a frame projects every portal of the building at once
#: (one numpy batch); above, the portals of the cells reached are projected a wave at a time.
_PROJECT_ALL = 2048


def cull_portals_reference(
    graph: PortalGraph,
    start: int,
    eye: ArrayLike,
    view: ArrayLike,
    proj: ArrayLike,
    size: tuple[int, int],
    *,
    fog_m: float = math.inf,
    max_depth: int | None = None,
    clip_m: float = 0.03,
    pass_m: float = 0.05,
    max_vsas: int = 4,
    naive: bool = False,
) -> PortalCull:
    """The reference walk: the parameters and result of
    :func:`~walkstream.shared.portals.cull_portals` (see there), kept unchanged."""
    t0 = time.perf_counter()
    if start not in graph.index:
        raise InputError(f"cull_portals: no cell {start} in the interior")
    e = np.asarray(eye, np.float64).reshape(3)
    V = np.asarray(view, np.float64)
    P = np.asarray(proj, np.float64)
    w, h = int(size[0]), int(size[1])
    # A portal's rectangle depends on the camera only, not on the VSA it is seen
    # through: the portals of the cells waiting in the queue are projected together,
    # vectorised, the first time one of them is taken (a few batches per frame, and
    # only the cells reached), and the walk below intersects whole-pixel rectangles
    # as plain ints, no numpy per cell.
    m = len(graph.target)
    k = graph.poly.shape[1]
    edges = np.stack([np.arange(k), (np.arange(k) + 1) % k], axis=1)
    near_pass = max(pass_m, clip_m * corner_secant(P) * 1.01)
    # per directed row: None (culled: beyond the fog or wholly behind the eye),
    # True (pass the parent's VSA through), or its rectangle
    R: list[Any] = [None] * m
    done = [False] * len(graph.ids)

    def project(cells: list[int]) -> None:
        rows = np.concatenate([np.arange(graph.start[c], graph.start[c + 1]) for c in cells])
        for c in cells:
            done[c] = True
        if len(rows) == 0:
            return
        rows = rows[box_distance(graph.lo[rows], graph.hi[rows], e) <= fog_m]
        rect, front = rects_reference(graph.poly[rows], edges, V, P, (w, h), clip_m, naive)
        through = np.zeros(len(rows), bool)
        if not naive and len(rows):
            dist = np.abs(graph.plane[rows, :3] @ e + graph.plane[rows, 3])
            inside = np.all((e >= graph.lo[rows] - near_pass) & (e <= graph.hi[rows] + near_pass), axis=1)
            through = (dist <= near_pass) & inside
        for r, rc, ok, th in zip(rows.tolist(), rect.tolist(), front.tolist(), through.tolist(), strict=True):
            if th:
                R[r] = True
            elif ok:
                R[r] = rc

    if m <= _PROJECT_ALL:
        # a small building: one batch for all is cheaper than a batch per wave
        project(list(range(len(graph.ids))))
    target = graph.target.tolist()
    starts = graph.start.tolist()
    s = graph.index[start]
    full = (0, 0, w - 1, h - 1)
    bound: dict[int, tuple[int, int, int, int]] = {s: full}
    lists: dict[int, list[tuple[int, int, int, int]]] = {s: [full]}
    depth = {s: 0}
    order = [s]
    queue = deque([s])
    queued = {s}
    opened = tested = 0
    while queue:
        c = queue.popleft()
        queued.discard(c)
        dc = depth[c]
        if max_depth is not None and dc >= max_depth:
            continue
        if not done[c]:
            project([c] + [q for q in queue if not done[q]])
        vx0, vy0, vx1, vy1 = bound[c]
        for r in range(starts[c], starts[c + 1]):
            pr = R[r]
            if pr is None:
                continue
            tested += 1
            if pr is True:
                n = (vx0, vy0, vx1, vy1)
            else:
                n = (max(pr[0], vx0), max(pr[1], vy0), min(pr[2], vx1), min(pr[3], vy1))
                if n[0] > n[2] or n[1] > n[3]:
                    continue
            opened += 1
            t = target[r]
            ob = bound.get(t)
            if ob is None:
                bound[t] = n
                lists[t] = [n]
                depth[t] = dc + 1
                order.append(t)
            else:
                have = lists[t]
                if any(q[0] <= n[0] and q[1] <= n[1] and q[2] >= n[2] and q[3] >= n[3] for q in have):
                    continue
                have = [q for q in have if not (n[0] <= q[0] and n[1] <= q[1] and n[2] >= q[2] and n[3] >= q[3])]
                have.append(n)
                if len(have) > max_vsas:
                    have = [(min(q[0] for q in have), min(q[1] for q in have),
                             max(q[2] for q in have), max(q[3] for q in have))]
                lists[t] = have
                nb = (min(ob[0], n[0]), min(ob[1], n[1]), max(ob[2], n[2]), max(ob[3], n[3]))
                if nb == ob:
                    continue
                bound[t] = nb
                depth[t] = min(depth[t], dc + 1)
            if t not in queued:
                queue.append(t)
                queued.add(t)
    ids = graph.ids.tolist()
    return PortalCull(
        order=[ids[i] for i in order],
        vsas={ids[i]: lists[i] for i in order},
        depth={ids[i]: depth[i] for i in order},
        portals=opened,
        tested=tested,
        seconds=time.perf_counter() - t0,
    )


def rects_reference(
    pts: NDArray[np.float64],
    edges: NDArray[np.int64],
    view: NDArray[np.float64],
    proj: NDArray[np.float64],
    size: tuple[int, int],
    clip_m: float,
    naive: bool = False,
) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
    """The reference form of :func:`~walkstream.shared.screenrects.point_rects`: whole-pixel
    rectangles of point sets clipped at depth ``clip_m``.

    ``pts`` ``(m, k, 3)`` world points, ``edges`` ``(e, 2)`` the index pairs joining
    them (the polygon's sides or a box's edges).  Returns ``(m, 4)`` inclusive pixel
    rectangles (unclamped) and ``(m,)`` whether anything of each set lies in front.
    """
    m = len(pts)
    if m == 0:
        return np.zeros((0, 4), np.int64), np.zeros(0, bool)
    v = pts @ view[:3, :3].T + view[:3, 3]  # (m, k, 3) eye space
    if naive:
        # the paper's Figure 4: culled only when every vertex is behind the eye; the
        # others projected as they are, a vertex behind the eye flipped through it
        h = np.concatenate([v, np.ones((*v.shape[:2], 1))], axis=2) @ proj.T
        w = np.where(np.abs(h[..., 3]) < 1e-12, 1e-12, h[..., 3])
        ndc = h[..., :2] / w[..., None]
        front = np.any(-v[..., 2] > 0, axis=1)
        lo, hi = ndc.min(axis=1), ndc.max(axis=1)
    else:
        depth = -v[..., 2]
        ahead = np.all(depth >= clip_m, axis=1)
        rect = np.empty((m, 4), np.int64)
        front = np.ones(m, bool)
        if ahead.any():
            # the common case, nothing to clip: the vertices' projections bound the set
            va, da = v[ahead], depth[ahead]
            x = (proj[0, 0] * va[..., 0] + proj[0, 2] * va[..., 2]) / da
            y = (proj[1, 1] * va[..., 1] + proj[1, 2] * va[..., 2]) / da
            rect[ahead] = ndc_pixels(np.stack([x.min(axis=1), y.min(axis=1)], axis=1),
                                     np.stack([x.max(axis=1), y.max(axis=1)], axis=1), size)
        behind = np.all(depth < clip_m, axis=1)
        front[behind] = False
        rect[behind] = (1, 1, 0, 0)
        rest = ~ahead & ~behind
        if rest.any():
            rect[rest], front[rest] = clipped_rects(v[rest], depth[rest], edges, proj, size, clip_m)
        return rect, front
    return ndc_pixels(lo, hi, size), front
