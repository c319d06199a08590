"""Content kind ``walltex``: a textured virtual wall's texture for one zone, one blob per texture.

The bake (``--virtual-walls``, :mod:`walkstream.server.bake.wallplan`) stores each
texture (``wall_textures.data`` of the ``walls`` feature, a WebP file of
:mod:`walkstream.shared.codec.image`) under a texture id; the wall sides
(``GET .../walls``, :class:`~walkstream.shared.walls.WallSide`) list each side's
texture ids by zone.  The service answers ``GET .../walls/textures/{id}`` with the
file as stored (immutable, ETag, 304) and ``POST .../walls/textures`` with many in
the parts of :mod:`walkstream.shared.codec.cellbatch` (the texture id in the part's
``cell`` key); the client caches the decoded premultiplied RGBA under ``walltex``.  A texture baked
with ``--wall-depth G`` carries its depth grid as a trailer after the image
(:mod:`walkstream.shared.walldepth`): decoded, the RGBA holds it
(:class:`~walkstream.shared.walldepth.WallImage`).
"""

from __future__ import annotations

from typing import Any

from walkstream.shared.codec.image import decode_image
from walkstream.shared.content.kind import ContentKind
from walkstream.shared.walldepth import split_depth, with_depth

__all__ = ["WALLTEX_MEDIA", "KIND", "decode_walltex"]

WALLTEX_MEDIA = "image/webp"
"""Media type of a wall texture as the bake stores it (``webp-lossless``)."""


def decode_walltex(blob: bytes, what: str = "wall texture") -> Any:
    """A stored wall texture's premultiplied RGBA ``(h, w, 4) uint8``, holding its depth
    grid when it has one (:func:`~walkstream.shared.walldepth.with_depth`)."""
    image, inv = split_depth(blob, what)
    return with_depth(decode_image(image, what), inv)

KIND = ContentKind(
    name="walltex",
    owner="image",
    table="wall_textures",
    key_column="id",
    column="data",
    feature="walls",
    form=None,
    wire=WALLTEX_MEDIA,
    cache_kind="walltex",
    decode=decode_walltex,
)
"""The ``walltex`` content kind."""
