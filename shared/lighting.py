"""The one lighting of city objects: the light's direction, the ambient share, the sky's colour.

The client's renderer (:mod:`walkstream.client.draw.meshes`), the ground truth and the
bake's impostor images (:mod:`walkstream.server.bake.impostorrender`) all light a
surface of material colour ``c`` and unit normal ``n`` as
``c * (AMBIENT + (1 - AMBIENT) * max(n . l, 0))`` with ``l`` the unit
:data:`LIGHT_DIRECTION`, so an image baked on the server shows an object in the
colours the client would draw it in.
"""

from __future__ import annotations

__all__ = ["AMBIENT", "BACKGROUND_RGB", "LIGHT_DIRECTION"]

#: Clear colour, sRGB 0-255: a pale sky that no shaded material in the palette matches.
BACKGROUND_RGB: tuple[int, int, int] = (232, 238, 246)

#: Share of a material's colour lit regardless of the light (the default ``ambient``).
AMBIENT = 0.35

#: Direction towards the light (world, z-up): high sun from the south-south-west, so
#: the south, west and top faces a 3/4 view shows all get different shades.
LIGHT_DIRECTION: tuple[float, float, float] = (-0.3, -0.8, 0.6)
