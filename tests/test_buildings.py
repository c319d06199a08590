"""Buildings rebuilt from parameters with the grammar: LODs, party walls, traps."""

from __future__ import annotations

import re

import numpy as np
import pytest
import trimesh

from walkstream.shared.buildings import (
    build_lod,
    build_lods,
    default_grammar,
    default_grammar_text,
    derive_building,
    predict_triangles,
)
from walkstream.shared.lsystem.derive import evaluate_lets
from walkstream.shared.lsystem.grammar import parse_grammar
from walkstream.shared.records import BuildingParams, Mesh


def rect(w: float, d: float, x: float = 0.0, y: float = 0.0) -> np.ndarray:
    return np.array([[x, y], [x + w, y], [x + w, y + d], [x, y + d]], float)


def building(rings: list[np.ndarray], floors: int = 3, nb: list[np.ndarray] | None = None, **kw) -> BuildingParams:
    heights = nb if nb is not None else [np.zeros(len(r)) for r in rings]
    return BuildingParams(0, tuple(rings), tuple(heights), floors=floors, floor_height=kw.pop("fh", 3.0), **kw)


def footprint_area(b: BuildingParams) -> float:
    from walkstream.shared.geometry import signed_area

    return sum(signed_area(r) for r in b.rings)


def assert_closed_solid(m: Mesh, volume: float) -> None:
    t = trimesh.Trimesh(m.positions.astype(np.float64), m.indices, process=True)
    assert t.is_watertight
    assert t.is_winding_consistent
    # positive volume: faces wind outward
    assert t.volume == pytest.approx(volume, rel=1e-4)


def assert_normals_match_winding(m: Mesh) -> None:
    """Every vertex normal agrees with its triangle's counter-clockwise face normal."""
    p = m.positions.astype(np.float64)
    a, b, c = p[m.indices[:, 0]], p[m.indices[:, 1]], p[m.indices[:, 2]]
    face = np.cross(b - a, c - a)
    good = np.linalg.norm(face, axis=1) > 1e-9
    vn = m.normals[m.indices[:, 0]].astype(np.float64)
    dots = np.einsum("ij,ij->i", face[good], vn[good])
    assert (dots > 0).all()


FOOTPRINTS = {
    "rectangle": [rect(20, 12)],
    "l_shape": [np.array([[0, 0], [20, 0], [20, 8], [8, 8], [8, 18], [0, 18]], float)],
    "courtyard": [rect(30, 30), rect(14, 14, 8, 8)[::-1]],
    "collinear": [np.array([[0, 0], [10, 0], [20, 0], [20, 12], [0, 12]], float)],
    "clockwise": [rect(20, 12)[::-1]],
}


@pytest.mark.parametrize("name", sorted(FOOTPRINTS))
def test_lod0_is_a_closed_outward_prism(name: str) -> None:
    b = building(FOOTPRINTS[name], floors=4)
    m0 = build_lod(b, 0)
    assert_closed_solid(m0, footprint_area(b) * b.height)
    assert_normals_match_winding(m0)


@pytest.mark.parametrize("name", sorted(FOOTPRINTS))
def test_lod_triangle_counts_increase_and_normals_face_out(name: str) -> None:
    b = building(FOOTPRINTS[name], floors=3)
    meshes = build_lods(b)
    tris = [m.triangles for m in meshes]
    assert tris[0] < tris[1] < tris[2]
    assert tuple(tris) == predict_triangles(b)
    for m in meshes:
        assert_normals_match_winding(m)
    # walls face away from the footprint: sample wall vertices, step out along the normal
    from shapely.geometry import Point, Polygon

    poly = Polygon(b.rings[0], b.rings[1:])
    m1 = meshes[1]
    # plain walls only: a ledge's end cap at a re-entrant corner rightly faces the other wing
    walls = (np.abs(m1.normals[:, 2]) < 0.5) & np.isin(m1.materials, (0, 8))
    assert walls.any()
    pts = m1.positions[walls][::7, :2].astype(float) + 0.05 * m1.normals[walls][::7, :2]
    assert not any(poly.contains(Point(p)) for p in pts)


def test_lod1_frontage_walls_are_shared_with_lod2() -> None:
    b = building([rect(24, 10)], floors=2)
    m1, m2 = build_lod(b, 1), build_lod(b, 2)

    def tri_set(m: Mesh) -> set[bytes]:
        return {np.round(m.positions[t], 4).tobytes() for t in m.indices}

    assert tri_set(m1) <= tri_set(m2)


def test_party_wall_starts_at_neighbour_height_and_has_no_openings() -> None:
    ring = rect(20, 10)
    # edge 1 (x = 20) has a 6 m neighbour, edge 3 (x = 0) a neighbour taller than us
    nb = np.array([0.0, 6.0, 0.0, 40.0])
    b = building([ring], floors=4, nb=[nb], fh=3.0)
    for lod in (1, 2):
        m = build_lod(b, lod)
        tri = m.positions[m.indices].astype(float)  # (t, 3, 3)
        centre = tri.mean(axis=1)
        nrm = m.normals[m.indices[:, 0]]
        mats = m.materials[m.indices[:, 0]]
        # away from the corners, where the frontages' ledges end
        inner = (centre[:, 1] > 0.5) & (centre[:, 1] < 9.5)
        east = np.isclose(centre[:, 0], 20.0, atol=1e-4) & (nrm[:, 0] > 0.9) & inner
        assert east.any()
        assert tri[east][..., 2].min() == pytest.approx(6.0)
        assert set(mats[east]) == {8}  # party wall material, no windows or doors
        west = (centre[:, 0] < 0.2) & (nrm[:, 0] < -0.9) & inner
        assert not west.any()
    # LOD0 keeps every wall so the massing stays watertight
    assert_closed_solid(build_lod(b, 0), 200.0 * 12.0)


def test_two_windows_per_bay_and_no_door_by_editing_the_grammar_text() -> None:
    text = default_grammar_text()
    text = re.sub(r"^let WPB = .*$", "let WPB = 2", text, flags=re.M)
    text = re.sub(r"^let HAS_DOOR = .*$", "let HAS_DOOR = 0", text, flags=re.M)
    text = re.sub(r"^let BAY = .*$", "let BAY = 4.0", text, flags=re.M)
    g = parse_grammar(text)
    w, d, floors = 24.0, 10.0, 3
    b = building([rect(w, d)], floors=floors)
    # per frontage and floor: wall quad (2) + ledge box (10); per frontage: parapet box (10);
    # per window: pane quad (2) + sill and lintel boxes (2 x 10); roof: 2 triangles
    bays = lambda length: max(1, int(length // 4.0))  # noqa: E731
    windows = floors * 2 * sum(2 * bays(length) for length in (w, d))
    lod1 = 2 + 4 * (floors * 12 + 10)
    lod2 = lod1 + windows * 22
    assert predict_triangles(b, g) == (12, lod1, lod2)
    m2 = build_lod(b, 2, g)
    assert m2.triangles == lod2
    assert not (m2.materials == 2).any()  # no door
    # the unedited grammar has a door and one window per bay
    assert (build_lod(b, 2).materials == 2).any()


def test_one_square_metre_building_and_a_200_floor_tower() -> None:
    tiny = building([rect(1, 1)], floors=1)
    m = build_lods(tiny)
    assert_closed_solid(m[0], 3.0)
    assert m[0].triangles < m[1].triangles
    tower = building([rect(30, 30)], floors=200)
    t0, t1, t2 = predict_triangles(tower)
    assert t2 > 200 * 4 * 12
    assert build_lod(tower, 2).triangles == t2


def test_duplicate_vertices_do_not_break_the_rebuild() -> None:
    ring = np.array([[0, 0], [10, 0], [10, 0], [10, 8], [0, 8]], float)
    b = building([ring], floors=2)
    m0 = build_lod(b, 0)
    assert_closed_solid(m0, 80.0 * 6.0)
    assert build_lod(b, 2).triangles > build_lod(b, 1).triangles


def test_derivation_reports_terminals_only() -> None:
    mods = derive_building(building([rect(12, 9)], floors=2), 2)
    assert set(mods) <= {"Quad", "Box", "Cap"}


def test_style_seed_varies_the_facade() -> None:
    scope = [evaluate_lets(default_grammar(), {"S": s, "F": 3, "FH": 3, "H": 9, "LOD": 2, "LMAX": 10, "K": 0, "LMIN": 0, "T": 9})["BAY"] for s in range(20)]
    assert len(set(np.round(scope, 3))) > 10
    a = build_lod(building([rect(40, 10)], floors=2, style=1), 2).triangles
    b = [build_lod(building([rect(40, 10)], floors=2, style=s), 2).triangles for s in range(2, 12)]
    assert any(x != a for x in b)


def test_far_from_origin_footprint_rebuilds_like_one_at_the_origin() -> None:
    """Projected coordinates of millions of metres reach the builder as local float64."""
    from walkstream.server.sources.geojson import load_geojson_dict

    def fc(x0: float, y0: float) -> dict:
        ring = (rect(23.37, 11.91) + [x0, y0]).tolist()
        ring.append(ring[0])
        return {
            "type": "FeatureCollection",
            "crs": {"type": "name", "properties": {"name": "EPSG:32633"}},
            "features": [
                {"type": "Feature", "id": "a", "properties": {"floors": 4},
                 "geometry": {"type": "Polygon", "coordinates": [ring]}},
            ],
        }

    far = load_geojson_dict(fc(612_345.678, 5_000_000.123)).buildings[0]
    near = load_geojson_dict(fc(0.0, 0.0)).buildings[0]
    for lod in (0, 1, 2):
        a, b = build_lod(far, lod), build_lod(near, lod)
        assert a.triangles == b.triangles
        # same local geometry once each scene's own origin is taken away
        da = a.positions - a.positions.min(axis=0)
        db = b.positions - b.positions.min(axis=0)
        assert np.abs(da - db).max() < 1e-3
