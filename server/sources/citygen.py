"""Deterministic procedural city generator (the paper's synthetic test scenes).

Marvie et al. (2003) evaluate their streaming on procedurally generated cities of
350 m x 350 m and 700 m x 700 m.  This module builds such a city as a GeoJSON
``FeatureCollection`` (a plain ``dict``) so that it goes through exactly the same
loader as real footprint data.

Layout
------
1. **Street graph.**  A grid of nodes whose row and column spacings vary between
   about 60 and 110 m; every node is jittered by a few metres (nodes on the border
   only along the border) so blocks are irregular quads.  Each grid line has one
   width, 10-12 m, and a few interior lines are 18-20 m avenues.
2. **Crossroads, street pieces, blocks.**  Around each node, the two streets that
   bound a quadrant are offset by their half widths; the offset lines meet in a
   *corner point*.  The four corner points of a node form its crossroad (where the
   street surfaces overlap), the corner points at the two ends of a street segment
   form its street piece, and the corner points of the four nodes around a block
   form the block.  Because every polygon is built from the same corner points,
   crossroads, street pieces and blocks tile the plane exactly.
3. **Squares.**  About one block in twelve is left open as a square.
4. **Lots and footprints.**  Other blocks get a perimeter band of lots (depth 12-20 m
   per block edge, frontages of about 8-25 m, corner lots at the corners), built
   from walkstream.shared points so that neighbouring lots share edges exactly.  Most lots are
   fully built; some are L-shaped (a rear corner cut away, so the neighbour's wall
   is only partly shared); a few are vacant; some blocks are one courtyard building
   (the whole band as one polygon with a hole); a few backyards hold a small
   detached building.
5. **Landmarks.**  A few blocks (3 in the 700 m city, one per 16 ha, none below
   400 m) get a tall, detailed building standing free in the middle of their
   backyard: a tower (setbacks and a mast) or a spire, alternately.  Its footprint is
   a square and the feature carries ``landmark: "tower" | "spire"``; the building
   grammar builds the crown from that kind (:mod:`walkstream.shared.landmarks`), so a
   landmark travels as parameters like any building.  They are over the bake's
   ``--complex-triangles`` default at LOD2, so the complex-impostor path runs on every
   demo.  Landmarks draw from their own random stream: the rest of the city is the
   same with or without them (where they stand: :mod:`.citylandmarks`).
6. **Shared vertices.**  Where a lot's corner lies on a neighbour's wall the wall gets
   that vertex too (:func:`~walkstream.server.sources.partywalls.split_shared_edges`),
   so that rounding to 1 cm keeps neighbours wall to wall.  The party walls themselves
   (the neighbour height behind each edge) are not written: like any footprint file,
   the city gets them when it is loaded (:mod:`~walkstream.server.sources.geojson`),
   the one place they are found.

Buildings are set back :data:`FRONTAGE_GAP` (2 cm) from the street surfaces: the
output is rounded to 1 cm, which can move a vertex by up to 7 mm, and without the
gap that rounding would make facades overlap the street by a few square centimetres.

Coordinates are computed in a local frame (south-west corner at 0, 0) and shifted to
UTM zone 33N (EPSG:32633) with the south-west corner at :data:`ORIGIN`, so that the
scene exercises the far-from-origin path of the loaders.
"""

from __future__ import annotations

import json
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from walkstream.server.sources.citylandmarks import LANDMARK_FLOOR_HEIGHT, choose_landmarks
from walkstream.server.sources.citysummary import city_summary
from walkstream.server.sources.partywalls import split_shared_edges
from walkstream.shared.arrays import F64
from walkstream.shared.errors import InputError

__all__ = [
    "DEFAULT_SIZE",
    "DEFAULT_SEED",
    "CRS_NAME",
    "FRONTAGE_GAP",
    "GENERATOR_VERSION",
    "MAX_SIZE",
    "MIN_SIZE",
    "ORIGIN",
    "generate_city",
    "write_city",
]


#: Accepted city sizes (side of the square, metres).
DEFAULT_SIZE = 700.0
"""Side of the built-in default city, metres (the paper's 490,000 m² model)."""
DEFAULT_SEED = 1
"""Seed of the built-in default city."""
MIN_SIZE = 100.0
MAX_SIZE = 5000.0
#: Where the south-west corner of the city lies, in EPSG:32633 metres.
ORIGIN = (600000.0, 5340000.0)
#: The CRS written into the legacy ``crs`` member.
CRS_NAME = "urn:ogc:def:crs:EPSG::32633"
#: Distance between the street surfaces and the building frontages (see module doc).
FRONTAGE_GAP = 0.02
#: Version of the generator's layout rules; bump it when the output changes.
GENERATOR_VERSION = 2

# Street grid.
_MEAN_SPACING = 85.0  # metres between grid lines on average
_SPACING_RANGE = (60.0, 110.0)
_JITTER = 5.0  # metres a node may move along each axis
_STREET_WIDTH = (10.0, 12.0)
_AVENUE_WIDTH = (18.0, 20.0)
_AVENUE_EVERY = 5  # one avenue per this many grid lines (interior lines only)
_GHOST_SPACING = 80.0  # distance of the virtual nodes outside the border

# Blocks and lots.
_SQUARE_SHARE = 1.0 / 12.0
_COURTYARD_SHARE = 0.08
_LOT_DEPTH = (12.0, 20.0)
_MIN_LOT_DEPTH = 8.0  # below this a block is built as one solid building
_MIN_YARD = 10.0  # the backyard keeps at least this width between opposite bands
_FRONTAGE = (10.0, 18.0)  # per-block mean frontage; lots vary +-30 % around it
_SKEW_SHARE = 0.5  # share of lot divisions whose rear end is shifted sideways
_SKEW_MAX = 1.5  # metres
_L_SHARE = 0.15
_VACANT_SHARE = 0.04
_DETACHED_SHARE = 0.25

# Buildings.
_FLOORS = (3, 7)  # per block, inclusive
_FLOOR_VARIATION = 2  # per lot, +-
_FLOOR_HEIGHT = (3.0, 3.6)
_STYLE_COUNT = 10000



def _check_size(size: float) -> float:
    """Return ``size`` as a float, or raise :class:`InputError` when it is out of range."""
    try:
        value = float(size)
    except (TypeError, ValueError):
        raise InputError(f"city size: expected a number of metres, got {size!r}") from None
    if not (MIN_SIZE <= value <= MAX_SIZE):  # also rejects NaN
        raise InputError(
            f"city size: expected {MIN_SIZE:g} <= size <= {MAX_SIZE:g} metres, got {size!r}"
        )
    return value


def _check_seed(seed: int) -> int:
    """Return ``seed`` as a non-negative int, or raise :class:`InputError`."""
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or int(seed) < 0:
        raise InputError(f"city seed: expected a non-negative integer, got {seed!r}")
    return int(seed)


# --------------------------------------------------------------------------- geometry


def _left(d: F64) -> F64:
    """Rotate vectors (..., 2) by +90 degrees."""
    return np.stack([-d[..., 1], d[..., 0]], axis=-1)


def _cross(a: F64, b: F64) -> F64:
    """2D cross product of (..., 2) arrays."""
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _unit(d: F64) -> F64:
    """Normalise vectors (..., 2)."""
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def _meet(a: F64, da: F64, b: F64, db: F64) -> F64:
    """Intersection of the lines ``a + s da`` and ``b + t db`` (vectorised)."""
    s = _cross(b - a, db) / _cross(da, db)
    return a + s[..., None] * da


def _inset(quads: F64, dist: F64 | float) -> tuple[F64, F64]:
    """Move every edge of CCW convex quads inward.

    Parameters
    ----------
    quads:
        ``(n, 4, 2)`` counter-clockwise convex quads; edge ``k`` runs from vertex ``k``
        to vertex ``k + 1``.
    dist:
        Inset distance, a scalar or ``(n, 4)`` per edge.

    Returns
    -------
    inner, normals:
        The inset quads ``(n, 4, 2)`` (vertex ``k`` is where the moved edges ``k - 1``
        and ``k`` meet) and the inward unit normal of each edge ``(n, 4, 2)``.
    """
    u = _unit(np.roll(quads, -1, axis=1) - quads)
    nrm = _left(u)  # inward for a CCW ring
    d = np.broadcast_to(np.asarray(dist, dtype=np.float64), quads.shape[:2])
    a = quads + nrm * d[..., None]
    inner = _meet(np.roll(a, 1, axis=1), np.roll(u, 1, axis=1), a, u)
    return inner, nrm




# ------------------------------------------------------------------------ street graph


class _Network:
    """Street grid: nodes, corner points and the polygons built from them."""

    def __init__(self, size: float, rng: np.random.Generator) -> None:
        xs = self._lines(size, rng)
        ys = self._lines(size, rng)
        nx, ny = len(xs), len(ys)
        self.nx, self.ny = nx, ny
        self.col_width = self._widths(nx, rng)  # streets running north-south, per column
        self.row_width = self._widths(ny, rng)  # streets running east-west, per row

        jitter = rng.uniform(-_JITTER, _JITTER, (nx, ny, 2))
        # Border nodes only slide along the border so the city stays a clean square.
        jitter[[0, -1], :, 0] = 0.0
        jitter[:, [0, -1], 1] = 0.0
        p = np.stack(np.meshgrid(xs, ys, indexing="ij"), axis=-1) + jitter
        self.nodes = p  # (nx, ny, 2)

        # Virtual nodes one ring outside the border continue every border street
        # straight outward, so border crossroads get the same four-corner shape.
        pp = np.zeros((nx + 2, ny + 2, 2))
        pp[1:-1, 1:-1] = p
        pp[0, 1:-1] = p[0] - (_GHOST_SPACING, 0.0)
        pp[-1, 1:-1] = p[-1] + (_GHOST_SPACING, 0.0)
        pp[1:-1, 0] = p[:, 0] - (0.0, _GHOST_SPACING)
        pp[1:-1, -1] = p[:, -1] + (0.0, _GHOST_SPACING)
        east = _unit(pp[2:, 1:-1] - p)
        north = _unit(pp[1:-1, 2:] - p)
        west = _unit(pp[:-2, 1:-1] - p)
        south = _unit(pp[1:-1, :-2] - p)
        h_row = np.broadcast_to(self.row_width[None, :] / 2.0, (nx, ny))
        h_col = np.broadcast_to(self.col_width[:, None] / 2.0, (nx, ny))

        def corner(d1: F64, h1: F64, d2: F64, h2: F64) -> F64:
            # Street d1 offset to its left meets street d2 (the next one CCW) offset
            # to its right: the corner of the quadrant between them.
            return _meet(p + _left(d1) * h1[..., None], d1, p - _left(d2) * h2[..., None], d2)

        # Quadrants 0..3 = NE, NW, SW, SE (counter-clockwise).
        self.corners = np.stack(
            [
                corner(east, h_row, north, h_col),
                corner(north, h_col, west, h_row),
                corner(west, h_row, south, h_col),
                corner(south, h_col, east, h_row),
            ],
            axis=2,
        )  # (nx, ny, 4, 2)

    @staticmethod
    def _lines(size: float, rng: np.random.Generator) -> F64:
        """Grid line positions from 0 to ``size`` with spacings varying per line."""
        n = max(1, round(size / _MEAN_SPACING))
        w = rng.uniform(*_SPACING_RANGE, n)
        pos = np.concatenate([[0.0], np.cumsum(w / w.sum() * size)])
        pos[-1] = size
        return pos

    @staticmethod
    def _widths(n_lines: int, rng: np.random.Generator) -> F64:
        """Street width per grid line: mostly 10-12 m, a few interior 18-20 m avenues."""
        w = np.round(rng.uniform(*_STREET_WIDTH, n_lines), 1)
        interior = np.arange(1, n_lines - 1)
        n_av = min(len(interior), n_lines // _AVENUE_EVERY)
        if n_av:
            av = rng.choice(interior, size=n_av, replace=False)
            w[av] = np.round(rng.uniform(*_AVENUE_WIDTH, n_av), 1)
        return w

    def node_id(self, i: int, j: int) -> int:
        """Stable node id, row by row from the south-west corner."""
        return j * self.nx + i

    def crossroads(self) -> list[tuple[int, F64, float]]:
        """``(node id, CCW ring, width of the widest street there)`` per node."""
        out = []
        for j in range(self.ny):
            for i in range(self.nx):
                w = max(float(self.row_width[j]), float(self.col_width[i]))
                out.append((self.node_id(i, j), self.corners[i, j], w))
        return out

    def streets(self) -> list[tuple[int, int, F64, float]]:
        """``(from node, to node, CCW ring, width)`` per street segment.

        A piece runs between the two crossroads: its long sides are block edges and
        its short sides are crossroad edges.
        """
        c = self.corners
        out = []
        for j in range(self.ny):
            for i in range(self.nx - 1):
                ring = np.stack([c[i, j, 3], c[i + 1, j, 2], c[i + 1, j, 1], c[i, j, 0]])
                out.append(
                    (self.node_id(i, j), self.node_id(i + 1, j), ring, float(self.row_width[j]))
                )
        for i in range(self.nx):
            for j in range(self.ny - 1):
                ring = np.stack([c[i, j, 0], c[i, j + 1, 3], c[i, j + 1, 2], c[i, j, 1]])
                out.append(
                    (self.node_id(i, j), self.node_id(i, j + 1), ring, float(self.col_width[i]))
                )
        return out

    def blocks(self) -> tuple[F64, F64]:
        """Block quads ``(nb, 4, 2)`` (CCW) and the widest street around each ``(nb,)``."""
        c = self.corners
        q = np.stack([c[:-1, :-1, 0], c[1:, :-1, 1], c[1:, 1:, 2], c[:-1, 1:, 3]], axis=2)
        q = q.transpose(1, 0, 2, 3).reshape(-1, 4, 2)  # block index = j * (nx - 1) + i
        rw, cw = self.row_width, self.col_width
        widest = np.maximum(
            np.maximum(rw[:-1, None], rw[1:, None]), np.maximum(cw[None, :-1], cw[None, 1:])
        ).reshape(-1)
        return q, widest


# ------------------------------------------------------------------------ lots, footprints


class _Building:
    """A generated footprint before its shared vertices are added (local metres)."""

    __slots__ = ("rings", "floors", "floor_height", "style", "use")

    def __init__(self, rings: list[F64], floors: int, floor_height: float, style: int) -> None:
        self.rings = rings
        self.floors = floors
        self.floor_height = floor_height
        self.style = style
        self.use = "lot"  # "lot", "shed" (detached, in a backyard), "tower" or "spire"

    @property
    def height(self) -> float:
        return round(self.floors * self.floor_height, 2)


def _building(rings: list[F64], floors: int, rng: np.random.Generator) -> _Building:
    """A building with a random floor height (5 cm steps) and style."""
    fh = round(float(rng.uniform(*_FLOOR_HEIGHT)) * 20.0) / 20.0
    return _Building(rings, max(1, int(floors)), fh, int(rng.integers(_STYLE_COUNT)))


def _cut_parameters(length: float, frontage: float, rng: np.random.Generator) -> tuple[F64, F64]:
    """Where to divide a strip of ``length`` metres into lots.

    Returns the outer (street side) and inner (backyard side) parameters in [0, 1],
    equal at both ends; about half of the interior divisions are skewed by up to
    :data:`_SKEW_MAX` metres at the back so lots are not all rectangles.
    """
    n = max(1, round(length / frontage))
    w = rng.uniform(0.7, 1.3, n)
    t = np.concatenate([[0.0], np.cumsum(w) / w.sum()])
    t[-1] = 1.0
    skew_m = np.minimum(_SKEW_MAX, 0.2 * np.minimum(w[:-1], w[1:]) / w.sum() * length)
    skew = rng.uniform(-1.0, 1.0, n - 1) * skew_m * (rng.random(n - 1) < _SKEW_SHARE)
    ti = t.copy()
    ti[1:-1] += skew / length
    return t, ti


def _l_shape(o0: F64, o1: F64, i1: F64, i0: F64, rng: np.random.Generator) -> F64:
    """The lot ``o0 o1 i1 i0`` (CCW) minus one rear corner, as a 6-vertex CCW ring."""
    a = float(rng.uniform(0.45, 0.7))  # how far back the side wall still runs
    b = float(rng.uniform(0.35, 0.6))  # how much of the rear is cut away
    if rng.random() < 0.5:
        p = o1 + a * (i1 - o1)
        r = i1 + b * (i0 - i1)
        return np.stack([o0, o1, p, p + (r - i1), r, i0])
    r = i0 + b * (i1 - i0)
    p = o0 + a * (i0 - o0)
    return np.stack([o0, o1, i1, r, p + (r - i0), p])


def _depths(outer: F64, rng: np.random.Generator) -> tuple[F64, NDArray[np.bool_]]:
    """Lot depth per block edge ``(nb, 4)`` and whether the block is too small for a band.

    Opposite bands keep a backyard of at least :data:`_MIN_YARD` between them.
    """
    depth = rng.uniform(*_LOT_DEPTH, outer.shape[:2])
    # Distance across the block, measured from each edge's line to the far vertices.
    u = _unit(np.roll(outer, -1, axis=1) - outer)
    far = np.stack([np.roll(outer, -2, axis=1), np.roll(outer, -3, axis=1)], axis=2)
    across = np.min(_cross(u[:, :, None], far - outer[:, :, None]), axis=2)  # (nb, 4)
    across = np.minimum(across, np.roll(across, 2, axis=1))
    pair = depth + np.roll(depth, 2, axis=1)
    scale = np.minimum(1.0, np.maximum(across - _MIN_YARD, 0.0) / pair)
    depth = depth * scale
    solid = np.min(depth, axis=1) < _MIN_LOT_DEPTH
    return depth, solid


def _perimeter_block(
    outer: F64, inner: F64, nrm: F64, depth: F64, floors: int, rng: np.random.Generator
) -> tuple[list[_Building], int]:
    """Cut one block's perimeter band into lots and build their footprints.

    ``outer``/``inner`` are the block's CCW quads at the frontage and at the back of
    the band, ``nrm`` the inward edge normals and ``depth`` the band depth per edge.
    Returns the buildings and the number of lots.
    """
    # Feet of the inner corners on the outer edges: the corner lots are the kites
    # outer_k, fs_k, inner_k, fe_{k-1}; between them each edge has a rectangle.
    fs = inner - nrm * depth[:, None]
    fe = np.roll(inner, -1, axis=0) - nrm * depth[:, None]
    frontage = float(rng.uniform(*_FRONTAGE))
    out: list[_Building] = []
    lots = 0

    def lot_floors() -> int:
        return floors + int(rng.integers(-_FLOOR_VARIATION, _FLOOR_VARIATION + 1))

    for k in range(4):
        lots += 1
        corner = np.stack([outer[k], fs[k], inner[k], fe[k - 1]])
        out.append(_building([corner], lot_floors(), rng))

        i_a, i_b = inner[k], inner[(k + 1) % 4]
        length = float(np.linalg.norm(fe[k] - fs[k]))
        t, ti = _cut_parameters(length, frontage, rng)
        op = fs[k] + t[:, None] * (fe[k] - fs[k])
        ip = i_a + ti[:, None] * (i_b - i_a)
        # The strip's end points are shared with the corner lots: set them exactly.
        op[0], op[-1], ip[0], ip[-1] = fs[k], fe[k], i_a, i_b
        n = len(t) - 1
        kind = rng.random(n)
        lots += n
        for m in range(n):
            if kind[m] < _VACANT_SHARE:
                continue
            if kind[m] < _VACANT_SHARE + _L_SHARE and (t[m + 1] - t[m]) * length >= 8.0:
                ring = _l_shape(op[m], op[m + 1], ip[m + 1], ip[m], rng)
            else:
                ring = np.stack([op[m], op[m + 1], ip[m + 1], ip[m]])
            out.append(_building([ring], lot_floors(), rng))

    if rng.random() < _DETACHED_SHARE:
        shed = _detached(inner, rng)
        if shed is not None:
            out.append(_building([shed], int(rng.integers(1, 3)), rng))
            out[-1].use = "shed"
    return out, lots


def _landmarks(
    size: float, seed: int, yards: list[tuple[F64, int, int]], buildings: list[_Building]
) -> list[_Building]:
    """``buildings`` with a few landmarks (:func:`~.citylandmarks.choose_landmarks`): each
    takes the place (and the id) of its block's detached shed, if any, else joins the end.

    ``yards``: ``(yard quad (4, 2), first, end)`` per perimeter block: its backyard and
    the range of its buildings in ``buildings``.
    """
    out = list(buildings)
    for pick in choose_landmarks(size, seed, [y[0] for y in yards], _STYLE_COUNT):
        bd = _Building([pick.site], pick.floors, LANDMARK_FLOOR_HEIGHT, pick.style)
        bd.use = pick.use
        first, end = yards[pick.yard][1], yards[pick.yard][2]
        shed = [i for i in range(first, end) if buildings[i].use == "shed"]
        if shed:
            out[shed[0]] = bd
        else:
            out.append(bd)
    return out


def _detached(yard: F64, rng: np.random.Generator) -> F64 | None:
    """A small rectangle in the middle of a backyard quad, or None if it does not fit."""
    u = _unit(yard[1] - yard[0])
    v = _left(u)
    half = np.array([rng.uniform(3.0, 5.5), rng.uniform(2.5, 4.0)])
    c = yard.mean(axis=0)
    signs = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])  # CCW
    shed = c + signs[:, :1] * half[0] * u + signs[:, 1:] * half[1] * v
    # Keep 2 m of yard on every side (signed distance of each shed corner to each edge).
    e = np.roll(yard, -1, axis=0) - yard
    dist = _cross(_unit(e)[None], shed[:, None] - yard[None])
    return shed if bool(np.all(dist >= 2.0)) else None


# ------------------------------------------------------------------------ output


def _coords(ring: F64) -> list[list[float]]:
    """A closed GeoJSON ring in projected metres, rounded to 1 cm."""
    g = np.round(np.asarray(ring, dtype=np.float64) + ORIGIN, 2)
    return np.concatenate([g, g[:1]]).tolist()




def generate_city(size: float, seed: int = 1) -> dict[str, Any]:
    """Generate a procedural city as a GeoJSON FeatureCollection.

    Parameters
    ----------
    size:
        Side of the square city in metres, ``100 <= size <= 5000``.
    seed:
        Seed of :func:`numpy.random.default_rng`, the only source of randomness, so
        the same ``(size, seed)`` always gives the same city.

    Returns
    -------
    dict
        A FeatureCollection with a legacy ``crs`` member (EPSG:32633), a ``walkstream``
        member ``{"generator": "city", "size", "seed", "version", "lots"}`` and, in this
        order, building, street, crossroad and square features.  Coordinates are
        EPSG:32633 metres rounded to 1 cm, rings closed, exteriors counter-clockwise
        and holes clockwise.  See the module documentation for the properties.

    Raises
    ------
    InputError
        If ``size`` is outside [100, 5000] or ``seed`` is not a non-negative integer.
    """
    size = _check_size(size)
    seed = _check_seed(seed)
    rng = np.random.default_rng(seed)

    net = _Network(size, rng)
    quads, widest = net.blocks()
    nb = len(quads)

    # Block use: square, courtyard building or perimeter lots.
    use = rng.random(nb)
    square = use < _SQUARE_SHARE
    if nb > 1 and size >= 300.0 and not square.any():
        square[int(rng.integers(nb))] = True
    if square.all():  # never leave a city without buildings
        square[:] = False
    courtyard = ~square & (use < _SQUARE_SHARE + _COURTYARD_SHARE)
    block_floors = rng.integers(_FLOORS[0], _FLOORS[1] + 1, nb)

    outer, _ = _inset(quads, FRONTAGE_GAP)
    depth, solid = _depths(outer, rng)
    inner, nrm = _inset(outer, depth)

    buildings: list[_Building] = []
    yards: list[tuple[F64, int, int]] = []
    lots = 0
    for b in range(nb):
        if square[b]:
            continue
        if solid[b]:
            # Too small for a band around a yard: one building on the whole block.
            lots += 1
            buildings.append(_building([outer[b]], int(block_floors[b]), rng))
        elif courtyard[b]:
            lots += 1
            buildings.append(_building([outer[b], inner[b][::-1]], int(block_floors[b]), rng))
        else:
            new, n = _perimeter_block(
                outer[b], inner[b], nrm[b], depth[b], int(block_floors[b]), rng
            )
            yards.append((inner[b], len(buildings), len(buildings) + len(new)))
            buildings.extend(new)
            lots += n
    buildings = _landmarks(size, seed, yards, buildings)

    split = split_shared_edges([bd.rings for bd in buildings])
    features: list[dict[str, Any]] = []
    for k, (bd, rings) in enumerate(zip(buildings, split, strict=True)):
        fid = f"b{k}"
        features.append(
            {
                "type": "Feature",
                "id": fid,
                "geometry": {"type": "Polygon", "coordinates": [_coords(r) for r in rings]},
                "properties": {
                    "kind": "building",
                    "id": fid,
                    "floors": bd.floors,
                    "floor_height": bd.floor_height,
                    "height": bd.height,
                    "style": bd.style,
                    **({"landmark": bd.use} if bd.use in ("tower", "spire") else {}),
                },
            }
        )
    for k, (a, b, ring, w) in enumerate(net.streets()):
        fid = f"s{k}"
        centre = np.stack([(ring[0] + ring[3]) / 2.0, (ring[1] + ring[2]) / 2.0])
        features.append(
            {
                "type": "Feature",
                "id": fid,
                "geometry": {"type": "Polygon", "coordinates": [_coords(ring)]},
                "properties": {
                    "kind": "street",
                    "id": fid,
                    "width": w,
                    "from": a,
                    "to": b,
                    "centreline": np.round(centre + ORIGIN, 2).tolist(),
                },
            }
        )
    for node, ring, w in net.crossroads():
        fid = f"c{node}"
        features.append(
            {
                "type": "Feature",
                "id": fid,
                "geometry": {"type": "Polygon", "coordinates": [_coords(ring)]},
                "properties": {"kind": "crossroad", "id": fid, "width": w, "node": node},
            }
        )
    for k, blk in enumerate(np.flatnonzero(square).tolist()):
        fid = f"q{k}"
        features.append(
            {
                "type": "Feature",
                "id": fid,
                "geometry": {"type": "Polygon", "coordinates": [_coords(quads[blk])]},
                "properties": {
                    "kind": "square",
                    "id": fid,
                    "width": float(widest[blk]),
                    "block": blk,
                },
            }
        )

    return {
        "type": "FeatureCollection",
        "name": f"city-{size:g}m-seed{seed}",
        "crs": {"type": "name", "properties": {"name": CRS_NAME}},
        "walkstream": {
            "generator": "city",
            "size": size,
            "seed": seed,
            "version": GENERATOR_VERSION,
            "lots": lots,
        },
        "features": features,
    }


def write_city(path: str | PathLike[str], size: float, seed: int = 1) -> dict[str, Any]:
    """Generate a city and write it as compact GeoJSON.

    Parameters
    ----------
    path:
        Destination file; its parent directory must exist.  Written via a temporary
        file and renamed, so a reader never sees half a city.
    size, seed:
        As for :func:`generate_city`.

    Returns
    -------
    dict
        :func:`city_summary` of the written city.
    """
    fc = generate_city(size, seed)
    dest = Path(path)
    tmp = dest.with_name(dest.name + ".tmp")
    # Coordinates are already rounded to 1 cm; compact separators keep files small and
    # sorted output is not needed because the dicts are built in a fixed order.
    tmp.write_text(json.dumps(fc, separators=(",", ":"), allow_nan=False), encoding="utf-8")
    tmp.replace(dest)
    return city_summary(fc)
