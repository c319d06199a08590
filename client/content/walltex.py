"""The client side of the content kind ``walltex``: an image in the cache.

The cache holds the decoded premultiplied RGBA array (:func:`~walkstream.shared.codec.image.decode_image`)
under ``("walltex", texture id)``, counted at its texels' bytes (4 per texel), which is
also what it takes as a texture.  A wall texture is a texture, not a mesh: the frame
draws it as a textured quad (:mod:`walkstream.client.draw.quads`), so
:meth:`WallTextureContent.upload` refuses a mesh.
"""

from __future__ import annotations

from collections.abc import Hashable
from dataclasses import dataclass
from typing import Any

from walkstream.client.content.base import Uploader
from walkstream.shared.content.kind import ContentKind
from walkstream.shared.content.walltex import KIND as WALLTEX
from walkstream.shared.errors import InputError
from walkstream.shared.records import Mesh

__all__ = ["WALLTEX_CONTENT", "WallTextureContent"]


@dataclass(frozen=True)
class WallTextureContent:
    """The ``walltex`` content kind on the client."""

    kind: ContentKind = WALLTEX

    def cache_entry(self, payload: bytes, decoded: Any) -> tuple[Any, int]:
        """``(the premultiplied RGBA image, its bytes)``; ``payload`` is not kept."""
        return decoded, max(int(decoded.nbytes), 1)

    def gpu_key(self, item: int, part: int) -> Hashable:
        """``("walltex", texture id, part)``: no object's or cell's key."""
        return (self.kind.name, item, part)

    def upload(self, renderer: Uploader, item: int, part: int, mesh: Mesh) -> Hashable:
        """Refused: a wall texture is an image, uploaded as a texture, never as a mesh."""
        raise InputError(f"wall texture {item}: an image, not a mesh (textures are not uploaded through meshes)")


WALLTEX_CONTENT = WallTextureContent()
"""The ``walltex`` content kind on the client."""
