"""The streaming client: replay a recorded walk over a shaped link, draw it, report it.

Folders follow one frame's flow: :mod:`.net` (the HTTP API and the shaped link) ->
:mod:`.stream` (which cell, what next, the caches) -> :mod:`.rewrite` (rebuilding
geometry from parameters) -> :mod:`.draw` (culling, LOD allocation, the budget,
devices, drawing) -> :mod:`.report` (figures, files, plots, the page).
:mod:`.replay` wires them for one walk on a :mod:`.clock`.  The client knows the
server only through an httpx transport.  Public names are imported lazily.
"""

from walkstream.shared.exports import lazy_exports

_EXPORTS = {
    "ReplayConfig": "walkstream.client.config",
    "ReplayResult": "walkstream.client.replay",
    "run_replay": "walkstream.client.replay",
    "RealClock": "walkstream.client.clock",
    "SimClock": "walkstream.client.clock",
    "SceneClient": "walkstream.client.net.api",
    "LinkProfile": "walkstream.client.net.link",
    "ShapedTransport": "walkstream.client.net.link",
    "Cache": "walkstream.client.stream.cache",
    "DiskCache": "walkstream.client.stream.diskcache",
    "Streamer": "walkstream.client.stream.streamer",
    "StreamerConfig": "walkstream.client.stream.streamer",
    "RewritePool": "walkstream.client.rewrite.pool",
    "ObjectGeometry": "walkstream.client.rewrite.geometry",
    "BudgetController": "walkstream.client.draw.budget",
    "make_device": "walkstream.client.draw.devices",
    "FrameRenderer": "walkstream.client.draw.frames",
    "MeshRenderer": "walkstream.client.draw.meshes",
    "FrameLog": "walkstream.client.report.metrics",
    "summarise": "walkstream.client.report.metrics",
    "write_report": "walkstream.client.report.html",
    "write_comparison": "walkstream.client.report.html",
}

__all__ = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
