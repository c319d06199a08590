"""Recorded paths added to a finished scene: routed on its navigation graph, or imported from a line.

:mod:`.graph` reads a scene's one navigation graph (streets, rooms, entrances) from its
database; :mod:`.record` routes on it (:func:`record_path` along streets,
:func:`record_walk` through rooms and entrances); :mod:`.importline` imports a line.  Each writes a new scene version with :func:`walkstream.server.store.write_path`.  The
path format is :mod:`walkstream.shared.paths`; the default walks the bake records
are :mod:`walkstream.server.bake.walks`.
"""

from walkstream.server.paths.graph import scene_graph
from walkstream.server.paths.importline import import_linestring, import_path
from walkstream.server.paths.record import record_path, record_walk

__all__ = ["record_path", "record_walk", "scene_graph", "import_path", "import_linestring"]
