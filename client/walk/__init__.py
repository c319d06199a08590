"""The walk through a scene whose cells have both visibility models (streets and rooms joined at an entrance).

:mod:`.crossing` is the frame loop of a crossing scene as named steps (locate, visible
set by the current cell's model, wants, build, allocate, draw, measure), on one link
with one cache; :mod:`.crosstruth` its ground truth (every city object and every room
part at full detail).  Public names are imported lazily.
"""

from walkstream.shared.exports import lazy_exports

_EXPORTS = {
    "CrossingFrames": "walkstream.client.walk.crossing",
    "replay_crossing": "walkstream.client.walk.crossing",
    "walk_crossing": "walkstream.client.walk.crossing",
    "crossing_truth": "walkstream.client.walk.crosstruth",
}

__all__ = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
