"""The interior culling reused from frame to frame while the view changes little, never hiding what is seen.

A frame's culling (the portal walk, :func:`~walkstream.shared.portals.cull_portals`, and
the parts culling, :func:`~walkstream.shared.partcull.cull_parts`) costs a few
milliseconds at two hundred visible cells, and consecutive frames look at nearly the
same thing.  :class:`CullCache` culls once for a **guard view** that holds every view
the eye can take within ``move_m`` of where it stood and ``turn_deg`` of where it
looked, from the same cell, and hands that answer out again while the frames stay
within it (a *hit*: a few numpy calls to check, no walk).

The guard view (made on a *miss*):

- its apex ``a`` stands ``b = move_m / 2 + 2 clip_m`` behind the eye ``e`` on the view
  axis;
- its pyramid is the camera's own, each half-angle widened by ``turn_deg``, with as
  many more pixels as keep the camera's pixel size; its near plane at half the clip
  plane, its far plane beyond the camera's by ``R``;
- every portal is grown by ``R = b + move_m`` on all sides (the walk's ``grow_m``: the
  grown box is projected, and passed through when the apex comes within the
  pass-through distance of it), the fog by ``R``, and portals and boxes keep every pixel
  they touch (:data:`~walkstream.shared.screenrects.TOUCH_MARGIN_PX`), not only the
  centres.

A frame is *within* the guard when its eye ``e'`` lies within ``R`` of the apex, inside
the guard's pyramid at a depth of at least the clip plane, its frustum's four corner
rays lie inside the pyramid, and it is culled from the same cell with the same
projection, viewport, fog, closed portals and boxes.  Why nothing such a frame sees is
left out: a point ``X`` it sees lies in the guard pyramid (the pyramid is convex and
holds ``e'`` and every direction of the frame's frustum), at a depth from ``a`` of at
least ``e'``'s, so beyond the clip plane.  The segment ``e' X`` passes the portals
``P1 ... Pk`` from the start cell to ``X``'s cell; the segment ``a X`` passes, at the
same fraction of its length, within ``|a - e'| <= R`` of each crossing point, so
through each grown portal, where its points project to ``X``'s pixel from ``a`` (a
grown box farther from the apex than the pass-through distance has its points in the
pyramid beyond the clip plane).  So that pixel lies in every grown portal's rectangle
(or the walk passes the portal through), in a VSA of ``X``'s cell, and in the
rectangle of ``X``'s box: the box is kept.  Distances from ``a`` exceed those from
``e'`` by at most ``R``, so the fog grown by ``R`` keeps whatever the frame's fog keeps.
The frame the guard is made on is within it.

What a hit costs: the pose checks (in plain floats) and an identity check of the
visible cells' boxes (a cell loaded or replaced since is a miss).  What a miss costs:
one walk and one parts culling of the guard view, wider than the frame's (more cells
and boxes; the portals' boxes instead of their polygons), 1.3-1.4 times a frame culled
anew.  While a guard serves, the next one is made ahead (:meth:`CullCache.cull`), a
quarter of it a frame (the portals' projection, the walk, the parts of half the cells,
the others), so a steady walk or turn misses only where it starts and no frame pays
for a whole guard.  The answer holds
every part the frame sees, and more than the frame's own culling keeps (on the
generated offices' tours 2-3 times the parts); it tests rays, not the frame's pixel
grid, so a part the frame's own rectangles keep by their rounding alone may be left
out (the id truth finds no pixel of any: tests/test_cullcache.py, docs/benchmarks.md).
``walkstream bench portals --cull --cull-cache`` measures it.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from operator import is_
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.shared.camera import frustum_projection, view_matrix
from walkstream.shared.partcull import Boxes, cull_parts, near_far
from walkstream.shared.portalgraph import PortalGraph
from walkstream.shared.portals import PortalCull, PortalRows, cull_portals, portal_rows
from walkstream.shared.screenrects import TOUCH_MARGIN_PX, corner_secant

__all__ = ["AHEAD_FRAMES", "LEAD_FRAMES", "CachedCull", "CullCache", "guard_view"]

#: The next guard is made for the pose this many frames on (the last step and turn
#: repeated): it takes four frames to make (:meth:`CullCache.cull`) and serves from the fifth.
AHEAD_FRAMES = 5

#: A guard made on a miss is made for the pose this many frames on, when the frame lies
#: within it (:meth:`CullCache.cull`), so that it serves while the next is made.
LEAD_FRAMES = 2

#: The walk's pass-through distance (:func:`~walkstream.shared.portals.cull_portals`' default).
_PASS_M = 0.05


@dataclass
class CachedCull:
    """One frame's culling from :meth:`CullCache.cull`.

    Attributes
    ----------
    order : list of int
        The visible cells of the guard view, in the walk's order.
    masks : dict of int -> (n,) bool
        Per visible cell with boxes, the parts to draw (read-only arrays, shared by every
        frame the guard serves).
    fresh : bool
        Whether the guard was made for this frame (a miss).
    walk_s, parts_s : float
        CPU seconds (``time.process_time``) of the walk (or, on a hit, the checks) and of
        the parts culling (0 on a hit).
    """

    order: list[int]
    masks: dict[int, NDArray[np.bool_]]
    fresh: bool
    walk_s: float = 0.0
    parts_s: float = 0.0


@dataclass
class _Guard:
    key: tuple[Any, ...]
    apex: NDArray[np.float64]
    reach: float  # how far from the apex a frame's eye may stand
    tan_x: float
    tan_y: float
    order: list[int]
    masks: dict[int, NDArray[np.bool_]]
    cells: list[int]
    src: list[Any] = field(default_factory=list)
    rows: list[list[float]] = field(default_factory=list)  # the guard camera's rotation, plain floats
    m: list[tuple[float, float, float]] = field(default_factory=list)  # scratch


@dataclass
class _Plan:
    """The next guard in the making (:meth:`CullCache._ahead`): its portals projected
    (``rows``), then walked (``pc``), then its parts culled half the cells at a time."""

    key: tuple[Any, ...]
    made: tuple[Any, ...]  # guard_view's answer
    rows: PortalRows | None = None
    pc: PortalCull | None = None
    first_half: bool = False
    masks: dict[int, NDArray[np.bool_]] = field(default_factory=dict)
    src: dict[int, Any] = field(default_factory=dict)  # the boxes each cell was culled with

    def guard(self) -> _Guard:
        """The guard these make."""
        assert self.pc is not None
        apex, gv, gp, _gsize, grow = self.made
        cells = list(self.pc.order)
        return _Guard(self.key, apex.copy(), grow / 1.001, 1.0 / gp[0, 0], 1.0 / gp[1, 1], self.pc.order,
                      self.masks, cells, [self.src.get(c) for c in cells], gv[:3, :3].tolist())


def guard_view(
    eye: NDArray[np.float64], rot: NDArray[np.float64], proj: NDArray[np.float64], size: tuple[int, int], *,
    turn_deg: float, move_m: float, clip_m: float,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], tuple[int, int], float] | None:
    """The guard view of a camera at ``eye`` ``(3,)`` turned by ``rot`` ``(3, 3)`` (its view
    matrix's upper left) with the projection ``proj`` ``(4, 4)`` (module docstring): its apex
    ``(3,)``, view and projection ``(4, 4)`` (:func:`~walkstream.shared.camera.view_matrix`,
    :func:`~walkstream.shared.camera.frustum_projection`), viewport size and the growth
    ``R`` in metres; None for a
    projection that is not a symmetric perspective one or a widening past 80 degrees a side."""
    planes = near_far(proj)
    if planes is None or proj[0, 2] != 0.0 or proj[1, 2] != 0.0:
        return None
    tx, ty = 1.0 / float(proj[0, 0]), 1.0 / float(proj[1, 1])
    hx, hy = math.atan(tx) + math.radians(turn_deg), math.atan(ty) + math.radians(turn_deg)
    if max(hx, hy) > math.radians(80.0):
        return None
    gx, gy = math.tan(hx), math.tan(hy)
    rot = np.asarray(rot, np.float64)
    fwd = -rot[2]
    back = 0.5 * move_m + 2.0 * clip_m
    apex = eye - back * fwd
    grow = 1.001 * (back + move_m)
    gv = view_matrix(rot, apex)
    gp = frustum_projection(1.0 / gx, 1.0 / gy, 0.5 * clip_m, planes[1] * corner_secant(proj) + grow)
    gsize = (math.ceil(size[0] * gx / tx), math.ceil(size[1] * gy / ty))
    return apex, gv, gp, gsize, grow


class CullCache:
    """Portal and parts culling reused while the view stays within a guard (module docstring).

    Parameters
    ----------
    graph : PortalGraph
        The interior's portals (one cache per graph).
    turn_deg : float
        Degrees each half-angle of the frustum is widened by: the turn a hit allows.
    move_m : float
        Metres the eye may move on from the guard's frame before a miss (the portals are
        grown by this and the apex's distance behind the eye; module docstring).
    clip_m : float
        The walk's clip plane (:func:`~walkstream.shared.portals.cull_portals`).
    ahead : bool
        Make the next guard ahead of the walker (:meth:`cull`).
    locate : callable, optional
        The cell id that holds a point ``(3,)`` (None outside every cell): with it, the next
        guard is made for the cell the walker is about to enter, so that a door crossed
        at a steady pace is not a miss.
    """

    def __init__(self, graph: PortalGraph, *, turn_deg: float = 10.0, move_m: float = 0.3,
                 clip_m: float = 0.03, ahead: bool = True,
                 locate: Callable[[NDArray[np.float64]], int | None] | None = None) -> None:
        self.graph = graph
        self.locate = locate
        self.turn_deg = float(turn_deg)
        self.move_m = float(move_m)
        self.clip_m = float(clip_m)
        self.ahead = ahead
        self.hits = 0
        self.misses = 0
        self._guard: _Guard | None = None
        self._next: _Guard | None = None
        self._plan: _Plan | None = None  # the next guard, in the making
        self._last: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None

    def cull(
        self,
        start: int,
        eye: ArrayLike,
        view: ArrayLike,
        proj: ArrayLike,
        size: tuple[int, int],
        boxes: Boxes,
        *,
        fog_m: float = math.inf,
        closed: frozenset[int] = frozenset(),
    ) -> CachedCull:
        """The cells and parts to draw from cell ``start`` with the camera ``view``, ``proj``
        ``(4, 4)`` at ``eye`` ``(3,)``: a guard's answer when the frame lies within one, else
        a new guard's.  ``boxes`` as :func:`~walkstream.shared.partcull.cull_parts` takes them
        (its arrays must not change in place; a cell whose pair is replaced is a miss).

        With ``ahead`` (the default) a hit also makes a quarter of the next guard, for the
        pose :data:`AHEAD_FRAMES` frames on (the last frame's step and turn repeated), when
        that pose would leave the current guard: its portals' projection on one frame, its
        walk on the next, the parts of the first half of its cells on the third and of the
        others on the fourth, so that a viewer who walks or turns steadily finds the next
        guard made instead of a miss, and no frame pays for more than a quarter of it."""
        t0 = time.process_time()
        e = np.asarray(eye, np.float64).reshape(3)
        V = np.asarray(view, np.float64)
        P = np.asarray(proj, np.float64)
        key = (start, P.tobytes(), int(size[0]), int(size[1]), float(fog_m), closed, id(boxes))
        last, self._last = self._last, (e, V[:3, :3])
        for g in (self._next, self._guard):
            if g is not None and g.key == key and self._within(g, e, V[:3, :3], P) \
                    and all(map(is_, map(boxes.get, g.cells), g.src)):
                if g is self._next:
                    self._guard, self._next = g, None
                self.hits += 1
                walk_s = parts_s = 0.0
                if self.ahead:
                    walk_s, parts_s = self._ahead(key, e, V, P, size, boxes, fog_m, closed, last)
                return CachedCull(g.order, dict(g.masks), False, time.process_time() - t0 - parts_s, parts_s)
        self.misses += 1
        self._guard = self._next = None
        self._plan = None
        made = self._lead(start, e, V[:3, :3], P, size, last) if self.ahead else None
        if made is None:
            made = self._guard_view(e, V[:3, :3], P, size)
        if made is None:  # not a symmetric perspective: the frame's own culling, not kept
            pc = cull_portals(self.graph, start, e, V, P, size, fog_m=fog_m, closed=closed, clip_m=self.clip_m)
            t1 = time.process_time()
            masks = cull_parts("portals", pc.order, boxes, e, V, P, size, vsas=pc.vsas, fog_m=fog_m, clip_m=self.clip_m)
            return CachedCull(pc.order, masks, True, t1 - t0, time.process_time() - t1)
        pc = self._walk(key, made, fog_m, closed)
        t1 = time.process_time()
        g = self._guard = self._parts(key, made, pc, boxes, fog_m)
        return CachedCull(g.order, dict(g.masks), True, t1 - t0, time.process_time() - t1)

    def _rows(self, made: tuple[Any, ...], fog_m: float, closed: frozenset[int]) -> PortalRows:
        """The guard view's portals projected (``made`` from :func:`guard_view`)."""
        apex, gv, gp, gsize, grow = made
        return portal_rows(self.graph, apex, gv, gp, gsize, self.clip_m, _PASS_M, fog_m + grow, False, closed,
                           TOUCH_MARGIN_PX, grow)

    def _walk(self, key: tuple[Any, ...], made: tuple[Any, ...], fog_m: float, closed: frozenset[int],
              rows: PortalRows | None = None) -> PortalCull:
        """The guard view's portal walk (on ``rows`` from :meth:`_rows` when given)."""
        apex, gv, gp, gsize, grow = made
        return cull_portals(self.graph, key[0], apex, gv, gp, gsize, fog_m=fog_m + grow, closed=closed,
                            clip_m=self.clip_m, pass_m=_PASS_M, margin_px=TOUCH_MARGIN_PX, grow_m=grow, rows=rows)

    def _masks(self, made: tuple[Any, ...], pc: PortalCull, cells: list[int], boxes: Boxes, fog_m: float,
               into: _Plan) -> None:
        """The guard view's parts culling of ``cells`` (of the walk ``pc``) into ``into``, with
        the boxes they were culled with."""
        apex, gv, gp, gsize, grow = made
        masks = cull_parts("portals", cells, boxes, apex, gv, gp, gsize, vsas=pc.vsas, fog_m=fog_m + grow,
                           clip_m=self.clip_m, margin_px=TOUCH_MARGIN_PX)
        for m in masks.values():
            m.flags.writeable = False  # shared by every frame the guard serves
        into.masks.update(masks)
        into.src.update(zip(cells, map(boxes.get, cells), strict=True))

    def _parts(self, key: tuple[Any, ...], made: tuple[Any, ...], pc: PortalCull, boxes: Boxes,
               fog_m: float) -> _Guard:
        """The guard view's parts culling, and the guard."""
        plan = _Plan(key, made, pc=pc)
        self._masks(made, pc, pc.order, boxes, fog_m, plan)
        return plan.guard()

    def _ahead(self, key: tuple[Any, ...], e: NDArray[np.float64], V: NDArray[np.float64], P: NDArray[np.float64],
               size: tuple[int, int], boxes: Boxes, fog_m: float, closed: frozenset[int],
               last: tuple[NDArray[np.float64], NDArray[np.float64]] | None) -> tuple[float, float]:
        """A quarter of the next guard (:meth:`cull`); the CPU seconds of its walk and of its parts."""
        t0 = time.process_time()
        plan = self._plan
        if plan is not None:
            if plan.key[1:] != key[1:]:  # another fog, projection or boxes: made anew when due
                self._plan = None
                return 0.0, 0.0
            if plan.pc is None:
                plan.pc = self._walk(plan.key, plan.made, fog_m, closed, plan.rows)
                plan.rows = None
                return time.process_time() - t0, 0.0
            order = plan.pc.order
            half = (len(order) + 1) // 2
            if not plan.first_half:
                self._masks(plan.made, plan.pc, order[:half], boxes, fog_m, plan)
                plan.first_half = True
            else:
                self._masks(plan.made, plan.pc, order[half:], boxes, fog_m, plan)
                self._next, self._plan = plan.guard(), None
            return 0.0, time.process_time() - t0
        g = self._guard
        if self._next is not None or last is None or g is None:
            return 0.0, 0.0
        # the pose AHEAD_FRAMES frames on (the last step and the last turn made as many
        # times more): when it leaves the guard or its cell, the next guard is made for it
        # over the next frames (its portals projected now), used from the frame after
        turn = V[:3, :3] @ last[1].T
        rot = np.linalg.matrix_power(turn, AHEAD_FRAMES) @ V[:3, :3]
        centre = e + float(AHEAD_FRAMES) * (e - last[0])
        cell = key[0] if self.locate is None else self.locate(centre)
        if cell is None:
            return 0.0, 0.0
        if cell == key[0] and self._within(g, centre, rot, P):
            return 0.0, 0.0
        key = (cell, *key[1:])
        made = self._guard_view(centre, rot, P, size)
        if made is None:
            return 0.0, 0.0
        self._plan = _Plan(key, made, rows=self._rows(made, fog_m, closed))
        return time.process_time() - t0, 0.0

    def _lead(self, start: int, e: NDArray[np.float64], rot: NDArray[np.float64], P: NDArray[np.float64],
              size: tuple[int, int], last: tuple[NDArray[np.float64], NDArray[np.float64]] | None,
              ) -> tuple[Any, ...] | None:
        """On a miss, the guard view made for the pose :data:`LEAD_FRAMES` frames on (the last
        step and turn repeated) when this frame lies within it (else None): a guard centred
        on the frame itself would serve half its reach, too few frames to make the next
        one a quarter a frame."""
        if last is None:
            return None
        turn = rot @ last[1].T
        ahead_rot = np.linalg.matrix_power(turn, LEAD_FRAMES) @ rot
        centre = e + float(LEAD_FRAMES) * (e - last[0])
        if self.locate is not None and self.locate(centre) != start:
            return None
        made = self._guard_view(centre, ahead_rot, P, size)
        if made is None:
            return None
        apex, gv, gp, _gsize, grow = made
        probe = _Guard((), apex, grow / 1.001, 1.0 / gp[0, 0], 1.0 / gp[1, 1], [], {}, [], [], gv[:3, :3].tolist())
        return made if self._within(probe, e, rot, P) else None

    def _guard_view(self, e: NDArray[np.float64], rot: NDArray[np.float64], P: NDArray[np.float64],
                    size: tuple[int, int]) -> tuple[Any, ...] | None:
        """:func:`guard_view` with this cache's turn, step and clip plane."""
        return guard_view(e, rot, P, size, turn_deg=self.turn_deg, move_m=self.move_m, clip_m=self.clip_m)

    def _within(self, g: _Guard, e: NDArray[np.float64], rot: NDArray[np.float64], P: NDArray[np.float64]) -> bool:
        """Whether a frame at ``e`` turned by ``rot`` ``(3, 3)`` with the projection ``P`` lies
        within the guard: the eye
        within its reach of the apex, inside its pyramid at a depth of at least the clip
        plane, and the frustum's corner rays inside the pyramid."""
        d = e - g.apex
        if float(d @ d) > g.reach * g.reach:
            return False
        (r0, r1, r2), (s0, s1, s2), (q0, q1, q2) = g.rows
        d0, d1, d2 = d.tolist()
        depth = -(q0 * d0 + q1 * d1 + q2 * d2)
        if depth < 1.01 * self.clip_m or abs(r0 * d0 + r1 * d1 + r2 * d2) > g.tan_x * depth \
                or abs(s0 * d0 + s1 * d1 + s2 * d2) > g.tan_y * depth:
            return False
        tx, ty = 1.0 / float(P[0, 0]), 1.0 / float(P[1, 1])
        # the frame's corner rays (eye axes (+-tx, +-ty, -1)) in the guard camera's axes,
        # in plain floats (a few microseconds, not a dozen numpy calls): the frame's
        # rotation transposed stands for its inverse, a float32 camera being orthonormal
        # to about 1e-7, which the slack of 1e-5 below covers
        (a0, a1, a2), (b0, b1, b2), (c0, c1, c2) = rot.tolist()
        gx, gy, slack = g.tan_x * (1.0 - 1e-5), g.tan_y * (1.0 - 1e-5), 1e-5
        for r0, r1, r2 in g.rows:
            # (guard row) . (frame rotation transposed): the row applied to the frame's axes
            m0 = r0 * a0 + r1 * a1 + r2 * a2
            m1 = r0 * b0 + r1 * b1 + r2 * b2
            m2 = r0 * c0 + r1 * c1 + r2 * c2
            g.m.append((m0, m1, m2))
        (x0, x1, x2), (y0, y1, y2), (z0, z1, z2) = g.m
        g.m.clear()
        for sx, sy in ((tx, ty), (tx, -ty), (-tx, ty), (-tx, -ty)):
            depth = -(z0 * sx + z1 * sy - z2)
            if depth <= slack:
                return False
            if abs(x0 * sx + x1 * sy - x2) > gx * depth or abs(y0 * sx + y1 * sy - y2) > gy * depth:
                return False
        return True

