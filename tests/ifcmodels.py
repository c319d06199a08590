"""Small IFC models written with ifcopenshell's API, for the interior traps.

Each model is a real IFC4 file (spaces, walls with opening elements filled by doors
and windows, slabs, stairs, furniture) placed ``offset`` metres from the CRS origin,
so tests can put a building millions of metres away.  Geometry is given in metres
relative to the offset; every product's placement is absolute.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["IfcBuilder", "two_rooms_model", "l_room_model", "stair_model", "stairwell_model", "open_hall_model"]


class IfcBuilder:
    """Builds an IFC4 model step by step (see the module docstring)."""

    def __init__(self, offset: tuple[float, float] = (0.0, 0.0)) -> None:
        import ifcopenshell
        import ifcopenshell.api.aggregate
        import ifcopenshell.api.context
        import ifcopenshell.api.root
        import ifcopenshell.api.unit
        import ifcopenshell.util.shape_builder

        self.api = ifcopenshell.api
        self.f = ifcopenshell.file(schema="IFC4")
        self.offset = np.array([offset[0], offset[1], 0.0])
        project = ifcopenshell.api.root.create_entity(self.f, ifc_class="IfcProject", name="test")
        ifcopenshell.api.unit.assign_unit(self.f, length={"is_metric": True, "raw": "METERS"})
        model = ifcopenshell.api.context.add_context(self.f, context_type="Model")
        self.body = ifcopenshell.api.context.add_context(
            self.f, context_type="Model", context_identifier="Body", target_view="MODEL_VIEW", parent=model
        )
        self.shape = ifcopenshell.util.shape_builder.ShapeBuilder(self.f)
        self.site = self._product("IfcSite", "site")
        self.building = self._product("IfcBuilding", "building")
        ifcopenshell.api.aggregate.assign_object(self.f, products=[self.site], relating_object=project)
        ifcopenshell.api.aggregate.assign_object(self.f, products=[self.building], relating_object=self.site)
        self.storeys: list[Any] = []

    def _product(self, cls: str, name: str, z: float = 0.0) -> Any:
        import ifcopenshell.api.geometry
        import ifcopenshell.api.root

        p = self.api.root.create_entity(self.f, ifc_class=cls, name=name)
        m = np.eye(4)
        m[:3, 3] = self.offset + np.array([0.0, 0.0, z])
        ifcopenshell.api.geometry.edit_object_placement(self.f, product=p, matrix=m)
        return p

    def _body(self, product: Any, items: Sequence[Any]) -> None:
        import ifcopenshell.api.geometry

        rep = self.shape.get_representation(self.body, list(items))
        ifcopenshell.api.geometry.assign_representation(self.f, product=product, representation=rep)

    def _prism(self, ring: Sequence[Sequence[float]], z0: float, height: float) -> Any:
        pts = [(float(x), float(y)) for x, y in ring]
        curve = self.shape.polyline(pts, closed=True)
        return self.shape.extrude(self.shape.profile(curve), height, position=(0.0, 0.0, z0))

    def storey(self, name: str, z: float) -> Any:
        import ifcopenshell.api.aggregate

        s = self._product("IfcBuildingStorey", name, z)
        s.Elevation = z
        ifcopenshell.api.aggregate.assign_object(self.f, products=[s], relating_object=self.building)
        self.storeys.append(s)
        return s

    def _contain(self, product: Any, storey: Any) -> None:
        import ifcopenshell.api.spatial

        ifcopenshell.api.spatial.assign_container(self.f, products=[product], relating_structure=storey)

    def space(self, name: str, storey: Any, ring: Sequence[Sequence[float]], z0: float, height: float) -> Any:
        import ifcopenshell.api.aggregate

        s = self._product("IfcSpace", name)
        self._body(s, [self._prism(ring, z0, height)])
        ifcopenshell.api.aggregate.assign_object(self.f, products=[s], relating_object=storey)
        return s

    def wall(self, storey: Any, a: Sequence[float], b: Sequence[float], thickness: float, z0: float, height: float) -> Any:
        pa, pb = np.asarray(a, float), np.asarray(b, float)
        u = (pb - pa) / np.linalg.norm(pb - pa)
        n = np.array([-u[1], u[0]]) * 0.5 * thickness
        ring = [pa - n, pb - n, pb + n, pa + n]
        w = self._product("IfcWall", "wall")
        self._body(w, [self._prism(ring, z0, height)])
        self._contain(w, storey)
        return w

    def opening(
        self, storey: Any, wall: Any, centre: Sequence[float], along: Sequence[float], width: float,
        depth: float, z0: float, z1: float, fill: str | None = "door",
    ) -> Any:
        """A box-shaped opening through ``wall`` (filled by a door or window, or empty)."""
        import ifcopenshell.api.feature

        c = np.asarray(centre, float)
        u = np.asarray(along, float) / np.linalg.norm(along)
        n = np.array([-u[1], u[0]]) * 0.5 * depth
        w = u * 0.5 * width
        ring = [c - w - n, c + w - n, c + w + n, c - w + n]
        op = self._product("IfcOpeningElement", "opening")
        self._body(op, [self._prism(ring, z0, z1 - z0)])
        ifcopenshell.api.feature.add_feature(self.f, feature=op, element=wall)
        if fill is None:
            return op
        cls = "IfcDoor" if fill == "door" else "IfcWindow"
        el = self._product(cls, fill)
        thin = np.array([-u[1], u[0]]) * 0.02
        self._body(el, [self._prism([c - w - thin, c + w - thin, c + w + thin, c - w + thin], z0, z1 - z0)])
        self._contain(el, storey)
        ifcopenshell.api.feature.add_filling(self.f, opening=op, element=el)
        return el

    def slab(self, storey: Any, ring: Sequence[Sequence[float]], top: float, thickness: float = 0.2,
             holes: Sequence[Sequence[Sequence[float]]] = ()) -> Any:
        s = self._product("IfcSlab", "slab")
        outer = self.shape.polyline([(float(x), float(y)) for x, y in ring], closed=True)
        inner = [self.shape.polyline([(float(x), float(y)) for x, y in h], closed=True) for h in holes]
        prof = self.shape.profile(outer, inner_curves=inner)
        self._body(s, [self.shape.extrude(prof, thickness, position=(0.0, 0.0, top - thickness))])
        self._contain(s, storey)
        return s

    def furniture(self, storey: Any, ring: Sequence[Sequence[float]], z0: float, height: float, name: str = "table") -> Any:
        e = self._product("IfcFurnishingElement", name)
        self._body(e, [self._prism(ring, z0, height)])
        self._contain(e, storey)
        return e

    def stair(self, storey: Any, start: Sequence[float], end: Sequence[float], width: float, z0: float,
              rise: float, steps: int = 16) -> Any:
        """A straight flight of solid steps from ``start`` (bottom) to ``end`` (top)."""
        a, b = np.asarray(start, float), np.asarray(end, float)
        u = (b - a) / np.linalg.norm(b - a)
        n = np.array([-u[1], u[0]]) * 0.5 * width
        going = float(np.linalg.norm(b - a)) / steps
        items = []
        for k in range(steps):
            p0, p1 = a + u * going * k, a + u * going * (k + 1)
            items.append(self._prism([p0 - n, p1 - n, p1 + n, p0 + n], z0, rise * (k + 1) / steps))
        st = self._product("IfcStair", "stair")
        self._body(st, items)
        self._contain(st, storey)
        return st

    def flights(self, storey: Any, flights: Sequence[tuple[Sequence[float], Sequence[float], float, float, int]],
                landings: Sequence[tuple[Sequence[Sequence[float]], float]], width: float) -> Any:
        """One ``IfcStair`` of several straight flights ``(start, end, z0, rise, steps)``
        of solid steps and flat ``landings`` ``(ring, top)`` (solid down to ``z0`` of the
        first flight)."""
        items = []
        for start, end, z0, rise, steps in flights:
            a, b = np.asarray(start, float), np.asarray(end, float)
            u = (b - a) / np.linalg.norm(b - a)
            n = np.array([-u[1], u[0]]) * 0.5 * width
            going = float(np.linalg.norm(b - a)) / steps
            for k in range(steps):
                p0, p1 = a + u * going * k, a + u * going * (k + 1)
                items.append(self._prism([p0 - n, p1 - n, p1 + n, p0 + n], z0, rise * (k + 1) / steps))
        base = float(flights[0][2])
        for ring, top in landings:
            items.append(self._prism(ring, base, top - base))
        st = self._product("IfcStair", "stair")
        self._body(st, items)
        self._contain(st, storey)
        return st

    def write(self, path: Path) -> Path:
        self.f.write(str(path))
        return path


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
