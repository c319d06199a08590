"""Street networks: street lines noded into a graph and cut into junction regions and street pieces.

Both readers of real streets (:mod:`.osm` and :mod:`.geojson`) hand their street lines
(centre lines in scene-local metres, each with a width) and street areas (squares,
pedestrian zones, holes kept) to :func:`street_network`, which returns flat pieces:

1. **Noding.**  The lines are snapped to a millimetre grid and noded: two lines meet
   at a shared vertex (an OSM node) and wherever they cross.  Only ground-level
   lines come here (the readers leave tunnels and other layers out,
   :func:`~walkstream.server.sources.osmtags.ground_layer`), so every crossing is a
   real junction.  Duplicate vertices, zero-length lines and lines that only touch
   need no special case; a line that is not finite is skipped and reported.
2. **The street space** is the union of every noded edge buffered by half its width
   (round ends), closed by :data:`CLOSE_GAP` (a dilation then an erosion): a sidewalk
   or cycleway running beside a road less than twice that far from it merges into
   the road's space instead of making a thin strip of its own.  Squares are
   subtracted from it (they are pieces of their own).
3. **Junctions** are nodes of degree 3 or more.  Junctions closer together than the
   wider road's width plus :data:`CLOSE_GAP` form one cluster (a dual carriageway
   crossing, a roundabout's entries, a sidewalk crossing a side street next to the
   road's junction).  Each cluster becomes one region: the street space around it,
   cut across every way that leaves the cluster where that way's buffer separates
   from the buffers of the cluster's other ways (plus :data:`CUT_MARGIN`), and at
   most :data:`CUT_SHARE` of the way's length to the next junction.
4. **Pieces.**  The street space split by those cuts gives faces: a face holding a
   junction node is a ``crossroad``; the rest are ``street`` pieces (the ways between
   junctions, and dead ends).  Faces under :data:`MIN_PIECE_AREA` m² are merged into
   the neighbour they share most boundary with.  A street piece takes its width,
   source id and passage flag from the edge running longest inside it.
5. **Holes.**  Pieces are single rings (:class:`~walkstream.shared.records.StreetParams`),
   so a piece with holes (a loop road around its island, a square around a
   fountain) is cut through each hole into ring pieces: the holes stay holes.

The cutting into convex view cells of at most ``--cell-size`` metres, and the
clipping against building footprints, happen in the bake
(:mod:`walkstream.server.bake.streetcells`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import shapely
from numpy.typing import NDArray

from walkstream.shared.arrays import F64
from walkstream.shared.geometry import signed_area

__all__ = [
    "CLOSE_GAP",
    "CUT_MARGIN",
    "CUT_SHARE",
    "MIN_PIECE_AREA",
    "NetLine",
    "NetArea",
    "NetPiece",
    "Network",
    "street_network",
    "split_holes",
]

#: Gaps (metres) between parallel ways up to twice this wide are closed.
CLOSE_GAP = 1.5
#: A junction region reaches this far (metres) past where its ways separate.
CUT_MARGIN = 0.5
#: A junction region takes at most this share of a way's length to the next junction.
CUT_SHARE = 0.45
#: Faces smaller than this (m²) are merged into a neighbour.
MIN_PIECE_AREA = 2.0
# snapping grid of the noding, metres
_GRID = 1e-3
# longest stretch of a way (metres) looked at when cutting a junction region
_MAX_CUT = 40.0


@dataclass(frozen=True)
class NetLine:
    """A street centre line: ``xy`` ``(n, 2)`` scene-local metres, width in metres."""

    uid: str
    xy: F64
    width: float
    passage: bool = False


@dataclass(frozen=True)
class NetArea:
    """A street area (square, pedestrian zone): exterior ring then holes, ``(n, 2)`` each."""

    uid: str
    rings: tuple[F64, ...]


@dataclass(frozen=True)
class NetPiece:
    """One flat piece: ``kind`` crossroad|street|square, a CCW ring without holes."""

    kind: str
    ring: F64
    width: float
    source_id: str
    passage: bool = False


@dataclass
class Network:
    """What :func:`street_network` made: pieces, and counts for the summary."""

    pieces: list[NetPiece] = field(default_factory=list)
    junctions: int = 0
    clusters: int = 0
    components: int = 0
    skipped: list[tuple[str, str]] = field(default_factory=list)


# --------------------------------------------------------------------------- public


def street_network(
    lines: Sequence[NetLine],
    areas: Sequence[NetArea] = (),
    *,
    close_gap: float = CLOSE_GAP,
) -> Network:
    """Cut a street network into junction regions, street pieces and squares.

    Parameters
    ----------
    lines:
        Ground-level street centre lines (scene-local metres).
    areas:
        Street areas (squares), holes kept.
    close_gap:
        Half the widest gap between parallel ways that is closed (metres, >= 0).

    Returns
    -------
    Network
        The pieces (crossroads, streets, squares; none overlaps another except where
        a square and a street area overlap in the input), the number of junction
        nodes and clusters, of connected parts, and the lines skipped with why.
    """
    # GEOS sets floating-point flags on degenerate input (numpy would warn): the
    # results are checked, not the flags
    with np.errstate(all="ignore"):
        return _street_network(lines, areas, close_gap)


def _street_network(lines: Sequence[NetLine], areas: Sequence[NetArea], close_gap: float) -> Network:
    net = Network()
    edges, widths, owners = _noded_edges(lines, net)
    square_geoms = _area_polygons(areas, net)
    squares = shapely.union_all(square_geoms) if square_geoms else shapely.Polygon()
    for a, g in zip(
        [a for a in areas if _area_ok(a)], square_geoms, strict=True
    ):
        for part in split_holes(g):
            net.pieces.append(NetPiece("square", _ring(part), 0.0, a.uid))
    if not len(edges):
        net.components = len(shapely.get_parts(squares)) if not squares.is_empty else 0
        return net

    buffers = shapely.buffer(edges, widths / 2.0, quad_segs=2)
    space = shapely.union_all(buffers)
    if close_gap > 0:
        space = shapely.buffer(
            shapely.buffer(space, close_gap, quad_segs=2, join_style="mitre", mitre_limit=2.0),
            -close_gap,
            quad_segs=2,
            join_style="mitre",
            mitre_limit=2.0,
        )
        space = shapely.union(space, shapely.union_all(buffers))
    space = shapely.make_valid(space)
    if not squares.is_empty:
        space = shapely.difference(space, squares)
    space = _polygonal(space)
    net.components = len(shapely.get_parts(shapely.union(space, squares)))
    if space.is_empty:
        return net

    graph = _Graph(edges, widths)
    clusters = graph.clusters(close_gap)
    net.junctions = int((graph.degree >= 3).sum())
    net.clusters = len(clusters)
    cuts = _cuts(graph, clusters, buffers, space, close_gap)
    faces = _faces(space, cuts)
    node_cluster = np.full(len(graph.nodes), -1, np.int64)
    for c, members in enumerate(clusters):
        node_cluster[members] = c
    is_cross = _cross_faces(faces, graph.nodes[node_cluster >= 0])
    faces, is_cross = _merge_small(faces, is_cross)

    tree = shapely.STRtree(edges)
    for face, cross in zip(faces, is_cross, strict=True):
        fi, ei = tree.query(np.array([face], dtype=object), predicate="intersects")
        inside = shapely.length(shapely.intersection(face, edges[ei])) if len(ei) else np.zeros(0)
        if len(ei) and inside.max() > 0:
            # the main road rather than the sidewalk merged into its piece
            best = int(ei[int(np.argmax(inside * widths[ei]))])
        else:
            best = int(tree.query_nearest(face.point_on_surface())[0])
        line = lines[owners[best]]
        if cross:
            ways = sorted({lines[owners[int(e)]].uid for e in ei})
            sid = "junction " + "+".join(ways[:3]) + ("+..." if len(ways) > 3 else "")
            width = float(widths[ei].max()) if len(ei) else float(widths[best])
            kind, passage = "crossroad", False
        else:
            sid, width, kind, passage = line.uid, float(widths[best]), "street", line.passage
        for part in split_holes(face):
            net.pieces.append(NetPiece(kind, _ring(part), width, sid, passage))
    return net


def split_holes(poly: shapely.Polygon) -> list[shapely.Polygon]:
    """Polygons without holes covering ``poly``: each hole is cut through by a line across it.

    >>> ring = shapely.Polygon([(0, 0), (10, 0), (10, 10), (0, 10)], [[(4, 4), (6, 4), (6, 6), (4, 6)]])
    >>> parts = split_holes(ring)
    >>> len(parts), round(sum(p.area for p in parts), 6), any(p.interiors for p in parts)
    (2, 96.0, False)
    """
    todo = [poly]
    out: list[shapely.Polygon] = []
    while todo:
        p = todo.pop()
        if not p.interiors:
            out.append(p)
            continue
        cx = float(np.asarray(p.interiors[0].coords)[:, 0].mean())
        x0, y0, x1, y1 = p.bounds
        for half in (shapely.box(x0 - 1, y0 - 1, cx, y1 + 1), shapely.box(cx, y0 - 1, x1 + 1, y1 + 1)):
            todo.extend(
                q for q in _polygon_parts(shapely.intersection(p, half)) if q.area > 1e-6
            )
    return out


# --------------------------------------------------------------------------- noding


def _noded_edges(lines: Sequence[NetLine], net: Network) -> tuple[NDArray[np.object_], F64, NDArray[np.int64]]:
    """Noded edges (LineStrings), their widths and the index of the line each came from."""
    good: list[shapely.LineString] = []
    which: list[int] = []
    for k, line in enumerate(lines):
        xy = np.asarray(line.xy, dtype=np.float64).reshape(-1, 2)
        if not np.isfinite(xy).all():
            net.skipped.append((line.uid, "NaN or infinite coordinates"))
            continue
        if not (math.isfinite(line.width) and line.width > 0):
            net.skipped.append((line.uid, f"width {line.width!r} is not a positive number"))
            continue
        xy = np.round(xy / _GRID) * _GRID
        keep = np.concatenate([[True], np.any(np.diff(xy, axis=0) != 0, axis=1)])
        xy = xy[keep]
        if len(xy) < 2:
            net.skipped.append((line.uid, "zero-length way (fewer than 2 distinct points)"))
            continue
        good.append(shapely.LineString(xy))
        which.append(k)
    if not good:
        return np.empty(0, object), np.zeros(0), np.zeros(0, np.int64)
    src = np.array(good, dtype=object)
    noded = shapely.union_all(src, grid_size=_GRID)
    edges = np.array(
        [e for e in shapely.get_parts(noded) if isinstance(e, shapely.LineString) and e.length > 0],
        dtype=object,
    )
    if not len(edges):
        return np.empty(0, object), np.zeros(0), np.zeros(0, np.int64)
    mids = shapely.line_interpolate_point(edges, 0.5, normalized=True)
    ei, si = shapely.STRtree(src).query(mids, predicate="dwithin", distance=10 * _GRID)
    width_of = np.array([lines[k].width for k in which])
    best = np.full(len(edges), -1, np.int64)
    best_w = np.full(len(edges), -np.inf)
    for e, s in zip(ei.tolist(), si.tolist(), strict=True):
        if width_of[s] > best_w[e]:
            best_w[e], best[e] = width_of[s], s
    for e in np.flatnonzero(best < 0).tolist():
        best[e] = int(shapely.STRtree(src).query_nearest(mids[e])[0])
    owners = np.array([which[b] for b in best], dtype=np.int64)
    return edges, width_of[best], owners


def _area_ok(a: NetArea) -> bool:
    return len(a.rings) > 0 and all(np.isfinite(np.asarray(r, np.float64)).all() for r in a.rings)


def _area_polygons(areas: Sequence[NetArea], net: Network) -> list[shapely.Geometry]:
    out = []
    for a in areas:
        if not _area_ok(a):
            net.skipped.append((a.uid, "NaN, infinite or missing coordinates"))
            continue
        rings = [np.asarray(r, np.float64).reshape(-1, 2) for r in a.rings]
        poly = shapely.make_valid(shapely.Polygon(rings[0], rings[1:]))
        out.append(_polygonal(poly))
    return out


# --------------------------------------------------------------------------- the graph


class _Graph:
    """Nodes (edge ends) and incidence of the noded edges."""

    def __init__(self, edges: NDArray[np.object_], widths: F64) -> None:
        self.edges = edges
        self.widths = widths
        self.lengths = shapely.length(edges)
        coords = [np.asarray(e.coords)[:, :2] for e in edges]
        ends = np.array([[c[0], c[-1]] for c in coords]).reshape(-1, 2)
        key = np.round(ends / _GRID).astype(np.int64)
        uniq, inv = np.unique(key, axis=0, return_inverse=True)
        inv = inv.reshape(-1)
        self.nodes = (uniq * _GRID).astype(np.float64)
        self.ends = inv.reshape(-1, 2)  # (e, 2) node of each end
        self.degree = np.bincount(inv, minlength=len(uniq))
        self.incident: list[list[tuple[int, int]]] = [[] for _ in range(len(uniq))]
        for e, (a, b) in enumerate(self.ends.tolist()):
            self.incident[a].append((e, 0))
            self.incident[b].append((e, 1))
        self.node_width = np.zeros(len(uniq))
        np.maximum.at(self.node_width, inv, np.repeat(widths, 2))
        self.coords = coords

    def clusters(self, close_gap: float) -> list[list[int]]:
        """Junction nodes merged when closer than the wider road's width plus the gap."""
        junction = np.flatnonzero(self.degree >= 3)
        if not len(junction):
            return []
        parent = {int(j): int(j) for j in junction}

        def find(a: int) -> int:
            while parent[a] != a:
                parent[a] = parent[parent[a]]
                a = parent[a]
            return a

        pts = shapely.points(self.nodes[junction])
        reach = float(self.node_width[junction].max()) + close_gap
        i, j = shapely.STRtree(pts).query(pts, predicate="dwithin", distance=reach)
        for a, b in zip(i.tolist(), j.tolist(), strict=True):
            if a >= b:
                continue
            na, nb = int(junction[a]), int(junction[b])
            limit = max(self.node_width[na], self.node_width[nb]) + close_gap
            if float(np.hypot(*(self.nodes[na] - self.nodes[nb]))) < limit:
                parent[find(na)] = find(nb)
        groups: dict[int, list[int]] = {}
        for j in junction.tolist():
            groups.setdefault(find(int(j)), []).append(int(j))
        return sorted(groups.values())

    def chain(self, node: int, edge: int, side: int, stop: set[int]) -> tuple[F64, float, int]:
        """The polyline from ``node`` along ``edge`` through degree-2 nodes.

        Returns the polyline (oriented away from ``node``), its length and its last node.
        """
        parts: list[F64] = []
        length = 0.0
        seen = {edge}
        e, s = edge, side
        while True:
            c = self.coords[e] if s == 0 else self.coords[e][::-1]
            parts.append(c if not parts else c[1:])
            length += float(self.lengths[e])
            end = int(self.ends[e, 1 - s])
            if end in stop or self.degree[end] != 2 or length > 4 * _MAX_CUT:
                break
            nxt = [(f, fs) for f, fs in self.incident[end] if f not in seen]
            if not nxt:
                break
            e, s = nxt[0]
            seen.add(e)
        return np.concatenate(parts), length, end


def _cuts(
    g: _Graph,
    clusters: list[list[int]],
    buffers: NDArray[np.object_],
    space: shapely.Geometry,
    close_gap: float,
) -> list[shapely.Geometry]:
    """Cut segments across every way where it leaves its junction cluster."""
    cuts: list[shapely.Geometry] = []
    shapely.prepare(space)
    for members in clusters:
        inside = set(members)
        leaving: list[tuple[int, F64, float]] = []  # edge, polyline, length
        internal: list[int] = []
        for n in members:
            for e, side in g.incident[n]:
                other = int(g.ends[e, 1 - side])
                if other in inside and g.lengths[e] <= 2 * (g.node_width[n] + close_gap):
                    internal.append(e)
                    continue
                poly, length, _ = g.chain(n, e, side, inside)
                leaving.append((e, poly, length))
        if len(leaving) < 2:
            continue
        reach = [min(CUT_SHARE * length, _MAX_CUT) for _, _, length in leaving]
        heads = [
            _substring(poly, r) if r > 0 else None
            for (_, poly, _), r in zip(leaving, reach, strict=True)
        ]
        head_buf = [
            shapely.buffer(h, g.widths[e] / 2.0, quad_segs=2) if h is not None else None
            for (e, _, _), h in zip(leaving, heads, strict=True)
        ]
        inner = shapely.union_all(buffers[sorted(set(internal))]) if internal else None
        for k, (e, poly, length) in enumerate(leaving):
            if length < 1.0 or heads[k] is None:
                continue
            others = [b for j, b in enumerate(head_buf) if j != k and b is not None]
            if inner is not None:
                others.append(inner)
            if not others:
                continue
            overlap = shapely.intersection(
                shapely.buffer(heads[k], g.widths[e] / 2.0, cap_style="flat", quad_segs=2),
                shapely.union_all(others),
            )
            line = shapely.LineString(poly)
            if overlap.is_empty:
                d = CUT_MARGIN
            else:
                pts = shapely.points(shapely.get_coordinates(overlap))
                d = float(shapely.line_locate_point(line, pts).max()) + CUT_MARGIN
            d = min(d, reach[k])
            if d <= 0:
                continue
            p = np.asarray(shapely.get_coordinates(line.interpolate(d)))[0]
            a = np.asarray(shapely.get_coordinates(line.interpolate(max(d - 0.5, 0.0))))[0]
            b = np.asarray(shapely.get_coordinates(line.interpolate(min(d + 0.5, length))))[0]
            t = b - a
            nt = float(np.hypot(*t))
            if nt < 1e-9:
                continue
            normal = np.array([-t[1], t[0]]) / nt
            half = g.widths[e] / 2.0 + 2 * close_gap + 3.0
            seg = shapely.LineString([p - half * normal, p + half * normal])
            piece = shapely.intersection(seg, space)
            at = shapely.Point(p)
            for part in shapely.get_parts(piece):
                if isinstance(part, shapely.LineString) and part.length > 0 and part.distance(at) < 1e-6:
                    cuts.append(part)
    return cuts


# --------------------------------------------------------------------------- faces


def _faces(space: shapely.Geometry, cuts: list[shapely.Geometry]) -> list[shapely.Polygon]:
    """The street space split by the cut segments."""
    parts = _polygon_parts(space)
    if not cuts:
        return parts
    linework = shapely.union_all(
        np.array([shapely.boundary(space), *cuts], dtype=object), grid_size=_GRID / 10
    )
    faces = [f for f in shapely.get_parts(shapely.polygonize(shapely.get_parts(linework))) if f.area > 0]
    if not faces:
        return parts
    arr = np.array(faces, dtype=object)
    # polygonize also fills the holes of the space: keep the faces inside it
    covered = shapely.area(shapely.intersection(arr, space)) >= 0.5 * shapely.area(arr)
    return [f for f, ok in zip(faces, covered, strict=True) if ok]


def _cross_faces(faces: list[shapely.Polygon], nodes: F64) -> NDArray[np.bool_]:
    out = np.zeros(len(faces), bool)
    if not len(faces) or not len(nodes):
        return out
    arr = np.array(faces, dtype=object)
    _, fj = shapely.STRtree(arr).query(shapely.points(nodes), predicate="dwithin", distance=1e-6)
    out[np.unique(fj)] = True
    return out


def _merge_small(
    faces: list[shapely.Polygon], cross: NDArray[np.bool_]
) -> tuple[list[shapely.Polygon], NDArray[np.bool_]]:
    """Merge faces under MIN_PIECE_AREA into the neighbour sharing the most boundary."""
    faces = list(faces)
    cross = cross.copy()
    alive = [True] * len(faces)
    order = sorted(range(len(faces)), key=lambda k: faces[k].area)
    for k in order:
        if faces[k].area >= MIN_PIECE_AREA:
            break
        grown = shapely.buffer(faces[k], 1e-6, quad_segs=1, join_style="mitre")
        best, best_len = -1, 0.0
        for j in range(len(faces)):
            if j == k or not alive[j] or not faces[j].intersects(grown):
                continue
            shared = shapely.length(shapely.intersection(shapely.boundary(faces[j]), grown))
            if shared > best_len:
                best, best_len = j, float(shared)
        if best < 0:
            continue
        merged = _polygon_parts(shapely.union(faces[best], faces[k]))
        if len(merged) != 1:
            continue
        faces[best] = merged[0]
        cross[best] = cross[best] or cross[k]
        alive[k] = False
    keep = [k for k in range(len(faces)) if alive[k]]
    return [faces[k] for k in keep], cross[keep]


# --------------------------------------------------------------------------- helpers


def _substring(xy: F64, length: float) -> shapely.LineString | None:
    """The first ``length`` metres of a polyline."""
    seg = np.hypot(*np.diff(xy, axis=0).T)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    if cum[-1] <= 0:
        return None
    if length >= cum[-1]:
        return shapely.LineString(xy)
    i = int(np.searchsorted(cum, length, side="right")) - 1
    f = (length - cum[i]) / seg[i] if seg[i] > 0 else 0.0
    pts = np.vstack([xy[: i + 1], xy[i] + f * (xy[i + 1] - xy[i])])
    return shapely.LineString(pts) if len(pts) >= 2 else None


def _polygon_parts(geom: shapely.Geometry) -> list[shapely.Polygon]:
    return [p for p in shapely.get_parts(geom) if isinstance(p, shapely.Polygon) and not p.is_empty]


def _polygonal(geom: shapely.Geometry) -> shapely.Geometry:
    """The polygons of a geometry (lines and points a repair left over are dropped)."""
    parts = [p for g in shapely.get_parts(geom) for p in _polygon_parts(g)]
    if not parts:
        return shapely.Polygon()
    return shapely.multipolygons(parts) if len(parts) > 1 else parts[0]


def _ring(poly: shapely.Polygon) -> F64:
    """CCW exterior ring without the closing vertex."""
    r = np.asarray(poly.exterior.coords, dtype=np.float64)[:-1, :2]
    if signed_area(r) < 0:
        r = r[::-1]
    return np.ascontiguousarray(r)
