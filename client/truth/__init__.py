"""The ground truth of a replay frame, for every scene kind, and what the client's frame gets wrong against it.

:mod:`.render` (the one truth renderer: every city object at LOD2 and every room
part, colour, key and depth, sharing nothing of the client's culling or LOD code),
:mod:`.scene` (what the truth fetches of a scene through the API on an unshaped path:
every object, every room cell's contents), :mod:`.notes` (what a frame loop notes of a
compared frame), :mod:`.recorder` (notes the compared frames during the walk and
produces the scene's figures after it), :mod:`.missing` (a city's frames compared in
colour, missing pixels by cause) with :mod:`.compare` (the pixel comparison and the
causes (a)-(f) of a missing pixel), :mod:`.culled` (what a frame with rooms kept
against the truth: culled pixels and pinholes), :mod:`.colour` (a frame's colour error:
linear-RGB error, CIEDE2000, visible pixels per pixel and at the viewer's scale
(S-CIELAB), PSNR, colour causes) with
:mod:`.picture` (the client's picture drawn by the truth renderer, and the
``impostor`` hook), :mod:`.pop` (the pop at an impostor's switch).  The figures computed from the
colour-compared frames are :mod:`walkstream.client.report.truth`.  Public names are
imported lazily.
"""

from walkstream.shared.exports import lazy_exports

_EXPORTS = {
    "CAUSES": "walkstream.client.truth.compare",
    "FrameError": "walkstream.client.truth.compare",
    "compare_frame": "walkstream.client.truth.compare",
    "missing_mask": "walkstream.client.truth.compare",
    "TruthRenderer": "walkstream.client.truth.render",
    "form_key": "walkstream.client.truth.render",
    "COLOUR_CAUSES": "walkstream.client.truth.colour",
    "VISIBLE_DE": "walkstream.client.truth.colour",
    "ColourError": "walkstream.client.truth.colour",
    "compare_colour": "walkstream.client.truth.colour",
    "delta_e_2000": "walkstream.client.truth.colour",
    "psnr": "walkstream.client.truth.colour",
    "SCIELAB_VISIBLE_DE": "walkstream.client.truth.colour",
    "pixels_per_degree": "walkstream.client.truth.colour",
    "scielab_delta_e": "walkstream.client.truth.colour",
    "ClientPicture": "walkstream.client.truth.picture",
    "Overlay": "walkstream.client.truth.picture",
    "client_picture": "walkstream.client.truth.picture",
    "object_key": "walkstream.client.truth.render",
    "TruthCheck": "walkstream.client.truth.culled",
    "check_kept": "walkstream.client.truth.culled",
    "FrameNote": "walkstream.client.truth.notes",
    "TruthScene": "walkstream.client.truth.scene",
    "fetch_contents": "walkstream.client.truth.scene",
    "TruthRecorder": "walkstream.client.truth.recorder",
    "TruthResult": "walkstream.client.truth.recorder",
    "PopMeter": "walkstream.client.truth.pop",
    "summarise_pop": "walkstream.client.truth.pop",
    "SeamMeter": "walkstream.client.truth.seam",
    "SeamWall": "walkstream.client.truth.seam",
}

__all__ = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
