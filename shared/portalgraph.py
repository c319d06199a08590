"""An interior's portals as arrays: each portal once per direction, with its box and plane.

What the portal walk (:mod:`walkstream.shared.portals`) and the frustum walk go
through: built once per scene from the topology's cells and portal references
(:meth:`PortalGraph.from_topology`), with the walk's adjacency as plain ints.  A
portal with no wall about it (:data:`OPEN_KINDS`) is grown to the whole face its two
cells share.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["OPEN_KINDS", "PortalGraph"]


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
    #: ``(k, 2)`` the vertex index pairs joining a padded polygon's sides.
    edges: NDArray[np.int64] = field(init=False, repr=False, compare=False)
    #: :attr:`poly` coordinate-major, ``(3, k, m)``: the layout the frame's batch projects
    #: (:func:`~walkstream.shared.screenrects.coord_rects`), made once per scene.
    poly_ckm: NDArray[np.float64] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        k = self.poly.shape[1]
        # frozen: the derived tables are set once, here
        object.__setattr__(self, "edges", np.stack([np.arange(k), (np.arange(k) + 1) % k], axis=1))
        object.__setattr__(self, "poly_ckm", np.ascontiguousarray(self.poly.transpose(2, 1, 0)))

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
OPEN_KINDS = frozenset({"opening", "virtual", "split", "void", "wall"})


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
