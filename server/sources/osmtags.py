"""OpenStreetMap tags: which ways a network keeps, how wide a street is, what is a square.

Both readers of real data use these rules (:mod:`.osm` for ``.osm`` / ``.osm.pbf``
files, :mod:`.geojson` for features carrying OSM-style properties), so a street is
read the same way whatever file it came in.

Networks (``--network``)
    ``walk``: what a pedestrian may use: every ``highway`` class except
    ``motorway``, ``motorway_link``, ``trunk``, ``trunk_link``, ``bus_guideway``,
    ``raceway``, ``construction``, ``proposed``, ``abandoned``, ``platform``,
    ``elevator`` and ``escape``; a way whose ``foot`` is ``no`` (or whose ``access``
    is ``no`` / ``private`` without a ``foot`` that allows it) is left out, and
    ``foot=yes|designated|permissive`` brings back even a class left out.
    ``drive``: what a car may use: ``motorway`` ... ``residential``,
    ``living_street``, ``service``, ``road`` and the ``*_link`` classes; a way with
    ``access``, ``vehicle``, ``motor_vehicle`` or ``motorcar`` = ``no`` / ``private``
    is left out (the last of those given decides).

Widths (metres)
    The ``width`` tag (``"7"``, ``"7 m"``, ``"23 ft"``), else ``lanes`` times
    :data:`LANE_WIDTH`, else :data:`CLASS_WIDTH` by class (``*_link`` as its class),
    else :data:`DEFAULT_WIDTH`.

Layers
    A way is on the ground when its ``layer`` is 0 or absent and it is not a
    tunnel; ``tunnel=building_passage`` (a passage through a building) and
    ``covered=yes`` are on the ground.  ``tunnel=yes|culvert|...`` and any other
    layer (bridges with ``layer=1``, underpasses with ``layer=-1``) are not: the
    street cells are flat, so only the ground network becomes cells.

Squares
    A closed way or multipolygon is a square (an open street area) when it has
    ``area:highway=*``, ``place=square``, or a ``highway`` class with ``area=yes``
    (a pedestrian zone).  Squares belong to the walk network only.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from walkstream.server.sources.heights import parse_length

__all__ = [
    "NETWORKS",
    "LANE_WIDTH",
    "DEFAULT_WIDTH",
    "CLASS_WIDTH",
    "highway_class",
    "in_network",
    "street_width",
    "ground_layer",
    "is_passage",
    "is_square",
]

#: The networks ``--network`` chooses from.
NETWORKS = ("walk", "drive")
#: Metres per lane when a way has ``lanes`` but no ``width``.
LANE_WIDTH = 3.0
#: Width of a way whose class is not in :data:`CLASS_WIDTH`.
DEFAULT_WIDTH = 5.0
#: Width per ``highway`` class (metres), used without ``width`` and ``lanes``.
CLASS_WIDTH: dict[str, float] = {
    "motorway": 11.0,
    "trunk": 10.0,
    "primary": 9.0,
    "secondary": 8.0,
    "tertiary": 7.0,
    "unclassified": 6.0,
    "residential": 6.0,
    "road": 6.0,
    "living_street": 5.0,
    "pedestrian": 6.0,
    "service": 4.0,
    "track": 3.0,
    "busway": 4.0,
    "cycleway": 2.5,
    "footway": 2.0,
    "path": 2.0,
    "bridleway": 2.0,
    "steps": 2.0,
    "corridor": 2.0,
    "crossing": 2.0,
}

_NOT_WALK = {
    "motorway", "trunk", "bus_guideway", "raceway", "construction", "proposed",
    "abandoned", "platform", "elevator", "escape", "razed", "disused",
}  # fmt: skip
_DRIVE = {
    "motorway", "trunk", "primary", "secondary", "tertiary", "unclassified",
    "residential", "living_street", "service", "road",
}  # fmt: skip
_FOOT_OK = {"yes", "designated", "permissive", "official", "destination"}
_CLOSED = {"no", "private"}


def highway_class(tags: Mapping[str, Any]) -> str | None:
    """The ``highway`` value with ``_link`` dropped (``motorway_link`` -> ``motorway``)."""
    hw = tags.get("highway")
    if not isinstance(hw, str) or not hw:
        return None
    return hw[: -len("_link")] if hw.endswith("_link") else hw


def in_network(tags: Mapping[str, Any], network: str) -> bool:
    """Whether a ``highway`` way belongs to the ``walk`` or ``drive`` network (see above).

    >>> in_network({"highway": "footway"}, "walk"), in_network({"highway": "footway"}, "drive")
    (True, False)
    >>> in_network({"highway": "residential", "foot": "no"}, "walk")
    False
    """
    cls = highway_class(tags)
    if cls is None:
        return False
    if network == "walk":
        foot = str(tags.get("foot", "")).lower()
        if foot in _FOOT_OK:
            return True
        if foot == "no" or cls in _NOT_WALK:
            return False
        return str(tags.get("access", "")).lower() not in _CLOSED
    if network == "drive":
        if cls not in _DRIVE:
            return False
        decide = [
            str(tags[k]).lower()
            for k in ("access", "vehicle", "motor_vehicle", "motorcar")
            if k in tags
        ]
        return not decide or decide[-1] not in _CLOSED
    raise ValueError(f"network must be one of {NETWORKS}, got {network!r}")


def street_width(tags: Mapping[str, Any]) -> tuple[float, str | None]:
    """Width in metres by the module's rules, and a note when a tag had to be ignored.

    >>> street_width({"highway": "residential"})
    (6.0, None)
    >>> street_width({"highway": "primary", "lanes": "4"})
    (12.0, None)
    >>> street_width({"highway": "footway", "width": "1,5"})
    (1.5, None)
    """
    note = None
    raw = tags.get("width")
    if raw is not None and raw != "":
        w = parse_length(raw)
        if w is not None and 0 < w < 200:
            return float(w), None
        note = f"bad width={raw!r} ignored"
    lanes = tags.get("lanes")
    if lanes is not None and lanes != "":
        try:
            n = float(str(lanes).split(";")[0].strip())
        except ValueError:
            n = 0.0
        if 0 < n <= 20:
            return n * LANE_WIDTH, note
        note = (note + "; " if note else "") + f"bad lanes={lanes!r} ignored"
    cls = highway_class(tags)
    return CLASS_WIDTH.get(cls or "", DEFAULT_WIDTH), note


def ground_layer(tags: Mapping[str, Any]) -> tuple[bool, str]:
    """Whether a way lies on the ground, and what it is when it does not.

    Returns ``(True, "")`` or ``(False, reason)`` with reason ``"tunnel"`` or
    ``"layer N"`` (see the module docstring).

    >>> ground_layer({"tunnel": "building_passage"}), ground_layer({"bridge": "yes", "layer": "1"})
    ((True, ''), (False, 'layer 1'))
    """
    tunnel = str(tags.get("tunnel", "no")).lower()
    if tunnel not in ("no", "building_passage", "") and str(tags.get("covered", "")).lower() != "yes":
        return False, "tunnel"
    raw = tags.get("layer")
    if raw is None or raw == "":
        return True, ""
    try:
        layer = int(float(str(raw).split(";")[0].strip()))
    except ValueError:
        return True, ""  # an unreadable layer: taken as the ground
    if layer == 0 or tunnel == "building_passage":
        return True, ""
    return False, f"layer {layer}"


def is_passage(tags: Mapping[str, Any]) -> bool:
    """``tunnel=building_passage``: a street that passes under a building (kept as cells)."""
    return str(tags.get("tunnel", "")).lower() == "building_passage"


def is_square(tags: Mapping[str, Any]) -> bool:
    """Whether a closed way / multipolygon is an open street area (see the module docstring).

    >>> is_square({"highway": "pedestrian", "area": "yes"}), is_square({"highway": "residential"})
    (True, False)
    """
    if tags.get("area:highway") or str(tags.get("place", "")).lower() == "square":
        return True
    return highway_class(tags) is not None and str(tags.get("area", "")).lower() == "yes"
