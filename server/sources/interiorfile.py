"""The ``walkstream-interior`` file format: a building interior in a few numbers per element.

``walkstream generate interior`` writes it and the bake reads it (:func:`load_interior`),
turning every element into meshes with :mod:`.interiormesh`.  One JSON object::

    {"format": "walkstream-interior", "version": 1,
     "name": str,
     "crs": "EPSG:NNNN" or null,
     "slab": 0.25,
     "storeys": [{"name": str, "elevation": m, "height": m}, ...],
     "rooms": [{"id": str, "name": str, "storey": i, "outline": [[x, y], ...]}, ...],
     "walls": [{"id": str, "storey": i, "from": [x, y], "to": [x, y], "thickness": m,
                "exterior": bool,
                "openings": [{"id": str, "kind": "door" | "window" | "opening",
                              "offset": m, "width": m, "sill": m, "head": m,
                              "swing": 1 | -1}, ...]}, ...],
     "slabs": [{"id": str, "storey": i, "outline": [[x, y], ...], "holes": [[[x, y], ...], ...]}],
     "stairs": [{"id": str, "storey": i, "x": [x1, x2], "y": [y_landing, y_turn],
                 "width": m}, ...],
     "furniture": [{"id": str, "kind": str, "storey": i, "at": [x, y], "yaw": rad}, ...]}

Coordinates ``x, y`` are in the CRS (projected metres; millions of metres are fine:
the reader moves everything to a scene-local origin, the centre of the rooms' box,
as for cities); heights are metres.  ``storeys`` are ordered bottom to top;
``height`` runs from a storey's floor to the next floor.  A room's volume runs from
its storey's floor to the underside of the slab above (``height - slab``).  A wall
runs along its centre line from its storey's floor to the slab above; each opening is
centred ``offset`` metres along the wall from ``from``, ``width`` wide, from ``sill``
to ``head`` above the floor.  A door is drawn open: its leaf swung 90 degrees, at
right angles to the wall, into the side ``swing`` says (1: left of ``from`` -> ``to``;
a walk keeps its clearance from it).  A slab is the floor
of its storey (its top at the storey's elevation, ``slab`` thick), with holes where
stairs pass; the roof is a slab of the storey past the last.  A stair is a switchback
in a stairwell from storey ``i`` to ``i + 1``: the first half-flight climbs along
``x[0]`` from ``y[0]`` (the floor landing) to ``y[1]`` (the half landing), the second
comes back along ``x[1]``.  Furniture kinds are those of
:data:`~walkstream.server.sources.interiormesh.FURNITURE_KINDS`.

Doors, windows and openings become the scene's openings (candidate portals); which
rooms they join is found from the geometry by the bake.  Two rooms whose outlines
touch with no wall between them are joined by an open portal (how a long corridor is
cut into convex pieces).  Everything a bad file does wrong is a one-line
:class:`~walkstream.shared.errors.SourceError` naming the element.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from walkstream.server.sources.interior import (
    Element,
    InteriorScene,
    Opening,
    Room,
    Stair,
    Storey,
)
from walkstream.server.sources.interiormesh import (
    FURNITURE_KINDS,
    box_mesh,
    door_boxes,
    furniture_boxes,
    prism_mesh,
    switchback_boxes,
    wall_boxes,
    window_boxes,
)
from walkstream.shared.arrays import F64
from walkstream.shared.errors import SourceError
from walkstream.shared.palette import MATERIALS

__all__ = ["INTERIOR_FORMAT", "INTERIOR_VERSION", "load_interior", "load_interior_dict", "is_interior_file"]

INTERIOR_FORMAT = "walkstream-interior"
"""The ``format`` member of an interior file."""
INTERIOR_VERSION = 1
"""The one version this code reads and writes."""

_MAT = {name: mid for mid, name, _ in MATERIALS}
_MAX_BYTES = 512 << 20
#: The highest storey (floor to floor, metres) and the widest interior (metres) read:
#: far above any real storey or building, far below what the cell-mesh codec's
#: fixed-point positions hold (about 1,000 km), so a wrong unit or a stray
#: exponent is named here, at the storey or room, not deep in the bake.
MAX_STOREY_HEIGHT = 100.0
MAX_EXTENT = 10_000.0
_FABRIC = {"chair", "sofa", "bench"}
_METAL = {"machine", "robot"}


def is_interior_file(path: str | os.PathLike[str]) -> bool:
    """Whether a ``.json`` file declares the ``walkstream-interior`` format (reads its start)."""
    try:
        with open(path, "rb") as f:
            head = f.read(256)
    except OSError:
        return False
    return b'"format"' in head and INTERIOR_FORMAT.encode() in head


def load_interior(path: str | os.PathLike[str]) -> InteriorScene:
    """Read an interior file.

    Raises
    ------
    SourceError
        The file cannot be read, is not JSON, not this format, or an element is bad
        (the message names the element).
    """
    p = Path(path)
    try:
        size = p.stat().st_size
        if size > _MAX_BYTES:
            raise SourceError(f"{p}: {size} bytes, more than {_MAX_BYTES} for an interior file")
        doc = json.loads(p.read_text(encoding="utf-8"), parse_int=_parse_int)
    except OSError as exc:
        raise SourceError(f"{p}: cannot read ({exc.strerror or exc})") from exc
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise SourceError(f"{p}: not a JSON file ({exc})") from exc
    return load_interior_dict(doc, p.stem, str(p))


def _parse_int(text: str) -> int | float:
    # Python refuses ints of more than 4,300 digits (ValueError); NaN is named by _num
    return int(text) if len(text) <= 400 else math.nan


def _num(v: Any, what: str) -> float:
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        raise SourceError(f"{what}: expected a finite number, got {v!r:.40}")
    return float(v)


def _pt(v: Any, what: str) -> F64:
    if not isinstance(v, list | tuple) or len(v) != 2:
        raise SourceError(f"{what}: expected [x, y], got {v!r:.60}")
    return np.array([_num(v[0], what), _num(v[1], what)])


def _ring(v: Any, what: str) -> F64:
    if not isinstance(v, list) or len(v) < 3:
        raise SourceError(f"{what}: expected a ring of at least 3 [x, y] points")
    return np.array([_pt(q, what) for q in v])


def _items(doc: dict[str, Any], key: str, label: str) -> list[dict[str, Any]]:
    items = doc.get(key, [])
    if not isinstance(items, list) or not all(isinstance(i, dict) for i in items):
        raise SourceError(f"{label}: {key!r} must be a list of objects")
    return items


class _Builder:
    """Collects elements and keeps their ids dense."""

    def __init__(self, origin: F64) -> None:
        self.origin = origin
        self.elements: list[Element] = []

    def add(self, key: str, kind: str, name: str, v: F64, t: NDArray[Any], m: NDArray[np.uint8] | int) -> None:
        if len(t) == 0:
            return
        mats = np.full(len(t), m, np.uint8) if isinstance(m, int) else m
        self.elements.append(Element(len(self.elements), key, kind, name, v, t, mats))

    def boxes(self, key: str, kind: str, name: str, rows: F64, material: int) -> None:
        v, t = box_mesh(rows)
        self.add(key, kind, name, v, t, material)


def _normals(v: F64, t: NDArray[Any]) -> F64:
    a, b, c = v[t[:, 0]], v[t[:, 1]], v[t[:, 2]]
    n = np.cross(b - a, c - a)
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)


def load_interior_dict(doc: Any, name: str = "interior", label: str = "interior") -> InteriorScene:
    """Build the scene of an interior document (the parsed JSON); see the module docstring."""
    if not isinstance(doc, dict) or doc.get("format") != INTERIOR_FORMAT:
        raise SourceError(f"{label}: not a {INTERIOR_FORMAT} file (no \"format\": \"{INTERIOR_FORMAT}\")")
    if doc.get("version") != INTERIOR_VERSION:
        raise SourceError(f"{label}: version {doc.get('version')!r}, this walkstream reads {INTERIOR_VERSION}")
    crs = doc.get("crs")
    if crs is not None and not isinstance(crs, str):
        raise SourceError(f"{label}: crs must be a string such as 'EPSG:32633' or null")
    slab = _num(doc.get("slab", 0.25), f"{label}: slab")
    if not 0.05 <= slab <= 2.0:
        raise SourceError(f"{label}: slab: expected 0.05 to 2 metres, got {slab}")
    storeys_in = _items(doc, "storeys", label)
    if not storeys_in:
        raise SourceError(f"{label}: no storeys")
    elev = [_num(s.get("elevation"), f"{label}: storey {k}: elevation") for k, s in enumerate(storeys_in)]
    height = [_num(s.get("height"), f"{label}: storey {k}: height") for k, s in enumerate(storeys_in)]
    for k, h in enumerate(height):
        if h > MAX_STOREY_HEIGHT:
            raise SourceError(f"{label}: storey {k}: height {h:g} m, more than the {MAX_STOREY_HEIGHT:g} m a storey may be")
    if elev[-1] - elev[0] > MAX_EXTENT:
        raise SourceError(f"{label}: storeys span {elev[-1] - elev[0]:g} m, more than {MAX_EXTENT:g} m")
    if any(h <= slab + 1.8 for h in height) or any(b <= a for a, b in zip(elev, elev[1:], strict=False)):
        raise SourceError(f"{label}: storeys must go up and be at least {slab + 1.8:g} m high")
    rooms_in = _items(doc, "rooms", label)
    if not rooms_in:
        raise SourceError(f"{label}: no rooms; an interior needs rooms to make cells of")
    ring_pts = np.concatenate([_ring(r.get("outline"), f"{label}: room {r.get('id')!r}: outline") for r in rooms_in])
    lo, hi = ring_pts.min(axis=0), ring_pts.max(axis=0)
    if float((hi - lo).max()) > MAX_EXTENT:
        raise SourceError(f"{label}: rooms span {float((hi - lo).max()):.4g} m, more than {MAX_EXTENT:g} m")
    # a round origin near the centre: local coordinates stay small and exact
    ox, oy = (float(np.round(0.5 * (lo[k] + hi[k]))) for k in range(2))
    oz = float(elev[0])
    origin = np.array([ox, oy])
    storeys = tuple(
        Storey(str(s.get("name", k)), e - oz) for k, (s, e) in enumerate(zip(storeys_in, elev, strict=True))
    )

    def storey_of(item: dict[str, Any], what: str, top: bool = False) -> int:
        k = item.get("storey")
        if isinstance(k, bool) or not isinstance(k, int) or not 0 <= k < len(storeys) + (1 if top else 0):
            raise SourceError(f"{what}: storey must be an index 0..{len(storeys) - 1}, got {k!r}")
        return k

    def floor(k: int) -> float:
        return elev[k] - oz if k < len(elev) else elev[-1] + height[-1] - oz

    rooms = []
    for r in rooms_in:
        what = f"{label}: room {r.get('id')!r}"
        k = storey_of(r, what)
        ring = _ring(r.get("outline"), what) - origin
        rooms.append(Room(str(r.get("id")), str(r.get("name", r.get("id"))), k, ring, floor(k), floor(k) + height[k] - slab))
    b = _Builder(origin)
    openings: list[Opening] = []
    centre = 0.5 * (lo + hi) - origin
    for w in _items(doc, "walls", label):
        what = f"{label}: wall {w.get('id')!r}"
        k = storey_of(w, what)
        a, e = _pt(w.get("from"), what) - origin, _pt(w.get("to"), what) - origin
        length = float(np.hypot(*(e - a)))
        t = _num(w.get("thickness"), f"{what}: thickness")
        if length < 0.05 or not 0.02 <= t <= 2.0:
            raise SourceError(f"{what}: expected a wall at least 5 cm long and 2 cm to 2 m thick")
        z0, z1 = floor(k), floor(k) + height[k] - slab
        ux = (e - a) / length
        nrm = np.array([-ux[1], ux[0]])  # left of from -> to
        holes = []
        for o in w.get("openings", []):
            ow = f"{what}: opening {o.get('id')!r}" if isinstance(o, dict) else what
            if not isinstance(o, dict) or o.get("kind") not in ("door", "window", "opening"):
                raise SourceError(f"{ow}: kind must be door, window or opening")
            off, wid = _num(o.get("offset"), ow), _num(o.get("width"), ow)
            sill, head = _num(o.get("sill", 0.0), ow), _num(o.get("head"), ow)
            if not (0.5 * wid <= off <= length - 0.5 * wid and 0 <= sill < head <= z1 - z0 and wid >= 0.3):
                raise SourceError(f"{ow}: does not fit in its wall")
            holes.append((off, wid, sill, head))
            c = a + ux * off
            swing = 1.0 if o.get("swing", 1) >= 0 else -1.0
            key, kind = str(o.get("id")), str(o["kind"])
            openings.append(
                Opening(key, kind, key, k, np.array([c[0], c[1], z0 + 0.5 * (sill + head)]), nrm, wid, t,
                        z0 + sill, z0 + head, source="file")
            )
            if kind == "door":
                frame, leaf = door_boxes(c, nrm * swing, wid, t, z0 + sill, z0 + head)
                b.boxes(f"{key}/frame", "door", f"{key} frame", frame, _MAT["frame"])
                b.boxes(f"{key}/leaf", "door", f"{key} leaf", leaf, _MAT["door"])
            elif kind == "window":
                side = 1.0 if float(np.dot(centre[:2] - c, nrm)) >= 0 else -1.0
                frame, glass = window_boxes(c, nrm * side, wid, t, z0 + sill, z0 + head)
                b.boxes(f"{key}/frame", "window", f"{key} frame", frame, _MAT["frame"])
                b.boxes(f"{key}/glass", "window", f"{key} glass", glass, _MAT["glass"])
        try:
            rows = wall_boxes(a, e, t, z0, z1, holes)
        except ValueError as exc:
            raise SourceError(f"{what}: {exc}") from exc
        v, tri = box_mesh(rows)
        mats = np.full(len(tri), _MAT["inner_wall"], np.uint8)
        if w.get("exterior") and len(tri):
            outward = _normals(v, tri)[:, :2] @ (0.5 * (a + e) - centre[:2])
            mats[outward > 1e-9] = _MAT["wall"]
        b.add(str(w.get("id")), "wall", str(w.get("id")), v, tri, mats)
    for s in _items(doc, "slabs", label):
        what = f"{label}: slab {s.get('id')!r}"
        k = storey_of(s, what, top=True)
        rings = [_ring(s.get("outline"), what) - origin] + [
            _ring(h, f"{what}: hole") - origin for h in s.get("holes", [])
        ]
        v, tri = prism_mesh(rings, floor(k) - slab, floor(k))
        nz = _normals(v, tri)[:, 2]
        mats = np.where(nz > 0.5, _MAT["floor"], np.where(nz < -0.5, _MAT["ceiling"], _MAT["slab"])).astype(np.uint8)
        b.add(str(s.get("id")), "slab", str(s.get("id")), v, tri, mats)
    stairs = []
    for st in _items(doc, "stairs", label):
        what = f"{label}: stair {st.get('id')!r}"
        k = storey_of(st, what)
        if k + 1 >= len(storeys):
            raise SourceError(f"{what}: climbs from the top storey to nowhere")
        xs = st.get("x")
        ys = st.get("y")
        if not (isinstance(xs, list) and isinstance(ys, list) and len(xs) == 2 and len(ys) == 2):
            raise SourceError(f"{what}: x and y must be [a, b]")
        x1, x2 = (_num(v, what) - ox for v in xs)
        y0, y1 = (_num(v, what) - oy for v in ys)
        width = _num(st.get("width", 1.1), what)
        rise = floor(k + 1) - floor(k)
        half = 0.5 * rise
        boxes_a, path_a, boxes_b, path_b, landing, ym = switchback_boxes((x1, x2), (y0, y1), width, floor(k), rise)
        key = str(st.get("id"))
        b.boxes(key, "stair", f"stair {key}", np.concatenate([boxes_a, boxes_b, landing]), _MAT["stair"])
        turn = np.array([[x1, ym, floor(k) + half], [x2, ym, floor(k) + half]])
        path = np.concatenate([path_a, turn, path_b])
        stairs.append(Stair(key, f"stair {key}", k, path))
    for f in _items(doc, "furniture", label):
        what = f"{label}: furniture {f.get('id')!r}"
        k = storey_of(f, what)
        fkind = str(f.get("kind"))
        if fkind not in FURNITURE_KINDS:
            raise SourceError(f"{what}: kind must be one of {', '.join(FURNITURE_KINDS)}, got {f.get('kind')!r}")
        rows = furniture_boxes(fkind, _pt(f.get("at"), what) - origin, _num(f.get("yaw", 0.0), what), floor(k))
        mat = (_MAT["fabric"] if fkind in _FABRIC else _MAT["metal"] if fkind in _METAL
               else _MAT["fixture"] if fkind == "plant" else _MAT["furniture"])
        b.boxes(str(f.get("id")), "furniture", f"{fkind} {f.get('id')}", rows, mat)
    return InteriorScene(
        name=str(doc.get("name") or name),
        crs=crs or "local",
        origin=(ox, oy, oz),
        storeys=storeys,
        rooms=tuple(rooms),
        openings=tuple(openings),
        stairs=tuple(stairs),
        elements=tuple(b.elements),
        source_format=f"{INTERIOR_FORMAT}/{INTERIOR_VERSION}",
    )
