"""Scene sources: what the bake reads, made into buildings and street pieces in local metres.

:mod:`.read` picks the reader by the file's ending (one table).  Cities:
:mod:`.geojson` and :mod:`.osm` (OpenStreetMap ``.osm`` / ``.osm.pbf``), both finished by
:mod:`.assemble` (with :mod:`.features`, :mod:`.rings`, :mod:`.heights`,
:mod:`.partywalls`), :mod:`.osmtags` (networks, widths, layers, squares),
:mod:`.network` (street networks), :mod:`.citygen` (generated cities); :mod:`.scene` is
what a city source hands to the bake.  Interiors: :mod:`.ifc` (IFC models),
:mod:`.interiorfile` (the ``walkstream-interior`` format, with :mod:`.interiormesh`),
:mod:`.interiorgen` (generated offices); :mod:`.interior` is what an interior source
hands to the bake.  Shared: :mod:`.crs` (coordinate systems, the one lon/lat check),
:mod:`.jsonfile`, :mod:`.geojsonlines` and :mod:`.gpx` (a walk recorded as a line or a
track), :mod:`.clip` (``--bbox``).  A new source format is a module here returning a
:class:`SourceScene` (or an interior) and one row of :data:`.read.READERS`.
"""

from walkstream.server.sources.citygen import generate_city, write_city
from walkstream.server.sources.citysummary import city_summary
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
