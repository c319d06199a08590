"""The outside cell's long groups cut into columns, each part with a small box (server/bake/outsidetiles.py)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from walkstream.server.bake.outsidetiles import (
    LONG_TILES,
    OUTSIDE_TILE_M,
    outside_parts,
    tile_triangles,
)


def _area(tris: np.ndarray) -> float:
    return float(0.5 * np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1).sum())


def _normals(tris: np.ndarray) -> np.ndarray:
    n = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def _facade(length: float, height: float = 3.0, y: float = -0.3) -> np.ndarray:
    """A wall's outer face from x = 0.5 to 0.5 + length, two triangles facing -y."""
    a, b = 0.5, 0.5 + length
    p = np.array([[a, y, 0.0], [b, y, 0.0], [b, y, height], [a, y, height]])
    return np.array([[p[0], p[1], p[2]], [p[0], p[2], p[3]]])


def test_a_long_face_is_clipped_into_columns_keeping_area_and_winding() -> None:
    face = _facade(17.0)
    tri, src, cube = tile_triangles(face, 4.0)
    assert _area(tri) == pytest.approx(_area(face), rel=1e-9)
    # every piece lies in the column of its centroid (x and y), heights uncut
    lo, hi = cube[:, None, :2] * 4.0 - 1e-9, (cube[:, None, :2] + 1) * 4.0 + 1e-9
    assert np.all((tri[:, :, :2] >= lo) & (tri[:, :, :2] <= hi))
    assert set(cube[:, 0].tolist()) == {0, 1, 2, 3, 4}  # 0.5 .. 17.5 m: five columns
    assert np.all(cube[:, 2] == 0)
    # winding: every piece faces as the triangle it comes from
    assert np.allclose(_normals(tri), _normals(face)[src])
    with pytest.raises(ValueError, match="tile"):
        tile_triangles(face, 0.0)


def test_only_long_groups_are_cut() -> None:
    long_face, short = _facade(17.0), _facade(LONG_TILES * 4.0 - 0.5) + np.array([0.0, 0.0, 3.0])
    soup = np.concatenate([long_face, short])
    elem = np.array([7, 7, 9, 9])
    mat = np.array([1, 1, 1, 1])
    parts = outside_parts(soup, elem, mat, 4.0)
    whole = [p for p in parts if p[0] == 9]
    cut = [p for p in parts if p[0] == 7]
    assert len(whole) == 1 and len(whole[0][3]) == 2  # a window, a beam, a door: kept whole
    assert len(cut) == 5
    for _, m, v, t in cut:
        assert m == 1
        span = v[t].reshape(-1, 3).max(axis=0) - v[t].reshape(-1, 3).min(axis=0)
        assert span[0] <= 4.0 + 1e-9
    assert sum(_area(v[t]) for _, _, v, t in cut) == pytest.approx(_area(long_face))
    # 0: one part per element and material, as before
    assert [(e, len(t)) for e, _, _, t in outside_parts(soup, elem, mat, 0.0)] == [(7, 2), (9, 2)]


def test_a_generated_offices_facades_reach_the_outside_cell_in_columns(tmp_path: Path) -> None:
    """The bake's outside cell: no part spans more than two columns across, while the same
    surface is there (the area of every element's outside triangles unchanged)."""
    from walkstream.server.bake.interior import interior_parts, room_contents
    from walkstream.server.sources.interior import InteriorScene
    from walkstream.server.sources.interiorgen import InteriorPlan, write_interior
    from walkstream.server.sources.read import read_source

    write_interior(tmp_path / "office.json", InteriorPlan(storeys=1, length=26.0, width=8.0, seed=4, furniture=0.0))
    scene = read_source(tmp_path / "office.json")
    assert isinstance(scene, InteriorScene)
    layout = interior_parts(scene, tmp_path / "office.json").layout
    cut = room_contents(scene, layout)[layout.outside]
    whole = room_contents(scene, layout, outside_tile=0.0)[layout.outside]
    spans = [float(np.ptp(v[t].reshape(-1, 3)[:, :2], axis=0).max()) for _, _, v, t in cut]
    assert max(float(np.ptp(v[t].reshape(-1, 3)[:, :2], axis=0).max()) for _, _, v, t in whole) > 26.0
    assert max(spans) <= LONG_TILES * OUTSIDE_TILE_M + 1e-6  # cut into columns, or short enough to stay whole
    assert len(cut) > len(whole)
    area = {}
    for e, _, v, t in whole:
        area[e] = area.get(e, 0.0) + _area(v[t])
    for e, _, v, t in cut:
        area[e] -= _area(v[t])
    assert max(abs(a) for a in area.values()) < 1e-6
