"""What a generated city holds, counted: buildings, streets, shapes, landmarks, party walls.

:func:`city_summary` reads a FeatureCollection of :mod:`~walkstream.server.sources.citygen`'s
shape (or any of the same shape); ``walkstream build city`` and ``walkstream demo`` print
it, and the generator's tests check the city against it.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from walkstream.shared.arrays import F64
from walkstream.shared.geometry import signed_area

__all__ = ["city_summary"]


def _cross2(a: F64, b: F64) -> F64:
    """2D cross product of (..., 2) arrays."""
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _simplify(ring: F64, sin_tol: float = 0.01) -> F64:
    """Drop (nearly) collinear vertices, such as the shared vertices added on walls."""
    r = ring
    while len(r) > 3:
        # neighbours by index (-1 wraps): np.roll's bookkeeping was most of this on small rings
        k = np.arange(len(r))
        a = r[k - 1] - r
        b = r[(k + 1) % len(r)] - r
        s = np.abs(_cross2(a, b)) / (np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1))
        straight = (s < sin_tol) & (np.sum(a * b, axis=1) < 0)
        if not straight.any():
            break
        r = r[~straight]
    return r


def _shape_kind(rings: list[F64]) -> str:
    """``"courtyard"`` (has holes), ``"rect"``, ``"l"`` (six corners, one reflex) or ``"irregular"``."""
    if len(rings) > 1:
        return "courtyard"
    r = _simplify(rings[0])
    k = np.arange(len(r))
    a = r[k - 1] - r
    b = r[(k + 1) % len(r)] - r
    na = np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1)
    cos = np.sum(a * b, axis=1) / na
    turn = _cross2(b, a)  # > 0 at a convex vertex of a CCW ring
    square = bool(np.all(np.abs(cos) < math.sin(math.radians(1.0))))
    if len(r) == 4 and square:
        return "rect"
    if len(r) == 6 and square and int(np.sum(turn < 0)) == 1:
        return "l"
    return "irregular"


def city_summary(fc: dict[str, Any]) -> dict[str, Any]:
    """Count what a generated city (or any FeatureCollection of the same shape) holds.

    Parameters
    ----------
    fc:
        A FeatureCollection as returned by :func:`generate_city`.

    Returns
    -------
    dict
        ``buildings``, ``streets``, ``crossroads``, ``squares``, ``lots`` (from the
        ``walkstream`` member, None when absent), ``shapes`` (counts of ``rect``, ``l``,
        ``courtyard``, ``irregular`` footprints), ``landmarks`` (counts of ``tower``
        and ``spire``), ``floors`` (``min``, ``mean``,
        ``max``), ``party_wall_edges`` (edges with a neighbour behind, once the
        footprints are loaded: the loader splits partly shared edges),
        ``free_edges``, ``built_area_m2`` (footprint area) and ``area_m2`` (the
        city square, None when the size is unknown).
    """
    counts = {"building": 0, "street": 0, "crossroad": 0, "square": 0}
    shapes = {"rect": 0, "l": 0, "courtyard": 0, "irregular": 0}
    landmarks = {"tower": 0, "spire": 0}
    floors: list[int] = []
    party = free = 0
    built = 0.0
    for f in fc.get("features", []):
        props = f.get("properties") or {}
        kind = props.get("kind")
        if kind in counts:
            counts[kind] += 1
        if kind != "building":
            continue
        rings = [np.asarray(r, dtype=np.float64)[:-1] for r in f["geometry"]["coordinates"]]
        shapes[_shape_kind(rings)] += 1
        built += sum(signed_area(r) for r in rings)  # holes are CW: they subtract
        floors.append(int(props["floors"]))
        if props.get("landmark") in landmarks:
            landmarks[props["landmark"]] += 1
    if counts["building"]:
        # party walls as the loader finds them (the one place that does)
        from walkstream.server.sources.geojson import load_geojson_dict

        for b in load_geojson_dict(fc).buildings:
            for h in b.neighbour_heights:
                party += int(np.count_nonzero(h > 0))
                free += int(np.count_nonzero(h <= 0))
    meta = fc.get("walkstream") or {}
    size = meta.get("size")
    return {
        "buildings": counts["building"],
        "streets": counts["street"],
        "crossroads": counts["crossroad"],
        "squares": counts["square"],
        "lots": meta.get("lots"),
        "shapes": shapes,
        "landmarks": landmarks,
        "floors": {
            "min": min(floors) if floors else 0,
            "mean": round(float(np.mean(floors)), 2) if floors else 0.0,
            "max": max(floors) if floors else 0,
        },
        "party_wall_edges": party,
        "free_edges": free,
        "built_area_m2": round(built, 1),
        "area_m2": float(size) ** 2 if size is not None else None,
    }
