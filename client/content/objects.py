"""The client side of the object content kinds ``params`` and ``mesh``: cache entries, LOD upload.

Both end as an object's geometry (:class:`~walkstream.client.rewrite.pool.ObjectGeometry`,
cache kind ``geom``): ``params`` rebuilt locally with the grammar, ``mesh`` the LOD2
mesh as downloaded.  Each LOD is uploaded under ``(object id, lod)``, the key
:meth:`~walkstream.client.draw.frames.FrameRenderer.forget_object` drops when the
object's geometry leaves the cache.
"""

from __future__ import annotations

from collections.abc import Hashable
from dataclasses import dataclass
from typing import Any

from walkstream.client.content.base import Uploader
from walkstream.shared.content.kind import ContentKind
from walkstream.shared.content.mesh import KIND as MESH
from walkstream.shared.content.params import KIND as PARAMS
from walkstream.shared.records import Mesh

__all__ = ["ObjectContent", "PARAMS_CONTENT", "MESH_CONTENT"]


@dataclass(frozen=True)
class ObjectContent:
    """An object content kind on the client.

    Attributes
    ----------
    kind : ContentKind
        The shared description.
    keep_decoded : bool
        Whether the cache holds the decoded value (``params``: rebuilt again when the
        geometry was evicted) or the bytes as they arrived (``mesh``: the geometry is
        the decoded mesh itself).
    """

    kind: ContentKind
    keep_decoded: bool

    def cache_entry(self, payload: bytes, decoded: Any) -> tuple[Any, int]:
        """``(value, nbytes)`` of an arrived object: at least 16 bytes each."""
        return (decoded if self.keep_decoded else payload), max(len(payload), 16)

    def gpu_key(self, item: int, part: int) -> Hashable:
        """``(object id, lod)``."""
        return (item, part)

    def upload(self, renderer: Uploader, item: int, part: int, mesh: Mesh) -> Hashable:
        """Upload LOD ``part`` of object ``item`` unless already there; its key."""
        key = self.gpu_key(item, part)
        if not renderer.has(key):
            renderer.upload(key, mesh)
        return key


PARAMS_CONTENT = ObjectContent(PARAMS, keep_decoded=True)
"""``params``: the decoded parameters are cached; the rewrite pool builds the LODs."""

MESH_CONTENT = ObjectContent(MESH, keep_decoded=False)
"""``mesh``: the downloaded bytes are cached; the decoded mesh is the LOD2 geometry."""
