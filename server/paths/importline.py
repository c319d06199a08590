"""A recorded path imported from a GeoJSON line or a GPX track and stored in a finished scene.

The line is clipped to the scene's cells: its longest stretch inside them, bridging
gaps of up to :data:`CLIP_GAP` metres, becomes the path.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np
import shapely

from walkstream.server.bake.navgraph import CellGraph
from walkstream.server.bake.viewcell import ViewCell
from walkstream.server.paths.record import open_existing
from walkstream.server.sources.geojsonlines import read_linestring
from walkstream.server.sources.gpx import read_gpx
from walkstream.server.store import CellInfo, write_path
from walkstream.shared.arrays import F64
from walkstream.shared.errors import RouteError
from walkstream.shared.paths import WALK_EYE_HEIGHT, RecordedPath

__all__ = ["CLIP_GAP", "MIN_PATH_SECONDS", "import_linestring", "import_path"]
#: Gaps (metres) outside the cells that a clipped GeoJSON line may bridge.
CLIP_GAP = 60.0
#: The shortest path imported (seconds): a shorter one replays as no frame at all.
MIN_PATH_SECONDS = 1.0


def _inside_intervals(g: CellGraph, xy: F64) -> F64:
    """Stretches of a polyline inside the cells, as ``(k, 2)`` distances along it, in order.

    Worked out segment by segment, so a line that crosses or runs over itself is
    measured right.
    """
    seg_len = np.hypot(*np.diff(xy, axis=0).T)
    start = np.concatenate([[0.0], np.cumsum(seg_len)])
    segs = shapely.linestrings(np.stack([xy[:-1], xy[1:]], axis=1))
    si, ci = g._tree.query(segs, predicate="intersects")
    if not len(si):
        return np.zeros((0, 2))
    parts = shapely.intersection(segs[si], g.polys[ci])
    out = []
    for s_idx, geom in zip(si.tolist(), parts, strict=True):
        a, d = xy[s_idx], xy[s_idx + 1] - xy[s_idx]
        n2 = float(d @ d)
        for piece in shapely.get_parts(geom):
            if not isinstance(piece, shapely.LineString) or piece.length <= 0:
                continue
            c = np.asarray(piece.coords)[:, :2]
            f = np.clip((c - a) @ d / n2, 0.0, 1.0) * seg_len[s_idx] + start[s_idx]
            out.append((float(f.min()), float(f.max())))
    if not out:
        return np.zeros((0, 2))
    out.sort()
    merged = [list(out[0])]
    for lo, hi in out[1:]:
        if lo <= merged[-1][1] + 1e-6:  # touching cells: one stretch
            merged[-1][1] = max(merged[-1][1], hi)
        else:
            merged.append([lo, hi])
    return np.array(merged, dtype=np.float64)


def _substring(xy: F64, lo: float, hi: float) -> F64:
    """The part of a polyline between two distances along it."""
    seg = np.hypot(*np.diff(xy, axis=0).T)
    cum = np.concatenate([[0.0], np.cumsum(seg)])

    def at(s: float) -> F64:
        i = min(int(np.searchsorted(cum, s, side="right")) - 1, len(seg) - 1)
        f = (s - cum[i]) / seg[i] if seg[i] > 0 else 0.0
        return np.asarray(xy[i] + f * (xy[i + 1] - xy[i]), dtype=np.float64)

    mid = xy[(cum > lo) & (cum < hi)]
    return np.vstack([at(lo), mid, at(hi)])


def import_linestring(
    source: str | os.PathLike[str] | Mapping[str, Any],
    crs: str,
    origin: Sequence[float],
    speed_kmh: float,
    name: str,
    clip_to: Iterable[ViewCell | CellInfo] | CellGraph | None = None,
    *,
    cells: Iterable[ViewCell | CellInfo] | CellGraph | None = None,
    eye_height: float = WALK_EYE_HEIGHT,
    max_gap: float = CLIP_GAP,
) -> tuple[RecordedPath, float | None]:
    """A recorded path along a GeoJSON line (see :func:`read_linestring`).

    Parameters
    ----------
    source, crs, origin:
        The line and the scene's CRS and origin (``SceneReader.meta``).
    speed_kmh, name, eye_height:
        As for :meth:`~walkstream.shared.paths.RecordedPath.from_polyline`.
    clip_to:
        The scene's cells: keep only the longest stretch of the line inside them.
        Gaps of up to ``max_gap`` metres (a street corner where a grid cell was
        dropped for being almost all building) do not end a stretch; the longest
        is the one with the most metres inside.
    cells:
        The scene's cells, only to measure how much of the line lies inside them.

    Returns
    -------
    tuple
        The path, and the metres of the (whole, unclipped) line inside the cells
        (None when no cells were given).

    Raises
    ------
    SourceError
        A bad file (see :func:`read_linestring`).
    RouteError
        With ``clip_to``: no part of the line lies inside the cells.
    """
    if isinstance(source, str | os.PathLike) and os.fspath(source).lower().endswith(".gpx"):
        xy = read_gpx(source, crs, origin)
    else:
        xy = read_linestring(source, crs, origin)
    area = clip_to if clip_to is not None else cells
    if area is None:
        return RecordedPath.from_polyline(name, xy, speed_kmh, eye_height), None
    g = area if isinstance(area, CellGraph) else CellGraph(area)
    spans = _inside_intervals(g, xy)
    inside = float((spans[:, 1] - spans[:, 0]).sum())
    if clip_to is not None:
        xy = _longest_inside(g, xy, max_gap)
    return RecordedPath.from_polyline(name, xy, speed_kmh, eye_height), inside


def _longest_inside(g: CellGraph, xy: F64, max_gap: float) -> F64:
    """The longest stretch of a polyline inside the cells, bridging gaps up to ``max_gap`` m."""
    spans = _inside_intervals(g, xy)
    if not len(spans):
        raise RouteError("the line lies entirely outside the scene's view cells")
    runs = [[spans[0, 0], spans[0, 1], spans[0, 1] - spans[0, 0]]]
    for lo, hi in spans[1:]:
        if lo - runs[-1][1] <= max_gap:
            runs[-1][1] = hi
            runs[-1][2] += hi - lo
        else:
            runs.append([lo, hi, hi - lo])
    # the most metres inside; the earliest of equals
    lo, hi, _ = max(runs, key=lambda r: (r[2], -r[0]))
    return _substring(xy, float(lo), float(hi))


def import_path(
    db: str | os.PathLike[str],
    name: str,
    file: str | os.PathLike[str] | Mapping[str, Any],
    speed_kmh: float,
    clip: bool = False,
    *,
    replace: bool = False,
    eye_height: float = WALK_EYE_HEIGHT,
) -> tuple[RecordedPath, str, float]:
    """Import a GeoJSON line as a path of a finished scene (see :func:`import_linestring`).

    Parameters
    ----------
    db, name, replace, eye_height:
        As for :func:`record_path`.
    file:
        The GeoJSON file (or parsed object).
    speed_kmh:
        Speed, km/h.
    clip:
        Keep only the longest stretch inside the cells (see :func:`import_linestring`).

    Returns
    -------
    tuple
        The path, the new scene version and the metres of the line inside the cells.

    Raises
    ------
    SourceError
        A bad GeoJSON file.
    RouteError
        No part of the line lies inside the scene's cells.
    StoreError
        Not a scene database, or the name is taken and ``replace`` is false.
    """
    reader = open_existing(db, name, replace)
    try:
        meta = reader.meta
        graph = CellGraph(reader.cells())
    finally:
        reader.close()
    path, inside = import_linestring(
        file,
        meta.crs,
        meta.origin,
        speed_kmh,
        name,
        clip_to=graph if clip else None,
        cells=graph,
        eye_height=eye_height,
    )
    assert inside is not None
    if path.duration < MIN_PATH_SECONDS:
        raise RouteError(
            f"{name}: {path.length_m():.0f} m at {speed_kmh:g} km/h lasts {path.duration:.3g} s, "
            f"under the {MIN_PATH_SECONDS:g} s a path must last to replay a frame (a speed in m/s?)"
        )
    if inside <= 0:
        raise RouteError(
            f"{os.fspath(file) if not isinstance(file, Mapping) else 'the line'}: no part of "
            f"the line lies inside the view cells of {os.fspath(db)} (a line for another "
            "place, or in another CRS?)"
        )
    return path, write_path(db, name, path.to_msgpack()), inside
