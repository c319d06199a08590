"""Which typed area (:data:`~walkstream.shared.areakinds.AREA_KINDS`) a polygon's tags make.

OpenStreetMap tags (and GeoJSON properties with the same keys) of a closed way or a
multipolygon that is neither a building nor a street area, read in this order (the
first that applies wins):

``water``
    ``natural=water``, ``water=*``, ``waterway=riverbank|dock``, ``landuse=reservoir|basin``
``parking``
    ``amenity=parking``, ``parking=surface``
``pedestrian``
    ``highway=pedestrian`` on a closed way not tagged ``area=yes`` (with ``area=yes``,
    ``area:highway`` or ``place=square`` it is a square of the street network, which
    the reader sorts out first)
``sport``
    ``leisure=pitch|track|stadium|sports_centre``
``sand``
    ``natural=sand|beach|bare_rock|scree|shingle``
``wood``
    ``landuse=forest``, ``natural=wood|scrub``
``grass``
    ``leisure=park|garden|playground|common|recreation_ground|golf_course|dog_park``,
    ``landuse=grass|meadow|village_green|recreation_ground|cemetery``,
    ``natural=grassland|heath|fell``, ``amenity=grave_yard``
``farmland``
    ``landuse=farmland|farmyard|orchard|vineyard|allotments|plant_nursery|greenhouse_horticulture``
``built``
    any other ``landuse`` (residential, commercial, industrial, retail, railway, ...)

Anything else (another ``leisure`` or ``natural`` value, ``amenity`` other than parking)
makes no area.  A GeoJSON polygon may also say its kind outright: ``kind`` one of the
area kinds.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from walkstream.shared.areakinds import AREA_KINDS

__all__ = ["area_kind"]

_WATER_WATERWAY = {"riverbank", "dock"}
_WATER_LANDUSE = {"reservoir", "basin"}
_SPORT = {"pitch", "track", "stadium", "sports_centre"}
_SAND = {"sand", "beach", "bare_rock", "scree", "shingle"}
_GRASS_LEISURE = {"park", "garden", "playground", "common", "recreation_ground", "golf_course", "dog_park"}
_GRASS_LANDUSE = {"grass", "meadow", "village_green", "recreation_ground", "cemetery"}
_GRASS_NATURAL = {"grassland", "heath", "fell"}
_FARMLAND = {
    "farmland", "farmyard", "orchard", "vineyard", "allotments", "plant_nursery", "greenhouse_horticulture",
}  # fmt: skip


def _v(tags: Mapping[str, Any], key: str) -> str:
    v = tags.get(key)
    return v.strip().lower() if isinstance(v, str) else ""


def area_kind(tags: Mapping[str, Any]) -> str | None:
    """The area kind of a polygon's tags (see the module docstring), or None.

    >>> area_kind({"natural": "water"}), area_kind({"landuse": "residential"}), area_kind({"shop": "bakery"})
    ('water', 'built', None)
    """
    kind = _v(tags, "kind")
    if kind in AREA_KINDS:
        return kind
    landuse, natural, leisure = _v(tags, "landuse"), _v(tags, "natural"), _v(tags, "leisure")
    if natural == "water" or _v(tags, "water") or _v(tags, "waterway") in _WATER_WATERWAY or landuse in _WATER_LANDUSE:
        return "water"
    if _v(tags, "amenity") == "parking" or _v(tags, "parking") == "surface":
        return "parking"
    if _v(tags, "highway") == "pedestrian":
        return "pedestrian"
    if leisure in _SPORT:
        return "sport"
    if natural in _SAND:
        return "sand"
    if landuse == "forest" or natural in ("wood", "scrub"):
        return "wood"
    if (
        leisure in _GRASS_LEISURE
        or landuse in _GRASS_LANDUSE
        or natural in _GRASS_NATURAL
        or _v(tags, "amenity") == "grave_yard"
    ):
        return "grass"
    if landuse in _FARMLAND:
        return "farmland"
    if landuse:
        return "built"
    return None
