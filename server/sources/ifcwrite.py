"""IFC4 (or IFC2X3) models written with ifcopenshell's API: a builder and the generated interiors.

:class:`IfcBuilder` writes a model step by step, as an exporter does: a project, a site,
a building, storeys (``IfcBuildingStorey``), spaces (``IfcSpace``, an extruded footprint
each), walls with ``IfcOpeningElement`` voids filled by an ``IfcDoor`` / ``IfcWindow``,
slabs with holes, stairs (``IfcStair`` made of ``IfcStairFlight`` and landing
``IfcSlab`` parts), railings and furnishing elements.  Every product is placed at the
builder's ``offset`` (CRS metres, so a building may lie millions of metres from the
origin) and its geometry is given in metres relative to it, as extruded solids.

:func:`write_interior_ifc` writes a ``walkstream-interior`` document (a generated
office or hall, :mod:`.interiorgen`, :mod:`.hallgen`) as such a model, element by
element with the shapes :mod:`.interiorfile` gives them, so the same building can be
baked from its JSON and from its IFC and the two compared; space boundaries (doors and
windows to the spaces they open into) on request, as some exporters write them.

ifcopenshell is the optional ``ifc`` extra: without it a one-line error says so.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any, cast

import numpy as np
import shapely
from numpy.typing import ArrayLike

from walkstream.server.sources.interiormesh import (
    door_boxes,
    furniture_boxes,
    switchback_boxes,
    window_boxes,
)
from walkstream.shared.errors import InputError

__all__ = ["IFC_WRITE_SCHEMAS", "IfcBuilder", "write_interior_ifc"]

IFC_WRITE_SCHEMAS = ("IFC4", "IFC2X3")
"""Schemas :class:`IfcBuilder` writes."""


def _set_type(e: Any, value: str) -> None:
    """Set a product's predefined type where its schema has one (IFC2X3's stair has a
    ``ShapeType`` instead, its flight none)."""
    info = e.get_info(recursive=False)
    if "PredefinedType" in info:
        e.PredefinedType = value
    elif "ShapeType" in info:
        e.ShapeType = value


def _owner_history_settings() -> None:
    """IFC2X3 makes an owner history mandatory: tell ifcopenshell's API who writes (the
    way its ``owner.create_owner_history`` documentation asks), once per file."""
    import ifcopenshell.api.owner.settings as owner

    def user(f: Any) -> Any:
        found = f.by_type("IfcPersonAndOrganization")
        if found:
            return found[0]
        org = f.create_entity("IfcOrganization", Name="walkstream")
        return f.create_entity("IfcPersonAndOrganization", ThePerson=f.create_entity("IfcPerson", FamilyName="walkstream"),
                               TheOrganization=org)

    def application(f: Any) -> Any:
        found = f.by_type("IfcApplication")
        if found:
            return found[0]
        org = user(f).TheOrganization
        return f.create_entity("IfcApplication", ApplicationDeveloper=org, Version="1",
                               ApplicationFullName="walkstream", ApplicationIdentifier="walkstream")

    setattr(owner, "get_user", user)  # noqa: B010 (the documented hooks, typed narrower)
    setattr(owner, "get_application", application)  # noqa: B010


def _xy(ring: ArrayLike) -> list[tuple[float, float]]:
    """A ring's points as plain ``(x, y)`` floats (what the shape builder takes)."""
    return [(float(x), float(y)) for x, y in np.asarray(ring, dtype=np.float64).reshape(-1, 2)]


def _need_ifcopenshell() -> None:
    try:
        import ifcopenshell  # noqa: F401
        import ifcopenshell.api  # noqa: F401
    except ImportError as exc:  # optional dependency: fail only when used
        raise InputError("writing IFC needs ifcopenshell: pip install 'walkstream[ifc]'") from exc


class IfcBuilder:
    """Builds an IFC4 (or IFC2X3) model step by step (see the module docstring)."""

    def __init__(self, offset: tuple[float, float] = (0.0, 0.0), name: str = "test", schema: str = "IFC4") -> None:
        if schema not in IFC_WRITE_SCHEMAS:
            raise InputError(f"IFC schema {schema!r}: choose one of {', '.join(IFC_WRITE_SCHEMAS)}")
        _need_ifcopenshell()
        import ifcopenshell
        import ifcopenshell.api.aggregate
        import ifcopenshell.api.context
        import ifcopenshell.api.root
        import ifcopenshell.api.unit
        import ifcopenshell.util.shape_builder

        self.api = ifcopenshell.api
        self.f = ifcopenshell.file(schema=cast(Any, schema))
        if schema == "IFC2X3":  # every rooted entity needs an owner history there
            _owner_history_settings()
        self.offset = np.array([offset[0], offset[1], 0.0])
        project = ifcopenshell.api.root.create_entity(self.f, ifc_class="IfcProject", name=name)
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
        """A product of class ``cls`` placed at the offset (raised by ``z``), no body yet."""
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

    def _prism(self, ring: ArrayLike, z0: float, height: float) -> Any:
        pts = _xy(ring)
        curve = self.shape.polyline(pts, closed=True)
        return self.shape.extrude(self.shape.profile(curve), height, position=(0.0, 0.0, z0))

    def storey(self, name: str, z: float) -> Any:
        """A building storey at elevation ``z`` (its placement and ``Elevation``)."""
        import ifcopenshell.api.aggregate

        s = self._product("IfcBuildingStorey", name, z)
        s.Elevation = z
        ifcopenshell.api.aggregate.assign_object(self.f, products=[s], relating_object=self.building)
        self.storeys.append(s)
        return s

    def _contain(self, product: Any, storey: Any) -> None:
        import ifcopenshell.api.spatial

        ifcopenshell.api.spatial.assign_container(self.f, products=[product], relating_structure=storey)

    def space(self, name: str, storey: Any, ring: ArrayLike, z0: float, height: float,
              long_name: str | None = None) -> Any:
        """A space (a room): its footprint ``ring`` extruded from ``z0``, part of ``storey``."""
        import ifcopenshell.api.aggregate

        s = self._product("IfcSpace", name)
        if long_name is not None:
            s.LongName = long_name
        self._body(s, [self._prism(ring, z0, height)])
        ifcopenshell.api.aggregate.assign_object(self.f, products=[s], relating_object=storey)
        return s

    def wall(self, storey: Any, a: ArrayLike, b: ArrayLike, thickness: float, z0: float, height: float,
             name: str = "wall") -> Any:
        """A straight wall along its centre line ``a`` -> ``b``, ``thickness`` thick."""
        pa, pb = np.asarray(a, float), np.asarray(b, float)
        u = (pb - pa) / np.linalg.norm(pb - pa)
        n = np.array([-u[1], u[0]]) * 0.5 * thickness
        ring = [pa - n, pb - n, pb + n, pa + n]
        w = self._product("IfcWall", name)
        self._body(w, [self._prism(ring, z0, height)])
        self._contain(w, storey)
        return w

    def opening(
        self, storey: Any, wall: Any, centre: ArrayLike, along: ArrayLike, width: float,
        depth: float, z0: float, z1: float, fill: str | None = "door", name: str | None = None,
        body: Sequence[Any] | None = None,
    ) -> Any:
        """A box-shaped opening through ``wall`` (filled by a door or window, or empty).

        The filling's body is a thin panel closing the opening unless ``body`` (box rows,
        :func:`box_items`) gives its parts; ``name`` names the filling."""
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
        el = self._product(cls, name or fill)
        if body is None:
            thin = np.array([-u[1], u[0]]) * 0.02
            self._body(el, [self._prism([c - w - thin, c + w - thin, c + w + thin, c - w + thin], z0, z1 - z0)])
        else:
            self._body(el, body)
        self._contain(el, storey)
        ifcopenshell.api.feature.add_filling(self.f, opening=op, element=el)
        return el

    def slab(self, storey: Any, ring: ArrayLike, top: float, thickness: float = 0.2,
             holes: Sequence[ArrayLike] = (), name: str = "slab") -> Any:
        """A floor slab (a polygon with ``holes``) whose top lies at ``top``."""
        s = self._product("IfcSlab", name)
        outer = self.shape.polyline(_xy(ring), closed=True)
        inner = [self.shape.polyline(_xy(h), closed=True) for h in holes]
        prof = self.shape.profile(outer, inner_curves=inner)
        self._body(s, [self.shape.extrude(prof, thickness, position=(0.0, 0.0, top - thickness))])
        self._contain(s, storey)
        return s

    def furniture(self, storey: Any, ring: ArrayLike, z0: float, height: float, name: str = "table") -> Any:
        """A furnishing element: one block, ``ring`` extruded from ``z0``."""
        e = self._product("IfcFurnishingElement", name)
        self._body(e, [self._prism(ring, z0, height)])
        self._contain(e, storey)
        return e

    def stair(self, storey: Any, start: ArrayLike, end: ArrayLike, width: float, z0: float,
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

    def flights(self, storey: Any, flights: Sequence[tuple[ArrayLike, ArrayLike, float, float, int]],
                landings: Sequence[tuple[ArrayLike, float]], width: float) -> Any:
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

    def element(self, cls: str, name: str, storey: Any, rows: Any, *, within: Any = None,
                predefined: str | None = None) -> Any:
        """A product of class ``cls`` whose body is the boxes ``rows`` (``(k, 7)``:
        ``cx, cy, length, depth, yaw, z0, z1``, see :mod:`.interiormesh`), contained in
        ``storey``, or part of ``within`` (a stair's flight or landing) when given."""
        import ifcopenshell.api.aggregate

        e = self._product(cls, name)
        if predefined is not None:
            _set_type(e, predefined)
        self._body(e, self.box_items(rows))
        if within is None:
            self._contain(e, storey)
        else:
            ifcopenshell.api.aggregate.assign_object(self.f, products=[e], relating_object=within)
        return e

    def boundary(self, space: Any, element: Any, internal: bool = True) -> Any:
        """A physical space boundary: ``element`` (a door, a wall) bounds ``space``; no
        connection geometry (optional in IFC4): it says which spaces, not where."""
        import ifcopenshell.guid

        return self.f.create_entity(
            "IfcRelSpaceBoundary", GlobalId=ifcopenshell.guid.new(), RelatingSpace=space,
            RelatedBuildingElement=element, PhysicalOrVirtualBoundary="PHYSICAL",
            InternalOrExternalBoundary="INTERNAL" if internal else "EXTERNAL",
        )

    def assembly(self, cls: str, name: str, storey: Any, predefined: str | None = None) -> Any:
        """A product with no body of its own (a stair), contained in ``storey``; its parts
        are :meth:`element` calls with ``within`` set to it."""
        e = self._product(cls, name)
        if predefined is not None:
            _set_type(e, predefined)
        self._contain(e, storey)
        return e

    def box_items(self, rows: Any) -> list[Any]:
        """Extruded solids of box rows (``cx, cy, length, depth, yaw, z0, z1``); empty boxes dropped."""
        b = np.asarray(rows, dtype=np.float64).reshape(-1, 7)
        b = b[(b[:, 2] > 1e-6) & (b[:, 3] > 1e-6) & (b[:, 6] - b[:, 5] > 1e-6)]
        items = []
        for cx, cy, length, depth, yaw, z0, z1 in b:
            u = np.array([math.cos(yaw), math.sin(yaw)]) * 0.5 * length
            v = np.array([-math.sin(yaw), math.cos(yaw)]) * 0.5 * depth
            c = np.array([cx, cy])
            items.append(self._prism([c - u - v, c + u - v, c + u + v, c - u + v], z0, z1 - z0))
        return items

    def fix_ids(self, key: str) -> None:
        """Make the file depend on its content only: every ``GlobalId`` derived from
        ``key`` and the entity's rank, relationships' members in creation order (the API
        keeps them in sets) and a fixed time stamp (same model, same bytes)."""
        import uuid

        import ifcopenshell.guid

        for rel in self.f.by_type("IfcRelationship"):
            for attr in ("RelatedObjects", "RelatedElements"):
                members = getattr(rel, attr, None) if hasattr(rel, attr) else None
                if members:
                    setattr(rel, attr, sorted(members, key=lambda x: x.id()))
        for units in self.f.by_type("IfcUnitAssignment"):
            units.Units = sorted(units.Units, key=lambda x: x.id())

        for i, e in enumerate(sorted(self.f.by_type("IfcRoot"), key=lambda x: x.id())):
            e.GlobalId = ifcopenshell.guid.compress(uuid.uuid5(uuid.NAMESPACE_URL, f"walkstream:{key}:{i}").hex)
        for history in self.f.by_type("IfcOwnerHistory"):  # IFC2X3's: creation dates
            history.CreationDate = 946684800
            if history.LastModifiedDate is not None:
                history.LastModifiedDate = 946684800
        self.f.header.file_name.time_stamp = "2000-01-01T00:00:00"

    def write(self, path: str | os.PathLike[str]) -> Path:
        """Write the model as an IFC-SPF file."""
        dest = Path(path)
        try:
            # written here, not by ifcopenshell's write(): that one makes missing folders
            dest.write_text(self.f.to_string(), encoding="utf-8")
        except OSError as exc:
            raise InputError(f"{dest}: cannot write ({exc.strerror or exc})") from exc
        return dest


def write_interior_ifc(path: str | os.PathLike[str], doc: dict[str, Any], boundaries: bool = False,
                       schema: str = "IFC4") -> Path:
    """Write a ``walkstream-interior`` document as an IFC4 (or IFC2X3) file; return its path.

    What each element becomes: a room an ``IfcSpace`` (its outline extruded from its
    storey's floor to the underside of the slab above, ``Name`` its id, ``LongName``
    its name); a wall an ``IfcWall`` (one extruded box along its centre line) with an
    ``IfcOpeningElement`` per opening (2 cm deeper than the wall, so the cut is clean),
    filled by an ``IfcDoor`` (its frame and the leaf drawn open) or an ``IfcWindow``
    (frame and pane); a slab an ``IfcSlab`` (the roof one of type ``ROOF`` on the top
    storey); a switchback stair an ``IfcStair`` of two ``IfcStairFlight`` and a
    ``LANDING`` slab, with an ``IfcRailing`` beside each flight; furniture an
    ``IfcFurnishingElement`` of boxes.  Without ``boundaries`` the file carries no
    space boundaries: a reader finds which rooms a door joins from the geometry; with
    them, each door and window has a physical ``IfcRelSpaceBoundary`` to each space it
    opens into (10 cm past the wall's faces), as exporters that write boundaries do.
    Same document, same bytes (:meth:`IfcBuilder.fix_ids`).

    Raises
    ------
    InputError
        ifcopenshell is missing, the document is bad (named as the interior reader
        names it), or the file cannot be written.
    """
    from walkstream.server.sources.interiorfile import load_interior_dict
    from walkstream.shared.errors import SourceError

    try:
        load_interior_dict(doc, label="interior")  # the reader's checks, one line each
    except SourceError as exc:
        raise InputError(str(exc)) from exc
    slab = float(doc.get("slab", 0.25))
    elev = [float(s["elevation"]) for s in doc["storeys"]]
    height = [float(s["height"]) for s in doc["storeys"]]
    pts = np.array([q for r in doc["rooms"] for q in r["outline"]], dtype=np.float64)
    off = np.floor(pts.min(axis=0))
    b = IfcBuilder((float(off[0]), float(off[1])), name=str(doc.get("name", "interior")), schema=schema)
    storeys = [b.storey(str(s.get("name", k)), e) for k, (s, e) in enumerate(zip(doc["storeys"], elev, strict=True))]

    def floor(k: int) -> float:
        return elev[k] if k < len(elev) else elev[-1] + height[-1]

    def local(p: Any) -> np.ndarray:
        return np.asarray(p, dtype=np.float64)[:2] - off

    def ring(r: Any) -> list[np.ndarray]:
        return [local(q) for q in r]

    spaces: list[tuple[int, shapely.Polygon, Any]] = []
    for r in doc["rooms"]:
        k = int(r["storey"])
        sp = b.space(str(r["id"]), storeys[k], ring(r["outline"]), floor(k), height[k] - slab,
                     str(r.get("name", r["id"])))
        spaces.append((k, shapely.Polygon(ring(r["outline"])), sp))
    centre = 0.5 * (pts.min(axis=0) + pts.max(axis=0)) - off
    for w in doc["walls"]:
        k = int(w["storey"])
        a, e, t = local(w["from"]), local(w["to"]), float(w["thickness"])
        z0, z1 = floor(k), floor(k) + height[k] - slab
        wall = b.wall(storeys[k], a, e, t, z0, z1 - z0, str(w["id"]))
        ux = (e - a) / float(np.hypot(*(e - a)))
        nrm = np.array([-ux[1], ux[0]])
        for o in w.get("openings", []):
            c = a + ux * float(o["offset"])
            wid, sill, head = float(o["width"]), float(o.get("sill", 0.0)), float(o["head"])
            kind = str(o["kind"])
            body = None
            if kind == "door":
                swing = 1.0 if o.get("swing", 1) >= 0 else -1.0
                body = b.box_items(np.concatenate(door_boxes(c, nrm * swing, wid, t, z0 + sill, z0 + head)))
            elif kind == "window":
                side = 1.0 if float(np.dot(centre - c, nrm)) >= 0 else -1.0
                body = b.box_items(np.concatenate(window_boxes(c, nrm * side, wid, t, z0 + sill, z0 + head)))
            fill = b.opening(storeys[k], wall, c, ux, wid, t + 0.02, z0 + sill, z0 + head,
                             kind if kind in ("door", "window") else None, str(o.get("id", kind)), body)
            if boundaries and kind in ("door", "window"):
                sides = [shapely.Point(c + nrm * sgn * (0.5 * t + 0.1)) for sgn in (1.0, -1.0)]
                found = [sp for ks, poly, sp in spaces if ks == k and any(poly.contains(q) for q in sides)]
                for sp in found:
                    b.boundary(sp, fill, internal=len(found) == 2)
    for s in doc["slabs"]:
        k = int(s["storey"])
        roof = k >= len(storeys)
        el = b.slab(storeys[min(k, len(storeys) - 1)], ring(s["outline"]), floor(k), slab,
                    [ring(h) for h in s.get("holes", [])], str(s["id"]))
        _set_type(el, "ROOF" if roof else "FLOOR")
    for st in doc["stairs"]:
        _stair(b, storeys[int(st["storey"])], st, off, floor(int(st["storey"])),
               floor(int(st["storey"]) + 1) - floor(int(st["storey"])))
    for f in doc["furniture"]:
        k = int(f["storey"])
        rows = furniture_boxes(str(f["kind"]), local(f["at"]), float(f.get("yaw", 0.0)), floor(k))
        b.element("IfcFurnishingElement", f"{f['kind']} {f['id']}", storeys[k], rows)
    b.fix_ids(str(doc.get("name", "interior")))
    return b.write(path)


def _stair(b: IfcBuilder, storey: Any, st: dict[str, Any], off: np.ndarray, z0: float, rise: float) -> None:
    """A switchback stair (the interior format's, :mod:`.interiorfile`): two half-flights
    and the half landing as parts of one ``IfcStair``, a balustrade beside each flight."""
    x1, x2 = (float(v) - off[0] for v in st["x"])
    y0, y1 = (float(v) - off[1] for v in st["y"])
    width = float(st.get("width", 1.1))
    flight_a, _, flight_b, _, landing, _ = switchback_boxes((x1, x2), (y0, y1), width, z0, rise)
    key = str(st["id"])
    stair = b.assembly("IfcStair", f"stair {key}", storey, "HALF_TURN_STAIR")
    # the last row of each flight is its balustrade: a railing of its own, beside the stair
    b.element("IfcStairFlight", f"{key} flight 1", storey, flight_a[:-1], within=stair, predefined="STRAIGHT")
    b.element("IfcSlab", f"{key} landing", storey, landing, within=stair, predefined="LANDING")
    b.element("IfcStairFlight", f"{key} flight 2", storey, flight_b[:-1], within=stair, predefined="STRAIGHT")
    for n, rail in enumerate((flight_a[-1:], flight_b[-1:])):
        b.element("IfcRailing", f"{key} balustrade {n + 1}", storey, rail, predefined="BALUSTRADE")
