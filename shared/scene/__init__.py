"""The scene model both sides share: the kinds of view cell and how each finds what it sees.

The modules: :mod:`.cellkinds` (every cell kind, its visibility model -- a baked PVS
with ACH, or portals walked per frame -- and whether a viewer can stand in it), :mod:`.placement` (contents kept in an interior's own frame
and the move that places them in the scene).
"""

from walkstream.shared.exports import lazy_exports

_EXPORTS = {
    "CELL_KINDS": "walkstream.shared.scene.cellkinds",
    "LOCATABLE_KINDS": "walkstream.shared.scene.cellkinds",
    "VISIBILITY_MODELS": "walkstream.shared.scene.cellkinds",
    "CellKind": "walkstream.shared.scene.cellkinds",
    "cell_kind": "walkstream.shared.scene.cellkinds",
    "ContentsPlacement": "walkstream.shared.scene.placement",
    "placement_for": "walkstream.shared.scene.placement",
    "visibility_of": "walkstream.shared.scene.cellkinds",
}

__all__ = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
