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
building is clipped and projected in one numpy batch per frame (:func:`portal_rows`,
coordinate-major: :func:`~walkstream.shared.screenrects.rects_ckm`); the walk is then one
call of a compiled loop (:func:`~walkstream.shared.cullkernels.walk_kernel`, numba) over
that table and the graph's adjacency arrays.  It is the reference walk step for step
(:mod:`walkstream.benchmarks.portalwalk` keeps that one; tests/test_portalwalk.py checks
they agree): the FIFO order decides the VSA lists (which VSAs reach a cell before it is
looked through), so the walk stays a walk.  In Python it cost 4-6 us a visible cell
(1.3-1.5 ms at the open 16 x 16 hall's 236 cells); numpy batches by levels were
measured and cost more (docs/benchmarks.md, "a walk by levels measured"); compiled, the
walk itself takes some 20 us there, and the frame's walk is the projection's numpy
calls and the answer's Python lists.
``walkstream bench portals --cull`` times it (:mod:`walkstream.benchmarks.cullcpu`).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.shared.cullkernels import walk_kernel
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
    rows : PortalRows, optional
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
    # (portal_rows), and the compiled walk (cullkernels.walk_kernel) intersects the
    # whole-pixel rectangles.  It is the round-one FIFO walk (benchmarks/portalwalk.py)
    # step for step, so its cells, VSAs and depths are the same.
    table = rows if rows is not None else portal_rows(graph, e, V, P, (w, h), clip_m, pass_m, fog_m, naive, closed,
                                                      margin_px, grow_m)
    limit = len(graph.ids) + 1 if max_depth is None else max_depth  # a chain of first visits has at most nc cells
    cells, depths, vsa_rows, counts, opened, tested = walk_kernel(
        graph.target, graph.start, table.what, table.rect, graph.index[start], w, h, limit, max_vsas)
    ids = graph.ids[cells].tolist()
    # the VSAs as tuples of plain ints, each cell's a slice of one list (no statement per cell)
    flat = list(map(tuple, vsa_rows.tolist()))
    ends = np.cumsum(counts)
    vsas = dict(zip(ids, map(flat.__getitem__, map(slice, (ends - counts).tolist(), ends.tolist())), strict=True))
    return PortalCull(
        order=ids,
        vsas=vsas,
        depth=dict(zip(ids, depths.tolist(), strict=True)),
        portals=int(opened),
        tested=int(tested),
        seconds=time.perf_counter() - t0,
    )


@dataclass(frozen=True)
class PortalRows:
    """Every directed portal's part in a frame's walk, made by :func:`portal_rows` for one
    camera and one set of settings (:attr:`~walkstream.shared.portalgraph.PortalGraph.target`'s
    rows).

    Attributes
    ----------
    what : (m,) int8
        0 culled (beyond the fog, wholly behind the clip plane, or closed), 1 passed
        through (the parent's VSA goes on unchanged), 2 its rectangle.
    rect : (4, m) int64
        The portals' whole-pixel rectangles (rows ``x0, y0, x1, y1``), where ``what`` is 2.
    """

    what: NDArray[np.int8]
    rect: NDArray[np.int64]


#: Directed portals above which a frame projects only the portals within the fog (a large
#: building of which a few cells are seen); up to it, all of them (the selection's calls
#: cost more than projecting a few hundred).  Either way in one numpy batch.
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
    """Every directed portal's part in the walk (:class:`PortalRows`): culled (beyond the fog
    or wholly behind the clip plane), passed through, or its whole-pixel rectangle; the
    portals projected in one numpy batch.  The arguments as :func:`cull_portals` takes
    them (``e`` ``(3,)``, ``V``, ``P`` ``(4, 4)`` float64)."""
    m = len(graph.target)
    if m == 0:
        return PortalRows(np.zeros(0, np.int8), np.zeros((4, 0), np.int64))
    fogged = box_distance(graph.lo, graph.hi, e) > fog_m if math.isfinite(fog_m) else None
    few = None if fogged is None or m <= _LIST_ALL or naive or grow_m > 0.0 else np.flatnonzero(~fogged)
    if naive:
        rect, front = point_rects(graph.poly, graph.edges, V, P, size, clip_m, naive, margin_px)
        rect4 = np.ascontiguousarray(rect.T)
    elif grow_m > 0.0:
        # the portals' boxes grown by ``grow_m``: a ray from any point within ``grow_m`` of
        # the eye through a portal passes, from the eye, through the grown box (the
        # cache's walk, :mod:`walkstream.shared.cullcache`); a box across the clip plane
        # gets the unclipped superset of its rectangle
        glo, ghi = graph.lo - grow_m, graph.hi + grow_m
        rect4, front, _near, _far = box_rects_ckm(np.stack([glo.T, ghi.T], axis=1), V, P, size, clip_m, margin_px,
                                                  clip_rest=False)
    elif few is not None:
        # each portal's figures are its own (elementwise), so a subset's are the same
        rect4 = np.empty((4, m), np.int64)
        front = np.zeros(m, bool)
        rect4[:, few], front[few], _near, _far = rects_ckm(graph.poly_ckm[:, :, few], graph.edges, V, P, size,
                                                           clip_m, margin_px)
    else:
        rect4, front, _near, _far = rects_ckm(graph.poly_ckm, graph.edges, V, P, size, clip_m, margin_px)
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
    if fogged is not None:
        what[fogged] = 0
    if closed:
        what[np.isin(graph.portal, np.fromiter(closed, np.int64, len(closed)))] = 0
    return PortalRows(what, rect4)


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

