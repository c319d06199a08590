"""The server side: scene sources, the bake, the scene database and the HTTP service.

Folders follow the flow of the data: :mod:`.sources` (generated cities, GeoJSON, CRS)
-> :mod:`.bake` (cells, sample points, visibility, navigation graph, walks, map) ->
:mod:`.store` (schema, writer, reader, edits) -> :mod:`.service` (the FastAPI app).
:mod:`.paths` adds recorded paths to a finished scene.  The service never imports
the bake.  Public names are imported lazily.
"""

from walkstream.shared.exports import lazy_exports

_EXPORTS = {
    "SourceScene": "walkstream.server.sources.scene",
    "FeatureIssue": "walkstream.server.sources.scene",
    "load_geojson": "walkstream.server.sources.geojson",
    "load_geojson_dict": "walkstream.server.sources.geojson",
    "generate_city": "walkstream.server.sources.citygen",
    "write_city": "walkstream.server.sources.citygen",
    "bake": "walkstream.server.bake.pipeline",
    "BakeSettings": "walkstream.server.bake.settings",
    "make_cells": "walkstream.server.bake.cells",
    "ViewCell": "walkstream.server.bake.viewcell",
    "CellGraph": "walkstream.server.bake.navgraph",
    "default_paths": "walkstream.server.bake.walks",
    "SceneReader": "walkstream.server.store.reader",
    "SceneWriter": "walkstream.server.store.writer",
    "write_path": "walkstream.server.store.edit",
    "create_app": "walkstream.server.service.main",
    "serve": "walkstream.server.service.run",
    "server_process": "walkstream.server.service.process",
    "record_path": "walkstream.server.paths.record",
    "import_path": "walkstream.server.paths.importline",
}

__all__ = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
