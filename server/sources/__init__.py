"""Scene sources: what the bake reads, made into buildings and street pieces in local metres.

:mod:`.geojson` (footprints and streets, with :mod:`.features`, :mod:`.rings`,
:mod:`.heights`, :mod:`.partywalls`), :mod:`.citygen` (generated cities),
:mod:`.crs` (coordinate systems, the one lon/lat check), :mod:`.jsonfile`,
:mod:`.geojsonlines` (a walk recorded as a line), :mod:`.clip` (``--bbox``);
:mod:`.scene` is what every source hands to the bake.  A new source (an
OpenStreetMap reader) is a module here returning a :class:`SourceScene`.
"""

from walkstream.server.sources.citygen import city_summary, generate_city, write_city
from walkstream.server.sources.clip import clip_scene
from walkstream.server.sources.geojson import load_geojson, load_geojson_dict
from walkstream.server.sources.geojsonlines import read_linestring
from walkstream.server.sources.partywalls import find_party_walls
from walkstream.server.sources.scene import FeatureIssue, SourceScene

__all__ = [
    "SourceScene",
    "FeatureIssue",
    "load_geojson",
    "load_geojson_dict",
    "generate_city",
    "write_city",
    "city_summary",
    "find_party_walls",
    "clip_scene",
    "read_linestring",
]
