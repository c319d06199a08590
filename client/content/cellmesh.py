"""The client side of the content kind ``cellmesh``: a cell's contents in the cache, its parts on the GPU.

The cache holds the decoded :class:`~walkstream.shared.codec.cellmesh.CellMesh` under
``("cellmesh", cell id)``, counted at the bytes of its parts' positions and indices;
each part is uploaded under ``("cellmesh", cell id, part)``, a key no object's
``(object id, lod)`` can take, so a city and an interior share one renderer.
"""

from __future__ import annotations

from collections.abc import Hashable
from dataclasses import dataclass
from typing import Any

from walkstream.client.content.base import Uploader
from walkstream.shared.codec.cellmesh import CellMesh
from walkstream.shared.content.cellmesh import KIND as CELLMESH
from walkstream.shared.content.kind import ContentKind
from walkstream.shared.records import Mesh

__all__ = ["CellMeshContent", "CELLMESH_CONTENT", "decoded_bytes"]


def decoded_bytes(mesh: CellMesh) -> int:
    """Memory the decoded parts of a cell take (positions and indices)."""
    return sum(p.positions.nbytes + p.indices.nbytes for p in mesh.parts)


@dataclass(frozen=True)
class CellMeshContent:
    """The ``cellmesh`` content kind on the client."""

    kind: ContentKind = CELLMESH

    def cache_entry(self, payload: bytes, decoded: Any) -> tuple[Any, int]:
        """``(the CellMesh, its decoded bytes or 1)``; ``payload`` is not kept."""
        return decoded, max(decoded_bytes(decoded), 1)

    def gpu_key(self, item: int, part: int) -> Hashable:
        """``("cellmesh", cell id, part)``."""
        return (self.kind.name, item, part)

    def upload(self, renderer: Uploader, item: int, part: int, mesh: Mesh) -> Hashable:
        """Upload part ``part`` of cell ``item`` unless already there; its key."""
        key = self.gpu_key(item, part)
        if not renderer.has(key):
            renderer.upload(key, mesh)
        return key


CELLMESH_CONTENT = CellMeshContent()
"""The ``cellmesh`` content kind on the client."""
