"""What each interior cell holds: every element's triangles clipped to the cells they occupy.

A cell's contents are the pieces of the building elements that lie within
:data:`REACH` (6 cm) of its volume: the faces of its walls (on the cell's side of the
wall), its floor and ceiling, its furniture, the frames in its doorway.  Triangles
are clipped exactly at the (slightly grown) cell planes, so a slab that spans ten
rooms gives each room its own piece of floor and a wall between two rooms gives each
its own face; where the grown volumes of two cells overlap (along a thin wall, a
doorway's edges) a piece is in both.  The horizontal reach stops short of the next
storey's floor (its top face belongs to the storey above).

Whatever lies outside every room and doorway (outer faces of outer walls, roofs,
the middle of thick walls, anything the rooms do not cover) goes whole to the
``outside`` cell, which the client draws when a window or outer door shows it.

The work is plain numpy on plain arrays (:func:`contents_task`), so the bake can run
it in worker processes or on Dask.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import shapely
from numpy.typing import NDArray

from walkstream.server.bake.roomgeom import clip_polygons, fan_triangles
from walkstream.shared.arrays import F64

__all__ = ["REACH", "Part", "grown_planes", "contents_task", "outside_mask", "weld"]

REACH = 0.06
"""Metres by which a cell's volume is grown (sideways and downwards) to collect its contents."""

Part = tuple[int, int, F64, NDArray[np.int64]]
"""``(element id, material, vertices (n, 3), triangles (m, 3))``: one piece of one element."""


def grown_planes(planes: F64, reach: float = REACH) -> F64:
    """A cell's planes moved outward by ``reach`` (the ceiling too: a roof's underside
    at the top storey's ceiling plane is that storey's ceiling; what lies on or above
    the ceiling plane and does not face down, such as the floor of the storey above,
    is dropped by :func:`_above_ceiling`)."""
    g = np.array(planes, dtype=np.float64)
    g[:, 3] -= reach
    return g


def _above_ceiling(tris: F64, planes: F64) -> NDArray[np.bool_]:
    """``(t,)`` triangles on or above a cell's ceiling plane that do not face down
    (the storey above's floor and the feet of its walls)."""
    top = planes[planes[:, 2] > 0.5]
    if len(tris) == 0 or len(top) == 0:
        return np.zeros(len(tris), bool)
    zmax = -float(top[0, 3]) / float(top[0, 2])
    n = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    down = n[:, 2] < -0.5 * np.linalg.norm(n, axis=1)
    return np.all(tris[:, :, 2] >= zmax - 1e-6, axis=1) & ~down


def _inside(points: F64, planes: F64) -> NDArray[np.bool_]:
    """``(..., )`` whether each point is behind every plane (within 1e-9)."""
    return np.all(points @ planes[:, :3].T + planes[:, 3] <= 1e-9, axis=-1)


def weld(tris: F64) -> tuple[F64, NDArray[np.int64]]:
    """Shared vertices for a triangle soup ``(t, 3, 3)``: corners at the same place (to
    0.1 mm) are merged only between faces of the same orientation, so that normals
    recomputed from the faces stay flat.

    Returns
    -------
    vertices : (n, 3) float64
    triangles : (t, 3) int64
    """
    if len(tris) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    n = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    pos = tris.reshape(-1, 3)
    key = np.concatenate(
        [np.rint(pos / 1e-4).astype(np.int64), np.repeat(np.rint(n * 1000).astype(np.int64), 3, axis=0)], axis=1
    )
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    # keep the order in which vertices first appear (small index deltas compress well)
    order = np.argsort(first)
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    verts = pos[first[order]]
    return verts, rank[inverse.reshape(-1)].reshape(-1, 3)


def _parts(pieces: F64, elem: NDArray[np.int64], mat: NDArray[np.int64]) -> list[Part]:
    """Group triangles by (element, material) and weld each group."""
    if len(pieces) == 0:
        return []
    key = elem * 256 + mat
    order = np.argsort(key, kind="stable")
    keys, starts = np.unique(key[order], return_index=True)
    ends = np.append(starts[1:], len(order))
    out: list[Part] = []
    for k, s, e in zip(keys.tolist(), starts.tolist(), ends.tolist(), strict=True):
        v, t = weld(pieces[order[s:e]])
        out.append((int(k) // 256, int(k) % 256, v, t))
    return out


def contents_task(
    cells: Sequence[tuple[int, F64]],
    soup: F64,
    elem: NDArray[np.int64],
    mat: NDArray[np.int64],
    reach: float = REACH,
) -> list[tuple[int, list[Part], NDArray[np.int64]]]:
    """Clip the triangles to each of some cells.

    Parameters
    ----------
    cells:
        ``(cell id, planes (k, 4))`` per cell (:func:`~.roomgeom.cell_planes`).
    soup : (t, 3, 3) float64
        Every element triangle of the scene.
    elem, mat : (t,) int
        Element id and material of each triangle.
    reach:
        How far beyond its planes a cell collects (:data:`REACH`).

    Returns
    -------
    list
        ``(cell id, parts, triangles fully inside the grown cell)`` per cell; the last
        says which scene triangles some cell holds whole.
    """
    if len(soup) == 0:
        return [(cid, [], np.zeros(0, np.int64)) for cid, _ in cells]
    lo = soup.min(axis=1)
    hi = soup.max(axis=1)
    tree = shapely.STRtree(shapely.box(lo[:, 0], lo[:, 1], hi[:, 0], hi[:, 1]))
    out: list[tuple[int, list[Part], NDArray[np.int64]]] = []
    for cid, planes in cells:
        g = grown_planes(planes, reach)
        box = _planes_box(planes, reach)
        cand = tree.query(shapely.box(*box[:4]))
        cand = cand[(hi[cand, 2] >= box[4]) & (lo[cand, 2] <= box[5])]
        if len(cand) == 0:
            out.append((cid, [], np.zeros(0, np.int64)))
            continue
        tri = soup[cand]
        inside = _inside(tri, g)  # (c, 3)
        whole = inside.all(axis=1)
        d = tri @ g[:, :3].T + g[:, 3]  # (c, 3, planes)
        gone = np.any(np.all(d > 1e-9, axis=1), axis=1)
        cut = ~whole & ~gone
        pieces = [tri[whole]]
        pe = [elem[cand][whole]]
        pm = [mat[cand][whole]]
        if cut.any():
            src = np.flatnonzero(cut)
            poly = tri[cut]
            count = np.full(len(poly), 3, np.int64)
            for plane in g:
                poly, count = clip_polygons(poly, count, plane)
                keep = count >= 3
                poly, count, src = poly[keep], count[keep], src[keep]
                if len(poly) == 0:
                    break
            if len(poly):
                ft, fsrc = fan_triangles(poly, count)
                pieces.append(ft)
                pe.append(elem[cand][src[fsrc]])
                pm.append(mat[cand][src[fsrc]])
        allp, alle, allm = np.concatenate(pieces), np.concatenate(pe), np.concatenate(pm)
        keep = ~_above_ceiling(allp, planes)
        held = cand[whole][~_above_ceiling(tri[whole], planes)]
        out.append((cid, _parts(allp[keep], alle[keep], allm[keep]), held))
    return out


def _planes_box(planes: F64, reach: float) -> F64:
    """``minx, miny, maxx, maxy, minz, maxz`` of a prism cell grown by ``reach``."""
    sides = planes[np.abs(planes[:, 2]) < 0.5]
    # corners: intersections of consecutive side lines (the outline is in order)
    a, b = sides[:, :2], sides[:, 3]
    a2, b2 = np.roll(a, -1, axis=0), np.roll(b, -1, axis=0)
    det = a[:, 0] * a2[:, 1] - a[:, 1] * a2[:, 0]
    ok = np.abs(det) > 1e-12
    x = np.where(ok, (-b * a2[:, 1] + b2 * a[:, 1]) / np.where(ok, det, 1.0), np.nan)
    y = np.where(ok, (-a[:, 0] * b2 + a2[:, 0] * b) / np.where(ok, det, 1.0), np.nan)
    zmin = -float(planes[planes[:, 2] < -0.5][0, 3])
    zmax = -float(planes[planes[:, 2] > 0.5][0, 3])
    r = reach + 1e-6
    return np.array([np.nanmin(x) - r, np.nanmin(y) - r, np.nanmax(x) + r, np.nanmax(y) + r, zmin - r, zmax])


def outside_mask(
    soup: F64, cells: Sequence[tuple[F64, float, float]], held: NDArray[np.bool_], reach: float = REACH
) -> NDArray[np.bool_]:
    """Which triangles reach outside every cell (so the outside cell gets them whole).

    A triangle some cell holds whole (``held``) is inside; any other is outside when
    one of its corners, edge midpoints or centroid lies in no grown cell.

    Parameters
    ----------
    soup : (t, 3, 3)
    cells : ``(outline (n, 2), zmin, zmax)`` of every room and doorway cell
    held : (t,) bool
    """
    todo = np.flatnonzero(~held)
    out = np.zeros(len(soup), bool)
    if len(todo) == 0:
        return out
    t = soup[todo]
    samples = np.concatenate(
        [t, 0.5 * (t + np.roll(t, -1, axis=1)), t.mean(axis=1, keepdims=True)], axis=1
    )  # (k, 7, 3)
    pts = samples.reshape(-1, 3)
    polys = [shapely.Polygon(o).buffer(reach, join_style="mitre") for o, _, _ in cells]
    zr = np.array([[z0 - reach, z1 - reach] for _, z0, z1 in cells])
    tree = shapely.STRtree(polys)
    pi, ci = tree.query(shapely.points(pts[:, :2]), predicate="intersects")
    z = pts[pi, 2]
    ok = (z >= zr[ci, 0]) & (z <= zr[ci, 1])
    covered = np.zeros(len(pts), bool)
    covered[pi[ok]] = True
    out[todo] = ~covered.reshape(-1, 7).all(axis=1)
    return out
