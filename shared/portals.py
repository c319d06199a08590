"""Portal culling with visible screen areas (Mulloni et al., Figures 3 and 4), near-plane safe.

Pure numpy, no GL.  The portals come as a :class:`~walkstream.shared.portalgraph.PortalGraph`
(built once per scene), the rectangles from :mod:`walkstream.shared.screenrects`.  One frame:

1. The viewer's cell gets the whole viewport as its **visible screen area** (VSA), an
   axis-aligned rectangle of whole pixels ``(x0, y0, x1, y1)``, inclusive, row 0 at
   the bottom (GL's window coordinates).
2. A cell taken from the queue tests all its portals at once: a portal farther than
   the fog distance (its box's distance from the eye) is culled; the others are
   **clipped against a plane** ``clip_m`` in front of the eye *before* projection,
   so a vertex behind the eye never projects to a wrong place (the paper's
   ``IsPortalCulled`` projects vertices as they are: a door the walker is passing
   through gets a wrong rectangle and the room behind it vanishes); the clipped
   polygon's projected bounding rectangle is taken as the whole pixels whose centres
   it may cover (:mod:`walkstream.shared.screenrects`: a rasteriser draws no other) and
   intersected with the cell's VSA; an empty intersection culls the portal.
3. When the eye is within a few centimetres of a portal's plane and inside its
   bounds, the portal's projection degenerates (it fills the screen or nothing):
   the cell behind it gets the parent's VSA unchanged (**pass-through**).
4. The VSAs that reach one cell are **merged**: a short list (at most ``max_vsas``,
   beyond which they become their bounding rectangle), and the cell is propagated
   with their bounding rectangle.  A cell enters the render queue **once per frame**;
   it is only looked through again when its rectangle grew, which happens at most a
   few times per frame (the rectangle grows by whole pixels within the viewport),
   so paths through many portals cannot grow exponentially.  The walk **stops on
   distance**, not on depth: a portal whose box is beyond the fog is not looked
   through, and no depth limit cuts a cell the fog still shows (a corridor split into
   a dozen segments is seen to its end); a caller may still give one (``max_depth``).
5. Each queued cell's contents are culled by their boxes (:mod:`walkstream.shared.partcull`):
   a box is kept when it comes within the fog distance and its clipped, projected
   rectangle meets one of the cell's VSAs; the frustum test follows, as in the paper
   (of its six planes only the near and the far one can cull such a box: a VSA lies
   within the viewport, so a box whose rectangle meets one has a point inside each
   side plane; the two are tested as depths).

Why a clip plane of its own (``clip_m``, 3 cm) and not the camera's near plane
(0.1 m): a door 5 cm in front of the eye lies wholly before the camera's near plane,
yet the room behind it is seen through it; only points at depth 0 cannot be
projected.  A point seen beyond a portal projects where the portal point on the same
ray does, and that one is at depth ``>= clip_m`` unless the eye is within
``clip_m`` times the secant of the frustum's corner angle of the portal, the case
the pass-through takes (its threshold is the larger of that and ``pass_m``).

``naive=True`` is the paper's test as printed (no clipping, no pass-through), kept to
show that the conservative test catches it.

Cost: a portal's rectangle depends on the camera only, so every directed portal of the
building is clipped and projected in one numpy batch per frame; the walk is then a FIFO
walk over plain ints (per-scene adjacency lists built once, in
:class:`~walkstream.shared.portalgraph.PortalGraph`),
about 4-6 us per visible cell on the 2-core machine.  It is the reference walk step for
step (:mod:`walkstream.benchmarks.portalwalk` keeps that one; tests/test_portalwalk.py checks they agree):
a walk by levels with numpy batches per level was not taken, since the FIFO order
decides the VSA lists (which VSAs reach a cell before it is looked through) and a
level costs tens of numpy calls whatever its size, more than the few cells of a
level cost in Python.  Measured on the open 16 x 16 hall (236 cells visible over 31
levels of at most 14 cells): the levels' portal clipping against their parents' VSAs
and the test against the targets' VSA lists alone, as one numpy batch per level,
took 1.2-1.5 times the CPU of this whole walk, before any merge, queue or projection.
Nor does projecting only the portals of the cells reached, a batch per level, pay on
a tour's frame (a tenth of a generated office's portals tested over 3-8 levels): the
per-level batches cost what the whole building's one batch does.  A frame's cost is
mostly numpy's per-call cost, not the elements: the batches run coordinate-major (:func:`~walkstream.shared.screenrects.coord_rects`,
each call one pass over long rows), the few sets that straddle the clip plane are
clipped in plain floats, and the parts culling takes every visible cell's boxes in
one batch (:mod:`walkstream.shared.partcull`); a VSA arriving at a cell is appended
in place.
``walkstream bench portals --cull`` times it (:mod:`walkstream.benchmarks.cullcpu`).
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.shared.errors import InputError
from walkstream.shared.frustum import frustum_cull
from walkstream.shared.portalgraph import PortalGraph
from walkstream.shared.screenrects import (
    CENTRE_MARGIN_PX,
    box_rects_ckm,
    corner_secant,
    point_rects,
    rects_ckm,
)

__all__ = [
    "CULLING_MODES",
    "PortalCull",
    "PortalRows",
    "cull_portals",
    "portal_rows",
    "frustum_cells",
    "box_distance",
]

#: The replay's ``--culling`` choices: portal culling with VSAs, the frustum alone
#: (every cell reached through portals whose box meets the frustum, no VSA), or
#: drawing every part of every loaded visible cell.
CULLING_MODES: tuple[str, ...] = ("portals", "frustum", "none")


@dataclass
class PortalCull:
    """One frame's portal culling.

    Attributes
    ----------
    order : list of int
        The render queue: visible cell ids, each once, in the order first reached.
    vsas : dict of int -> list of (x0, y0, x1, y1)
        Per visible cell, the VSAs through which it is seen (whole pixels, inclusive;
        plain ints: ``np.asarray`` makes a ``(k, 4)`` array of them).
    depth : dict of int -> int
        Portals passed on the shortest way to each visible cell.
    portals : int
        Portals opened (their rectangle met the VSA, or passed through).
    tested : int
        Portal tests made.
    seconds : float
        CPU time of the cell-to-cell step.
    """

    order: list[int]
    vsas: dict[int, list[tuple[int, int, int, int]]]
    depth: dict[int, int]
    portals: int = 0
    tested: int = 0
    seconds: float = 0.0


#: What :func:`portal_rows` gives: for a cell index, its directed portals as
#: ``(target index, what)`` pairs.
PortalRows = Callable[[int], Iterable[tuple[int, Any]]]


def box_distance(lo: NDArray[np.float64], hi: NDArray[np.float64], eye: NDArray[np.float64]) -> NDArray[np.float64]:
    """``(n,)`` distances from ``eye`` ``(3,)`` to boxes ``(n, 3)`` (0 inside)."""
    gap = np.maximum(np.maximum(lo - eye, eye - hi), 0.0)
    return np.sqrt(np.einsum("nk,nk->n", gap, gap))


def cull_portals(
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
    closed: frozenset[int] = frozenset(),
    margin_px: float = CENTRE_MARGIN_PX,
    grow_m: float = 0.0,
    rows: PortalRows | None = None,
) -> PortalCull:
    """Cells seen from cell ``start`` through portals, with their VSAs (module docstring).

    Parameters
    ----------
    graph : PortalGraph
    start : int
        The viewer's cell id.
    eye : (3,) float
    view, proj : (4, 4) float
        The camera (``proj`` a perspective projection).
    size : (int, int)
        Viewport width and height, pixels.
    fog_m : float
        Portals whose box is farther than this are culled.
    max_depth : int, optional
        Portals passed, at most (None, the default: no limit; the fog bounds the walk,
        and a cell is looked through again only when its rectangle grows).
    clip_m, pass_m : float
        The clip plane's depth and the pass-through distance, metres.
    max_vsas : int
        VSAs kept per cell before they are merged into one.
    naive : bool
        The paper's test (no clipping, no pass-through); for the tests only.
    closed : frozenset of int
        Portal ids the walk does not pass (virtual walls drawn as their texture:
        :mod:`walkstream.shared.walls`).
    margin_px : float
        Pixels by which a portal's projection is grown before the pixel centres it
        covers are taken (:func:`~walkstream.shared.screenrects.ndc_pixels`; a
        predicted view's walk takes every pixel touched, ``TOUCH_MARGIN_PX``).
    grow_m : float
        Metres by which every portal is grown on all sides before it is projected (its
        box, grown, is projected instead of its polygon, and the walk passes a portal
        through when the eye comes within the pass-through distance of the grown box):
        the walk of an eye that may be anywhere within ``grow_m`` of ``eye``
        (:mod:`walkstream.shared.cullcache`).  The fog is tested on the portal as it is.
    rows : callable, optional
        The portals' rectangles already made for this camera and these settings by
        :func:`portal_rows` (a caller that spreads a walk over two frames: the
        projection on one, the walk on the next); by default made here.
    """
    t0 = time.perf_counter()
    if start not in graph.index:
        raise InputError(f"cull_portals: no cell {start} in the interior")
    e = np.asarray(eye, np.float64).reshape(3)
    V = np.asarray(view, np.float64)
    P = np.asarray(proj, np.float64)
    w, h = int(size[0]), int(size[1])
    # A portal's rectangle depends on the camera only, not on the VSA it is seen
    # through: every directed portal is projected in one numpy batch per frame
    # (portal_rows; the adjacency is built once per scene), and the walk below intersects
    # whole-pixel rectangles as plain ints.  The walk is the round-one FIFO walk
    # (benchmarks/portalwalk.py) step for step, so its cells, VSAs and depths are the
    # same; only the constant work per portal is less.
    rows_of = rows if rows is not None else portal_rows(graph, e, V, P, (w, h), clip_m, pass_m, fog_m, naive, closed,
                                                        margin_px, grow_m)
    s = graph.index[start]
    full = (0, 0, w - 1, h - 1)
    # per cell index (lists, not dicts: indexing is the walk's most frequent step)
    nc = len(graph.ids)
    bound: list[Any] = [None] * nc
    lists: list[Any] = [None] * nc
    depth = [0] * nc
    queued = [False] * nc
    bound[s], lists[s], queued[s] = full, [full], True
    order = [s]
    queue = deque([s])
    pop, push = queue.popleft, queue.append
    opened = tested = 0
    limit = nc + 1 if max_depth is None else max_depth  # a chain of first visits has at most nc cells
    while queue:
        c = pop()
        queued[c] = False
        dc = depth[c]
        if dc >= limit:
            continue
        dn = dc + 1
        vx0, vy0, vx1, vy1 = bound[c]
        for t, pr in rows_of(c):
            if pr is None:
                continue
            tested += 1
            if pr is True:
                a0, a1, a2, a3 = vx0, vy0, vx1, vy1
            else:
                a0, a1, a2, a3 = pr
                # the portal's rectangle met the parent's VSA (max / min, inlined)
                if a0 < vx0:
                    a0 = vx0
                if a2 > vx1:
                    a2 = vx1
                if a0 > a2:
                    continue
                if a1 < vy0:
                    a1 = vy0
                if a3 > vy1:
                    a3 = vy1
                if a1 > a3:
                    continue
            opened += 1
            ob = bound[t]
            if ob is None:  # the first visit
                n = (a0, a1, a2, a3)
                bound[t] = n
                lists[t] = [n]
                depth[t] = dn
                order.append(t)
                push(t)
                queued[t] = True
            else:
                have = lists[t]
                # one pass: is the new VSA covered by one the cell has (nothing to do), or
                # does it cover some (they go)?  The list is changed in place when none
                # goes (the common case: no new list per arrival)
                drop = False
                for q in have:
                    q0, q1, q2, q3 = q
                    if q0 <= a0 and q1 <= a1 and q2 >= a2 and q3 >= a3:
                        break
                    if a0 <= q0 and a1 <= q1 and a2 >= q2 and a3 >= q3:
                        drop = True
                else:
                    n = (a0, a1, a2, a3)
                    if drop:
                        have = [q for q in have if not (a0 <= q[0] and a1 <= q[1] and a2 >= q[2] and a3 >= q[3])]
                        lists[t] = have
                    have.append(n)
                    if len(have) > max_vsas:
                        lists[t] = [_bounding(have)]
                    b0, b1, b2, b3 = ob
                    grew = False
                    if a0 < b0:
                        b0, grew = a0, True
                    if a1 < b1:
                        b1, grew = a1, True
                    if a2 > b2:
                        b2, grew = a2, True
                    if a3 > b3:
                        b3, grew = a3, True
                    if not grew:
                        continue
                    bound[t] = (b0, b1, b2, b3)
                    if dn < depth[t]:
                        depth[t] = dn
                    if not queued[t]:
                        push(t)
                        queued[t] = True
    ids = graph.ids.tolist()
    return PortalCull(
        order=[ids[i] for i in order],
        vsas={ids[i]: lists[i] for i in order},
        depth={ids[i]: depth[i] for i in order},
        portals=opened,
        tested=tested,
        seconds=time.perf_counter() - t0,
    )


def _bounding(rects: list[tuple[int, int, int, int]]) -> tuple[int, int, int, int]:
    """The bounding rectangle of whole-pixel rectangles."""
    x0, y0, x1, y1 = rects[0]
    for q in rects[1:]:
        x0, y0, x1, y1 = min(x0, q[0]), min(y0, q[1]), max(x1, q[2]), max(y1, q[3])
    return (x0, y0, x1, y1)


#: Directed portals up to which a frame turns every portal's rectangle into Python ints
#: at once; above, a cell's are turned when the walk first reaches it (a large building
#: of which a few cells are seen).  Either way all are projected in one numpy batch.
_LIST_ALL = 1024


def portal_rows(
    graph: PortalGraph,
    e: NDArray[np.float64],
    V: NDArray[np.float64],
    P: NDArray[np.float64],
    size: tuple[int, int],
    clip_m: float,
    pass_m: float,
    fog_m: float,
    naive: bool,
    closed: frozenset[int] = frozenset(),
    margin_px: float = CENTRE_MARGIN_PX,
    grow_m: float = 0.0,
) -> PortalRows:
    """A function giving, for a cell index, its directed portals as ``(target index, what)``
    pairs: ``what`` is ``None`` (culled: beyond the fog or wholly behind the clip plane),
    ``True`` (pass the parent's VSA through) or the portal's whole-pixel rectangle
    ``[x0, y0, x1, y1]``; every portal projected in one numpy batch.  The arguments as
    :func:`cull_portals` takes them (``e`` ``(3,)``, ``V``, ``P`` ``(4, 4)`` float64)."""
    m = len(graph.target)
    adjacency, starts = graph.adjacency, graph.row_start
    if m == 0:
        return lambda c: ()
    if naive:
        rect, front = point_rects(graph.poly, graph.edges, V, P, size, clip_m, naive, margin_px)
        rect4 = rect.T
    elif grow_m > 0.0:
        # the portals' boxes grown by ``grow_m``: a ray from any point within ``grow_m`` of
        # the eye through a portal passes, from the eye, through the grown box (the
        # cache's walk, :mod:`walkstream.shared.cullcache`); a box across the clip plane
        # gets the unclipped superset of its rectangle
        glo, ghi = graph.lo - grow_m, graph.hi + grow_m
        rect4, front, _near, _far = box_rects_ckm(np.stack([glo.T, ghi.T], axis=1), V, P, size, clip_m, margin_px,
                                                  clip_rest=False)
        rect = rect4.T
    else:
        rect4, front, _near, _far = rects_ckm(graph.poly_ckm, graph.edges, V, P, size, clip_m, margin_px)
        rect = rect4.T
    # 0 culled, 1 pass through, 2 the rectangle
    what = np.where(front, 2, 0).astype(np.int8)
    if grow_m > 0.0 and not naive:
        # the eye near a grown box: some ray of the eyes it stands for may pass the
        # portal at a depth the projection cannot hold
        near_pass = max(pass_m, clip_m * corner_secant(P) * 1.01)
        what[box_distance(glo, ghi, e) <= near_pass] = 1
    elif not naive:
        near_pass = max(pass_m, clip_m * corner_secant(P) * 1.01)
        dist = np.abs(graph.plane[:, :3] @ e + graph.plane[:, 3])
        near = np.flatnonzero(dist <= near_pass)
        if len(near):
            inside = np.all((e >= graph.lo[near] - near_pass) & (e <= graph.hi[near] + near_pass), axis=1)
            what[near[inside]] = 1
    if math.isfinite(fog_m):
        what[box_distance(graph.lo, graph.hi, e) > fog_m] = 0
    if closed:
        what[np.isin(graph.portal, np.fromiter(closed, np.int64, len(closed)))] = 0
    if m <= _LIST_ALL:
        # a rectangle that meets no pixel of the viewport meets no VSA (they all lie
        # within it): such a portal is tested as before (the counts stay) but against
        # an empty rectangle, and only the others are turned into ints (a tenth of a
        # generated office's portals at a time)
        x0, y0, x1, y1 = rect4
        opens = np.flatnonzero((what == 2) & (x0 <= x1) & (y0 <= y1) & (x1 >= 0) & (y1 >= 0)
                               & (x0 < size[0]) & (y0 < size[1]))
        sparse = 2 * len(opens) < m  # else all at once is cheaper (an open hall)
        table: list[Any] = [_NO_PIXEL] * m if sparse else rect.tolist()
        for i in np.flatnonzero(what == 0).tolist():
            table[i] = None
        for i in np.flatnonzero(what == 1).tolist():
            table[i] = True
        if sparse:
            for i, r in zip(opens.tolist(), rect4[:, opens].T.tolist(), strict=True):
                table[i] = r
        return lambda c: zip(adjacency[c], table[starts[c] : starts[c + 1]], strict=True)
    done: dict[int, list[tuple[int, Any]]] = {}

    def rows_of(c: int) -> list[tuple[int, Any]]:
        got = done.get(c)
        if got is None:
            a, b = starts[c], starts[c + 1]
            got = [
                (t, r if k == 2 else (None if k == 0 else True))
                for t, r, k in zip(adjacency[c], rect[a:b].tolist(), what[a:b].tolist(), strict=True)
            ]
            done[c] = got
        return got

    return rows_of


def frustum_cells(
    graph: PortalGraph,
    start: int,
    eye: ArrayLike,
    view_proj: ArrayLike,
    *,
    fog_m: float = math.inf,
    max_depth: int | None = None,
    near_m: float = 0.5,
) -> list[int]:
    """Frustum culling alone: the cells reached from ``start`` through portals whose box
    meets the view frustum (or comes within ``near_m`` of the eye) and lies within the
    fog, breadth first (to ``max_depth`` portals when one is given); no VSA narrows the view.

    Returns the cell ids, ``start`` first.
    """
    if start not in graph.index:
        raise InputError(f"frustum_cells: no cell {start} in the interior")
    e = np.asarray(eye, np.float64).reshape(3)
    s = graph.index[start]
    depth = {s: 0}
    order = [s]
    i = 0
    while i < len(order):
        c = order[i]
        i += 1
        a, b = int(graph.start[c]), int(graph.start[c + 1])
        if (max_depth is not None and depth[c] >= max_depth) or a == b:
            continue
        rows = np.arange(a, b)
        near = box_distance(graph.lo[rows], graph.hi[rows], e)
        seen = (frustum_cull(graph.lo[rows], graph.hi[rows], view_proj) | (near < near_m)) & (near <= fog_m)
        for r in rows[seen].tolist():
            t = int(graph.target[r])
            if t not in depth:
                depth[t] = depth[c] + 1
                order.append(t)
    return [int(graph.ids[c]) for c in order]


#: An empty whole-pixel rectangle (no pixel centre): pads a cell's VSAs.
_NO_PIXEL = (1, 1, 0, 0)
