"""The walk: one frame loop for every scene, a pipeline of named steps.

:mod:`.loop` runs each frame's steps in order, each a module of its own and a phase
of the phases report: :mod:`.locate`, :mod:`.wants`, :mod:`.visible`, :mod:`.build`,
:mod:`.allocate`, :mod:`.draw` (``upload`` and ``draw``), :mod:`.measure`.  They share
:mod:`.state` (the walk's and the frame's), :mod:`.scene` (the streamers of the scene's
cell models on one cache, the projection), :mod:`.objects` (the visible PVS as arrays)
and :mod:`.figures` (the per-frame figures beyond the frame log).  A crossing scene's
topology joins its entrances' street cells (:mod:`.crossing`).  The ground truth
(every city object and every room part at full detail) is :mod:`walkstream.client.truth`.
Public names are imported lazily.
"""

from walkstream.shared.exports import lazy_exports

_EXPORTS = {
    "walk": "walkstream.client.walk.loop",
    "STEPS": "walkstream.client.walk.loop",
    "WalkScene": "walkstream.client.walk.scene",
    "WalkState": "walkstream.client.walk.state",
    "WalkFrames": "walkstream.client.walk.figures",
    "crossing_topology": "walkstream.client.walk.crossing",
}

__all__ = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
