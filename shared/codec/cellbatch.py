"""Many interior cells' contents in one answer (``walkstream-cellbatch/1``).

``POST /v1/scenes/{scene}/rooms/contents`` answers a list of cell ids with a stream of
msgpack maps, one *part* per cell in the order asked::

    {"cell": id, "etag": str, "body": bin}

``body`` is a ``walkstream-cellmesh`` blob (:mod:`.cellmesh`), decoded with
:func:`~walkstream.shared.codec.cellmesh.decode_cell_mesh`; ``etag`` is the one
``GET .../rooms/{id}/contents`` sends for the same cell.  When the answer is
gzip-compressed (the client sent ``Accept-Encoding: gzip``) a stored blob is
inflated to its ``N`` form (:func:`~walkstream.shared.codec.cellmesh.inflate_cell_mesh`)
and the whole stream is compressed together, flushed after each part, so a cell
decodes as soon as its part is in and the cells share one dictionary (the 21 cells
visible at the office tour's start: 29.4 kB compressed one by one, 22.9 kB as one
gzip stream); a blob that costs fewer bytes there as stored (lzma beats gzip on large
cells) goes as stored.  Uncompressed answers carry the stored blobs as they are.

The interior start bundle may send a cell's *head* first, a part with one more
field, ``missing`` (:mod:`~walkstream.shared.codec.cellhead`); its whole part
follows later in the same stream.

The client decodes the parts bounded (:func:`check_contents_part`).
"""

from __future__ import annotations

from typing import Any

import msgpack

from walkstream.shared.errors import CodecError

__all__ = ["CELLBATCH_MAX_CELLS", "pack_contents_part", "pack_head_part", "check_contents_part"]

CELLBATCH_MAX_CELLS = 256
"""Cells one batch may ask for (more is a 422, as the OpenAPI's maxItems says: split the batch)."""

_KEYS = frozenset(("cell", "etag", "body"))


def pack_contents_part(cell: int, etag: str, body: bytes) -> bytes:
    """One part of a contents batch: the msgpack map ``{cell, etag, body}``."""
    data: bytes = msgpack.packb({"cell": int(cell), "etag": etag, "body": bytes(body)}, use_bin_type=True)
    return data


def pack_head_part(cell: int, etag: str, body: bytes, missing: bytes) -> bytes:
    """A cell's head in a contents stream: ``{cell, etag, body, missing}``
    (:mod:`~walkstream.shared.codec.cellhead`)."""
    data: bytes = msgpack.packb({"cell": int(cell), "etag": etag, "body": bytes(body), "missing": bytes(missing)},
                                use_bin_type=True)
    return data


def check_contents_part(obj: Any, what: str) -> tuple[int, str, bytes]:
    """``(cell, etag, body)`` of an unpacked part, every field checked (a head's
    ``missing`` is taken off ``obj`` first, see :func:`pack_head_part`).

    Raises
    ------
    CodecError
        Not a map of exactly ``cell`` (int), ``etag`` (str) and ``body`` (bytes).
    """
    if not isinstance(obj, dict) or set(obj) != _KEYS:
        got = sorted(map(str, obj)) if isinstance(obj, dict) else type(obj).__name__
        raise CodecError(f"{what}: expected a map of cell, etag and body, got {got}")
    cell, etag, body = obj["cell"], obj["etag"], obj["body"]
    if type(cell) is not int or cell < 0:
        raise CodecError(f"{what}: cell must be an integer >= 0, got {cell!r:.30}")
    if not isinstance(etag, str) or not isinstance(body, bytes):
        raise CodecError(f"{what}: etag must be a string and body bytes")
    return cell, etag, body
