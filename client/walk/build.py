"""The frame step ``build``: geometry the visible PVS lacks is rebuilt from parameters.

Decoding the rooms' contents happens as they arrive (the rooms' streamer); what a
frame can ask for is the rebuild of objects whose parameters are cached but whose
geometry is not (never built, or evicted).
"""

from __future__ import annotations

from walkstream.client.walk.state import Frame, WalkState

__all__ = ["build"]


def build(w: WalkState, f: Frame) -> None:
    """Queue the rebuilds the visible PVS needs."""
    city = w.scene.streets
    if city is not None and city.rewrite is not None and len(w.objects.geoms) < len(w.objects.pvs):
        city.ensure_geometry(w.objects.pvs)
