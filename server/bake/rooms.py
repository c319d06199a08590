"""Room cells and portals of an interior (Mulloni et al.'s cells and portals).

:func:`room_layout` turns an :class:`~walkstream.server.sources.interior.InteriorScene`
into convex cells, each with its plane set, and the portals between them:

1. **Storeys decide heights.**  A cell's volume runs from its storey's elevation to
   the next storey's (the top storey: its tallest room), whatever the room's own
   solid says, so a stair space that reaches into the storey above still belongs to
   its own storey only, and a viewer at any height is in at most one storey.
2. **Rooms.**  The rooms of a storey are made disjoint (smaller rooms keep what they
   share with larger ones; slivers under 2 cm go) and cut into convex parts
   (:func:`~.roomgeom.convex_parts`); the parts of one room are joined by open
   ``split`` portals over their shared edge.
3. **Doorways.**  Walls are thick, so the rooms on the two sides of a door are 10 to
   40 cm apart: each door, inner window or empty opening gets a ``doorway`` cell that
   fills the hole from one room's outline to the other's (so an eye in the doorway is
   in a cell), with a portal on each face (polygon: the shared edge, sill to head).
   Which rooms lie on the two sides is taken from the source when it names exactly
   two, else found from the geometry: probe points just beyond both faces of the
   opening, at half its height; a side with no room is the outside.  An outer window
   is one portal from its room to the outside cell, on the room's face.
4. **Open boundaries.**  A virtual boundary of the source joins the cells of its two
   rooms that touch it; two rooms that touch with no virtual boundary between them
   are joined over the parts of their shared edge no wall stands on (found from the
   walls' footprints).
5. **Floors with holes.**  Where a cell overlaps a cell of the storey above and the
   slabs between them leave a hole (stairwell, gallery), a horizontal portal joins
   them; a stair flight whose bottom and top lie in two such cells makes that portal
   walkable and records its walking line.
6. **Outside.**  One ``outside`` cell (no planes; nobody is located in it) is the
   other side of every outer window and door: the client draws what it holds (outer
   wall faces, roofs, anything no room holds) when one of those portals is visible.
"""

from __future__ import annotations

import math
from collections import Counter

import numpy as np
import shapely

from walkstream.server.bake.roomgeom import (
    cell_planes,
    convex_parts,
    orient_ccw,
    polygon_rings,
    ray_distance,
    shared_segments,
    without_holes,
)
from walkstream.server.bake.roomlayout import Portal, RoomCell, RoomLayout, StairLink
from walkstream.server.sources.interior import InteriorScene, Opening, mesh_footprint
from walkstream.shared.arrays import F64
from walkstream.shared.errors import SourceError

__all__ = [
    "room_layout",
    "storey_ranges",
]

_TOUCH = 0.03  # outlines this close touch
_MIN_PORTAL = 0.3  # shorter open stretches are no passage
_PROBES = (0.05, 0.15, 0.3, 0.5)  # beyond an opening's faces, metres
_LOW_WALL = 0.5  # a wall stopping this far or more below the next floor is seen over
_MIN_WALL = 1.0  # an open stretch between two rooms shorter than this stays open (no wall)
_GROW = 0.5  # a space is grown over free floor up to its walls this far at most


def storey_ranges(scene: InteriorScene) -> F64:
    """``(storeys, 2)`` height ranges: from each storey's elevation to the next one's;
    the top storey up to its ceiling: the highest room solid on it, slab, roof,
    covering or wall rising over its floor (at least 2.5 m).  A space drawn short of
    the ceiling (or an attic's space under a pitched roof) must not leave the ceiling
    and what hangs from it out of the top storey's cells."""
    elev = np.array([s.elevation for s in scene.storeys], dtype=np.float64)
    out = np.zeros((len(elev), 2))
    out[:, 0] = elev
    out[:-1, 1] = elev[1:]
    top = [r.zmax for r in scene.rooms if r.storey == len(elev) - 1]
    for e in scene.elements:
        if e.kind in ("slab", "roof", "covering", "wall") and len(e.vertices):
            zhi = float(e.vertices[:, 2].max())
            if zhi > elev[-1] + 1.0:
                top.append(zhi)
    out[-1, 1] = max([elev[-1] + 2.5] + top)
    return out


def _standing_walls(scene: InteriorScene, ranges: F64) -> list[list[tuple[shapely.Geometry, float]]]:
    """Per storey: the walls and columns standing at eye height, as ``(footprint, top)``."""
    out: list[list[tuple[shapely.Geometry, float]]] = [[] for _ in range(len(ranges))]
    for e in scene.elements:
        if e.kind not in ("wall", "column") or len(e.triangles) == 0:
            continue
        z0, z1 = float(e.vertices[:, 2].min()), float(e.vertices[:, 2].max())
        for k, (lo, _hi) in enumerate(ranges):
            if z0 < lo + 1.0 and z1 > lo + 1.8:
                fp = mesh_footprint(e.vertices, e.triangles)
                if not fp.is_empty:
                    out[k].append((fp, z1))
    return out


def _blocking_footprints(scene: InteriorScene, ranges: F64) -> list[shapely.Geometry]:
    """Per storey: where walls and columns stand at eye height (their footprints)."""
    return [shapely.union_all([fp for fp, _ in w]) if w else shapely.Polygon() for w in _standing_walls(scene, ranges)]


def _slab_cover(scene: InteriorScene, z: float) -> shapely.Geometry:
    """Footprint of the floor at height ``z``: the level faces of slabs, roofs and
    coverings from 0.65 m below to 0.5 m above it (a floor with its ceiling)."""
    parts = []
    for e in scene.elements:
        if e.kind not in ("slab", "roof", "covering") or len(e.triangles) == 0:
            continue
        zs = e.vertices[:, 2]
        if zs.max() < z - 0.65 or zs.min() > z + 0.5:
            continue
        tri = e.soup
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        level = np.abs(n[:, 2]) > 0.7 * np.linalg.norm(n, axis=1)
        cz = tri[:, :, 2].mean(axis=1)
        keep = level & (cz >= z - 0.65) & (cz <= z + 0.5)
        if keep.any():
            fp = mesh_footprint(tri[keep].reshape(-1, 3), np.arange(3 * int(keep.sum())).reshape(-1, 3))
            if not fp.is_empty:
                parts.append(fp)
    return shapely.union_all(parts) if parts else shapely.Polygon()


class _Builder:
    def __init__(self, scene: InteriorScene, wall_pitch: float | None = None) -> None:
        self.scene = scene
        self.wall_pitch = wall_pitch
        self._squares = 0  # grid squares numbered so far (wall_grid)
        self.ranges = storey_ranges(scene)
        self.cells: list[RoomCell] = []
        self.portals: list[Portal] = []
        self.stairs: list[StairLink] = []
        self.notes: list[str] = []
        self.sources: Counter[str] = Counter()
        self.linked: set[tuple[int, int]] = set()
        self._unions: dict[int, shapely.Geometry] = {}

    # -- cells ---------------------------------------------------------------

    def add_cell(self, kind: str, name: str, room: str | None, storey: int, ring: F64) -> RoomCell:
        lo, hi = self.ranges[storey]
        r = orient_ccw(ring)
        cell = RoomCell(len(self.cells), kind, name, room, storey, r, float(lo), float(hi),
                        cell_planes(r, float(lo), float(hi)))
        self.cells.append(cell)
        return cell

    def add_portal(self, kind: str, a: int, b: int, polygon: F64, source: str, name: str = "") -> Portal:
        p = Portal(len(self.portals), kind, a, b, np.asarray(polygon, np.float64), source, name)
        self.portals.append(p)
        self.sources[source] += 1
        self.linked.add((min(a, b), max(a, b)))
        return p

    def _rooms_union(self, k: int) -> shapely.Geometry:
        if k not in self._unions:
            self._unions[k] = shapely.union_all([x.polygon for x in self.storey_cells(k, ("room",))])
        return self._unions[k]

    def storey_cells(self, k: int, kinds: tuple[str, ...] = ("room", "doorway")) -> list[RoomCell]:
        return [c for c in self.cells if c.storey == k and c.kind in kinds]

    def locate(self, xy: F64, z: float, storey: int | None = None, among: list[RoomCell] | None = None) -> RoomCell | None:
        for c in among if among is not None else self.cells:
            if c.kind == "outside" or (storey is not None and c.storey != storey):
                continue
            if c.holds(xy, z):
                return c
        return None

    # -- 2: rooms -------------------------------------------------------------

    def rooms(self) -> None:
        # a room rising a metre or more into the storeys above (a stair space that the
        # file puts on one storey) is also a room of those storeys, where no other
        # room of theirs is
        by_storey: dict[int, list[tuple[int, float, int]]] = {}
        for i, r in enumerate(self.scene.rooms):
            area = shapely.Polygon(r.outline).area if len(r.outline) >= 3 else 0.0
            for k in range(r.storey, len(self.ranges)):
                if k == r.storey or r.zmax >= self.ranges[k][0] + 1.0:
                    by_storey.setdefault(k, []).append((0 if k == r.storey else 1, area, i))
        walls = _blocking_footprints(self.scene, self.ranges)
        for k in sorted(by_storey):
            taken = shapely.Polygon()
            originals = {i: shapely.make_valid(shapely.Polygon(self.scene.rooms[i].outline)) for _, _a, i in by_storey[k]}
            free = self._free_floor(k, walls[k])
            grew = 0
            for _, _area, i in sorted(by_storey[k]):
                room = self.scene.rooms[i]
                poly = originals[i]
                if not free.is_empty:
                    others = shapely.union_all([g for j, g in originals.items() if j != i])
                    poly, more = _grow_to_walls(poly, free, others)
                    grew += more
                poly = poly.difference(taken)
                # drop slivers left by a few centimetres of overlap with a neighbour
                poly = poly.buffer(-0.01, join_style="mitre").buffer(0.01, join_style="mitre")
                rings = polygon_rings(without_holes(poly), 0.25)
                if not rings:
                    if k == room.storey:
                        self.notes.append(f"room {room.name}: nothing left after overlaps, left out")
                    continue
                taken = taken.union(shapely.union_all([shapely.Polygon(r) for r in rings]))
                parts: list[RoomCell] = []
                square: list[int] = []  # the grid square of each part (-1: not cut)
                for ring in rings:
                    simple = shapely.Polygon(ring).simplify(0.005)
                    for part in convex_parts(np.asarray(simple.exterior.coords)[:-1]):
                        for sq, piece in self.wall_grid(part):
                            if shapely.Polygon(piece).area > 0.05:
                                parts.append(self.add_cell("room", room.name, room.key, k, piece))
                                square.append(sq)
                for x in range(len(parts)):
                    for y in range(x + 1, len(parts)):
                        # pieces of two grid squares are joined by a virtual wall; parts
                        # of one room otherwise: nothing between them up to the cells' top,
                        # wherever the space's solid stops
                        wall = square[x] >= 0 and square[y] >= 0 and square[x] != square[y]
                        kind = "wall" if wall else "split"
                        self.edge_portals(parts[x], parts[y], kind, kind, parts[x].zmax, room.name)
            if grew:
                self.notes.append(f"storey {k}: {grew} rooms grown to their walls (spaces that stop short of them)")

    def wall_grid(self, part: F64) -> list[tuple[int, F64]]:
        """A convex part cut by virtual walls: ``(grid square, convex piece)`` each.

        With ``wall_pitch`` ``S`` (``--virtual-walls``), a part whose area is over
        ``2 S**2`` is cut by lines parallel to its bounding box's sides into
        ``ceil(width / S)`` by ``ceil(depth / S)`` equal squares (each piece convex: a
        convex part cut by a box).  Without walls, or a smaller part, the part as it
        is with square -1.
        """
        pitch = self.wall_pitch
        poly = shapely.Polygon(part)
        if pitch is None or poly.area <= 2.0 * pitch * pitch:
            return [(-1, part)]
        x0, y0, x1, y1 = poly.bounds
        nx, ny = max(1, math.ceil((x1 - x0) / pitch - 1e-9)), max(1, math.ceil((y1 - y0) / pitch - 1e-9))
        xs, ys = np.linspace(x0, x1, nx + 1), np.linspace(y0, y1, ny + 1)
        first = self._squares
        self._squares += nx * ny
        out: list[tuple[int, F64]] = []
        for i in range(nx):
            for j in range(ny):
                piece = poly.intersection(shapely.box(xs[i], ys[j], xs[i + 1], ys[j + 1]))
                if isinstance(piece, shapely.Polygon) and piece.area > 0.05:
                    ring = np.asarray(piece.exterior.coords)[:-1]
                    out.append((first + i * ny + j, ring))
        return out

    def _free_floor(self, k: int, walls: shapely.Geometry) -> shapely.Geometry:
        """Storey ``k``'s floor (its slabs' level faces) where no wall or column stands
        and no opening goes through a wall: a space grown over it stops at its doors,
        never reaching through one to the floor beyond (a slab wider than the walls)."""
        floor = _slab_cover(self.scene, float(self.ranges[k][0]))
        if floor.is_empty:
            return floor
        blocked = shapely.union_all([walls, *_opening_footprints(self.scene.openings, k)])
        return floor.difference(blocked) if not blocked.is_empty else floor

    def edge_portals(self, x: RoomCell, y: RoomCell, kind: str, source: str, top: float, name: str = "",
                     z0: float | None = None) -> int:
        """Portals over every shared edge of two touching cells; returns how many."""
        lo = x.zmin if z0 is None else z0
        hi = min(top, x.zmax)
        n = 0
        for seg in shared_segments(x.outline, y.outline, _TOUCH):
            if float(np.hypot(*(seg[1] - seg[0]))) < 0.05:
                continue
            self.add_portal(kind, x.id, y.id, _vertical(seg, lo, hi), source, name)
            n += 1
        return n

    # -- 3: doorways and windows -------------------------------------------

    def openings(self) -> None:
        blocked = 0
        for op in self.scene.openings:
            if op.kind == "virtual" or op.depth < 0.01:
                continue
            if not 0 <= op.storey < len(self.ranges):
                continue
            sides = self.sides(op)
            if sides is None:
                blocked += 1
                continue
            a, b, source = sides
            if a is None and b is None:
                blocked += 1
                continue
            if a is not None and b is not None and a.room == b.room:
                self.notes.append(f"{op.kind} {op.name}: both sides lie in room {a.name}; no portal")
                continue
            if op.kind == "window" and (a is None or b is None):
                room = a if a is not None else b
                sign = -1.0 if a is not None else 1.0
                assert room is not None
                self.outer_window(op, room, sign, source)
            else:
                self.doorway(op, a, b, source)
        if blocked:
            self.notes.append(f"{blocked} openings with no room on either side: no portal")

    def sides(self, op: Opening) -> tuple[RoomCell | None, RoomCell | None, str] | None:
        """The cells beyond the opening's two faces (-normal side, +normal side)."""
        cells = self.storey_cells(op.storey, ("room",))
        named = set(op.rooms) if len(op.rooms) == 2 else set()
        z = min(max(op.zmin + 0.5 * min(op.zmax - op.zmin, 2.0), self.ranges[op.storey][0] + 0.2),
                self.ranges[op.storey][1] - 0.1)
        found: list[RoomCell | None] = []
        for s in (-1.0, 1.0):
            hit = None
            for delta in _PROBES:
                for u in (0.0, -0.3, 0.3):
                    q = op.centre[:2] + op.normal * s * (0.5 * op.depth + delta) + op.along * u * 0.5 * op.width
                    cand = [c for c in cells if (not named or c.room in named)]
                    hit = self.locate(q, z, op.storey, cand) or (self.locate(q, z, op.storey, cells) if named else None)
                    if hit is not None:
                        break
                if hit is not None:
                    break
            found.append(hit)
        a, b = found
        if a is None and b is None:
            return None
        source = "boundary" if named and {c.room for c in (a, b) if c is not None} == named else "geometry"
        return a, b, source

    def outer_window(self, op: Opening, room: RoomCell, sign: float, source: str) -> None:
        """A window between a room (on the ``sign`` side) and the outside: one portal on the room's face."""
        t = self.face_distance(op, room, sign)
        if t is None:
            t = 0.5 * op.depth
        c = op.centre[:2] + op.normal * sign * t
        seg = np.array([c - op.along * 0.5 * op.width, c + op.along * 0.5 * op.width])
        lo, hi = self.ranges[op.storey]
        self.add_portal("window", room.id, -1, _vertical(seg, max(op.zmin, lo), min(op.zmax, hi)), source, op.name)

    def face_distance(self, op: Opening, cell: RoomCell, sign: float) -> float | None:
        """How far from the opening's middle plane the cell's outline begins (max over
        three lines across the opening), or None when no line reaches it."""
        ds = []
        for u in (-0.45, 0.0, 0.45):
            start = op.centre[:2] + op.along * u * op.width
            d = ray_distance(start, op.normal * sign, cell.outline, reach=max(1.0, op.depth + 0.6))
            if d is not None:
                ds.append(d)
        return max(ds) if ds else None

    def doorway(self, op: Opening, a: RoomCell | None, b: RoomCell | None, source: str) -> None:
        """Doorway cells filling the hole from ``a``'s outline to ``b``'s, and their portals."""
        ext = []
        for cell, sign in ((a, -1.0), (b, 1.0)):
            d = self.face_distance(op, cell, sign) if cell is not None else None
            ext.append(0.5 * op.depth if d is None else min(d, op.depth + 0.6))
        ta, tb = ext
        c, u, n = op.centre[:2], op.along, op.normal
        w = 0.5 * op.width
        rect = shapely.Polygon([c - u * w - n * ta, c + u * w - n * ta, c + u * w + n * tb, c - u * w + n * tb])
        hole = rect.difference(self._rooms_union(op.storey))
        rings = polygon_rings(hole, 0.005)
        lo, hi = self.ranges[op.storey]
        z0, z1 = max(op.zmin, lo), min(op.zmax, hi)
        if not rings:
            # the rooms reach into the hole (spaces drawn to the wall's middle): a
            # portal across the opening's middle plane joins them directly
            if a is not None and b is not None:
                seg = np.array([c - u * w, c + u * w])
                self.add_portal(op.kind, a.id, b.id, _vertical(seg, z0, z1), source, op.name)
            return
        name = f"{op.kind} {op.name}"
        pieces: list[RoomCell] = []
        for ring in rings:
            for part in convex_parts(ring):
                if shapely.Polygon(part).area > 0.002:
                    pieces.append(self.add_cell("doorway", name, None, op.storey, part))
        for i in range(len(pieces)):
            for j in range(i + 1, len(pieces)):
                self.edge_portals(pieces[i], pieces[j], "split", "split", hi, name, z0)
        # a portal on each face: to the rooms it touches, and to the outside where it
        # ends at an outer face
        neighbours = [x for x in self.storey_cells(op.storey, ("room",))]
        for p in pieces:
            for x in neighbours:
                if p.polygon.distance(x.polygon) < _TOUCH:
                    for seg in shared_segments(p.outline, x.outline, _TOUCH):
                        self.add_portal(op.kind, p.id, x.id, _vertical(seg, z0, z1), source, op.name)
            for cell, sign, t in ((a, -1.0, ta), (b, 1.0, tb)):
                if cell is not None:
                    continue
                face = c + n * sign * t
                seg_line = shapely.LineString([face - u * w, face + u * w])
                on = seg_line.intersection(p.polygon.buffer(1e-6))
                if isinstance(on, shapely.LineString) and on.length > 0.05:
                    pts = np.asarray(on.coords)
                    self.add_portal(op.kind, p.id, -1, _vertical(pts[[0, -1]], z0, z1), source, op.name)

    # -- 4: open boundaries -------------------------------------------------

    def virtual(self) -> None:
        for op in self.scene.openings:
            if op.kind != "virtual" or op.polygon is None or len(op.rooms) != 2:
                continue
            poly = op.polygon
            if float(np.ptp(poly[:, 2])) < 0.3:  # horizontal: floors are handled by holes
                continue
            line = shapely.LineString(poly[:, :2]).envelope if len(poly) else None
            if line is None:
                continue
            ra, rb = op.rooms
            k = op.storey
            xs = [c for c in self.storey_cells(k, ("room",)) if c.room == ra]
            ys = [c for c in self.storey_cells(k, ("room",)) if c.room == rb]
            zone = shapely.MultiPoint(poly[:, :2]).convex_hull.buffer(_TOUCH)
            z0 = max(float(poly[:, 2].min()), self.ranges[k][0])
            z1 = min(float(poly[:, 2].max()), self.ranges[k][1])
            for x in xs:
                for y in ys:
                    for seg in shared_segments(x.outline, y.outline, _TOUCH):
                        part = shapely.LineString(seg).intersection(zone)
                        if isinstance(part, shapely.LineString) and part.length >= _MIN_PORTAL:
                            pts = np.asarray(part.coords)
                            self.add_portal("virtual", x.id, y.id, _vertical(pts[[0, -1]], z0, z1), "boundary", op.name)

    def touching(self) -> None:
        walls = _blocking_footprints(self.scene, self.ranges)
        for k in range(len(self.ranges)):
            cells = self.storey_cells(k, ("room",))
            cover = walls[k].buffer(0.05) if not walls[k].is_empty else walls[k]
            for i in range(len(cells)):
                for j in range(i + 1, len(cells)):
                    x, y = cells[i], cells[j]
                    if x.room == y.room or (min(x.id, y.id), max(x.id, y.id)) in self.linked:
                        continue
                    if x.polygon.distance(y.polygon) > _TOUCH:
                        continue
                    top = min(x.zmax, y.zmax)  # a wall stands at eye height or not at all
                    for seg in shared_segments(x.outline, y.outline, _TOUCH):
                        line = shapely.LineString(seg)
                        free = line.difference(cover) if not cover.is_empty else line
                        for g in getattr(free, "geoms", [free]):
                            if isinstance(g, shapely.LineString) and g.length >= _MIN_PORTAL:
                                pts = np.asarray(g.coords)
                                self.add_portal("opening", x.id, y.id, _vertical(pts[[0, -1]], x.zmin, top),
                                                "geometry", "open")

    def over_low_walls(self) -> None:
        """Open portals over walls that stop short of the ceiling, from the wall's top
        to the cells' top, between touching cells of two rooms (linked or not: a door
        in a low wall is not the only way through)."""
        standing = _standing_walls(self.scene, self.ranges)
        for k in range(len(self.ranges)):
            hi = float(self.ranges[k][1])
            walls = [(fp.buffer(0.05), top) for fp, top in standing[k] if top <= hi - _LOW_WALL]
            if not walls:
                continue
            cells = self.storey_cells(k, ("room",))
            for i in range(len(cells)):
                for j in range(i + 1, len(cells)):
                    x, y = cells[i], cells[j]
                    if x.room == y.room or x.polygon.distance(y.polygon) > _TOUCH:
                        continue
                    for seg in shared_segments(x.outline, y.outline, _TOUCH):
                        line = shapely.LineString(seg)
                        for fp, top in walls:
                            on = line.intersection(fp)
                            for g in getattr(on, "geoms", [on]):
                                if isinstance(g, shapely.LineString) and g.length >= 0.05:
                                    pts = np.asarray(g.coords)
                                    self.add_portal("opening", x.id, y.id,
                                                    _vertical(pts[[0, -1]], top, min(x.zmax, y.zmax)),
                                                    "geometry", "over a low wall")

    def open_walls(self) -> None:
        """With ``--virtual-walls``, the open stretches between rooms of one large open space
        become ``wall`` portals too: an open space is room cells joined by ``split``,
        ``wall`` and open (``touching``) portals; where its floor is over ``2 S**2`` (the
        bound that cuts one room part into a grid), every open stretch of at least
        :data:`_MIN_WALL` is a wall.  So a hall drawn as touching bays is split at their
        borders too; two offices sharing an open stretch stay open."""
        if self.wall_pitch is None:
            return
        parent = list(range(len(self.cells)))

        def find(i: int) -> int:
            while parent[i] != i:
                parent[i] = parent[parent[i]]
                i = parent[i]
            return i

        def is_open(p: Portal) -> bool:
            return p.kind == "opening" and p.source == "geometry" and p.name == "open"

        for p in self.portals:
            if p.kind in ("split", "wall") or is_open(p):
                parent[find(p.a)] = find(p.b)
        area: dict[int, float] = {}
        for c in self.cells:
            area[find(c.id)] = area.get(find(c.id), 0.0) + (c.polygon.area if c.kind == "room" else 0.0)
        made = 0
        for i, p in enumerate(self.portals):
            low = p.polygon[np.isclose(p.polygon[:, 2], p.polygon[:, 2].min())][:, :2]
            if (is_open(p) and area.get(find(p.a), 0.0) > 2.0 * self.wall_pitch ** 2
                    and float(np.hypot(*(low[-1] - low[0]))) >= _MIN_WALL):
                self.portals[i] = Portal(p.id, "wall", p.a, p.b, p.polygon, p.source, p.name)
                made += 1
        if made:
            self.notes.append(f"{made} open stretches between rooms of an open space made virtual walls")

    # -- 5: holes in floors and stairs ---------------------------------------

    def floors(self) -> None:
        vertical: dict[tuple[int, int], int] = {}
        for k in range(len(self.ranges) - 1):
            lower = self.storey_cells(k)
            upper = self.storey_cells(k + 1)
            if not lower or not upper:
                continue
            z = float(self.ranges[k + 1][0])
            cover = _slab_cover(self.scene, z)
            for x in lower:
                for y in upper:
                    ov = x.polygon.intersection(y.polygon)
                    if ov.area < 0.3:
                        continue
                    hole = ov.difference(cover.buffer(0.02)) if not cover.is_empty else ov
                    for ring in polygon_rings(hole, 0.3):
                        p = self.add_portal("void", x.id, y.id, np.column_stack([ring, np.full(len(ring), z)]),
                                            "geometry", "hole in the floor")
                        vertical[(x.id, y.id)] = p.id
        for st in self.scene.stairs:
            self.stair(st.path, st.name, vertical)

    def stair(self, path: F64, name: str, vertical: dict[tuple[int, int], int]) -> None:
        """A stair's links: one per pair of storeys it joins.  A flight that rises past
        a storey's floor on its way to the next (one stair through three storeys) is
        cut at the tread on that floor, so each piece joins its own two storeys."""
        k = int(np.searchsorted(self.ranges[:, 0], path[0, 2] + 0.05, side="right")) - 1
        floors = [float(z) for z in self.ranges[k + 1:, 0]] if k >= 0 else []
        start = 0
        for zb in floors:
            if zb >= path[-1, 2] - 0.3:
                break  # the last floor it reaches (or nearly): the piece below ends there
            j = int(np.argmax(path[:, 2] >= zb - 0.02))
            if j > start:
                self._stair_piece(path[start:j + 1], name, vertical)
                start = j
        if len(path) - start >= 2:
            self._stair_piece(path[start:], name, vertical)

    def _stair_piece(self, path: F64, name: str, vertical: dict[tuple[int, int], int]) -> None:
        k = int(np.searchsorted(self.ranges[:, 0], path[0, 2] + 0.05, side="right")) - 1
        if not 0 <= k < len(self.ranges) - 1:
            self.notes.append(f"stair {name}: not between two storeys")
            return
        low = self.locate(path[0, :2], path[0, 2] + 0.5, k) or self._near(path[0, :2], path[0, 2] + 0.5, k)
        zt = float(self.ranges[k + 1][0])
        d = path[-1, :2] - path[-2, :2]
        d = d / max(float(np.hypot(*d)), 1e-9)
        top_xy = path[-1, :2] + d * 0.3
        line = np.concatenate([path, [[top_xy[0], top_xy[1], zt]]])
        # the walker's eye (1.6 m up) passes the floor above where the treads are 1.6 m
        # below it: the cell there is the stair's upper cell
        zs = line[:, 2] + 1.6
        j = int(np.searchsorted(zs, zt))
        if 0 < j < len(line):
            f = (zt - zs[j - 1]) / max(zs[j] - zs[j - 1], 1e-9)
            cross = line[j - 1, :2] + f * (line[j, :2] - line[j - 1, :2])
        else:
            cross = line[-1, :2]
        up = self.locate(cross, zt + 0.5, k + 1) or self._near(cross, zt + 0.5, k + 1)
        if low is None or up is None:
            self.notes.append(f"stair {name}: no cell at its {'bottom' if low is None else 'top'}")
            return
        pid = vertical.get((low.id, up.id))
        if pid is None:
            # no hole found in the floor above: the stair's own footprint is the passage
            ov = low.polygon.intersection(up.polygon).intersection(shapely.LineString(line[:, :2]).buffer(0.6))
            rings = polygon_rings(ov, 0.1)
            if not rings:
                self.notes.append(f"stair {name}: its bottom and top cells do not overlap")
                return
            p = self.add_portal("stair", low.id, up.id, np.column_stack([rings[0], np.full(len(rings[0]), zt)]),
                                "geometry", name)
            self.notes.append(f"stair {name}: no hole found in the floor above; its footprint is the portal")
        else:
            old = self.portals[pid]
            p = Portal(old.id, "stair", old.a, old.b, old.polygon, old.source, name)
            self.portals[pid] = p
        self.stairs.append(StairLink(p.id, low.id, up.id, line, name))

    def _near(self, xy: F64, z: float, k: int) -> RoomCell | None:
        best, dist = None, 0.5
        pt = shapely.Point(xy)
        for c in self.storey_cells(k):
            d = c.polygon.distance(pt)
            if d < dist:
                best, dist = c, d
        return best

    # -- 6: the outside -----------------------------------------------------

    def outside(self) -> None:
        pts = np.concatenate([c.outline for c in self.cells])
        lo, hi = pts.min(axis=0) - 1.0, pts.max(axis=0) + 1.0
        ring = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]])
        zlo = float(self.ranges[0][0]) - 1.0
        zhi = float(max(self.ranges[-1][1], max((e.vertices[:, 2].max() for e in self.scene.elements if len(e.vertices)), default=0.0))) + 1.0
        cid = len(self.cells)
        self.cells.append(RoomCell(cid, "outside", "outside", None, -1, ring, zlo, zhi, np.zeros((0, 4))))
        self.portals = [
            Portal(p.id, p.kind, p.a, cid if p.b < 0 else p.b, p.polygon, p.source, p.name) for p in self.portals
        ]


def _opening_footprints(openings: tuple[Opening, ...], storey: int) -> list[shapely.Geometry]:
    """The footprints of storey ``storey``'s holes through walls (doors, windows,
    openings: ``depth`` > 0), each a rectangle ``width`` along the wall by its
    thickness across, 2 cm deeper on each side so that it meets both wall faces."""
    out = []
    for o in openings:
        if o.storey != storey or o.depth <= 0.0 or o.width <= 0.0:
            continue
        n = np.asarray(o.normal, dtype=np.float64)[:2]
        n = n / max(float(np.linalg.norm(n)), 1e-12)
        t = np.array([-n[1], n[0]])
        c = np.asarray(o.centre, dtype=np.float64)[:2]
        a, d = 0.5 * o.width * t, (0.5 * o.depth + 0.02) * n
        out.append(shapely.Polygon([c - a - d, c + a - d, c + a + d, c - a + d]))
    return out


def _grow_to_walls(poly: shapely.Geometry, free: shapely.Geometry, others: shapely.Geometry) -> tuple[shapely.Geometry, int]:
    """A space grown over the floor up to its walls: the free floor (no wall, no other
    space) within :data:`_GROW` of it and joined to it.  Exporters draw spaces to a
    lining or leave centimetres before the wall; a cell that stops short of its walls
    leaves their faces in no cell, where no portal walk can see them.  Returns the
    polygon and 1 when it grew by more than slivers, else 0."""
    near = poly.buffer(_GROW, join_style="mitre").intersection(free)
    if not others.is_empty:
        near = near.difference(others)
    extra = near.difference(poly).buffer(-0.01, join_style="mitre").buffer(0.01, join_style="mitre")
    # only floor along the space's edge: a piece that touches it at a corner (the gap
    # where two walls meet without a join) leads outside, not to its walls
    edge = poly.boundary
    extra = shapely.union_all([g for g in getattr(extra, "geoms", [extra])
                               if not g.is_empty and g.intersection(edge).length > 0.05])
    if extra.is_empty or extra.area < 0.02:
        return poly, 0
    grown = shapely.make_valid(poly.union(extra.intersection(near)))
    parts = [g for g in getattr(grown, "geoms", [grown]) if isinstance(g, shapely.Polygon) and g.intersects(poly)]
    out = shapely.union_all(parts) if parts else poly
    return out, int(out.area > poly.area + 0.02)


def _vertical(seg: F64, z0: float, z1: float) -> F64:
    """The vertical rectangle over a segment from ``z0`` to ``z1``, ``(4, 3)``."""
    a, b = seg[0], seg[-1]
    return np.array([[a[0], a[1], z0], [b[0], b[1], z0], [b[0], b[1], z1], [a[0], a[1], z1]], dtype=np.float64)


def room_layout(scene: InteriorScene, wall_pitch: float | None = None) -> RoomLayout:
    """Cells, portals and stairs of an interior (see the module docstring).

    ``wall_pitch`` (metres; ``--virtual-walls``) cuts every room part over twice its
    square into a grid of cells joined by ``wall`` portals (:meth:`_Builder.wall_grid`).

    Raises
    ------
    SourceError
        No room gives a cell.
    """
    b = _Builder(scene, wall_pitch)
    b.rooms()
    if not b.cells:
        raise SourceError(f"{scene.name}: no room gives a cell (all empty or overlapping)")
    b.openings()
    b.virtual()
    b.touching()
    b.over_low_walls()
    b.open_walls()
    b.floors()
    b.outside()
    return RoomLayout(b.cells, b.portals, b.stairs, b.ranges, b.notes, b.sources)
