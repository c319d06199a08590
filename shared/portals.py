"""Portal culling with visible screen areas (Mulloni et al., Figures 3 and 4), near-plane safe.

Pure numpy, no GL.  One frame:

1. The viewer's cell gets the whole viewport as its **visible screen area** (VSA), an
   axis-aligned rectangle of whole pixels ``(x0, y0, x1, y1)``, inclusive, row 0 at
   the bottom (GL's window coordinates).
2. A cell taken from the queue tests all its portals at once: a portal farther than
   the fog distance (its box's distance from the eye) is culled; the others are
   **clipped against a plane** ``clip_m`` in front of the eye *before* projection,
   so a vertex behind the eye never projects to a wrong place (the paper's
   ``IsPortalCulled`` projects vertices as they are: a door the walker is passing
   through gets a wrong rectangle and the room behind it vanishes); the clipped
   polygon's projected bounding rectangle is **rounded outward** to whole pixels and
   intersected with the cell's VSA; an empty intersection culls the portal.
3. When the eye is within a few centimetres of a portal's plane and inside its
   bounds, the portal's projection degenerates (it fills the screen or nothing):
   the cell behind it gets the parent's VSA unchanged (**pass-through**).
4. The VSAs that reach one cell are **merged**: a short list (at most ``max_vsas``,
   beyond which they become their bounding rectangle), and the cell is propagated
   with their bounding rectangle.  A cell enters the render queue **once per frame**;
   it is only looked through again when its rectangle grew, which happens at most a
   few times per frame (the rectangle grows by whole pixels within the viewport),
   so paths through many portals cannot grow exponentially.  A **depth limit**
   bounds the portals passed on the way to a cell.
5. Each queued cell's contents are culled by their boxes: a box is kept when it comes
   within the fog distance and its clipped, projected rectangle meets one of the
   cell's VSAs; the frustum test follows (for the far plane), as in the paper.

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
walk over plain ints (per-scene adjacency lists built once, in :class:`PortalGraph`),
about 4-6 us per visible cell on the 2-core machine.  It is the reference walk step for
step (:mod:`walkstream.benchmarks.portalwalk` keeps that one; tests/test_portalwalk.py checks they agree):
a walk by levels with numpy batches per level was not taken, since the FIFO order
decides the VSA lists (which VSAs reach a cell before it is looked through) and a
level costs tens of numpy calls whatever its size, more than the few cells of a
level cost in Python.
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.shared.errors import InputError
from walkstream.shared.frustum import frustum_cull

__all__ = [
    "CULLING_MODES",
    "OPEN_KINDS",
    "PortalGraph",
    "PortalCull",
    "cull_portals",
    "frustum_cells",
    "cull_parts",
    "box_rects",
    "cull_boxes",
    "full_vsa",
    "box_distance",
]

#: The replay's ``--culling`` choices: portal culling with VSAs, the frustum alone
#: (every cell reached through portals whose box meets the frustum, no VSA), or
#: drawing every part of every loaded visible cell.
CULLING_MODES: tuple[str, ...] = ("portals", "frustum", "none")

_EPS_PX = 1e-3


@dataclass(frozen=True)
class PortalGraph:
    """The portals of an interior as arrays, each portal once per direction.

    Attributes
    ----------
    ids : (n,) int64
        Cell ids, in the topology's order.
    outside : (n,) bool
        Whether each cell is the ``outside`` cell.
    start : (n + 1,) int64
        Cell ``i``'s directed portals are rows ``start[i]:start[i + 1]``.
    target : (m,) int64
        Index (into ``ids``) of the cell on the portal's other side.
    portal : (m,) int64
        Portal id.
    poly : (m, k, 3) float64
        Portal polygons, padded by repeating their last vertex.
    lo, hi : (m, 3) float64
        Their boxes.
    plane : (m, 4) float64
        Their planes ``n . p + d = 0``, ``|n| = 1``.
    """

    ids: NDArray[np.int64]
    outside: NDArray[np.bool_]
    start: NDArray[np.int64]
    target: NDArray[np.int64]
    portal: NDArray[np.int64]
    poly: NDArray[np.float64]
    lo: NDArray[np.float64]
    hi: NDArray[np.float64]
    plane: NDArray[np.float64]
    index: dict[int, int] = field(default_factory=dict)
    #: Per cell (by index) the target indices of its directed portals (rows
    #: ``start[i]:start[i + 1]``): the walk's adjacency as plain ints, built once per
    #: scene, not per frame.
    adjacency: list[list[int]] = field(init=False, repr=False, compare=False)
    #: :attr:`start` as plain ints.
    row_start: list[int] = field(init=False, repr=False, compare=False)
    #: ``(k, 2)`` the vertex index pairs joining a padded polygon's sides.
    edges: NDArray[np.int64] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        target = self.target.tolist()
        starts = self.start.tolist()
        adjacency = [target[a:b] for a, b in zip(starts[:-1], starts[1:], strict=True)]
        k = self.poly.shape[1]
        # frozen: the derived tables are set once, here
        object.__setattr__(self, "adjacency", adjacency)
        object.__setattr__(self, "row_start", starts)
        object.__setattr__(self, "edges", np.stack([np.arange(k), (np.arange(k) + 1) % k], axis=1))

    @classmethod
    def from_topology(cls, topology: Any) -> PortalGraph:
        """Build from a :class:`~walkstream.shared.roomwire.Topology` (its cells' portal refs)."""
        cells = list(topology.cells)
        index = {int(c.id): i for i, c in enumerate(cells)}
        rows: list[tuple[int, int, NDArray[np.float64]]] = []
        start = [0]
        for c in cells:
            for r in c.portals:
                if int(r.cell) in index:
                    rows.append((index[int(r.cell)], int(r.id), np.asarray(r.polygon, np.float64)))
            start.append(len(rows))
        kinds = {int(pid): str(kind) for pid, kind, _, _, _ in topology.portals}
        byid = {int(c.id): c for c in cells}
        rows = [
            (t, pid, _open_face(p, byid[int(c.id)], cells[t]) if kinds.get(pid) in OPEN_KINDS else p)
            for c, (t, pid, p) in zip(_owners(cells, index), rows, strict=True)
        ]
        k = max((len(p) for _, _, p in rows), default=3)
        poly = np.zeros((len(rows), k, 3))
        for i, (_, _, p) in enumerate(rows):
            poly[i, : len(p)] = p
            poly[i, len(p) :] = p[-1]
        plane = np.zeros((len(rows), 4))
        for i, (_, _, p) in enumerate(rows):
            # Newell's normal: robust for any planar polygon's winding
            q = np.roll(p, -1, axis=0)
            n = np.array([
                np.sum((p[:, 1] - q[:, 1]) * (p[:, 2] + q[:, 2])),
                np.sum((p[:, 2] - q[:, 2]) * (p[:, 0] + q[:, 0])),
                np.sum((p[:, 0] - q[:, 0]) * (p[:, 1] + q[:, 1])),
            ])
            norm = float(np.linalg.norm(n))
            n = n / norm if norm > 0 else np.array([0.0, 0.0, 1.0])
            plane[i, :3] = n
            plane[i, 3] = -float(n @ p.mean(axis=0))
        return cls(
            ids=np.array([int(c.id) for c in cells], np.int64),
            outside=np.array([c.kind == "outside" for c in cells], bool),
            start=np.array(start, np.int64),
            target=np.array([t for t, _, _ in rows], np.int64),
            portal=np.array([pid for _, pid, _ in rows], np.int64),
            poly=poly,
            lo=poly.min(axis=1) if len(rows) else np.zeros((0, 3)),
            hi=poly.max(axis=1) if len(rows) else np.zeros((0, 3)),
            plane=plane,
            index=index,
        )


#: Portal kinds with no wall about them (the boundary between two parts of one space,
#: a virtual space boundary): the whole face the two cells share is open, whatever
#: polygon the source gave (IFC virtual boundaries are often narrower than it).
OPEN_KINDS = frozenset({"opening", "virtual", "split", "void"})


def _owners(cells: list[Any], index: dict[int, int]) -> list[Any]:
    """The owning cell of each directed portal row, in the order of ``from_topology``."""
    return [c for c in cells for r in c.portals if int(r.cell) in index]


def _open_face(poly: NDArray[np.float64], a: Any, b: Any) -> NDArray[np.float64]:
    """A vertical portal grown to the face its two cells share (see :data:`OPEN_KINDS`).

    The cells' outline edges that lie in the portal's plane (within 1 cm) give each
    cell's extent along the plane; the shared face is their overlap, times the overlap
    of the cells' height ranges.  The polygon returned is the rectangle spanning both
    the source polygon and that face; a portal that is not vertical, or whose cells
    have no edge in its plane, is returned as it is.
    """
    p = np.asarray(poly, np.float64)
    n = np.cross(p[1] - p[0], p[2] - p[0])
    nh = float(np.hypot(n[0], n[1]))
    if nh < 1e-9 or abs(n[2]) > 0.1 * nh:
        return p
    nrm = np.array([n[0], n[1]]) / nh
    tan = np.array([-nrm[1], nrm[0]])
    off = float(nrm @ p[0, :2])

    def extent(cell: Any) -> tuple[float, float] | None:
        o = np.asarray(cell.outline, np.float64)
        q = np.roll(o, -1, axis=0)
        on = (np.abs(o @ nrm - off) < 0.01) & (np.abs(q @ nrm - off) < 0.01)
        if not on.any():
            return None
        s = np.concatenate([o[on] @ tan, q[on] @ tan])
        return float(s.min()), float(s.max())

    ea, eb = extent(a), extent(b)
    if ea is None or eb is None:
        return p
    s0, s1 = max(ea[0], eb[0]), min(ea[1], eb[1])
    z0, z1 = max(a.zmin, b.zmin), min(a.zmax, b.zmax)
    ps = p[:, :2] @ tan
    s0, s1 = min(s0, float(ps.min())), max(s1, float(ps.max()))
    z0, z1 = min(z0, float(p[:, 2].min())), max(z1, float(p[:, 2].max()))
    base = nrm * off
    c0, c1 = base + s0 * tan, base + s1 * tan
    return np.array([[c0[0], c0[1], z0], [c1[0], c1[1], z0], [c1[0], c1[1], z1], [c0[0], c0[1], z1]])


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


def full_vsa(size: tuple[int, int]) -> NDArray[np.int64]:
    """The whole viewport ``(4,)`` as a VSA."""
    return np.array([0, 0, int(size[0]) - 1, int(size[1]) - 1], np.int64)


def _corner_secant(proj: NDArray[np.float64]) -> float:
    """Secant of the angle between the view axis and the frustum's corner rays."""
    tx, ty = 1.0 / abs(float(proj[0, 0])), 1.0 / abs(float(proj[1, 1]))
    return math.sqrt(1.0 + tx * tx + ty * ty)


def _rects(
    pts: NDArray[np.float64],
    edges: NDArray[np.int64],
    view: NDArray[np.float64],
    proj: NDArray[np.float64],
    size: tuple[int, int],
    clip_m: float,
    naive: bool = False,
) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
    """Whole-pixel rectangles of point sets clipped against depth ``clip_m``.

    ``pts`` ``(m, k, 3)`` world points, ``edges`` ``(e, 2)`` the index pairs joining
    them (the polygon's sides or a box's edges).  Returns ``(m, 4)`` inclusive pixel
    rectangles (unclamped) and ``(m,)`` whether anything of each set lies in front.
    """
    m = len(pts)
    if m == 0:
        return np.zeros((0, 4), np.int64), np.zeros(0, bool)
    # eye space (m, k, 3); one 2-d product (a stack of m small ones is several times slower)
    v = (pts.reshape(-1, 3) @ view[:3, :3].T + view[:3, 3]).reshape(pts.shape)
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
        near_d, far_d = _kmin(depth), _kmax(depth)
        ahead = near_d >= clip_m
        front = np.ones(m, bool)
        # the common case, nothing to clip: the vertices' projections bound the set;
        # computed for every row (elementwise, so each row's figures are the same as
        # alone) and the others overwritten below
        d = np.where(ahead[:, None], depth, 1.0)
        x = (proj[0, 0] * v[..., 0] + proj[0, 2] * v[..., 2]) / d
        y = (proj[1, 1] * v[..., 1] + proj[1, 2] * v[..., 2]) / d
        rect = _pixels(np.stack([_kmin(x), _kmin(y)], axis=1), np.stack([_kmax(x), _kmax(y)], axis=1), size)
        behind = far_d < clip_m
        front[behind] = False
        rect[behind] = (1, 1, 0, 0)
        rest = ~ahead & ~behind
        if rest.any():
            rect[rest], front[rest] = _clipped(v[rest], depth[rest], edges, proj, size, clip_m)
        return rect, front
    return _pixels(lo, hi, size), front


def _kmin(a: NDArray[np.float64]) -> NDArray[np.float64]:
    """``(m,)`` minima over the second axis of ``(m, k)``: ``k - 1`` elementwise minima,
    cheaper than a reduction along a short axis for the few vertices of a portal or box."""
    out = a[:, 0].copy()
    for j in range(1, a.shape[1]):
        np.minimum(out, a[:, j], out=out)
    return out


def _kmax(a: NDArray[np.float64]) -> NDArray[np.float64]:
    """``(m,)`` maxima over the second axis of ``(m, k)`` (see :func:`_kmin`)."""
    out = a[:, 0].copy()
    for j in range(1, a.shape[1]):
        np.maximum(out, a[:, j], out=out)
    return out


def _clipped(
    v: NDArray[np.float64],
    depth: NDArray[np.float64],
    edges: NDArray[np.int64],
    proj: NDArray[np.float64],
    size: tuple[int, int],
    clip_m: float,
) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
    """:func:`_rects` of eye-space point sets ``(m, k, 3)`` that cross the clip plane."""
    a, b = v[:, edges[:, 0]], v[:, edges[:, 1]]  # (m, e, 3)
    da, db = depth[:, edges[:, 0]], depth[:, edges[:, 1]]
    cross = (da - clip_m) * (db - clip_m) < 0
    t = np.where(cross, (clip_m - da) / np.where(cross, db - da, 1.0), 0.0)
    xpts = a + t[..., None] * (b - a)
    allp = np.concatenate([v, xpts], axis=1)  # (m, k + e, 3)
    ok = np.concatenate([depth >= clip_m, cross], axis=1)
    d = np.where(ok, -allp[..., 2], 1.0)
    # a perspective projection: x_ndc = (P00 x + P02 z) / -z, likewise y
    x = (proj[0, 0] * allp[..., 0] + proj[0, 2] * allp[..., 2]) / d
    y = (proj[1, 1] * allp[..., 1] + proj[1, 2] * allp[..., 2]) / d
    front = np.any(ok, axis=1)
    big = 1e30
    lo = np.stack([np.where(ok, x, big).min(axis=1), np.where(ok, y, big).min(axis=1)], axis=1)
    hi = np.stack([np.where(ok, x, -big).max(axis=1), np.where(ok, y, -big).max(axis=1)], axis=1)
    return _pixels(lo, hi, size), front


def _pixels(lo: NDArray[np.float64], hi: NDArray[np.float64], size: tuple[int, int]) -> NDArray[np.int64]:
    """NDC bounds ``(m, 2)`` each to inclusive whole-pixel rectangles ``(m, 4)``, rounded outward."""
    wh = np.array([size[0], size[1]], np.float64)
    plo = np.clip((lo + 1.0) * 0.5 * wh, -1e9, 1e9)
    phi = np.clip((hi + 1.0) * 0.5 * wh, -1e9, 1e9)
    return np.concatenate([np.floor(plo - _EPS_PX), np.floor(phi + _EPS_PX)], axis=1).astype(np.int64)


def _meet(r: NDArray[np.int64], vsa: NDArray[np.int64]) -> NDArray[np.int64]:
    """Intersections ``(m, 4)`` of rectangles with one VSA ``(4,)`` (empty when x0 > x1 or y0 > y1)."""
    return np.concatenate([np.maximum(r[:, :2], vsa[:2]), np.minimum(r[:, 2:], vsa[2:])], axis=1)


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
    max_depth: int = 32,
    clip_m: float = 0.03,
    pass_m: float = 0.05,
    max_vsas: int = 4,
    naive: bool = False,
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
    max_depth : int
        Portals passed, at most.
    clip_m, pass_m : float
        The clip plane's depth and the pass-through distance, metres.
    max_vsas : int
        VSAs kept per cell before they are merged into one.
    naive : bool
        The paper's test (no clipping, no pass-through); for the tests only.
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
    # (_portal_rows; the adjacency is built once per scene), and the walk below intersects
    # whole-pixel rectangles as plain ints.  The walk is the round-one FIFO walk
    # (benchmarks/portalwalk.py) step for step, so its cells, VSAs and depths are the
    # same; only the constant work per portal is less.
    rows_of = _portal_rows(graph, e, V, P, (w, h), clip_m, pass_m, fog_m, naive)
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
    while queue:
        c = pop()
        queued[c] = False
        dc = depth[c]
        if dc >= max_depth:
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
            if ob is None:
                n = (a0, a1, a2, a3)
                bound[t] = n
                lists[t] = [n]
                depth[t] = dn
                order.append(t)
            else:
                have = lists[t]
                covered = False
                for q in have:
                    if q[0] <= a0 and q[1] <= a1 and q[2] >= a2 and q[3] >= a3:
                        covered = True
                        break
                if covered:
                    continue
                n = (a0, a1, a2, a3)
                have = [q for q in have if not (a0 <= q[0] and a1 <= q[1] and a2 >= q[2] and a3 >= q[3])]
                have.append(n)
                if len(have) > max_vsas:
                    have = [_bounding(have)]
                lists[t] = have
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


def _portal_rows(
    graph: PortalGraph,
    e: NDArray[np.float64],
    V: NDArray[np.float64],
    P: NDArray[np.float64],
    size: tuple[int, int],
    clip_m: float,
    pass_m: float,
    fog_m: float,
    naive: bool,
) -> Callable[[int], Iterable[tuple[int, Any]]]:
    """A function giving, for a cell index, its directed portals as ``(target index, what)``
    pairs: ``what`` is ``None`` (culled: beyond the fog or wholly behind the clip plane),
    ``True`` (pass the parent's VSA through) or the portal's whole-pixel rectangle
    ``[x0, y0, x1, y1]``; every portal projected in one numpy batch."""
    m = len(graph.target)
    adjacency, starts = graph.adjacency, graph.row_start
    if m == 0:
        return lambda c: ()
    rect, front = _rects(graph.poly, graph.edges, V, P, size, clip_m, naive)
    # 0 culled, 1 pass through, 2 the rectangle
    what = np.where(front, 2, 0).astype(np.int8)
    if not naive:
        near_pass = max(pass_m, clip_m * _corner_secant(P) * 1.01)
        dist = np.abs(graph.plane[:, :3] @ e + graph.plane[:, 3])
        near = np.flatnonzero(dist <= near_pass)
        if len(near):
            inside = np.all((e >= graph.lo[near] - near_pass) & (e <= graph.hi[near] + near_pass), axis=1)
            what[near[inside]] = 1
    if math.isfinite(fog_m):
        what[box_distance(graph.lo, graph.hi, e) > fog_m] = 0
    if m <= _LIST_ALL:
        table: list[Any] = rect.tolist()
        for i in np.flatnonzero(what == 0).tolist():
            table[i] = None
        for i in np.flatnonzero(what == 1).tolist():
            table[i] = True
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


_BOX_EDGES = np.array(
    [[0, 1], [2, 3], [4, 5], [6, 7], [0, 2], [1, 3], [4, 6], [5, 7], [0, 4], [1, 5], [2, 6], [3, 7]], np.int64
)


def box_rects(
    lo: ArrayLike, hi: ArrayLike, view: ArrayLike, proj: ArrayLike, size: tuple[int, int], clip_m: float = 0.03
) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
    """Whole-pixel rectangles ``(n, 4)`` of boxes ``(n, 3)`` clipped at depth ``clip_m``, and
    ``(n,)`` whether any part of each box lies in front of that plane."""
    lo_ = np.asarray(lo, np.float64).reshape(-1, 3)
    hi_ = np.asarray(hi, np.float64).reshape(-1, 3)
    bits = (np.arange(8)[:, None] >> np.arange(3)[None, :]) & 1  # (8, 3)
    corners = np.where(bits[None, :, :] == 1, hi_[:, None, :], lo_[:, None, :])
    return _rects(corners, _BOX_EDGES, np.asarray(view, np.float64), np.asarray(proj, np.float64), size, clip_m)


def cull_boxes(
    lo: ArrayLike,
    hi: ArrayLike,
    vsas: ArrayLike,
    eye: ArrayLike,
    view: ArrayLike,
    proj: ArrayLike,
    size: tuple[int, int],
    *,
    fog_m: float = math.inf,
    clip_m: float = 0.03,
) -> NDArray[np.bool_]:
    """Which of a cell's boxes to draw: within the fog, meeting one of its VSAs, in the frustum.

    Parameters
    ----------
    lo, hi : (n, 3) float
        The boxes of the cell's contents.
    vsas : (k, 4) int64
        The cell's VSAs (:attr:`PortalCull.vsas`).
    eye : (3,) float
    view, proj : (4, 4) float
    size : (int, int)
    fog_m, clip_m : float

    Returns
    -------
    (n,) bool
    """
    lo_ = np.asarray(lo, np.float64).reshape(-1, 3)
    hi_ = np.asarray(hi, np.float64).reshape(-1, 3)
    if len(lo_) == 0:
        return np.zeros(0, bool)
    e = np.asarray(eye, np.float64).reshape(3)
    keep = box_distance(lo_, hi_, e) <= fog_m
    rect, front = box_rects(lo_, hi_, view, proj, size, clip_m)
    v = np.asarray(vsas, np.int64).reshape(-1, 4)
    meet = (
        (rect[:, None, 0] <= v[None, :, 2]) & (rect[:, None, 2] >= v[None, :, 0])
        & (rect[:, None, 1] <= v[None, :, 3]) & (rect[:, None, 3] >= v[None, :, 1])
    )
    keep &= front & np.any(meet, axis=1)
    vp = np.asarray(proj, np.float64) @ np.asarray(view, np.float64)
    keep[keep] = frustum_cull(lo_[keep], hi_[keep], vp)
    return keep


def frustum_cells(
    graph: PortalGraph,
    start: int,
    eye: ArrayLike,
    view_proj: ArrayLike,
    *,
    fog_m: float = math.inf,
    max_depth: int = 32,
    near_m: float = 0.5,
) -> list[int]:
    """Frustum culling alone: the cells reached from ``start`` through portals whose box
    meets the view frustum (or comes within ``near_m`` of the eye) and lies within the
    fog, breadth first, to ``max_depth`` portals; no VSA narrows the view.

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
        if depth[c] >= max_depth or a == b:
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


def cull_parts(
    mode: str,
    cells: list[int],
    boxes: dict[int, tuple[NDArray[np.float64], NDArray[np.float64]]],
    eye: ArrayLike,
    view: ArrayLike,
    proj: ArrayLike,
    size: tuple[int, int],
    *,
    vsas: dict[int, list[tuple[int, int, int, int]]] | None = None,
    fog_m: float = math.inf,
    clip_m: float = 0.03,
) -> dict[int, NDArray[np.bool_]]:
    """Which parts of each visible cell to draw, by ``mode`` (:data:`CULLING_MODES`).

    Parameters
    ----------
    mode : str
        ``portals``: boxes against the cell's VSAs, the fog and the frustum
        (:func:`cull_boxes`); ``frustum``: the frustum and the fog; ``none``: all.
    cells : list of int
        Visible cells (those without boxes, i.e. not loaded, are left out).
    boxes : dict of int -> ((n, 3), (n, 3))
        Per cell, its parts' boxes.
    vsas : dict of int -> (k, 4) int64
        Per cell its VSAs (``portals`` mode).

    Returns
    -------
    dict of int -> (n,) bool
    """
    if mode not in CULLING_MODES:
        raise InputError(f"culling mode {mode!r}: expected one of {', '.join(CULLING_MODES)}")
    out: dict[int, NDArray[np.bool_]] = {}
    e = np.asarray(eye, np.float64).reshape(3)
    vp = np.asarray(proj, np.float64) @ np.asarray(view, np.float64)
    for c in cells:
        if c not in boxes:
            continue
        lo, hi = boxes[c]
        if mode == "none":
            out[c] = np.ones(len(lo), bool)
        elif mode == "frustum":
            keep = box_distance(lo, hi, e) <= fog_m
            keep[keep] = frustum_cull(lo[keep], hi[keep], vp)
            out[c] = keep
    if mode != "portals":
        return out
    # every visible cell's boxes in one vectorised pass, each against its own cell's VSAs
    seen = [c for c in cells if c in boxes and vsas is not None and c in vsas and len(boxes[c][0])]
    for c in cells:
        if c in boxes and c not in seen:
            out[c] = np.zeros(len(boxes[c][0]), bool)
    if not seen or vsas is None:
        return out
    counts = [len(boxes[c][0]) for c in seen]
    lo = np.concatenate([boxes[c][0] for c in seen])
    hi = np.concatenate([boxes[c][1] for c in seen])
    owner = np.repeat(np.arange(len(seen)), counts)
    kmax = max(len(vsas[c]) for c in seen)
    v = np.tile(np.array([1, 1, 0, 0], np.int64), (len(seen), kmax, 1))  # empty rectangles
    for i, c in enumerate(seen):
        v[i, : len(vsas[c])] = vsas[c]
    keep = box_distance(lo, hi, e) <= fog_m
    rect, front = box_rects(lo, hi, view, proj, size, clip_m)
    vv = v[owner]  # (n, kmax, 4)
    meet = (
        (rect[:, None, 0] <= vv[:, :, 2]) & (rect[:, None, 2] >= vv[:, :, 0])
        & (rect[:, None, 1] <= vv[:, :, 3]) & (rect[:, None, 3] >= vv[:, :, 1])
        & (vv[:, :, 0] <= vv[:, :, 2])
    )
    keep &= front & np.any(meet, axis=1)
    keep[keep] = frustum_cull(lo[keep], hi[keep], vp)
    for c, part in zip(seen, np.split(keep, np.cumsum(counts)[:-1]), strict=True):
        out[c] = part
    return out
