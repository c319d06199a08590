"""What the server and the client both need: records, errors, wire formats, geometry, buildings.

The public names below are imported lazily (on first use), so that a small module
such as :mod:`.errors` can be imported alone.  The modules: :mod:`.errors` (every
error class), :mod:`.records` (parameters, meshes, viewpoints), :mod:`.wire` (the
API's records), :mod:`.codec` (compact encodings), :mod:`.scene` (cell kinds and
their visibility models), :mod:`.cells` (locating points), :mod:`.geometry`,
:mod:`.paths` (recorded paths), :mod:`.lsystem` and :mod:`.buildings` (procedural
buildings), :mod:`.streets`, :mod:`.camera`, :mod:`.gl` (headless OpenGL),
:mod:`.palette`, :mod:`.export` (glTF).
"""

from walkstream.shared.exports import lazy_exports

_EXPORTS = {
    "WalkstreamError": "walkstream.shared.errors",
    "InputError": "walkstream.shared.errors",
    "GrammarError": "walkstream.shared.errors",
    "DerivationLimitError": "walkstream.shared.errors",
    "DatabaseDamagedError": "walkstream.shared.errors",
    "SourceError": "walkstream.shared.errors",
    "CodecError": "walkstream.shared.errors",
    "RenderError": "walkstream.shared.errors",
    "StoreError": "walkstream.shared.errors",
    "NotFoundError": "walkstream.shared.errors",
    "CacheDamagedError": "walkstream.shared.errors",
    "RouteError": "walkstream.shared.errors",
    "ApiError": "walkstream.shared.errors",
    "StreamCut": "walkstream.shared.errors",
    "ServiceError": "walkstream.shared.errors",
    "SimulationStalled": "walkstream.shared.errors",
    "AreaParams": "walkstream.shared.records",
    "BuildingParams": "walkstream.shared.records",
    "StreetParams": "walkstream.shared.records",
    "Mesh": "walkstream.shared.records",
    "Viewpoint": "walkstream.shared.records",
    "readonly": "walkstream.shared.records",
    "Manifest": "walkstream.shared.wire",
    "CellRecord": "walkstream.shared.wire",
    "ObjectFrame": "walkstream.shared.wire",
    "CELL_KINDS": "walkstream.shared.scene.cellkinds",
    "CellLocator": "walkstream.shared.cells",
    "inside_convex": "walkstream.shared.cells",
    "signed_area": "walkstream.shared.geometry",
    "triangulate_rings": "walkstream.shared.geometry",
    "RecordedPath": "walkstream.shared.paths",
    "Grammar": "walkstream.shared.lsystem.grammar",
    "parse_grammar": "walkstream.shared.lsystem.grammar",
    "load_grammar": "walkstream.shared.lsystem.grammar",
    "build_lod": "walkstream.shared.buildings",
    "build_lods": "walkstream.shared.buildings",
    "build_lod_batch": "walkstream.shared.buildings",
    "build_lods_batch": "walkstream.shared.buildings",
    "default_grammar": "walkstream.shared.buildings",
    "default_grammar_text": "walkstream.shared.buildings",
    "build_street": "walkstream.shared.streets",
    "build_area": "walkstream.shared.areas",
    "create_context": "walkstream.shared.gl",
    "export_glb": "walkstream.shared.export",
}

__all__ = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
