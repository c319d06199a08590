"""Small IFC models written with ifcopenshell's API, for the interior traps.

Each model is a real IFC4 file (spaces, walls with opening elements filled by doors
and windows, slabs, stairs, furniture) placed ``offset`` metres from the CRS origin,
so tests can put a building millions of metres away.  Geometry is given in metres
relative to the offset; every product's placement is absolute.  The builder is the
product's (:class:`~walkstream.server.sources.ifcwrite.IfcBuilder`).
"""

from __future__ import annotations

from pathlib import Path

from walkstream.server.sources.ifcwrite import IfcBuilder

__all__ = ["IfcBuilder", "two_rooms_model", "l_room_model", "stair_model", "stairwell_model", "open_hall_model"]


def two_rooms_model(path: Path, offset: tuple[float, float] = (0.0, 0.0)) -> Path:
    """Two rooms (4 x 4 m) side by side, 20 cm of wall between them with a door in it, a
    door to the outside in the west room, a window in the east room, and a low bench
    lying across both rooms (through the middle wall): an element spanning two rooms."""
    b = IfcBuilder(offset)
    s = b.storey("ground", 0.0)
    t, h = 0.2, 2.8
    b.space("West", s, [(0, 0), (4, 0), (4, 4), (0, 4)], 0.0, h)
    b.space("East", s, [(4.2, 0), (8.2, 0), (8.2, 4), (4.2, 4)], 0.0, h)
    outer = [(-t / 2, -t / 2), (8.2 + t / 2, -t / 2), (8.2 + t / 2, 4 + t / 2), (-t / 2, 4 + t / 2)]
    south = b.wall(s, outer[0], outer[1], t, 0.0, h)
    b.wall(s, outer[1], outer[2], t, 0.0, h)
    b.wall(s, outer[2], outer[3], t, 0.0, h)
    west = b.wall(s, outer[3], outer[0], t, 0.0, h)
    middle = b.wall(s, (4.1, 0), (4.1, 4), t, 0.0, h)
    b.opening(s, middle, (4.1, 2.0), (0, 1), 0.9, t + 0.02, 0.0, 2.1, "door")
    b.opening(s, west, (-t / 2, 1.5), (0, 1), 1.0, t + 0.02, 0.0, 2.1, "door")
    b.opening(s, south, (6.2, -t / 2), (1, 0), 1.2, t + 0.02, 0.9, 2.2, "window")
    b.slab(s, outer, 0.0)
    b.slab(s, outer, h + 0.2)
    # a long low beam lying on the floor across both rooms, through the middle wall
    b.furniture(s, [(2.0, 3.0), (6.0, 3.0), (6.0, 3.3), (2.0, 3.3)], 0.0, 0.3, "bench")
    return b.write(path)


def l_room_model(path: Path) -> Path:
    """One L-shaped room (6 x 6 m with a 3 x 3 m corner cut away)."""
    b = IfcBuilder()
    s = b.storey("ground", 0.0)
    ring = [(0, 0), (6, 0), (6, 3), (3, 3), (3, 6), (0, 6)]
    b.space("L room", s, ring, 0.0, 2.8)
    b.slab(s, ring, 0.0)
    b.furniture(s, [(1, 1), (2, 1), (2, 2), (1, 2)], 0.0, 0.8)
    return b.write(path)


def stair_model(path: Path) -> Path:
    """Two storeys (3 m apart) of one room each, a straight stair from the ground floor
    to the upper one through a hole in the upper floor slab."""
    b = IfcBuilder()
    g = b.storey("ground", 0.0)
    u = b.storey("upper", 3.0)
    ring = [(0, 0), (8, 0), (8, 5), (0, 5)]
    b.space("Hall", g, ring, 0.0, 2.8)
    b.space("Landing", u, ring, 3.0, 2.8)
    hole = [(1.0, 1.0), (6.5, 1.0), (6.5, 2.2), (1.0, 2.2)]
    b.slab(g, ring, 0.0)
    b.slab(u, ring, 3.0, holes=[hole])
    b.slab(u, ring, 6.0)
    b.stair(g, (1.2, 1.6), (6.0, 1.6), 1.0, 0.0, 3.0)
    return b.write(path)


def stairwell_model(path: Path) -> Path:
    """Two storeys (3 m apart): a hall below and a landing above, side by side with one
    stair space that the file puts on the ground storey only although it rises through
    both (as exporters do), a door from each of them into it, and a straight stair in
    it from the ground floor to the upper one (no slab over the stair space)."""
    b = IfcBuilder()
    g = b.storey("ground", 0.0)
    u = b.storey("upper", 3.0)
    t = 0.2
    rooms = [(0, 0), (6, 0), (6, 5), (0, 5)]
    well = [(6.2, 0), (9, 0), (9, 5), (6.2, 5)]
    b.space("Hall", g, rooms, 0.0, 2.8)
    b.space("Landing", u, rooms, 3.0, 2.8)
    b.space("Stair", g, well, 0.0, 5.8)
    middle = b.wall(g, (6.1, 0), (6.1, 5), t, 0.0, 5.8)
    b.opening(g, middle, (6.1, 4.0), (0, 1), 0.9, t + 0.02, 0.0, 2.1, "door")
    b.opening(u, middle, (6.1, 4.0), (0, 1), 0.9, t + 0.02, 3.0, 5.1, "door")
    b.slab(g, [(0, 0), (9, 0), (9, 5), (0, 5)], 0.0)
    b.slab(u, rooms, 3.0)
    b.slab(u, [(0, 0), (9, 0), (9, 5), (0, 5)], 6.0)
    b.stair(g, (7.6, 0.4), (7.6, 4.6), 1.0, 0.0, 3.0)
    return b.write(path)


def open_hall_model(path: Path, length: float = 48.0, width: float = 30.0, rows: int = 3, columns: int = 6) -> Path:
    """One storey whose one space is a large open hall (``length x width`` metres, 6 m
    high) with machines in ``rows x columns`` islands (furnishing elements: a base, a
    housing and a control desk each), an entrance door in the west wall."""
    b = IfcBuilder((600_000.0, 5_340_000.0))
    s = b.storey("hall", 0.0)
    t, h = 0.3, 6.0
    b.space("Production hall", s, [(0, 0), (length, 0), (length, width), (0, width)], 0.0, h)
    outer = [(-t / 2, -t / 2), (length + t / 2, -t / 2), (length + t / 2, width + t / 2), (-t / 2, width + t / 2)]
    for k in range(4):
        w = b.wall(s, outer[k], outer[(k + 1) % 4], t, 0.0, h)
        if k == 3:
            b.opening(s, w, (-t / 2, 0.5 * width), (0, 1), 3.0, t + 0.02, 0.0, 4.0, "door")
    b.slab(s, outer, 0.0)
    b.slab(s, outer, h + 0.3, 0.3)
    dx, dy = length / columns, width / rows
    for r in range(rows):
        for c in range(columns):
            x, y = (c + 0.5) * dx, (r + 0.5) * dy
            b.furniture(s, [(x - 1.5, y - 1.0), (x + 1.5, y - 1.0), (x + 1.5, y + 1.0), (x - 1.5, y + 1.0)], 0.0, 0.2,
                        f"machine {r}.{c} base")
            b.furniture(s, [(x - 1.3, y - 0.8), (x + 1.3, y - 0.8), (x + 1.3, y + 0.8), (x - 1.3, y + 0.8)], 0.2, 2.0,
                        f"machine {r}.{c} housing")
            b.furniture(s, [(x + 1.5, y - 0.4), (x + 2.0, y - 0.4), (x + 2.0, y + 0.4), (x + 1.5, y + 0.4)], 0.0, 1.4,
                        f"machine {r}.{c} desk")
    return b.write(path)
