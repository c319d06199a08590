"""Content kinds: one module per kind, one registry of them (:mod:`.registry`).

The modules: :mod:`.kind` (the record that names a kind's parts), :mod:`.registry`
(every kind, and what a new one takes), :mod:`.params` (procedural parameters of
buildings and streets), :mod:`.mesh` (objects' LOD2 meshes rebuilt by the service),
:mod:`.cellmesh` (an interior cell's meshes), :mod:`.impostor` (an image standing in for a
far or complex building).
"""

from walkstream.shared.exports import lazy_exports

_EXPORTS = {
    "ContentKind": "walkstream.shared.content.kind",
    "CONTENT_KINDS": "walkstream.shared.content.registry",
    "content_kind": "walkstream.shared.content.registry",
    "by_form": "walkstream.shared.content.registry",
    "object_forms": "walkstream.shared.content.registry",
    "cache_kinds": "walkstream.shared.content.registry",
    "frame_keys": "walkstream.shared.content.registry",
}

__all__ = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
