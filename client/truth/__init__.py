"""The ground truth of a replay frame, and what the client's frame gets wrong against it (issue 12).

(:mod:`.interior`: object-id frames of a whole interior, for portal culling's
conservative test.) :mod:`.compare` (the pixel comparison and the causes (a)-(f) of a missing pixel),
:mod:`.render` (the truth renderer: every object within the view distance at LOD2,
sharing nothing of the client's culling or LOD code), :mod:`.scene` (every object of
the scene, fetched through the API on an unshaped path), :mod:`.recorder` (notes the
compared frames during the walk and compares them after it).  The figures computed
from the compared frames are :mod:`walkstream.client.report.truth`.  Public names are
imported lazily.
"""

from walkstream.shared.exports import lazy_exports

_EXPORTS = {
    "CAUSES": "walkstream.client.truth.compare",
    "FrameError": "walkstream.client.truth.compare",
    "compare_frame": "walkstream.client.truth.compare",
    "missing_mask": "walkstream.client.truth.compare",
    "TruthRenderer": "walkstream.client.truth.render",
    "InteriorTruth": "walkstream.client.truth.interior",
    "TruthCheck": "walkstream.client.truth.interior",
    "TruthScene": "walkstream.client.truth.scene",
    "TruthRecorder": "walkstream.client.truth.recorder",
    "TruthResult": "walkstream.client.truth.recorder",
}

__all__ = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
