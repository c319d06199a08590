"""The walk through a scene whose cells have both visibility models (streets and rooms joined at an entrance).

:mod:`.crossing` is the frame loop of a crossing scene as named steps (locate, visible
set by the current cell's model, wants, build, allocate, draw, measure), on one link
with one cache; its ground truth is the one of every scene (:mod:`walkstream.client.truth`).
Public names are imported lazily.
"""

from walkstream.shared.exports import lazy_exports

_EXPORTS = {
    "CrossingFrames": "walkstream.client.walk.crossing",
    "replay_crossing": "walkstream.client.walk.crossing",
    "walk_crossing": "walkstream.client.walk.crossing",
}

__all__ = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
