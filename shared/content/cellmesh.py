"""Content kind ``cellmesh``: the meshes in an interior cell (walls, furniture), one blob per cell.

The bake stores each cell's quantised parts (``contents.data`` of the ``meshes``
feature, :mod:`walkstream.shared.codec.cellmesh`); the service answers
``GET .../rooms/{cell}/contents`` with the blob as stored (:data:`CONTENTS_MEDIA`) and
``POST .../rooms/contents`` with many of them (:mod:`walkstream.shared.codec.cellbatch`);
the client caches the decoded :class:`~walkstream.shared.codec.cellmesh.CellMesh` under
``cellmesh`` by cell id, apart from the objects' ``mesh`` entries that share ids with it.
It decodes a blob into the pieces the client culls
(:func:`~walkstream.shared.codec.cellpieces.decode_cell_pieces`: a part over
:data:`~walkstream.shared.codec.cellpieces.PIECE_TRIANGLES` triangles cut into pieces),
so the client and its ground truth key the same pieces.
"""

from __future__ import annotations

from walkstream.shared.codec.cellpieces import decode_cell_pieces
from walkstream.shared.content.kind import ContentKind

__all__ = ["CONTENTS_MEDIA", "KIND"]

CONTENTS_MEDIA = "application/vnd.walkstream.cellmesh"
"""Media type of a cell's contents (``walkstream-cellmesh/3, /2 or /1``, see :mod:`walkstream.shared.codec.cellmesh`)."""

KIND = ContentKind(
    name="cellmesh",
    owner="cell",
    table="contents",
    key_column="cell",
    column="data",
    feature="meshes",
    form=None,
    wire=CONTENTS_MEDIA,
    cache_kind="cellmesh",
    decode=decode_cell_pieces,
)
"""The ``cellmesh`` content kind."""
