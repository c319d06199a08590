"""IFC models (IFC2X3, IFC4) as interiors, read with ifcopenshell (an optional extra).

What is read, and how (:func:`load_ifc`):

* **Storeys** (``IfcBuildingStorey``): by elevation (their placement, else the
  ``Elevation`` attribute).
* **Rooms** (``IfcSpace``): the footprint is the union of the space solid's triangles
  seen from above (one outer ring; small notches of a few centimetres smoothed
  away), the height range that of the solid.  A space belongs to the storey that
  contains it, even when its solid reaches higher (a stair space): the bake cuts
  cells by storey height.
* **Openings** (the candidate portals): every ``IfcOpeningElement`` through a wall,
  filled by an ``IfcDoor`` / ``IfcWindow`` or empty, as a box (the minimum rotated
  rectangle of its footprint: width along the wall, depth across it, sill to head);
  a door or window that fills no opening element gives its own box.  Openings
  through slabs and roofs are not portals here: the bake finds holes in the floors
  from the slabs' own geometry.  The rooms an opening bounds are taken from the
  space boundaries (``IfcRelSpaceBoundary`` naming the door or window) when the
  file has them; first-level boundaries name only their own space, so a door's
  two rooms are the spaces of the boundaries naming it; a door bounding three
  spaces, or one with no boundary, is left for the bake to settle from the
  geometry (an opening whose two sides lie in two spaces).
* **Virtual boundaries** (``PhysicalOrVirtualBoundary = VIRTUAL``): they name no
  element, so two of them are paired when their polygons lie in one plane (within
  3 cm) and overlap; the overlap becomes an open portal.
* **Stairs** (``IfcStair``, ``IfcStairFlight``, ``IfcRamp``): the walking line is the
  sequence of tread centroids, one per tread height, bottom to top (a spiral stair
  gives a spiral).
* **Elements**: every other product with a body is tessellated (``ifcopenshell.geom``,
  several threads, world coordinates) and kept with its kind and a material per
  triangle.  Space solids and opening elements are not drawn, and neither are
  doors: a door exported closed would hide everything behind it and its leaf cannot
  be told from its frame, so the whole ``IfcDoor`` is left out (doorways are open
  holes, for the client and for any ground truth alike).

Coordinates: ``ifcopenshell`` gives world coordinates in metres (float64); everything
is moved to a scene-local origin (the centre of the spaces' box, rounded to a metre;
heights kept unless they are more than a kilometre from 0).  With an
``IfcMapConversion`` without rotation the origin is given in its target CRS.

Errors are one line naming the file: no ifcopenshell, not readable, not IFC,
truncated or corrupt, an unsupported schema, no spaces.
"""

from __future__ import annotations

import math
import os
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
import shapely
from numpy.typing import NDArray

from walkstream.server.sources.interior import (
    Element,
    InteriorScene,
    Opening,
    Room,
    Stair,
    Storey,
    mesh_footprint,
)
from walkstream.server.sources.scene import FeatureIssue
from walkstream.shared.arrays import F64
from walkstream.shared.errors import SourceError
from walkstream.shared.palette import MATERIALS

__all__ = ["IFC_SCHEMAS", "load_ifc", "NO_SPACES_HINT"]

IFC_SCHEMAS = ("IFC2X3", "IFC4", "IFC4X3")
"""Schemas this reader accepts (as ifcopenshell names them, prefix match)."""

NO_SPACES_HINT = (
    "walkstream makes its cells from rooms: add spaces (IfcSpace, 'rooms' or 'spaces' in the "
    "authoring tool) and export them to IFC, or describe the building as a walkstream-interior "
    "file (walkstream generate interior shows the format)"
)
"""What the one-line error for a file without spaces suggests."""

_MAT = {name: mid for mid, name, _ in MATERIALS}
# IFC class -> (element kind, material); the first matching class wins (subclasses first)
_KINDS: tuple[tuple[str, str, str], ...] = (
    ("IfcWall", "wall", "inner_wall"),
    ("IfcCurtainWall", "wall", "glass"),
    ("IfcSlab", "slab", "slab"),
    ("IfcRoof", "roof", "roof"),
    ("IfcWindow", "window", "frame"),
    ("IfcStairFlight", "stair", "stair"),
    ("IfcStair", "stair", "stair"),
    ("IfcRampFlight", "stair", "stair"),
    ("IfcRamp", "stair", "stair"),
    ("IfcRailing", "railing", "metal"),
    ("IfcFurnishingElement", "furniture", "furniture"),
    ("IfcCovering", "covering", "fixture"),
    ("IfcBeam", "beam", "metal"),
    ("IfcMember", "beam", "metal"),
    ("IfcPlate", "beam", "metal"),
    ("IfcColumn", "column", "slab"),
    ("IfcFooting", "slab", "slab"),
)
_NOT_DRAWN = ("IfcSpace", "IfcOpeningElement", "IfcDoor", "IfcVirtualElement", "IfcAnnotation", "IfcGrid")
_STAIR_CLASSES = ("IfcStair", "IfcRamp")
# hosts whose openings are wall openings (candidate portals)
_SLAB_HOSTS = ("IfcSlab", "IfcRoof", "IfcCovering", "IfcFooting")


def _ifcopenshell() -> Any:
    try:
        import ifcopenshell
        import ifcopenshell.geom  # noqa: F401
    except ImportError as exc:  # optional dependency: fail only when used
        raise SourceError(
            "reading IFC needs ifcopenshell: pip install 'walkstream[ifc]' "
            "(make demo / make test install it)"
        ) from exc
    return ifcopenshell


def _open(path: Path) -> Any:
    ios = _ifcopenshell()
    label = str(path)
    if not path.exists():
        raise SourceError(f"{label}: no such file")
    try:
        with open(path, "rb") as fh:
            head = fh.read(64)
    except OSError as exc:
        raise SourceError(f"{label}: cannot read ({exc.strerror or exc})") from exc
    if not head.lstrip().startswith(b"ISO-10303-21"):
        raise SourceError(f"{label}: not an IFC file (a STEP file starts with 'ISO-10303-21;')")
    try:
        model = ios.open(str(path))
    except Exception as exc:  # ifcopenshell raises bare errors for damaged files
        detail = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise SourceError(f"{label}: damaged or truncated IFC file ({detail[:160]})") from exc
    schema = str(model.schema)
    if not schema.upper().startswith(IFC_SCHEMAS):
        raise SourceError(f"{label}: IFC schema {schema} is not read here (only {', '.join(IFC_SCHEMAS)})")
    try:
        tail = path.read_bytes()[-64:].rstrip()
    except OSError:
        tail = b""
    if not tail.endswith(b"END-ISO-10303-21;"):
        raise SourceError(f"{label}: truncated IFC file (it does not end with 'END-ISO-10303-21;')")
    return model


def _placement(product: Any, scale: float) -> NDArray[np.float64]:
    import ifcopenshell.util.placement as up

    if getattr(product, "ObjectPlacement", None) is None:
        return np.eye(4)
    m = np.array(up.get_local_placement(product.ObjectPlacement), dtype=np.float64)
    m[:3, 3] *= scale
    return m


def _storey_of(product: Any) -> Any:
    """The IfcBuildingStorey that contains or aggregates ``product`` (walking up), or None."""
    seen = 0
    p = product
    while p is not None and seen < 16:
        seen += 1
        if p.is_a("IfcBuildingStorey"):
            return p
        nxt = None
        for rel in getattr(p, "ContainedInStructure", None) or ():
            nxt = rel.RelatingStructure
        if nxt is None:
            for rel in getattr(p, "Decomposes", None) or ():
                nxt = rel.RelatingObject
        if nxt is None and p.is_a("IfcOpeningElement"):
            for rel in getattr(p, "VoidsElements", None) or ():
                nxt = rel.RelatingBuildingElement
        if nxt is None and p.is_a("IfcElement"):
            for rel in getattr(p, "FillsVoids", None) or ():
                nxt = rel.RelatingOpeningElement
        p = nxt
    return None


def _shapes(ios: Any, model: Any, products: list[Any], threads: int) -> dict[int, tuple[F64, NDArray[np.int64], list[float], NDArray[np.int64]]]:
    """Tessellate ``products``: id -> (vertices, triangles, material transparencies, material ids)."""
    import ifcopenshell.geom as geom

    if not products:
        return {}
    settings = geom.settings()
    settings.set("use-world-coords", True)
    out: dict[int, tuple[F64, NDArray[np.int64], list[float], NDArray[np.int64]]] = {}
    it = geom.iterator(settings, model, max(1, threads), include=products)
    try:
        ok = it.initialize()
    except Exception as exc:
        raise SourceError(f"tessellation failed ({str(exc)[:160]})") from exc
    if not ok:
        return out
    while True:
        sh = it.get()
        g = sh.geometry
        v = np.asarray(g.verts, dtype=np.float64).reshape(-1, 3)
        t = np.asarray(g.faces, dtype=np.int64).reshape(-1, 3)
        mids = np.asarray(g.material_ids, dtype=np.int64).reshape(-1)
        trans = [float(getattr(m, "transparency", 0.0) or 0.0) for m in g.materials]
        if len(t) and len(v):
            out[int(sh.id)] = (v, t, trans, mids if len(mids) == len(t) else np.full(len(t), -1))
        if not it.next():
            break
    return out


def _kind(product: Any) -> tuple[str, str]:
    for cls, kind, mat in _KINDS:
        if product.is_a(cls):
            if kind == "slab" and getattr(product, "PredefinedType", None) == "ROOF":
                return "roof", "roof"
            return kind, mat
    return "other", "fixture"


def _materials(kind: str, base: str, v: F64, t: NDArray[np.int64], trans: list[float], mids: NDArray[np.int64]) -> NDArray[np.uint8]:
    m = np.full(len(t), _MAT[base], np.uint8)
    if kind in ("slab", "covering"):
        a, b, c = v[t[:, 0]], v[t[:, 1]], v[t[:, 2]]
        n = np.cross(b - a, c - a)
        nz = n[:, 2] / np.maximum(np.linalg.norm(n, axis=1), 1e-12)
        m[nz > 0.5] = _MAT["floor"] if kind == "slab" else _MAT["fixture"]
        m[nz < -0.5] = _MAT["ceiling"]
    if kind in ("window", "wall") and trans:
        glass = np.array([tr > 0.1 for tr in trans] + [False])
        m[glass[np.where(mids >= 0, mids, len(trans))]] = _MAT["glass"]
    return m


def _outline(v: F64, t: NDArray[np.int64]) -> F64 | None:
    """The outer ring of a space solid's footprint, 1 cm notches smoothed, or None."""
    fp = mesh_footprint(v, t)
    if fp.is_empty:
        return None
    geoms = getattr(fp, "geoms", [fp])
    polys = [g for g in geoms if isinstance(g, shapely.Polygon) and g.area > 0.05]
    if not polys:
        return None
    poly = max(polys, key=lambda g: g.area)
    poly = shapely.Polygon(poly.exterior).buffer(0.005, join_style="mitre").buffer(-0.005, join_style="mitre")
    poly = poly.simplify(0.01)
    if not isinstance(poly, shapely.Polygon) or poly.area < 0.05:
        return None
    return np.asarray(poly.exterior.coords, dtype=np.float64)[:-1, :2]


def _opening_box(v: F64, key: str, kind: str, storey: int, rooms: tuple[str, ...], source: str) -> Opening | None:
    """An opening box from a mesh: width along the wall, depth across it."""
    hull = shapely.MultiPoint(v[:, :2]).convex_hull
    if not isinstance(hull, shapely.Polygon) or hull.area < 1e-4:
        return None
    rr = np.asarray(shapely.minimum_rotated_rectangle(hull).exterior.coords)[:4]
    e1, e2 = rr[1] - rr[0], rr[2] - rr[1]
    l1, l2 = float(np.hypot(*e1)), float(np.hypot(*e2))
    along, width, depth = (e1 / l1, l1, l2) if l1 >= l2 else (e2 / l2, l2, l1)
    centre = rr.mean(axis=0)
    z0, z1 = float(v[:, 2].min()), float(v[:, 2].max())
    if width < 0.2 or z1 - z0 < 0.2:
        return None
    normal = np.array([along[1], -along[0]])
    return Opening(key, kind, key, storey, np.array([centre[0], centre[1], 0.5 * (z0 + z1)]), normal,
                   width, depth, z0, z1, rooms=rooms, source=source)


def _boundary_polygon(ios: Any, b: Any, scale: float) -> F64 | None:
    """The 3D polygon of a space boundary's connection surface, world metres, or None."""
    import ifcopenshell.geom as geom
    import ifcopenshell.util.placement as up

    cg = b.ConnectionGeometry
    surf = getattr(cg, "SurfaceOnRelatingElement", None) if cg is not None else None
    if surf is None or b.RelatingSpace is None:
        return None
    m = _placement(b.RelatingSpace, scale)
    pts: F64 | None = None
    if surf.is_a("IfcSurfaceOfLinearExtrusion"):
        curve = getattr(surf.SweptCurve, "Curve", None)
        if curve is None or not curve.is_a("IfcPolyline"):
            return None
        p2 = np.array([list(q.Coordinates)[:2] for q in curve.Points], dtype=np.float64) * scale
        pos = np.array(up.get_axis2placement(surf.Position), dtype=np.float64)
        pos[:3, 3] *= scale
        d = np.array(list(surf.ExtrudedDirection.DirectionRatios), dtype=np.float64)
        d = d / max(float(np.linalg.norm(d)), 1e-12) * float(surf.Depth) * scale
        base = np.column_stack([p2, np.zeros(len(p2))])
        top = base + d
        local = np.concatenate([base, top[::-1]])
        pts = local @ pos[:3, :3].T + pos[:3, 3]
    else:
        try:
            settings = geom.settings()
            tri = geom.create_shape(settings, surf)
            v = np.asarray(getattr(tri, "verts"), dtype=np.float64).reshape(-1, 3)  # noqa: B009
        except Exception:
            return None
        if len(v) < 3:
            return None
        pts = v
    w = pts @ m[:3, :3].T + m[:3, 3]
    return _planar_hull(w)


def _plane_basis(pts: F64) -> tuple[F64, F64, F64, F64] | None:
    c = pts.mean(axis=0)
    _, s, vt = np.linalg.svd(pts - c)
    if s[1] < 1e-6:
        return None
    return c, vt[0], vt[1], vt[2]


def _planar_hull(pts: F64) -> F64 | None:
    """Points of a planar surface -> the convex hull polygon in 3D, ordered."""
    basis = _plane_basis(pts)
    if basis is None:
        return None
    c, u, w, _ = basis
    uv = np.column_stack([(pts - c) @ u, (pts - c) @ w])
    hull = shapely.MultiPoint(uv).convex_hull
    if not isinstance(hull, shapely.Polygon) or hull.area < 1e-4:
        return None
    ring = np.asarray(hull.exterior.coords)[:-1]
    return c + ring[:, :1] * u + ring[:, 1:2] * w


def _pair_virtual(polys: list[tuple[str, F64]]) -> list[tuple[str, str, F64]]:
    """Pairs of virtual boundaries of two spaces lying in one plane and overlapping."""
    out = []
    infos = []
    for key, p in polys:
        basis = _plane_basis(p)
        if basis is not None:
            infos.append((key, p, basis))
    for i in range(len(infos)):
        ki, pi, (ci, ui, wi, ni) = infos[i]
        for j in range(i + 1, len(infos)):
            kj, pj, (cj, _uj, _wj, nj) = infos[j]
            if kj == ki or abs(float(np.dot(ni, nj))) < math.cos(math.radians(5)):
                continue
            if abs(float(np.dot(cj - ci, ni))) > 0.03:
                continue
            a = shapely.Polygon(np.column_stack([(pi - ci) @ ui, (pi - ci) @ wi]))
            b = shapely.Polygon(np.column_stack([(pj - ci) @ ui, (pj - ci) @ wi]))
            if not (a.is_valid and b.is_valid):
                continue
            ov = a.intersection(b)
            if not isinstance(ov, shapely.Polygon) or ov.area < 0.05:
                continue
            ring = np.asarray(ov.exterior.coords)[:-1]
            out.append((ki, kj, ci + ring[:, :1] * ui + ring[:, 1:2] * wi))
    return out


def _tread_line(v: F64, t: NDArray[np.int64]) -> F64 | None:
    """Walking line of a stair: the centroid of the up-facing faces at each height."""
    a, b, c = v[t[:, 0]], v[t[:, 1]], v[t[:, 2]]
    n = np.cross(b - a, c - a)
    area = 0.5 * np.linalg.norm(n, axis=1)
    up = (n[:, 2] > 0.9 * np.maximum(2 * area, 1e-12)) & (area > 1e-4)
    if up.sum() < 2:
        return None
    cen = (a + b + c)[up] / 3.0
    w = area[up]
    level = np.round(cen[:, 2] / 0.02).astype(np.int64)
    pts = []
    for lv in np.unique(level):
        sel = level == lv
        if w[sel].sum() < 0.02:  # a sliver (a stringer's top), not a tread
            continue
        xy = (cen[sel, :2] * w[sel, None]).sum(axis=0) / w[sel].sum()
        pts.append([xy[0], xy[1], float(cen[sel, 2].max())])
    line = np.array(pts, dtype=np.float64)
    # a cap or newel post above the top tread is no tread: trim rises far above the usual
    while len(line) > 3:
        rise = np.diff(line[:, 2])
        med = float(np.median(rise))
        if rise[-1] > 2.5 * med:
            line = line[:-1]
        elif rise[0] > 2.5 * med:
            line = line[1:]
        else:
            break
    return line if len(line) >= 2 else None


def load_ifc(path: str | os.PathLike[str], *, threads: int | None = None) -> InteriorScene:
    """Read an IFC model as an interior (see the module docstring).

    Parameters
    ----------
    path:
        The ``.ifc`` file.
    threads:
        Tessellation threads (default: the CPU count, at most 8).

    Raises
    ------
    SourceError
        One line naming the file: ifcopenshell missing, not an IFC file, damaged or
        truncated, an unsupported schema, or no spaces (with what to do about it).
    """
    p = Path(path)
    label = str(p)
    ios = _ifcopenshell()
    import ifcopenshell.util.unit as uu

    model = _open(p)
    try:
        scale = float(uu.calculate_unit_scale(model))
    except Exception:
        scale = 1.0
    spaces = list(model.by_type("IfcSpace"))
    if not spaces:
        raise SourceError(f"{label}: no spaces (IfcSpace) in this IFC file; {NO_SPACES_HINT}")
    issues: list[FeatureIssue] = []
    notes: list[str] = []
    # ---- storeys, by elevation
    raw_storeys = []
    for s in model.by_type("IfcBuildingStorey"):
        z = float(_placement(s, scale)[2, 3])
        if getattr(s, "ObjectPlacement", None) is None and s.Elevation is not None:
            z = float(s.Elevation) * scale
        raw_storeys.append((z, s))
    raw_storeys.sort(key=lambda zs: zs[0])
    if not raw_storeys:
        notes.append("no IfcBuildingStorey: one storey at the lowest space")
    storey_index = {s.id(): k for k, (_, s) in enumerate(raw_storeys)}
    # ---- geometry, in one multi-threaded pass
    products = [e for e in model.by_type("IfcProduct") if getattr(e, "Representation", None) is not None
                and not e.is_a("IfcBuildingStorey") and not e.is_a("IfcBuilding") and not e.is_a("IfcAnnotation")
                and not e.is_a("IfcGrid")]
    nthreads = threads or min(8, os.cpu_count() or 1)
    try:
        shapes = _shapes(ios, model, products, nthreads)
    except SourceError as exc:
        raise SourceError(f"{label}: {exc}") from exc
    space_shapes = [(s, shapes.get(s.id())) for s in spaces]
    pts = [sh[0] for _, sh in space_shapes if sh is not None]
    if not pts:
        raise SourceError(f"{label}: its {len(spaces)} spaces have no geometry; {NO_SPACES_HINT}")
    allp = np.concatenate(pts)
    lo, hi = allp.min(axis=0), allp.max(axis=0)
    ox, oy = float(np.round(0.5 * (lo[0] + hi[0]))), float(np.round(0.5 * (lo[1] + hi[1])))
    oz = 0.0 if abs(float(lo[2])) < 1000 else float(np.round(lo[2]))
    off = np.array([ox, oy, oz])
    crs, origin = "local", (ox, oy, oz)
    conv = model.by_type("IfcMapConversion") if model.schema != "IFC2X3" else []
    if conv:
        mc = conv[0]
        a, b = float(mc.XAxisAbscissa or 1.0), float(mc.XAxisOrdinate or 0.0)
        if abs(b) < 1e-9 and a > 0 and abs(float(mc.Scale or 1.0) - 1.0) < 1e-9:
            target = getattr(mc, "TargetCRS", None)
            crs = str(getattr(target, "Name", None) or "local")
            origin = (float(mc.Eastings) * scale + ox, float(mc.Northings) * scale + oy,
                      float(mc.OrthogonalHeight or 0.0) * scale + oz)
        else:
            notes.append("IfcMapConversion with rotation or scale: kept in the model's own frame")
    if not raw_storeys:
        storeys: tuple[Storey, ...] = (Storey("storey", float(lo[2]) - oz),)
    else:
        storeys = tuple(Storey(str(s.Name or s.GlobalId), z - oz) for z, s in raw_storeys)

    def storey_at(zmin: float) -> int:
        elev = [s.elevation for s in storeys]
        return max(0, int(np.searchsorted(elev, zmin + 0.1, side="right")) - 1)

    def storey_for(product: Any, zmin: float) -> int:
        st = _storey_of(product)
        if st is not None and st.id() in storey_index:
            return storey_index[st.id()]
        return storey_at(zmin)

    # ---- rooms
    rooms: list[Room] = []
    room_key: dict[int, str] = {}
    for s, sh in space_shapes:
        name = " ".join(str(x) for x in (s.Name, s.LongName) if x) or s.GlobalId
        if sh is None:
            issues.append(FeatureIssue(f"IfcSpace #{s.id()} {name}", "no geometry", "skipped"))
            continue
        v = sh[0] - off
        ring = _outline(v, sh[1])
        if ring is None:
            issues.append(FeatureIssue(f"IfcSpace #{s.id()} {name}", "no footprint", "skipped"))
            continue
        zmin, zmax = float(v[:, 2].min()), float(v[:, 2].max())
        room_key[s.id()] = str(s.GlobalId)
        rooms.append(Room(str(s.GlobalId), name, storey_for(s, zmin), ring, zmin, zmax))
    if not rooms:
        raise SourceError(f"{label}: none of its {len(spaces)} spaces has a usable solid; {NO_SPACES_HINT}")
    # ---- space boundaries: the spaces each element bounds; virtual ones paired
    bounded: dict[int, set[str]] = defaultdict(set)
    virtual: list[tuple[str, F64]] = []
    boundaries = list(model.by_type("IfcRelSpaceBoundary"))
    for b in boundaries:
        sp = b.RelatingSpace
        if sp is None or sp.id() not in room_key:
            continue
        el = b.RelatedBuildingElement
        if b.PhysicalOrVirtualBoundary == "VIRTUAL" or (el is not None and el.is_a("IfcVirtualElement")):
            poly = _boundary_polygon(ios, b, scale)
            if poly is not None:
                virtual.append((room_key[sp.id()], poly - off))
        elif el is not None:
            bounded[el.id()].add(room_key[sp.id()])
    door_window_bounds = sum(1 for k in bounded if model.by_id(k).is_a("IfcDoor") or model.by_id(k).is_a("IfcWindow"))
    if not boundaries:
        notes.append("no space boundaries: every portal found from the geometry (an opening whose two sides lie in two spaces)")
    elif door_window_bounds == 0:
        notes.append("space boundaries name no door or window: portals found from the geometry")
    # ---- openings
    openings: list[Opening] = []
    filled: set[int] = set()
    for o in model.by_type("IfcOpeningElement"):
        host = o.VoidsElements[0].RelatingBuildingElement if o.VoidsElements else None
        if host is None or any(host.is_a(h) for h in _SLAB_HOSTS) or host.is_a("IfcFurnishingElement"):
            continue
        fill = o.HasFillings[0].RelatedBuildingElement if o.HasFillings else None
        kind = "door" if fill is not None and fill.is_a("IfcDoor") else "window" if fill is not None else "opening"
        sh = shapes.get(o.id())
        if sh is None:
            continue
        if fill is not None:
            filled.add(fill.id())
        rooms_of = tuple(sorted(bounded.get(fill.id() if fill is not None else o.id(), ())))
        key = str(fill.GlobalId if fill is not None else o.GlobalId)
        # by height: one wall may rise through two storeys and hold doors of both
        op = _opening_box(sh[0] - off, key, kind, storey_at(float(sh[0][:, 2].min() - oz)), rooms_of,
                          "boundary" if len(rooms_of) == 2 else "geometry")
        if op is not None:
            name = str(getattr(fill, "Name", None) or getattr(o, "Name", None) or key)
            openings.append(Opening(op.key, op.kind, name, op.storey, op.centre, op.normal, op.width, op.depth,
                                    op.zmin, op.zmax, op.rooms, None, op.source))
    for el in list(model.by_type("IfcDoor")) + list(model.by_type("IfcWindow")):
        if el.id() in filled or el.id() not in shapes:
            continue
        kind = "door" if el.is_a("IfcDoor") else "window"
        rooms_of = tuple(sorted(bounded.get(el.id(), ())))
        v = shapes[el.id()][0] - off
        op = _opening_box(v, str(el.GlobalId), kind, storey_at(float(v[:, 2].min())), rooms_of,
                          "boundary" if len(rooms_of) == 2 else "geometry")
        if op is not None:
            openings.append(op)
    for ra, rb, poly in _pair_virtual(virtual):
        c = poly.mean(axis=0)
        basis = _plane_basis(poly)
        assert basis is not None
        n3 = basis[3]
        nh = n3[:2] if float(np.hypot(*n3[:2])) > 1e-6 else np.array([1.0, 0.0])
        st = rooms[[r.key for r in rooms].index(ra)].storey
        width = float(np.ptp(poly[:, :2] @ np.array([-nh[1], nh[0]]) / max(float(np.hypot(*nh)), 1e-12)))
        openings.append(Opening(f"virtual {ra}/{rb}", "virtual", "virtual boundary", st, c, nh, width, 0.0,
                                float(poly[:, 2].min()), float(poly[:, 2].max()), (ra, rb), poly, "boundary"))
    # ---- stairs
    stairs: list[Stair] = []
    for s in [e for c in _STAIR_CLASSES for e in model.by_type(c)]:
        if any(r.RelatingObject.is_a(c) for r in (s.Decomposes or ()) for c in _STAIR_CLASSES):
            continue  # a flight of a stair counted with its stair
        parts = [s] + [x for r in (s.IsDecomposedBy or ()) for x in r.RelatedObjects
                       if x.is_a("IfcStairFlight") or x.is_a("IfcRampFlight") or x.is_a("IfcSlab")]
        vs, ts, n = [], [], 0
        for part in parts:
            sh = shapes.get(part.id())
            if sh is not None:
                vs.append(sh[0] - off)
                ts.append(sh[1] + n)
                n += len(sh[0])
        line = _tread_line(np.concatenate(vs), np.concatenate(ts)) if vs else None
        if line is None:
            issues.append(FeatureIssue(f"{s.is_a()} #{s.id()}", "no treads found", "skipped"))
            continue
        stairs.append(Stair(str(s.GlobalId), str(s.Name or s.GlobalId), storey_for(s, float(line[0, 2])), line))
    # ---- elements
    elements: list[Element] = []
    for e in products:
        if any(e.is_a(c) for c in _NOT_DRAWN) or e.id() not in shapes:
            continue
        v, t, trans, mids = shapes[e.id()]
        kind, base = _kind(e)
        if e.is_a("IfcSite") and len(t) > 0:
            kind, base = "other", "slab"
        elements.append(Element(len(elements), str(e.GlobalId), kind, str(e.Name or e.is_a()), v - off, t,
                                _materials(kind, base, v, t, trans, mids)))
    return InteriorScene(
        name=p.stem,
        crs=crs,
        origin=origin,
        storeys=storeys,
        rooms=tuple(rooms),
        openings=tuple(openings),
        stairs=tuple(stairs),
        elements=tuple(elements),
        source_format=str(model.schema),
        issues=tuple(issues),
        notes=tuple(notes),
    )
