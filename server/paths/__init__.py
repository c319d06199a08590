"""Recorded paths added to a finished scene: routed along its cells, or imported from a line.

Each writes a new scene version with :func:`walkstream.server.store.write_path`.  The
path format is :mod:`walkstream.shared.paths`; the default walks the bake records
are :mod:`walkstream.server.bake.walks`.
"""

from walkstream.server.paths.importline import import_linestring, import_path
from walkstream.server.paths.record import record_path

__all__ = ["record_path", "import_path", "import_linestring"]
