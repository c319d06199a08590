"""Meshes of generated interiors: boxes, slabs with holes, walls with openings, furniture, stairs.

A generated interior (``walkstream-interior`` format, :mod:`.interiorfile`) describes
its building in a few numbers per element; these builders turn them into closed,
outward-facing triangle meshes, vectorised over many boxes at once.  Everything here
is a *box list*: ``(k, 7)`` float64 rows ``cx, cy, length, depth, yaw, z0, z1``
(centre, size along and across the heading ``yaw``, bottom and top).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.shared.arrays import F64
from walkstream.shared.geometry import orient_rings, triangulate_rings

__all__ = [
    "box_mesh",
    "prism_mesh",
    "wall_boxes",
    "door_boxes",
    "window_boxes",
    "furniture_boxes",
    "FURNITURE_KINDS",
    "STAIR_WAIST",
    "stair_boxes",
    "HALF_LANDING_M",
    "switchback_boxes",
]

# the 12 triangles of a unit box over corners numbered by bits (x, y, z): outward, CCW
_BOX_TRIS = np.array(
    [
        [0, 2, 3], [0, 3, 1],  # bottom (z-)
        [4, 5, 7], [4, 7, 6],  # top (z+)
        [0, 1, 5], [0, 5, 4],  # y-
        [2, 6, 7], [2, 7, 3],  # y+
        [0, 4, 6], [0, 6, 2],  # x-
        [1, 3, 7], [1, 7, 5],  # x+
    ],
    dtype=np.int64,
)
_CORNERS = np.array([[(i >> 0) & 1, (i >> 1) & 1, (i >> 2) & 1] for i in range(8)], dtype=np.float64)


def box_mesh(rows: ArrayLike) -> tuple[F64, NDArray[np.int64]]:
    """Closed meshes of many oriented boxes.

    Parameters
    ----------
    rows : (k, 7) float
        ``cx, cy, length, depth, yaw, z0, z1`` per box; boxes with a size of zero are
        dropped.

    Returns
    -------
    vertices : (8k', 3) float64
    triangles : (12k', 3) int64
        Counter-clockwise seen from outside.

    >>> v, t = box_mesh([[0, 0, 2, 1, 0, 0, 3]])
    >>> v.min(axis=0).tolist(), v.max(axis=0).tolist(), len(t)
    ([-1.0, -0.5, 0.0], [1.0, 0.5, 3.0], 12)
    """
    b = np.asarray(rows, dtype=np.float64).reshape(-1, 7)
    b = b[(b[:, 2] > 1e-6) & (b[:, 3] > 1e-6) & (b[:, 6] - b[:, 5] > 1e-6)]
    k = len(b)
    if k == 0:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    u = _CORNERS[None, :, 0] - 0.5  # (1, 8)
    w = _CORNERS[None, :, 1] - 0.5
    lx = u * b[:, 2:3]
    ly = w * b[:, 3:4]
    c, s = np.cos(b[:, 4:5]), np.sin(b[:, 4:5])
    x = b[:, 0:1] + c * lx - s * ly
    y = b[:, 1:2] + s * lx + c * ly
    z = b[:, 5:6] + _CORNERS[None, :, 2] * (b[:, 6:7] - b[:, 5:6])
    verts = np.stack([x, y, z], axis=-1).reshape(-1, 3)
    tris = (_BOX_TRIS[None, :, :] + 8 * np.arange(k)[:, None, None]).reshape(-1, 3)
    return verts, tris


def prism_mesh(rings: Sequence[ArrayLike], z0: float, z1: float) -> tuple[F64, NDArray[np.int64]]:
    """A polygon with holes extruded from ``z0`` to ``z1`` (a slab): closed, outward.

    Parameters
    ----------
    rings : exterior then holes, each (n, 2)
    z0, z1 : bottom and top, metres
    """
    rs = orient_rings([np.asarray(r, np.float64).reshape(-1, 2) for r in rings])
    flat = np.concatenate(rs)
    n = len(flat)
    cap = triangulate_rings(rs)  # CCW from above
    verts = np.concatenate(
        [np.column_stack([flat, np.full(n, z0)]), np.column_stack([flat, np.full(n, z1)])]
    )
    tris = [cap[:, ::-1], cap + n]  # bottom faces down, top faces up
    start = 0
    for r in rs:
        m = len(r)
        i = start + np.arange(m)
        j = start + (np.arange(m) + 1) % m
        # exterior CCW and holes CW: the side quad (i, j, j', i') faces outward
        tris.append(np.column_stack([i, j, j + n]))
        tris.append(np.column_stack([i, j + n, i + n]))
        start += m
    return verts, np.concatenate(tris).astype(np.int64)


def wall_boxes(
    a: ArrayLike,
    b: ArrayLike,
    thickness: float,
    z0: float,
    z1: float,
    openings: Sequence[tuple[float, float, float, float]] = (),
) -> F64:
    """Boxes of a straight wall from ``a`` to ``b`` with rectangular holes.

    Parameters
    ----------
    a, b : (2,) the ends of the wall's centre line
    thickness, z0, z1 : metres
    openings : ``(offset of the centre along the wall from a, width, sill, head)``;
        sill and head are heights above ``z0``.

    Returns
    -------
    (k, 7) box rows: the full-height pieces between the holes, and the pieces under
    and over each hole.
    """
    pa, pb = np.asarray(a, np.float64), np.asarray(b, np.float64)
    d = pb - pa
    length = float(np.hypot(*d))
    yaw = math.atan2(d[1], d[0])
    ux = d / length
    rows: list[list[float]] = []

    def piece(s0: float, s1: float, h0: float, h1: float) -> None:
        if s1 - s0 > 1e-6 and h1 - h0 > 1e-6:
            c = pa + ux * (0.5 * (s0 + s1))
            rows.append([c[0], c[1], s1 - s0, thickness, yaw, z0 + h0, z0 + h1])

    s = 0.0
    for off, width, sill, head in sorted(openings):
        o0, o1 = off - 0.5 * width, off + 0.5 * width
        piece(s, o0, 0.0, z1 - z0)
        piece(o0, o1, 0.0, sill)
        piece(o0, o1, head, z1 - z0)
        s = o1
    piece(s, length, 0.0, z1 - z0)
    return np.array(rows, dtype=np.float64).reshape(-1, 7)


def _frame(
    centre: F64, along: F64, normal: F64, width: float, depth: float, z0: float, z1: float,
    bar: float, sides: Sequence[float], head: bool = True,
) -> list[list[float]]:
    """Boxes of a rectangular frame (two jambs and, with ``head``, a head) in an opening's plane."""
    yaw = math.atan2(along[1], along[0])
    rows = []
    for off_n in sides:
        c = centre + normal * off_n
        for s in (-1.0, 1.0):
            jc = c + along * (s * (0.5 * width - 0.5 * bar))
            rows.append([jc[0], jc[1], bar, depth, yaw, z0, z1])
        if head:
            rows.append([c[0], c[1], width, depth, yaw, z1 - bar, z1])
    return rows


def door_boxes(
    centre: ArrayLike, normal: ArrayLike, width: float, thickness: float, z0: float, head: float
) -> tuple[F64, F64]:
    """A door drawn open: frame lining, architrave jambs on both faces, and the leaf.

    The leaf is swung 90 degrees into the room on the ``normal`` side, standing
    beside the doorway, so it never hides it (the client and any ground truth draw
    the same open door).

    Returns
    -------
    frame : (k, 7) box rows (lining, architraves)
    leaf : (1, 7) box row
    """
    c = np.asarray(centre, np.float64)[:2]
    n = np.asarray(normal, np.float64)
    n = n / float(np.hypot(*n))
    along = np.array([-n[1], n[0]])
    rows = _frame(c, along, n, width, thickness + 0.02, z0, head, 0.04, [0.0])
    arch = 0.07
    for side in (-1.0, 1.0):
        rows += _frame(
            c, along, n, width + 2 * arch, 0.02, z0, head + arch, arch,
            [side * (0.5 * thickness + 0.01)], head=False,
        )
    yaw = math.atan2(along[1], along[0])
    # the leaf: hinged at one jamb on the room side, opened at right angles to the wall
    hinge = c + along * (0.5 * width - 0.04) + n * (0.5 * thickness + 0.02)
    leaf_c = hinge + n * (0.5 * (width - 0.1)) + along * 0.03
    leaf = np.array([[leaf_c[0], leaf_c[1], 0.04, width - 0.1, yaw, z0 + 0.01, head - 0.03]])
    return np.array(rows, dtype=np.float64), leaf


def window_boxes(
    centre: ArrayLike, normal: ArrayLike, width: float, thickness: float, sill: float, head: float
) -> tuple[F64, F64]:
    """A window: a frame with a middle mullion and an inner sill, and its glass pane.

    Returns
    -------
    frame : (k, 7) box rows
    glass : (1, 7) box row (drawn opaque)
    """
    c = np.asarray(centre, np.float64)[:2]
    n = np.asarray(normal, np.float64)
    n = n / float(np.hypot(*n))
    along = np.array([-n[1], n[0]])
    yaw = math.atan2(along[1], along[0])
    rows = _frame(c, along, n, width, 0.08, sill, head, 0.06, [0.0])
    rows.append([c[0], c[1], width, 0.08, yaw, sill, sill + 0.06])  # bottom rail
    rows.append([c[0], c[1], 0.05, 0.08, yaw, sill, head])  # mullion
    inner = c + n * (0.5 * thickness + 0.06)
    rows.append([inner[0], inner[1], width + 0.1, 0.14, yaw, sill - 0.03, sill])  # inner sill
    glass = np.array([[c[0], c[1], width - 0.1, 0.02, yaw, sill + 0.06, head - 0.06]])
    return np.array(rows, dtype=np.float64), glass


# furniture as boxes in a local frame: x along the piece's front, y back, z up;
# (x0, y0, x1, y1, z0, z1) in metres for a piece of the nominal size
_FURNITURE: dict[str, tuple[tuple[float, float, float], list[tuple[float, ...]]]] = {
    "desk": ((1.6, 0.8, 0.75), [
        (0.0, 0.0, 1.6, 0.8, 0.72, 0.75),
        (0.02, 0.05, 0.05, 0.75, 0.0, 0.72), (1.55, 0.05, 1.58, 0.75, 0.0, 0.72),  # side panels
        (1.1, 0.05, 1.52, 0.75, 0.1, 0.68),  # drawer unit
        (0.05, 0.74, 1.55, 0.76, 0.35, 0.7),  # modesty panel
    ]),
    "chair": ((0.5, 0.5, 0.9), [
        (0.0, 0.0, 0.5, 0.5, 0.42, 0.47),
        (0.0, 0.44, 0.5, 0.5, 0.47, 0.9),
        (0.22, 0.22, 0.28, 0.28, 0.06, 0.42),  # post
        (0.05, 0.05, 0.45, 0.45, 0.0, 0.06),  # base
    ]),
    "shelf": ((1.0, 0.4, 2.0), [
        (0.0, 0.0, 0.02, 0.4, 0.0, 2.0), (0.98, 0.0, 1.0, 0.4, 0.0, 2.0),
        (0.0, 0.38, 1.0, 0.4, 0.0, 2.0),
        (0.02, 0.0, 0.98, 0.38, 0.0, 0.02), (0.02, 0.0, 0.98, 0.38, 0.66, 0.68),
        (0.02, 0.0, 0.98, 0.38, 1.32, 1.34), (0.0, 0.0, 1.0, 0.4, 1.98, 2.0),
    ]),
    "cabinet": ((0.8, 0.45, 1.1), [
        (0.0, 0.0, 0.8, 0.45, 0.05, 1.1), (0.02, 0.02, 0.78, 0.43, 0.0, 0.05),
        (0.05, -0.02, 0.38, 0.0, 0.1, 1.05), (0.42, -0.02, 0.75, 0.0, 0.1, 1.05),
    ]),
    "table": ((1.2, 1.2, 0.74), [
        (0.0, 0.0, 1.2, 1.2, 0.7, 0.74),
        (0.55, 0.55, 0.65, 0.65, 0.04, 0.7), (0.3, 0.3, 0.9, 0.9, 0.0, 0.04),
    ]),
    "sofa": ((2.0, 0.9, 0.85), [
        (0.0, 0.0, 2.0, 0.9, 0.0, 0.42), (0.0, 0.7, 2.0, 0.9, 0.42, 0.85),
        (0.0, 0.0, 0.2, 0.7, 0.42, 0.62), (1.8, 0.0, 2.0, 0.7, 0.42, 0.62),
    ]),
    "bench": ((1.8, 0.45, 0.45), [
        (0.0, 0.0, 1.8, 0.45, 0.4, 0.45),
        (0.05, 0.05, 0.15, 0.4, 0.0, 0.4), (1.65, 0.05, 1.75, 0.4, 0.0, 0.4),
    ]),
    "plant": ((0.5, 0.5, 1.3), [
        (0.1, 0.1, 0.4, 0.4, 0.0, 0.4), (0.0, 0.0, 0.5, 0.5, 0.4, 1.3),
        (0.12, 0.12, 0.38, 0.38, 1.3, 1.5),
    ]),
}


def _cylinder(cx: float, cy: float, r: float, z0: float, z1: float, n: int = 6) -> list[tuple[float, ...]]:
    """A round post as ``n`` boxes turned about its axis (a ``2n``-sided star of faces):
    seen from anywhere it is round enough, and it is made of boxes like everything here."""
    w = 2.0 * r * math.tan(math.pi / (2 * n))
    return [(cx - r, cy - 0.5 * w, cx + r, cy + 0.5 * w, z0, z1, math.pi * q / n) for q in range(n)]


def _machine() -> tuple[tuple[float, float, float], list[tuple[float, ...]]]:
    """A machine tool (a machining centre): housing, door, spindle, table, control panel, chip conveyor."""
    p: list[tuple[float, ...]] = [
        (0.0, 0.0, 2.4, 1.8, 0.0, 0.15),  # plinth
        (0.0, 0.0, 0.06, 1.8, 0.15, 2.2), (1.74, 0.0, 1.8, 1.8, 0.15, 2.2),  # side walls
        (0.0, 1.74, 1.8, 1.8, 0.15, 2.2), (0.0, 0.0, 1.8, 1.8, 2.2, 2.26),  # back, roof
        (0.06, 0.0, 1.74, 0.06, 0.15, 0.9), (0.06, 0.0, 1.74, 0.06, 1.9, 2.2),  # front below and above the door
        (0.06, -0.04, 0.12, 0.0, 0.9, 1.9), (1.68, -0.04, 1.74, 0.0, 0.9, 1.9),  # door frame
        (0.9, -0.06, 0.94, -0.02, 1.2, 1.6),  # door handle
        (0.3, 0.6, 1.5, 1.4, 0.15, 0.85), (0.25, 0.55, 1.55, 1.45, 0.85, 0.9),  # bed and table
        (0.7, 1.2, 1.1, 1.6, 1.5, 2.15),  # spindle head
        (1.8, 0.0, 2.4, 1.8, 0.15, 1.6),  # cabinet beside it
        (1.85, -0.3, 2.35, 0.0, 1.0, 1.8),  # control panel
    ]
    p += [(0.3 + 0.2 * q, 0.65, 0.34 + 0.2 * q, 1.35, 0.9, 0.93) for q in range(6)]  # T-slots
    p += _cylinder(0.9, 1.0, 0.08, 1.1, 1.5, 6)  # spindle
    p += _cylinder(0.9, 1.0, 0.03, 0.95, 1.1, 4)  # tool
    p += [(1.9 + 0.1 * (q % 4), -0.34, 1.96 + 0.1 * (q % 4), -0.3, 1.1 + 0.15 * (q // 4), 1.16 + 0.15 * (q // 4))
          for q in range(16)]  # buttons
    p += [(1.8, 0.2 + 0.1 * q, 1.83, 0.25 + 0.1 * q, 0.4, 1.4) for q in range(12)]  # vents
    p += [(0.1 + 0.17 * q, 1.8, 0.25 + 0.17 * q, 1.85 + 0.03 * q, 0.15 + 0.05 * q, 0.3 + 0.05 * q)
          for q in range(9)]  # chip conveyor
    return (2.4, 1.8, 2.26), p


def _robot() -> tuple[tuple[float, float, float], list[tuple[float, ...]]]:
    """An industrial robot on a pedestal, its arm reaching over a pallet, behind a low fence."""
    p: list[tuple[float, ...]] = []
    p += _cylinder(0.6, 0.6, 0.3, 0.0, 0.6, 8)  # pedestal
    p += _cylinder(0.6, 0.6, 0.25, 0.6, 0.9, 8)  # turret
    p += [(0.45, 0.45, 0.75, 0.75, 0.9, 1.2)]  # shoulder
    p += [(0.55 + 0.05 * q, 0.52, 0.7 + 0.05 * q, 0.68, 1.2 + 0.12 * q, 1.35 + 0.12 * q) for q in range(7)]  # upper arm
    p += _cylinder(0.95, 0.6, 0.1, 1.95, 2.15, 6)  # elbow
    p += [(0.95 + 0.08 * q, 0.55, 1.05 + 0.08 * q, 0.65, 2.0 - 0.1 * q, 2.1 - 0.1 * q) for q in range(5)]  # forearm
    p += _cylinder(1.35, 0.6, 0.05, 1.45, 1.65, 6)  # wrist
    p += [(1.3, 0.55, 1.32, 0.65, 1.3, 1.45), (1.38, 0.55, 1.4, 0.65, 1.3, 1.45)]  # gripper fingers
    p += [(0.0 + 0.3 * q, 0.0, 0.04 + 0.3 * q, 0.04, 0.0, 1.0) for q in range(5)]  # fence posts
    p += [(0.0, 0.0, 1.24, 0.03, 0.3 + 0.3 * q, 0.33 + 0.3 * q) for q in range(3)]  # fence rails
    return (1.25, 1.25, 2.2), p


def _rack() -> tuple[tuple[float, float, float], list[tuple[float, ...]]]:
    """A pallet rack: three bays, four levels, a pallet with goods on most places."""
    p: list[tuple[float, ...]] = []
    for q in range(4):
        x = 0.8 * q - (0.08 if q == 3 else 0.0)
        p += [(x, 0.0, x + 0.08, 0.08, 0.0, 3.0), (x, 0.92, x + 0.08, 1.0, 0.0, 3.0)]  # uprights
        p += [(x + 0.02, 0.08, x + 0.06, 0.92, 0.5 + 0.8 * k, 0.53 + 0.8 * k) for k in range(3)]  # braces
    for k in range(4):
        z = 0.8 * k
        p += [(0.0, 0.0, 2.4, 0.06, z + 0.08, z + 0.16), (0.0, 0.94, 2.4, 1.0, z + 0.08, z + 0.16)]  # beams
        for b in range(3):
            if (k + b) % 5 == 4:
                continue  # an empty place
            x = 0.8 * b + 0.1
            p += [(x, 0.05, x + 0.6, 0.95, z + 0.16, z + 0.3)]  # pallet
            p += [(x + 0.05, 0.1, x + 0.3, 0.5, z + 0.3, z + 0.55), (x + 0.32, 0.1, x + 0.55, 0.9, z + 0.3, z + 0.7),
                  (x + 0.05, 0.52, x + 0.3, 0.9, z + 0.3, z + 0.6)]  # goods
    return (2.4, 1.0, 3.0), p


_FURNITURE |= {"machine": _machine(), "robot": _robot(), "rack": _rack()}
FURNITURE_KINDS = tuple(sorted(_FURNITURE))
"""The furniture a generated interior may place (an office's, and a production hall's
machine tools, robots and pallet racks)."""


def furniture_boxes(kind: str, at: ArrayLike, yaw: float, z0: float) -> F64:
    """Box rows of one piece of furniture of ``kind`` standing at ``at`` (its centre).

    ``yaw`` turns the piece's front (its local -y side) away from +y; ``z0`` is the
    floor it stands on.
    """
    (sx, sy, _), parts = _FURNITURE[kind]
    # a part may carry a seventh number: its own turn about its centre (a round post's boxes)
    p = np.array([(*q, 0.0) if len(q) == 6 else q for q in parts], dtype=np.float64)
    c, s = math.cos(yaw), math.sin(yaw)
    lx = 0.5 * (p[:, 0] + p[:, 2]) - 0.5 * sx
    ly = 0.5 * (p[:, 1] + p[:, 3]) - 0.5 * sy
    x0, y0 = np.asarray(at, np.float64)[:2]
    cx = x0 + c * lx - s * ly
    cy = y0 + s * lx + c * ly
    return np.column_stack(
        [cx, cy, p[:, 2] - p[:, 0], p[:, 3] - p[:, 1], yaw + p[:, 6], z0 + p[:, 4], z0 + p[:, 5]]
    )


STAIR_WAIST = 0.2
"""How far (metres) a flight's soffit lies below each step's riser: the stair's slab."""


def stair_boxes(
    start: ArrayLike, end: ArrayLike, width: float, z0: float, rise: float, steps: int = 0,
    rails: Sequence[float] = (-1.0, 1.0),
) -> tuple[F64, F64]:
    """A straight flight from ``start`` (bottom) to ``end`` (top) climbing ``rise``.

    Returns
    -------
    boxes : (k, 7) box rows: one solid block per step, from :data:`STAIR_WAIST` below
        the step's riser up to its tread (no lower than ``z0``), so the flight is closed
        underneath by a stepped soffit and leaves headroom under it (a flight over
        another, a switchback's over the one below, is not filled down to its floor) and
        a balustrade on each side in ``rails`` (-1: right of the climb, 1: left)
    path : (steps + 1, 3) the walking line: floor points from the bottom of the
        first step to the top of the last
    """
    a, b = np.asarray(start, np.float64)[:2], np.asarray(end, np.float64)[:2]
    d = b - a
    run = float(np.hypot(*d))
    n = steps or max(2, int(round(rise / 0.175)))
    going = run / n
    yaw = math.atan2(d[1], d[0])
    u = d / run
    k = np.arange(n)
    centres = a + u * ((k + 0.5) * going)[:, None]
    tops = z0 + (k + 1) * rise / n
    rows = np.column_stack(
        [centres[:, 0], centres[:, 1], np.full(n, going), np.full(n, width), np.full(n, yaw),
         np.maximum(z0, tops - rise / n - STAIR_WAIST), tops]
    )
    side = np.array([-u[1], u[0]])
    mid = 0.5 * (a + b)
    stringers = []
    for s in rails:
        c = mid + side * s * (0.5 * width + 0.03)
        stringers.append([c[0], c[1], run, 0.06, yaw, z0, z0 + rise + 0.9])  # wall-side rail
    # walking line: on each tread, at the middle of the flight's width
    ts = np.concatenate([[0.0], (k + 1) * going])
    zs = np.concatenate([[z0], tops])
    path = np.column_stack([a + u * ts[:, None], zs])
    return np.concatenate([rows, np.array(stringers)]), path


HALF_LANDING_M = 1.0
"""Depth of a switchback stair's half landing, metres."""


def switchback_boxes(
    x: tuple[float, float], y: tuple[float, float], width: float, z0: float, rise: float,
) -> tuple[F64, F64, F64, F64, F64, float]:
    """A switchback stair as the interior format gives it: the first half-flight along
    ``x[0]`` from ``y[0]`` (the floor landing) to ``y[1]``, the half landing beyond it, the
    second half-flight back along ``x[1]``; ``rise`` the storey's height from ``z0``.

    Returns ``(flight_a, path_a, flight_b, path_b, landing, y_landing)``: each flight's
    box rows and walking line (:func:`stair_boxes`; each flight's last row its
    balustrade, on the outer side: the flights face each other inside), the landing's
    box row ``(1, 7)`` and the y of its middle line."""
    x1, x2 = x
    y0, y1 = y
    half = 0.5 * rise
    d = math.copysign(1.0, y1 - y0)
    outer = -1.0 if (x2 - x1) * (y1 - y0) < 0 else 1.0
    flight_a, path_a = stair_boxes((x1, y0), (x1, y1), width, z0, half, rails=(outer,))
    flight_b, path_b = stair_boxes((x2, y1), (x2, y0), width, z0 + half, half, rails=(outer,))
    ym = y1 + d * 0.5 * HALF_LANDING_M
    landing = np.array([[0.5 * (x1 + x2), ym, abs(x2 - x1) + width, HALF_LANDING_M, 0.0, z0 + half - 0.2, z0 + half]])
    return flight_a, path_a, flight_b, path_b, landing, ym
