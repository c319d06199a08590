"""A deterministic procedural production hall: the open-space test scene.

Ebbesmeyer (1998) tests textured virtual walls on "a medium sized laboratory for
production engineering": one large hall of machine tools, robots and accessories with
few walls.  Cells and portals cull well where walls occlude and fail in such a hall,
where every part of it sees every other.  This module builds halls of that kind as a
``walkstream-interior`` document (:mod:`~walkstream.server.sources.interiorfile`), so
that they go through the same bake, walks and replays as the generated offices
(:mod:`~walkstream.server.sources.interiorgen`).

Layout (one storey, ``height`` metres floor to floor):

1. **The hall.**  ``columns x rows`` square bays of ``bay`` metres, each a room of its
   own; bays touch with no wall between them, so the bake joins them by open portals
   and the hall is one open space cut into convex cells (as an office corridor is cut
   into segments).
2. **Equipment.**  In each corner of each bay (with probability ``equipment``) one
   island: a machine tool, a robot beside a pallet rack, or two pallet racks back to
   back (:data:`~walkstream.server.sources.interiormesh.FURNITURE_KINDS` ``machine``,
   ``robot``, ``rack``: hundreds of triangles each).  The four islands around a bay
   corner form one block of equipment with aisles between the blocks.  An island stays
   out of the diamond that joins the middles of the bay's sides, grown by the walks'
   clearance (:data:`~walkstream.server.bake.roomnav.CLEARANCE`): a walk inside a bay
   runs between its centre and the middles of its sides (the open portals' nodes),
   which all lie in that diamond, so the ``tour`` never passes through a machine.
3. **Side rooms.**  Along the north side a row of rooms ``side_depth`` deep (a control
   room, a tool store, offices), each ``2`` bays wide, behind a 15 cm wall with a door
   onto the middle of a bay's side; furniture along their back wall.  These are the
   hall's few walls.
4. **Shell.**  Outer walls 30 cm, an entrance gate in the west wall onto the middle of
   the first row's west side, a floor slab and a roof.

Coordinates are UTM 33N, the south-west inner corner at
:data:`~walkstream.server.sources.interiorgen.ORIGIN`.  Same arguments, same bytes.
:data:`HALL_PRESETS` names the hall of ``walkstream generate interior --preset hall``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from walkstream.server.sources.interiorfile import INTERIOR_FORMAT, INTERIOR_VERSION
from walkstream.server.sources.interiorgen import ORIGIN
from walkstream.shared.errors import InputError

__all__ = ["HallPlan", "HALL_PRESETS", "generate_hall", "hall_islands"]

_TE, _TI, _SLAB = 0.3, 0.15, 0.3
_WALK_CLEARANCE = 0.3  # the walks' clearance (roomnav.CLEARANCE; sources do not import the bake)
_EDGE = 0.2  # equipment keeps this far inside its bay (it is not cut by the bay's planes)
_SLACK = 0.15  # beyond the clearance, between an island and the walks' diamond


@dataclass(frozen=True)
class HallPlan:
    """What :func:`generate_hall` builds (see the module docstring)."""

    columns: int = 8
    rows: int = 5
    bay: float = 12.0
    """Side of one square bay (one cell), metres."""
    height: float = 6.0
    """Floor to roof, metres."""
    side_depth: float = 6.0
    """Depth of the row of side rooms along the north wall (0: none)."""
    equipment: float = 1.0
    """Chance that a bay corner holds an island of equipment."""
    seed: int = 1

    def check(self) -> HallPlan:
        if not (1 <= self.columns <= 60 and 1 <= self.rows <= 60):
            raise InputError(f"hall: expected 1-60 columns and rows of bays, got {self.columns}x{self.rows}")
        if not 8.0 <= self.bay <= 40.0:
            raise InputError(f"hall: bay {self.bay:g} m: expected 8 to 40 m")
        if not 3.5 <= self.height <= 20.0:
            raise InputError(f"hall: height {self.height:g} m: expected 3.5 to 20 m")
        if self.side_depth != 0.0 and not 4.0 <= self.side_depth <= 20.0:
            raise InputError(f"hall: side rooms {self.side_depth:g} m deep: expected 0 (none) or 4 to 20 m")
        if not 0.0 <= self.equipment <= 1.0:
            raise InputError(f"hall: equipment {self.equipment:g}: expected a chance from 0 to 1")
        return self

    @property
    def size(self) -> tuple[float, float]:
        """Inner length (x) and width (y) of the building, metres."""
        side = self.side_depth + _TI if self.side_depth else 0.0
        return self.columns * self.bay, self.rows * self.bay + side


HALL_PRESETS: dict[str, HallPlan] = {
    # a production hall of 96 x 60 m (40 bays) with a row of side rooms: about 200,000
    # triangles of equipment, far past what the pda draws at 25 fps (about 600)
    "hall": HallPlan(),
}
"""Named halls; ``walkstream generate interior --preset NAME``."""


def _r(v: float) -> float:
    return float(round(v, 3))


def hall_islands(bay: float) -> tuple[float, float]:
    """Where an island of equipment may stand in a bay's corner: from ``lo`` to ``hi``
    metres from the bay's centre along both axes (its square stays out of the walks'
    diamond ``|x| + |y| <= bay / 2`` grown by the clearance, and inside the bay)."""
    half = 0.5 * bay
    hi = half - _EDGE
    lo = 0.5 * (half + _WALK_CLEARANCE * math.sqrt(2.0) + _SLACK)
    return lo, hi


def generate_hall(plan: HallPlan) -> dict[str, Any]:
    """A ``walkstream-interior`` document (a plain dict) for ``plan``."""
    p = plan.check()
    rng = np.random.default_rng(p.seed)
    B, H = p.bay, p.height
    L = p.columns * B
    Hy = p.rows * B
    _, W = p.size
    x0g, y0g = ORIGIN

    def pt(x: float, y: float) -> list[float]:
        return [_r(x0g + x), _r(y0g + y)]

    def rect(xa: float, ya: float, xb: float, yb: float) -> list[list[float]]:
        return [pt(xa, ya), pt(xb, ya), pt(xb, yb), pt(xa, yb)]

    doc: dict[str, Any] = {
        "format": INTERIOR_FORMAT,
        "version": INTERIOR_VERSION,
        "name": f"hall-{p.columns}x{p.rows}x{B:g}-s{p.seed}",
        "crs": "EPSG:32633",
        "slab": _SLAB,
        "storeys": [{"name": "hall", "elevation": 0.0, "height": H}],
        "rooms": [],
        "walls": [],
        "slabs": [],
        "stairs": [],
        "furniture": [],
    }
    rooms, walls, furn = doc["rooms"], doc["walls"], doc["furniture"]
    lo, hi = hall_islands(B)
    mid = 0.5 * (lo + hi)
    n_f = 0

    def put(kind: str, x: float, y: float, yaw: float) -> None:
        nonlocal n_f
        n_f += 1
        furn.append({"id": f"e{n_f:04d}", "kind": kind, "storey": 0, "at": pt(x, y), "yaw": _r(yaw)})

    for r in range(p.rows):
        for c in range(p.columns):
            name = f"{chr(ord('A') + r % 26)}{'' if r < 26 else r // 26}{c + 1}"
            rooms.append({"id": f"bay.{r}.{c}", "name": f"hall {name}", "storey": 0,
                          "outline": rect(c * B, r * B, (c + 1) * B, (r + 1) * B)})
            cx, cy = (c + 0.5) * B, (r + 0.5) * B
            for sx, sy in ((-1, -1), (1, -1), (-1, 1), (1, 1)):
                if rng.random() >= p.equipment:
                    continue
                ix, iy = cx + sx * mid, cy + sy * mid
                face = 0.0 if sy > 0 else math.pi  # the front (local -y) towards the bay's centre row
                kind = rng.choice(["machine", "machine", "robot", "racks"])
                if kind == "machine":
                    put("machine", ix, iy + sy * 0.1, face)
                elif kind == "robot":
                    put("robot", ix - sx * 0.55, iy - sy * 0.55, face)
                    put("rack", ix, iy + sy * 0.7, face)
                else:
                    put("rack", ix, iy - sy * 0.55, face)
                    put("rack", ix, iy + sy * 0.55, face + math.pi)
    # the side rooms, two bays wide each (the last takes what is left), doors onto bay middles
    doors: list[dict[str, Any]] = []
    if p.side_depth:
        ya, yb = Hy + _TI, W
        starts = list(range(0, p.columns, 2))
        uses = ["control room", "tool store", "office", "office", "store"]
        for j, c0 in enumerate(starts):
            c1 = starts[j + 1] if j + 1 < len(starts) else p.columns
            xa = c0 * B + (0.5 * _TI if j else 0.0)
            xb = c1 * B - (0.5 * _TI if j + 1 < len(starts) else 0.0)
            use = uses[j % len(uses)]
            rid = f"side.{j}"
            rooms.append({"id": rid, "name": f"{use} {j + 1}", "storey": 0, "outline": rect(xa, ya, xb, yb)})
            doors.append({"id": f"d.side.{j}", "kind": "door", "offset": _r((c0 + 0.5) * B), "width": 1.2,
                          "sill": 0.0, "head": 2.3, "swing": 1})
            # along the back wall, out of the walk from the door to the room's centre
            n = max(1, int((xb - xa - 1.0) // 3.0))
            for q in range(n):
                x = xa + (xb - xa) * (q + 0.5) / n
                if use == "office" or use == "control room":
                    put("desk", x, yb - 0.45, 0.0)
                    put("chair", x, yb - 1.25, math.pi)
                else:
                    put("rack", x, yb - 0.55, 0.0)
            if j + 1 < len(starts):
                walls.append({"id": f"p.side.{j}", "storey": 0, "from": pt(c1 * B, ya), "to": pt(c1 * B, yb),
                              "thickness": _TI, "exterior": False, "openings": []})
        walls.append({"id": "w.side", "storey": 0, "from": pt(0.0, Hy + 0.5 * _TI), "to": pt(L, Hy + 0.5 * _TI),
                      "thickness": _TI, "exterior": False, "openings": doors})
    gate = {"id": "entrance", "kind": "door", "offset": _r(0.5 * B), "width": 3.0, "sill": 0.0,
            "head": min(4.0, H - _SLAB - 0.5), "swing": 1}
    walls += [
        {"id": "ow.s", "storey": 0, "from": pt(-_TE, -0.5 * _TE), "to": pt(L + _TE, -0.5 * _TE),
         "thickness": _TE, "exterior": True, "openings": []},
        {"id": "ow.n", "storey": 0, "from": pt(-_TE, W + 0.5 * _TE), "to": pt(L + _TE, W + 0.5 * _TE),
         "thickness": _TE, "exterior": True, "openings": []},
        {"id": "ow.w", "storey": 0, "from": pt(-0.5 * _TE, 0.0), "to": pt(-0.5 * _TE, W),
         "thickness": _TE, "exterior": True, "openings": [gate]},
        {"id": "ow.e", "storey": 0, "from": pt(L + 0.5 * _TE, 0.0), "to": pt(L + 0.5 * _TE, W),
         "thickness": _TE, "exterior": True, "openings": []},
    ]
    doc["slabs"] = [
        {"id": "floor", "storey": 0, "outline": rect(-_TE, -_TE, L + _TE, W + _TE), "holes": []},
        {"id": "roof", "storey": 1, "outline": rect(-_TE, -_TE, L + _TE, W + _TE), "holes": []},
    ]
    return doc
