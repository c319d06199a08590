"""Clean, orient and repair footprint rings: repeated and collinear vertices, degenerate holes, self-intersections."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import shapely

from walkstream.server.sources.features import CleanPart, IssueLog, PolyFeature
from walkstream.shared.arrays import F64
from walkstream.shared.geometry import signed_area

__all__ = ["MAX_RING_VERTICES", "MAX_RAW_VERTICES", "MIN_AREA", "SIMPLIFY_TOL", "bound_vertices", "clean_and_repair",
           "clean_and_repair_all", "dedupe"]
#: Polygons (and holes and repaired parts) smaller than this many m² are degenerate.
MIN_AREA = 0.01
#: Vertices closer than this (metres) are duplicates; a vertex this close to the
#: line through its neighbours is collinear.
_VERTEX_TOL = 1e-3
#: Vertices a ring (or a street line) may keep.  OpenStreetMap caps a way at 2,000
#: nodes; a footprint over this many is simplified (:data:`SIMPLIFY_TOL`) and skipped
#: if it is still over: the repair (``is_simple``, ``make_valid``), the party walls
#: and the grammar's per-edge modules grow faster than linearly with it (a
#: 100,000-vertex star took 50 s and 8.6 GB before this limit).
MAX_RING_VERTICES = 5_000
#: Vertices a ring may have as read, before anything is done with it: more is
#: skipped without looking (removing repeated vertices is one pass in Python).
MAX_RAW_VERTICES = 2_000_000
#: Douglas-Peucker tolerance (metres) for rings over :data:`MAX_RING_VERTICES`.
SIMPLIFY_TOL = 0.05
_CHUNK = 256


# ------------------------------------------------------------------------ cleaning




def dedupe(r: F64, closed: bool = True) -> F64:
    """Drop repeated vertices (within 1 mm of the last vertex kept), and for a ring the closing vertex.

    Compared with the last vertex kept, not the previous one, so a run of points
    each under 1 mm from the one before (a 10 m circle of 100,000 points) thins out
    to points 1 mm apart instead of collapsing to one.
    """
    if len(r) < 2:
        return r
    step = np.hypot(*np.diff(r, axis=0).T)
    if not (step < _VERTEX_TOL).any():
        keep = np.ones(len(r), dtype=bool)
    else:
        keep = _keep_spaced(r)
    r = r[keep]
    if closed:
        while len(r) > 1 and math.hypot(*(r[-1] - r[0])) < _VERTEX_TOL:
            r = r[:-1]
    return r


def _keep_spaced(r: F64) -> np.ndarray:
    """Which vertices are at least 1 mm from the last vertex kept before them (one pass)."""
    keep = np.zeros(len(r), dtype=bool)
    keep[0] = True
    xs, ys = r[:, 0].tolist(), r[:, 1].tolist()
    lx, ly = xs[0], ys[0]
    tol2 = _VERTEX_TOL * _VERTEX_TOL
    for i in range(1, len(xs)):
        dx, dy = xs[i] - lx, ys[i] - ly
        if dx * dx + dy * dy >= tol2:
            keep[i] = True
            lx, ly = xs[i], ys[i]
    return keep


def _simplify_chunked(r: F64, closed: bool) -> F64:
    """Douglas-Peucker (:data:`SIMPLIFY_TOL`) over runs of 256 vertices, in one GEOS call.

    Whole-ring Douglas-Peucker is quadratic on a star (10 s for 100,000 vertices, a
    crash for 1,000,000); runs that share their end vertices bound it, and each run
    is still within the tolerance of the original.
    """
    pts = np.vstack([r, r[:1]]) if closed else r
    n = len(pts)
    starts = range(0, n - 1, _CHUNK - 1)
    idx = np.concatenate([np.arange(a, min(a + _CHUNK, n)) for a in starts])
    owner = np.concatenate([np.full(min(a + _CHUNK, n) - a, k) for k, a in enumerate(starts)])
    runs = shapely.linestrings(pts[idx], indices=owner)
    done = shapely.get_coordinates(shapely.simplify(runs, SIMPLIFY_TOL, preserve_topology=False), return_index=True)
    coords, which = done
    first = np.ones(len(which), dtype=bool)
    first[1:] = which[1:] != which[:-1]
    first[0] = False  # every run after the first repeats the previous run's last vertex
    out = coords[~first]
    return out[:-1] if closed else out


def bound_vertices(r: F64, closed: bool = True, limit: int = MAX_RING_VERTICES) -> tuple[F64 | None, str | None]:
    """A ring (or line) within ``limit`` vertices (:data:`MAX_RING_VERTICES`), repeated vertices dropped.

    Returns ``(points, note)``: ``points`` None when it cannot be brought under the
    limit (``note`` says why, with the counts), else the points and, when they were
    simplified, a note saying so.
    """
    if len(r) > MAX_RAW_VERTICES:
        return None, f"{len(r)} vertices, more than the {MAX_RAW_VERTICES} read"
    d = dedupe(r, closed)
    if len(d) <= limit:
        return d, None
    if len(d) > 20 * limit:
        return None, f"{len(d)} distinct vertices, more than the {20 * limit} simplified"
    simple = dedupe(_simplify_chunked(d, closed), closed)
    if len(simple) > limit:
        return None, (
            f"{len(d)} vertices, {len(simple)} after simplifying to {SIMPLIFY_TOL * 100:g} cm, "
            f"more than the limit of {limit}"
        )
    return simple, f"{len(d)} vertices simplified to {len(simple)} ({SIMPLIFY_TOL * 100:g} cm)"


def _drop_collinear(r: F64) -> F64:
    """Drop ring vertices within 1 mm of the line through their two neighbours."""
    while len(r) >= 3:
        idx = np.arange(len(r))
        prev = r[idx - 1]  # index -1 wraps to the last vertex
        d = r[(idx + 1) % len(r)] - prev
        v = r - prev
        chord = np.hypot(d[:, 0], d[:, 1])
        cross = np.abs(d[:, 0] * v[:, 1] - d[:, 1] * v[:, 0])
        # A vertex whose neighbours coincide is a spike tip: keep it (make_valid
        # deals with spikes) instead of dividing by zero.
        dist = np.where(chord > 0, cross / np.where(chord > 0, chord, 1.0), np.inf)
        flag = dist < _VERTEX_TOL
        if not flag.any():
            break
        r = r[~flag]
    return r


def _clean_rings(rings: list[F64]) -> tuple[list[F64] | None, str | None, list[str]]:
    """Clean and orient a polygon's rings.

    Returns ``(rings, skip_reason, hole_notes)``: ``rings`` is None when the exterior
    is unusable (``skip_reason`` says why); ``hole_notes`` describe dropped holes.
    """
    ext = dedupe(rings[0])
    if len(ext) < 3:
        return None, f"fewer than 3 distinct points ({len(ext)})", []
    area = signed_area(ext)
    ext = _drop_collinear(ext)
    if abs(area) < MIN_AREA or len(ext) < 3:
        return None, f"zero or near-zero area ({abs(area):.3g} m²)", []
    if area < 0:
        ext = ext[::-1].copy()
    out = [ext]
    notes = []
    for j, hole in enumerate(rings[1:], start=1):
        h = dedupe(hole)
        if len(h) < 3:
            notes.append(f"degenerate hole {j} ({len(h)} distinct points); hole dropped")
            continue
        harea = signed_area(h)
        h = _drop_collinear(h)
        if abs(harea) < MIN_AREA or len(h) < 3:
            notes.append(f"degenerate hole {j} (area {abs(harea):.3g} m²); hole dropped")
            continue
        out.append(h[::-1].copy() if harea > 0 else h)
    return out, None, notes


def clean_and_repair(poly: PolyFeature, log: IssueLog) -> list[CleanPart]:
    """Clean one polygon; repair a self-intersecting one with make_valid (:func:`clean_and_repair_all` of one)."""
    return clean_and_repair_all([poly], log)[0]


def clean_and_repair_all(polys: Sequence[PolyFeature], log: IssueLog) -> list[list[CleanPart]]:
    """Clean each polygon; repair the self-intersecting ones with make_valid.

    What :func:`clean_and_repair` does to one polygon, done to many: the vertices are
    bounded and the rings cleaned one polygon at a time (small numpy arrays), but the
    GEOS checks (a simple exterior, a valid polygon) run as one whole-array call each
    over every polygon instead of a geometry object and a call per polygon: most of
    the time of loading a city of thousands of buildings went there.

    Parameters
    ----------
    polys:
        The polygons, projected (``local`` set); each one's ``local`` is replaced by its
        rings with repeated vertices dropped.
    log:
        Gets each polygon's issues, in the order :func:`clean_and_repair` one polygon at a
        time would have added them.

    Returns
    -------
    list of list of CleanPart
        One list per polygon, in order: its cleaned parts (none when skipped, several
        when make_valid split it).
    """
    notes = [IssueLog() for _ in polys]  # each polygon's issues, added to ``log`` in polygon order at the end
    out: list[list[CleanPart]] = [[] for _ in polys]
    bounded = [_bounded(poly, mine) for poly, mine in zip(polys, notes, strict=True)]
    # one is_simple over every exterior: a self-crossing exterior (bow-tie) has a
    # meaningless shoelace area, so it must be repaired before the area and
    # collinearity tests, not after
    checked = [k for k, rings in enumerate(bounded) if rings is not None and len(rings[0]) >= 3]
    crossing = set()
    if checked:
        exteriors = [bounded[k][0] for k in checked]  # type: ignore[index]
        simple = shapely.is_simple(_linearrings(exteriors))
        crossing = {k for k, ok in zip(checked, simple.tolist(), strict=True) if not ok}
    cleaned: dict[int, list[F64]] = {}
    for k, (poly, rings) in enumerate(zip(polys, bounded, strict=True)):
        if rings is None:
            continue
        if k in crossing:
            holes = [h for h in rings[1:] if len(h) >= 3]
            out[k] = _repair(poly, shapely.Polygon(rings[0], holes), notes[k])
            continue
        clean, skip, hole_notes = _clean_rings(rings)
        for note in hole_notes:
            notes[k].add(poly.index, poly.uid, note, "repaired")
        if clean is None:
            notes[k].add(poly.index, poly.uid, str(skip), "skipped")
            continue
        cleaned[k] = clean
    if cleaned:
        # one is_valid over every cleaned polygon, built in one call from all their rings
        keys = list(cleaned)
        rings_all = [r for k in keys for r in cleaned[k]]
        owner = np.repeat(np.arange(len(keys)), [len(cleaned[k]) for k in keys])
        shapes = shapely.polygons(_linearrings(rings_all), indices=owner)
        for k, shape, ok in zip(keys, shapes, shapely.is_valid(shapes).tolist(), strict=True):
            poly = polys[k]
            out[k] = [CleanPart(poly, poly.uid, cleaned[k])] if ok else _repair(poly, shape, notes[k])
    for mine in notes:
        for index, _, issue in mine.items:
            log.add(index, issue.feature_id, issue.problem, issue.action)
    return out


def _linearrings(rings: Sequence[F64]) -> np.ndarray:
    """Closed linear rings of ``rings`` (each ``(n, 2)``, n >= 3, unclosed), in one GEOS call."""
    counts = [len(r) for r in rings]
    return shapely.linearrings(np.concatenate(rings), indices=np.repeat(np.arange(len(rings)), counts))


def _bounded(poly: PolyFeature, log: IssueLog) -> list[F64] | None:
    """``poly``'s rings within :data:`MAX_RING_VERTICES` (``poly.local`` becomes them); None
    (and the reason logged) when its exterior cannot be."""
    assert poly.local is not None
    bounded: list[F64] = []
    for j, ring in enumerate(poly.local):
        pts, note = bound_vertices(ring)
        if pts is None:
            if j == 0:
                log.add(poly.index, poly.uid, str(note), "skipped")
                return None
            log.add(poly.index, poly.uid, f"hole {j}: {note}; hole dropped", "repaired")
            continue
        if note:
            log.add(poly.index, poly.uid, note if j == 0 else f"hole {j}: {note}", "repaired")
        bounded.append(pts)
    poly.local = bounded  # repeated vertices dropped
    return bounded


def _repair(poly: PolyFeature, shape: shapely.Polygon, log: IssueLog) -> list[CleanPart]:
    """make_valid an invalid polygon; every polygonal part of >= MIN_AREA is kept."""
    reason = shapely.is_valid_reason(shape)
    fixed = shapely.make_valid(shape)
    parts = [
        g for g in shapely.get_parts(fixed) if isinstance(g, shapely.Polygon | shapely.MultiPolygon)
    ]
    polygons = [p for g in parts for p in shapely.get_parts(g)]
    cleaned: list[list[F64]] = []
    dropped = 0
    for p in polygons:
        prings = [np.asarray(p.exterior.coords, np.float64)[:, :2]]
        prings += [np.asarray(i.coords, np.float64)[:, :2] for i in p.interiors]
        c, _, _ = _clean_rings(prings)
        if c is None:
            dropped += 1
        else:
            cleaned.append(c)
    if not cleaned:
        log.add(
            poly.index,
            poly.uid,
            f"zero or near-zero area: invalid polygon ({reason}) has no part of "
            f"{MIN_AREA} m² or more after make_valid",
            "skipped",
        )
        return []
    sep = "." if poly.is_part else "#"
    ids = [poly.uid] if len(cleaned) == 1 else [f"{poly.uid}{sep}{j}" for j in range(len(cleaned))]
    log.add(
        poly.index,
        poly.uid,
        f"invalid polygon ({reason}); repaired with make_valid into {len(cleaned)} part(s)"
        + (f", {dropped} part(s) under {MIN_AREA} m² dropped" if dropped else ""),
        "repaired",
    )
    return [CleanPart(poly, sid, c) for sid, c in zip(ids, cleaned, strict=True)]
