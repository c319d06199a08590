"""Content kind ``impostor``: an image standing in for a far or complex building, one blob per image.

The bake stores each image (``impostors.data`` of the ``impostors`` feature, a WebP
file of :mod:`walkstream.shared.codec.image`) under an image id; a cell record lists
which images its impostors use (:class:`~walkstream.shared.impostorwire.ImpostorRow`). The
service answers ``GET .../impostors/{id}`` with the file as stored (immutable, ETag,
304) and ``POST .../impostors`` with many of them in the parts of
:mod:`walkstream.shared.codec.cellbatch` (the image id in the part's ``cell`` key); the
client caches the decoded premultiplied RGBA under ``impostor`` by image id.
"""

from __future__ import annotations

from walkstream.shared.codec.image import decode_image
from walkstream.shared.content.kind import ContentKind

__all__ = ["IMPOSTOR_MEDIA", "KIND"]

IMPOSTOR_MEDIA = "image/webp"
"""Media type of an impostor image as the bake stores it by default (``webp-lossless``)."""

KIND = ContentKind(
    name="impostor",
    owner="image",
    table="impostors",
    key_column="id",
    column="data",
    feature="impostors",
    form=None,
    wire=IMPOSTOR_MEDIA,
    cache_kind="impostor",
    decode=decode_image,
)
"""The ``impostor`` content kind."""
