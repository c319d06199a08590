"""Deterministic procedural office interiors (the indoor test scenes).

Mulloni et al. (2007) test on a university building of 93 cells and 114 portals
(28,608 triangles, 102 to 452 per cell, 2 to 4 portals per cell).  This module builds
buildings of that kind as a ``walkstream-interior`` document
(:mod:`~walkstream.server.sources.interiorfile`), so that generated and real
interiors go through the same bake.

Layout, per storey (the building is ``size`` = length x width metres inside its
outer walls, long side along x):

1. **Corridor.**  A 2 m corridor along the middle of the long side, cut into
   segments (rooms of their own, touching with no wall between them, so the bake
   joins them by open portals) of at most ``doors_per_segment`` doors each, so that
   no cell gets more than a few portals.
2. **Rooms.**  Offices, meeting rooms and a kitchen on both sides, 3.6 to 6 m wide,
   each with a door to the corridor (drawn open) and one or two windows in the
   outer wall; furniture by use (desks with chairs along the windows, shelves and
   cabinets along the corridor wall, a table with chairs, a sofa).  Corridor
   segments get a bench or a plant.
3. **Stairwell.**  At the east end of the south side, a stair room on every storey
   with a switchback stair to the next one; the slab above each stair has a hole
   over the flights, through which the bake finds the vertical portal.
4. **Walls and slabs.**  Outer walls 30 cm, inner walls 15 cm (so doors need
   doorway cells), 25 cm slabs, floors 3.4 m apart, a roof slab on top.

Coordinates are UTM 33N (EPSG:32633) with the south-west corner at :data:`ORIGIN`, so
a generated interior exercises the far-from-origin path of the reader as cities do.
Same arguments, same bytes.

:data:`PRESETS` name the sizes the benchmarks use: ``paper`` (the scale of the
paper's model) and ``paper10`` (ten times its cells).
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from walkstream.server.sources.interiorfile import INTERIOR_FORMAT, INTERIOR_VERSION
from walkstream.shared.errors import InputError

__all__ = [
    "ORIGIN",
    "InteriorPlan",
    "PRESETS",
    "generate_interior",
    "write_interior",
    "write_interior_doc",
    "interior_summary",
]

ORIGIN = (600000.0, 5340000.0)
"""UTM 33N position of the building's south-west inner corner."""

_TE, _TI, _CORRIDOR, _SLAB = 0.3, 0.15, 2.0, 0.25
_DOOR_W, _DOOR_H = 0.9, 2.1
_STAIR_W, _FLIGHT_W = 3.4, 1.2


@dataclass(frozen=True)
class InteriorPlan:
    """What :func:`generate_interior` builds (see the module docstring)."""

    storeys: int = 3
    length: float = 60.0
    width: float = 20.0
    seed: int = 1
    floor_height: float = 3.4
    room_width: tuple[float, float] = (3.6, 6.0)
    doors_per_segment: int = 2
    furniture: float = 1.0
    """Scales how much furniture a room gets (1: the default amount)."""
    two_windows: float = 4.8
    """Rooms wider than this (metres) get two windows, the others one."""

    def check(self) -> InteriorPlan:
        if not 1 <= self.storeys <= 60:
            raise InputError(f"--storeys: expected 1 to 60, got {self.storeys}")
        if not (10.0 <= self.length <= 2000.0 and 8.0 <= self.width <= 200.0):
            raise InputError(f"--size: expected 10-2000 x 8-200 metres, got {self.length:g}x{self.width:g}")
        if self.storeys > 1 and self.width < 13.0:
            raise InputError(f"--size: a building with stairs needs a width of at least 13 m, got {self.width:g}")
        if self.length < 2 * _STAIR_W + 4 and self.storeys > 1:
            raise InputError(f"--size: a building with stairs needs a length of at least {2 * _STAIR_W + 4:g} m")
        lo, hi = self.room_width
        if not 2.5 <= lo <= hi <= 20:
            raise InputError(f"room width range {self.room_width}: expected 2.5 <= min <= max <= 20")
        if not 2.9 <= self.floor_height <= 6:
            raise InputError(f"floor height {self.floor_height}: expected 2.9 to 6 m")
        if self.doors_per_segment < 1:
            raise InputError("doors per corridor segment: at least 1")
        return self


PRESETS: dict[str, InteriorPlan] = {
    # the paper's model: 93 cells, 114 portals, 28,608 triangles (tuned with bench interiors)
    "paper": InteriorPlan(storeys=3, length=26.5, width=15.0, seed=1, room_width=(4.2, 5.6),
                          doors_per_segment=1, furniture=0.5, two_windows=99.0),
    # ten times the paper's cells
    "paper10": InteriorPlan(storeys=10, length=86.0, width=15.0, seed=1, room_width=(4.2, 5.6),
                            doors_per_segment=1, furniture=0.5, two_windows=99.0),
}
"""Named plans; ``walkstream generate interior --preset NAME``."""


def _split(total: float, lo: float, hi: float, rng: np.random.Generator) -> list[float]:
    """Widths in [lo, hi] (about) that add up to ``total``."""
    if total < lo:
        return [total] if total > 2.0 else []
    n = max(1, int(round(total / (0.5 * (lo + hi)))))
    w = rng.uniform(lo, hi, n)
    return list(w / w.sum() * total)


def _r(v: float) -> float:
    return float(round(v, 3))


def generate_interior(plan: InteriorPlan) -> dict[str, Any]:
    """A ``walkstream-interior`` document (a plain dict) for ``plan``."""
    p = plan.check()
    rng = np.random.default_rng(p.seed)
    L, W, H = p.length, p.width, p.floor_height
    single = W < 13.0  # one row of rooms along a corridor on the north side
    y_cs = 0.0 if single else round((W - _CORRIDOR) / 2 - _TI, 3) + _TI
    y_cn = y_cs + _CORRIDOR
    if single:
        y_cs, y_cn = 0.0, _CORRIDOR
    x0g, y0g = ORIGIN

    def pt(x: float, y: float) -> list[float]:
        return [_r(x0g + x), _r(y0g + y)]

    def rect(xa: float, ya: float, xb: float, yb: float) -> list[list[float]]:
        return [pt(xa, ya), pt(xb, ya), pt(xb, yb), pt(xa, yb)]

    stairs = p.storeys > 1
    stair_x0 = L - _STAIR_W
    doc: dict[str, Any] = {
        "format": INTERIOR_FORMAT,
        "version": INTERIOR_VERSION,
        "name": f"office-{p.storeys}x{L:g}x{W:g}-s{p.seed}",
        "crs": "EPSG:32633",
        "slab": _SLAB,
        "storeys": [{"name": f"{k}", "elevation": _r(k * H), "height": H} for k in range(p.storeys)],
        "rooms": [],
        "walls": [],
        "slabs": [],
        "stairs": [],
        "furniture": [],
    }
    rooms, walls, furn = doc["rooms"], doc["walls"], doc["furniture"]
    # the stairwell: flights along y, from the floor landing by the corridor southwards
    south_depth = y_cs - _TI
    run = math.ceil(0.5 * H / 0.175) * 0.28
    fx1, fx2 = L - 0.5 * _STAIR_W - 0.7, L - 0.5 * _STAIR_W + 0.7
    fy0 = south_depth - 1.4
    fy1 = fy0 - run
    if stairs and fy1 - 1.1 < 0.0:
        raise InputError(f"--size: {W:g} m is too narrow for a stair of {H:g} m storeys")
    hole = rect(L - _STAIR_W + 0.2, max(0.05, fy1 - 1.05), L - 0.2, fy0)
    for k in range(p.storeys):
        z = k * H
        sk = f"s{k}"
        door_xs: list[tuple[float, str]] = []
        leaves: list[float] = []  # where a door's leaf stands in the corridor
        wall_s: list[dict[str, Any]] = []  # openings in the south corridor wall
        wall_n: list[dict[str, Any]] = []
        win_s: list[dict[str, Any]] = []  # windows in the south / north outer walls
        win_n: list[dict[str, Any]] = []
        sides = [("n", y_cn + _TI, W)] if single else [("s", 0.0, south_depth), ("n", y_cn + _TI, W)]
        n_room = 0
        for side, ya, yb in sides:
            end = stair_x0 - _TI if (side == "s" and stairs) else L
            widths = _split(end, *p.room_width, rng)
            x = 0.0
            for j, wdt in enumerate(widths):
                xa, xb = x + (0.5 * _TI if j else 0.0), x + wdt - (0.5 * _TI if j < len(widths) - 1 else 0.0)
                x += wdt
                n_room += 1
                rid = f"r{k}.{n_room:02d}"
                use = rng.choice(["office", "office", "office", "meeting", "kitchen"]) if xb - xa > 4.5 else "office"
                rooms.append({"id": rid, "name": f"{k}.{n_room:02d} {use}", "storey": k, "outline": rect(xa, ya, xb, yb)})
                left = bool(rng.random() < 0.5)
                dx = xa + 0.3 + 0.5 * _DOOR_W if left else xb - 0.3 - 0.5 * _DOOR_W
                door = {"id": f"d{k}.{n_room:02d}", "kind": "door", "offset": _r(dx), "width": _DOOR_W,
                        "sill": 0.0, "head": _DOOR_H, "swing": -1 if side == "s" else 1}
                (wall_s if side == "s" else wall_n).append(door)
                door_xs.append((dx, side))
                nwin = 2 if xb - xa > p.two_windows else 1
                for q in range(nwin):
                    wx = xa + (xb - xa) * (q + 1) / (nwin + 1)
                    win = {"id": f"w{k}.{n_room:02d}.{q}", "kind": "window", "offset": _r(wx + _TE),
                           "width": 1.4 if nwin == 1 else 1.2, "sill": 0.9, "head": 2.4}
                    (win_s if side == "s" else win_n).append(win)
                _furnish(furn, rid, str(use), k, z, xa, ya, xb, yb, side, left, p.furniture, rng, pt)
                if j < len(widths) - 1:
                    walls.append({"id": f"p{k}.{n_room:02d}", "storey": k, "from": pt(x, ya), "to": pt(x, yb),
                                  "thickness": _TI, "exterior": False, "openings": []})
        if stairs:
            rid = f"stair{k}"
            rooms.append({"id": rid, "name": f"{k}.00 stair", "storey": k,
                          "outline": rect(stair_x0, 0.0, L, south_depth)})
            dx = L - 0.5 * _STAIR_W
            # the door opens into the corridor: swung into the stairwell its leaf would stand
            # between the flights' ends on the floor landing, leaving no body's width past it
            wall_s.append({"id": f"d{k}.stair", "kind": "door", "offset": _r(dx), "width": _DOOR_W,
                           "sill": 0.0, "head": _DOOR_H, "swing": 1})
            door_xs.append((dx, "s"))
            # its leaf stands in the corridor, hinged at the west jamb (``door_boxes``)
            leaves.append(dx - 0.5 * _DOOR_W + 0.01)
            win_s.append({"id": f"w{k}.stair", "kind": "window", "offset": _r(L - 0.5 * _STAIR_W + _TE),
                          "width": 1.2, "sill": 1.2, "head": 2.4})
            walls.append({"id": f"p{k}.stair", "storey": k, "from": pt(stair_x0 - 0.5 * _TI, 0.0),
                          "to": pt(stair_x0 - 0.5 * _TI, south_depth), "thickness": _TI, "exterior": False,
                          "openings": []})
            if k + 1 < p.storeys:
                doc["stairs"].append({"id": f"st{k}", "storey": k, "x": [_r(x0g + fx1), _r(x0g + fx2)],
                                      "y": [_r(y0g + fy0), _r(y0g + fy1)], "width": _FLIGHT_W})
        # the corridor, cut into segments between doors
        door_xs.sort()
        cuts = [0.0]
        count = 0
        for i, (dx, _) in enumerate(door_xs):
            count += 1
            nxt = door_xs[i + 1][0] if i + 1 < len(door_xs) else None
            if count >= p.doors_per_segment and nxt is not None and nxt - dx > _DOOR_W + 0.6:
                cuts.append(_r(0.5 * (dx + nxt)))
                count = 0
        cuts.append(L)
        for q in range(len(cuts) - 1):
            rid = f"c{k}.{q:02d}"
            rooms.append({"id": rid, "name": f"{k}.c{q:02d} corridor", "storey": k,
                          "outline": rect(cuts[q], y_cs, cuts[q + 1], y_cn)})
            if p.furniture > 0 and rng.random() < 0.5 * p.furniture and cuts[q + 1] - cuts[q] > 3.0:
                kind = "bench" if rng.random() < 0.5 else "plant"
                fy = y_cn - 0.3 if kind == "bench" else y_cn - 0.35
                fx = 0.5 * (cuts[q] + cuts[q + 1])
                # a walker passes the door (and the leaf of one opening into the corridor)
                reach = (0.9 if kind == "bench" else 0.25) + 0.5 * _DOOR_W + 0.3
                ends = [dx for dx, side in door_xs if side == "n"] + leaves
                if all(abs(fx - x) >= reach for x in ends):
                    furn.append({"id": f"f{rid}", "kind": kind, "storey": k, "at": pt(fx, fy), "yaw": 0.0})
        # corridor walls (with the doors) and the outer walls (with the windows)
        if not single:
            walls.append({"id": f"cw{k}.s", "storey": k, "from": pt(0.0, y_cs - 0.5 * _TI),
                          "to": pt(L, y_cs - 0.5 * _TI), "thickness": _TI, "exterior": False,
                          "openings": wall_s})
        walls.append({"id": f"cw{k}.n", "storey": k, "from": pt(0.0, y_cn + 0.5 * _TI),
                      "to": pt(L, y_cn + 0.5 * _TI), "thickness": _TI, "exterior": False, "openings": wall_n})
        cy = 0.5 * (y_cs + y_cn) + 0.5 * _TE
        end_win = [{"id": f"w{k}.end", "kind": "window", "offset": _r(cy), "width": 1.2, "sill": 0.9, "head": 2.4}]
        walls += [
            {"id": f"ow{k}.s", "storey": k, "from": pt(-_TE, -0.5 * _TE), "to": pt(L + _TE, -0.5 * _TE),
             "thickness": _TE, "exterior": True, "openings": [] if single else win_s},
            {"id": f"ow{k}.n", "storey": k, "from": pt(-_TE, W + 0.5 * _TE), "to": pt(L + _TE, W + 0.5 * _TE),
             "thickness": _TE, "exterior": True, "openings": win_n},
            {"id": f"ow{k}.w", "storey": k, "from": pt(-0.5 * _TE, 0.0), "to": pt(-0.5 * _TE, W),
             "thickness": _TE, "exterior": True, "openings": end_win},
            {"id": f"ow{k}.e", "storey": k, "from": pt(L + 0.5 * _TE, 0.0), "to": pt(L + 0.5 * _TE, W),
             "thickness": _TE, "exterior": True, "openings": [dict(end_win[0], id=f"w{k}.east")]},
        ]
        if k == 0:  # the entrance: a door in the west wall of the ground-floor corridor
            walls[-2]["openings"] = [{"id": "entrance", "kind": "door", "offset": _r(0.5 * (y_cs + y_cn)),
                                      "width": 1.2, "sill": 0.0, "head": 2.3, "swing": 1}]
        doc["slabs"].append({"id": sk, "storey": k, "outline": rect(-_TE, -_TE, L + _TE, W + _TE),
                             "holes": [hole] if (stairs and k > 0) else []})
    doc["slabs"].append({"id": "roof", "storey": p.storeys, "outline": rect(-_TE, -_TE, L + _TE, W + _TE),
                         "holes": []})
    return doc


def _furnish(
    furn: list[dict[str, Any]], rid: str, use: str, k: int, z: float, xa: float, ya: float, xb: float,
    yb: float, side: str, door_left: bool, amount: float, rng: np.random.Generator, pt: Any,
) -> None:
    """Furniture for one room by its use; the door end of the corridor wall stays free."""
    out = side == "s"  # the outer (window) wall is at ya for south rooms, yb for north ones
    y_win = ya if out else yb
    y_cor = yb if out else ya
    inward = 1.0 if out else -1.0  # from the window wall into the room
    back_yaw = math.pi if out else 0.0  # a piece with its back to the window wall
    cor_yaw = 0.0 if out else math.pi  # a piece with its back to the corridor wall
    width = xb - xa
    n = 0

    def put(kind: str, x: float, y: float, yaw: float) -> None:
        nonlocal n
        n += 1
        furn.append({"id": f"f{rid}.{n}", "kind": kind, "storey": k, "at": pt(x, y), "yaw": _r(yaw)})

    if use == "office":
        desks = max(1, min(3, int(width * amount / 1.9)))
        for q in range(desks):
            x = xa + width * (q + 0.5) / desks
            put("desk", x, y_win + inward * 0.45, back_yaw)
            put("chair", x, y_win + inward * 1.25, back_yaw + math.pi)
        free = xb - 0.7 if door_left else xa + 0.7
        if amount >= 0.5:
            put("shelf", free, y_cor - inward * 0.22, cor_yaw)
        if rng.random() < amount - 0.3:
            put("cabinet", free + (-1.0 if door_left else 1.0) * 1.0 if width > 4.5 else free,
                y_cor - inward * 0.25 - inward * (0.5 if width <= 4.5 else 0.0), cor_yaw)
        if rng.random() < 0.3 * amount:
            put("plant", xa + 0.35 if door_left else xb - 0.35, y_win + inward * 1.1, 0.0)
    elif use == "meeting":
        cx, cy = 0.5 * (xa + xb), 0.5 * (ya + yb)
        put("table", cx, cy, 0.0)
        seats = 2 if amount < 0.6 else 4 if amount < 1 else 6
        for q in range(seats):
            a = 2 * math.pi * q / seats
            put("chair", cx + 0.95 * math.sin(a), cy - 0.95 * math.cos(a), a)
        if amount >= 0.5:
            put("cabinet", xb - 0.6 if door_left else xa + 0.6, y_cor - inward * 0.25, cor_yaw)
    else:  # kitchen / lounge
        put("sofa", 0.5 * (xa + xb), y_win + inward * 0.5, back_yaw)
        put("table", 0.5 * (xa + xb), y_win + inward * 1.8, 0.0)
        put("cabinet", xb - 0.5 if door_left else xa + 0.5, y_cor - inward * 0.25, cor_yaw)
        if amount >= 0.5:
            put("cabinet", xb - 1.35 if door_left else xa + 1.35, y_cor - inward * 0.25, cor_yaw)


def interior_summary(doc: dict[str, Any]) -> dict[str, Any]:
    """Counts of a generated interior document (before the bake)."""
    openings = [o for w in doc["walls"] for o in w.get("openings", [])]
    return {
        "name": doc["name"],
        "storeys": len(doc["storeys"]),
        "rooms": len(doc["rooms"]),
        "doors": sum(1 for o in openings if o["kind"] == "door"),
        "windows": sum(1 for o in openings if o["kind"] == "window"),
        "stairs": len(doc["stairs"]),
        "furniture": len(doc["furniture"]),
        "walls": len(doc["walls"]),
    }


def write_interior(
    path: str | os.PathLike[str], plan: InteriorPlan, boundaries: bool = False, schema: str = "IFC4"
) -> dict[str, Any]:
    """Generate an interior and write it as compact JSON (via a temporary file), or as
    IFC4 when ``path`` ends in ``.ifc``.

    Returns
    -------
    dict
        :func:`interior_summary` of the written document.
    """
    return write_interior_doc(path, generate_interior(plan), boundaries, schema)


def write_interior_doc(
    path: str | os.PathLike[str], doc: dict[str, Any], boundaries: bool = False, schema: str = "IFC4"
) -> dict[str, Any]:
    """Write a generated interior document (an office's or a hall's) as compact JSON (via a
    temporary file), or as an IFC4 model when ``path`` ends in ``.ifc``
    (:func:`~walkstream.server.sources.ifcwrite.write_interior_ifc`), and return its
    :func:`interior_summary`; ``boundaries``: the IFC's doors and windows get space
    boundaries; ``schema``: IFC4 or IFC2X3."""
    dest = Path(path)
    if dest.suffix.lower() == ".ifc":
        from walkstream.server.sources.ifcwrite import write_interior_ifc

        if not dest.parent.is_dir():
            raise InputError(f"{dest}: cannot write (no folder {dest.parent})")
        _write_via_tmp(dest, lambda tmp: write_interior_ifc(tmp, doc, boundaries, schema))
    else:
        _write_via_tmp(dest, lambda tmp: tmp.write_text(json.dumps(doc, separators=(",", ":"), allow_nan=False),
                                                        encoding="utf-8"))
    return interior_summary(doc)


def _write_via_tmp(dest: Path, write: Callable[[Path], object]) -> None:
    """``write`` a file beside ``dest`` and put it in its place; a write that fails names
    ``dest`` and leaves nothing half-written behind."""
    tmp = dest.with_name(dest.name + ".tmp")
    try:
        write(tmp)
        tmp.replace(dest)
    except OSError as exc:
        raise InputError(f"{dest}: cannot write ({exc.strerror or exc})") from exc
    finally:
        tmp.unlink(missing_ok=True)
