"""Building heights and floor counts from feature properties, and the default rule without them."""

from __future__ import annotations

import math
import re
import zlib
from typing import Any

__all__ = [
    "parse_length", "default_floors", "FLOORS_BY_TYPE", "floor_levels", "is_positive",
    "MAX_HEIGHT", "MAX_FLOORS", "MAX_FLOOR_HEIGHT",
]  # fmt: skip
#: The largest height (m), floor count and floor height (m) taken from a feature; a
#: larger value is a bad value (ignored, the rules go on without it, reported).  The
#: tallest building has 828 m and 163 floors; the grammar derives one module per
#: storey and bay, so 100,000 floors ended the bake at the module limit.
MAX_HEIGHT = 1000.0
MAX_FLOORS = 200
MAX_FLOOR_HEIGHT = 50.0
_FOOT = 0.3048
_HEIGHT_KEYS = ("height", "building:height", "est_height")
_FLOOR_KEYS = ("building:levels", "levels", "floors")
_LENGTH_RE = re.compile(
    r"^\s*([+-]?(?:\d+(?:[.,]\d*)?|[.,]\d+)(?:[eE][+-]?\d+)?)\s*"
    r"(m|metres?|meters?|ft|feet|foot|'|)\s*$",
    re.IGNORECASE,
)


def parse_length(value: object) -> float | None:
    """Parse a length property in metres.

    Accepts numbers and strings such as ``"12"``, ``"12 m"``, ``"12.5m"``, ``"12,5"``
    (decimal comma), ``"40 ft"``, ``"40 feet"``, ``"40'"`` (feet, converted).  Returns
    ``None`` for anything else (booleans, unparsable strings).  The sign and
    finiteness are not checked here.
    """
    if isinstance(value, bool):
        return None
    if isinstance(value, int | float):
        return float(value)
    if isinstance(value, str):
        m = _LENGTH_RE.match(value)
        if m is None:
            return None
        num = float(m.group(1).replace(",", "."))
        return num * _FOOT if m.group(2).lower() in ("ft", "feet", "foot", "'") else num
    return None


#: Floors of a building without height or level tags, by its ``building=*`` value
#: (OpenStreetMap).  Values not listed (``yes`` among them) get the general rule,
#: 4 + crc32(id) % 3 floors.
FLOORS_BY_TYPE: dict[str, int] = {
    "house": 2, "detached": 2, "semidetached_house": 2, "terrace": 2, "bungalow": 1,
    "cabin": 1, "farm": 2, "residential": 2, "apartments": 5, "dormitory": 4,
    "hotel": 6, "commercial": 3, "office": 5, "retail": 1, "supermarket": 1,
    "kiosk": 1, "industrial": 2, "warehouse": 2, "manufacture": 2, "service": 1,
    "garage": 1, "garages": 1, "carport": 1, "shed": 1, "hut": 1, "roof": 1,
    "barn": 2, "farm_auxiliary": 1, "greenhouse": 1, "stable": 1, "transformer_tower": 1,
    "school": 3, "kindergarten": 1, "university": 4, "college": 3, "hospital": 5,
    "public": 3, "civic": 3, "government": 4, "church": 3, "chapel": 1,
    "train_station": 2, "parking": 3, "sports_hall": 2, "toilets": 1,
}  # fmt: skip


def default_floors(feature_id: str, building: object = None) -> int:
    """The default rule's floor count: :data:`FLOORS_BY_TYPE` for a known ``building``
    value, else 4 + crc32(id) % 3 (4 to 6).

    >>> default_floors("w1", "garage"), default_floors("w1", "yes") in (4, 5, 6)
    (1, True)
    """
    if isinstance(building, str) and building.lower() in FLOORS_BY_TYPE:
        return FLOORS_BY_TYPE[building.lower()]
    return 4 + zlib.crc32(feature_id.encode("utf-8")) % 3


# ----------------------------------------------------------------------- assembly


def is_positive(value: float | None) -> bool:
    """Whether ``value`` is a finite number above zero."""
    return value is not None and math.isfinite(value) and value > 0


def floor_levels(
    props: dict[str, Any], fid: str, default_floor_height: float
) -> tuple[int, float, list[str], str]:
    """Floors and floor height of a feature by the module's rules.

    Returns ``(floors, floor_height, bad_values, how)``; ``bad_values`` lists the
    properties that were ignored, ``how`` says which rule decided.
    """
    bad: list[str] = []

    def first_valid(keys: tuple[str, ...], parse: Any, limit: float) -> tuple[str, float] | None:
        for key in keys:
            raw = props.get(key)
            if raw is None or raw == "":
                continue
            value = parse(raw)
            if is_positive(value) and value <= limit:
                return key, float(value)
            bad.append(f"{key}={raw!r}")
        return None

    height = first_valid(_HEIGHT_KEYS, parse_length, MAX_HEIGHT)
    floors_v = first_valid(_FLOOR_KEYS, _parse_count, MAX_FLOORS)
    roof_v = _parse_count(props.get("roof:levels"))
    roof = ("roof:levels", roof_v) if roof_v is not None and math.isfinite(roof_v) and 0 < roof_v <= MAX_FLOORS else None
    if floors_v and roof:
        # OSM counts the floors under the roof apart; the grammar has only floors
        floors_v = (f"{floors_v[0]} + roof:levels", min(floors_v[1] + roof[1], MAX_FLOORS))
    fh_v = first_valid(("floor_height",), parse_length, MAX_FLOOR_HEIGHT)
    floor_height = fh_v[1] if fh_v else default_floor_height
    floors = int(math.floor(floors_v[1] + 0.5)) if floors_v else 0
    if floors_v and floors < 1:
        bad.append(f"{floors_v[0]}={props.get(floors_v[0])!r}")
        floors_v = None
    if height and floors_v:
        return floors, height[1] / floors, bad, f"{height[0]} and {floors_v[0]} used"
    if height:
        floors = min(MAX_FLOORS, max(1, int(math.floor(height[1] / floor_height + 0.5))))
        return floors, height[1] / floors, bad, f"{height[0]} used"
    if floors_v:
        return floors, floor_height, bad, f"{floors_v[0]} used"
    building = props.get("building")
    if isinstance(building, str) and building.lower() in FLOORS_BY_TYPE:
        return default_floors(fid, building), floor_height, bad, f"default for building={building}"
    return default_floors(fid), floor_height, bad, "default rule used"


def _parse_count(value: object) -> float | None:
    """A floor count from a number or numeric string (None when unparsable)."""
    if isinstance(value, bool):
        return None
    if isinstance(value, int | float):
        return float(value)
    if isinstance(value, str):
        try:
            return float(value.strip().replace(",", "."))
        except ValueError:
            return None
    return None
