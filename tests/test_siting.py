"""Which footprint an interior goes into, how it is turned and where its door goes (hand-made inputs)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import shapely

from walkstream.server.bake.cells import make_cells
from walkstream.server.bake.frontpath import front_path, with_front_path
from walkstream.server.bake.placement import FIT_TOLERANCE, EntranceDoor, fit_in_footprint
from walkstream.server.bake.siting import site_interior
from walkstream.server.sources.interiorgen import InteriorPlan, write_interior
from walkstream.server.sources.read import read_source
from walkstream.shared.errors import InputError

# a 13 x 11 m shell, its door 2 m wide in the middle of its south wall
SHELL = shapely.box(-6.5, -5.5, 6.5, 5.5)
DOOR = EntranceDoor(0, 0, np.array([[-1.0, -5.5], [1.0, -5.5]]), 0.0, 2.2, np.array([0.0, -1.0]))
# a street along y = 0 from x = -40 to 40, 6 m wide
STREET = shapely.box(-40.0, -3.0, 40.0, 3.0)


def _box(x0: float, y0: float, x1: float, y1: float) -> np.ndarray:
    return np.asarray(shapely.box(x0, y0, x1, y1).exterior.coords)[:-1]


def test_a_model_fits_a_footprint_of_its_size_with_its_door_to_the_street() -> None:
    # a footprint 0.8 x 0.6 m larger, 4 m back from the street, its long side along it
    fit = fit_in_footprint(DOOR, SHELL, _box(-6.9, 7.0, 6.9, 18.6), [STREET])
    assert fit is not None
    placed = shapely.Polygon(fit.placement.xy(np.asarray(SHELL.exterior.coords)))
    assert fit.match > 0.85 and fit.overhang < 0.05
    # the door faces the street (south) and sits on the footprint's street side
    assert fit.placement.turn(DOOR.normal) == pytest.approx([0.0, -1.0], abs=1e-9)
    assert placed.bounds[1] == pytest.approx(7.0, abs=1e-6)
    assert fit.gap == pytest.approx(4.0 - 0.1, abs=1e-6)


def test_the_door_turns_to_the_street_whichever_side_it_is_on() -> None:
    east = shapely.box(10.0, -40.0, 16.0, 40.0)
    fit = fit_in_footprint(DOOR, SHELL, _box(-2.0, -7.0, 9.0, 7.0), [east])
    assert fit is not None
    assert fit.placement.turn(DOOR.normal) == pytest.approx([1.0, 0.0], abs=1e-9)
    assert fit.gap < 1.0


def test_fits_means_at_most_the_tolerance_outside_the_footprint() -> None:
    assert FIT_TOLERANCE == 1.0
    # 0.6 m smaller each way than the shell: 0.3 m outside on every side
    fit = fit_in_footprint(DOOR, SHELL, _box(-6.2, 7.3, 6.2, 17.7), [STREET])
    assert fit is not None and 0.2 < fit.overhang <= FIT_TOLERANCE
    # 2.4 m smaller: at least 1.2 m outside
    assert fit_in_footprint(DOOR, SHELL, _box(-5.3, 8.2, 5.3, 16.8), [STREET]) is None


def test_a_shell_may_not_overhang_onto_a_neighbour_or_a_street() -> None:
    small = _box(-6.2, 3.0, 6.2, 13.4)  # 0.6 m too narrow: slid flush with one end, 0.6 m over the other
    east, west = shapely.box(6.2, 3.0, 12.0, 40.0), shapely.box(-12.0, 3.0, -6.2, 40.0)
    fit = fit_in_footprint(DOOR, SHELL, small, [STREET, east])
    assert fit is not None and fit.placement.shift[0] == pytest.approx(-0.3)
    # between two side streets it would stand on one of them
    assert fit_in_footprint(DOOR, SHELL, small, [STREET, east, west]) is None
    away = _box(-6.2, 7.3, 6.2, 17.7)
    # terraced: neighbours touching either side (party walls)
    neighbours = [shapely.box(6.2, 7.0, 20.0, 18.0), shapely.box(-20.0, 7.0, -6.2, 18.0)]
    assert fit_in_footprint(DOOR, SHELL, away, [STREET], obstacles=neighbours[:1]) is not None
    assert fit_in_footprint(DOOR, SHELL, away, [STREET], obstacles=neighbours) is None
    assert fit_in_footprint(DOOR, SHELL, away, [STREET], obstacles=[shapely.box(30, 7, 40, 18)]) is not None


def test_a_front_path_joins_the_street_to_a_door_set_back() -> None:
    ends = np.array([[-1.0, 7.0], [1.0, 7.0]])
    path = front_path(ends, np.array([0.0, -1.0]), STREET)
    assert path is not None
    quad = shapely.Polygon(path)
    assert quad.is_valid and quad.convex_hull.area == pytest.approx(quad.area)
    assert quad.exterior.is_ccw
    shared = quad.boundary.intersection(STREET.boundary)
    assert shared.length >= 2.0 and quad.intersection(STREET).area < 1e-6
    assert quad.distance(shapely.Point(0.0, 7.0)) < 1e-9
    # a shed between the door and the street blocks it
    assert front_path(ends, np.array([0.0, -1.0]), STREET, [shapely.box(-3.0, 4.0, 3.0, 5.0)]) is None


def _fc(*features: dict[str, Any]) -> dict[str, Any]:
    return {"type": "FeatureCollection", "crs": {"type": "name", "properties": {"name": "EPSG:32633"}},
            "features": list(features)}


def _building(fid: str, x0: float, y0: float, x1: float, y1: float) -> dict[str, Any]:
    x, y = 600_000.0, 5_340_000.0
    ring = [[x + x0, y + y0], [x + x1, y + y0], [x + x1, y + y1], [x + x0, y + y1], [x + x0, y + y0]]
    return {"type": "Feature", "id": fid, "properties": {"building": "yes", "building:levels": 2},
            "geometry": {"type": "Polygon", "coordinates": [ring]}}


@pytest.fixture(scope="module")
def street_of_three(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A street with three buildings north of it: too small, one of the office's size
    5 m back, a large one on the street; and a 12 x 10 m office (12.6 x 10.6 outside)."""
    d = tmp_path_factory.mktemp("siting")
    x, y = 600_000.0, 5_340_000.0
    street = {"type": "Feature", "id": "s", "properties": {"highway": "residential"},
              "geometry": {"type": "LineString", "coordinates": [[x - 60, y], [x + 70, y]]}}
    city = _fc(street, _building("small", -50, 5, -44, 11), _building("match", 0, 8, 10.9, 20.9),
               _building("large", 20, 3, 60, 33))
    (d / "city.geojson").write_text(json.dumps(city))
    write_interior(d / "office.json", InteriorPlan(storeys=1, length=12, width=10, seed=1))
    return d / "city.geojson", d / "office.json"


def test_auto_picks_the_footprint_that_matches_in_size_and_shape(street_of_three: tuple[Path, Path]) -> None:
    city_path, office = street_of_three
    city, inner = read_source(city_path), read_source(office)
    cells = make_cells(city)
    s = site_interior(city, cells, inner, "auto")
    assert city.buildings[s.index].source_id == "match"
    assert s.fit.match > 0.9 and 3.0 < s.fit.gap < 6.0
    # the door is back from the street: a front path cell joins them
    assert s.path is not None
    joined = with_front_path(cells, s.path, s.placement.xy(s.door.middle[None])[0] + s.placement.turn(s.door.normal) * 0.1)
    new = joined[-1]
    assert new.id == len(cells) and new.kind == "street" and len(new.neighbours) == 1
    assert new.id in joined[new.neighbours[0]].neighbours
    # --building names one: the large one takes the office too, with its door on the street
    big = site_interior(city, cells, inner, "large")
    assert city.buildings[big.index].source_id == "large" and big.path is None and big.fit.match < 0.2


def test_a_building_too_small_says_which_and_why(street_of_three: tuple[Path, Path]) -> None:
    city_path, office = street_of_three
    city, inner = read_source(city_path), read_source(office)
    cells = make_cells(city)
    with pytest.raises(InputError, match=r"does not fit building \d+ \(small\): its outline .* more than 1 m outside"):
        site_interior(city, cells, inner, "small")
    with pytest.raises(InputError, match="no building with that"):
        site_interior(city, cells, inner, "nope")


def test_nothing_fits_names_the_nearest_in_size(street_of_three: tuple[Path, Path], tmp_path: Path) -> None:
    city_path, _ = street_of_three
    write_interior(tmp_path / "huge.json", InteriorPlan(storeys=1, length=60, width=40, seed=1))
    city = read_source(city_path)
    with pytest.raises(InputError, match=r"no building of the city holds the interior .* the nearest in size, building"):
        site_interior(city, make_cells(city), read_source(tmp_path / "huge.json"), "auto")
