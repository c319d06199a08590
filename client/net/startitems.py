"""A start bundle's stream decoded item by item: what :meth:`~walkstream.client.net.api.SceneClient.start` yields.

The bundle is one msgpack stream of parts (:mod:`walkstream.shared.startwire`); some
parts announce frames that follow them (the objects, an interior's contents, the
first view's wall textures).  :class:`StartDecoder` keeps that state and turns each
unpacked object into one :data:`StartItem`.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

from walkstream.shared.codec.cellbatch import check_contents_part
from walkstream.shared.codec.cellhead import decode_cell_head
from walkstream.shared.codec.cellmesh import CellMesh
from walkstream.shared.codec.contentspack import is_pack, unpack_parts
from walkstream.shared.codec.objectboxes import decode_object_boxes
from walkstream.shared.content.cellmesh import KIND as CELLMESH
from walkstream.shared.content.walltex import KIND as WALLTEX
from walkstream.shared.errors import CodecError
from walkstream.shared.pathcodec import decode_path_any
from walkstream.shared.roomcompact import TOPOLOGY_COMPACT_MAGIC, decode_topology_compact
from walkstream.shared.roomwire import decode_topology
from walkstream.shared.startwire import decode_start_part
from walkstream.shared.walls import decode_walls
from walkstream.shared.wire import decode_cell, decode_cell_index, decode_frame, decode_manifest

__all__ = ["StartDecoder", "StartItem", "contents_part"]

StartItem = tuple[str, Any]
"""One item of a start bundle as :meth:`~walkstream.client.net.api.SceneClient.start`
yields it: ``("path", (RecordedPath, nbytes))`` (and ``("pathhead", ...)``, the path's
first seconds, when asked), ``("cell", CellRecord)`` (``("record", CellRecord)`` for
a cell whose objects the bundle does not all bring), ``("index", CellIndex)``,
``("topology", Topology)`` (interiors), ``("manifest", (Manifest, nbytes))``,
``("objects", count)`` (the PVS objects that follow), ``("object", ObjectFrame)``,
``("boxes", ObjectBoxes)`` (a city's first view), ``("contents", [cell ids])`` (interiors: the contents that follow) or ``("room", (cell
id, CellMesh))`` (:class:`StartDecoder` gives ``("rooms", [(cell id, CellMesh), ...])`` for
a pack of several, :mod:`~walkstream.shared.codec.contentspack`, which
:meth:`~walkstream.client.net.api.SceneClient.start` yields one ``room`` item each); with walls asked for, ``("walls", (sides, nbytes))``, ``("walltex",
[texture ids])`` (the textures that follow) and ``("texture", (texture id,
premultiplied RGBA, nbytes))``; ``nbytes`` (and the records' ``nbytes``) is what the
part cost on the wire."""


def contents_part(obj: Any, nbytes: int, expected: int, what: str, heads: bool = False) -> tuple[int, CellMesh]:
    """``(cell, contents)`` of one unpacked contents part, which must be cell
    ``expected``'s; ``nbytes`` is its share of the stream."""
    missing = obj.pop("missing", None) if heads and isinstance(obj, dict) else None
    cid, _etag, body = check_contents_part(obj, what)
    if cid != expected:
        raise CodecError(f"{what}: cell {cid} where {expected} was asked")
    if missing is not None:  # a head: the pieces drawn first, stand-ins for the others
        if not isinstance(missing, bytes):
            raise CodecError(f"{what}: missing must be bytes")
        return cid, replace(decode_cell_head(body, missing, f"head of cell {cid}"), nbytes=nbytes)
    return cid, replace(CELLMESH.decode(body, f"contents of cell {cid}"), nbytes=nbytes)


class StartDecoder:
    """Decodes a start bundle's unpacked objects in order (``decoder(obj, nbytes)``).

    Parameters
    ----------
    form:
        The object form asked for (``params`` or ``lod2``).
    heads:
        Whether an interior's contents may come as heads first, and its first view's
        parts as one pack (:mod:`~walkstream.shared.codec.contentspack`).
    what:
        The bundle in error lines.
    """

    def __init__(self, form: str, heads: bool, what: str = "start bundle") -> None:
        self.form, self.heads, self.what = form, heads, what
        self.objects = 0
        """Object frames announced and not yet decoded."""
        self.rooms: list[int] = []
        """Contents parts announced and not yet decoded, in order."""
        self.textures: list[int] = []
        """Wall textures announced and not yet decoded, in order."""
        self.k = 0
        """Items decoded."""

    def short(self) -> str | None:
        """What announced frames never came (None: nothing)."""
        if self.objects:
            return f"{self.objects} objects"
        if self.rooms:
            return f"{len(self.rooms)} cells' contents"
        if self.textures:
            return f"{len(self.textures)} wall textures"
        return None

    def __call__(self, obj: Any, nbytes: int) -> StartItem:
        what, k = self.what, self.k
        self.k += 1
        if self.rooms and self.heads and isinstance(obj, dict) and obj.get("part") == "pathhead":
            pass  # the path's head once the first pose's view is in (asked with pose): a start part
        elif self.rooms and self.heads and is_pack(obj):  # several cells' parts in one LZMA dictionary
            inner = unpack_parts(obj, f"{what}: item {k}")
            if len(inner) > len(self.rooms):
                raise CodecError(f"{what}: item {k}: a pack of {len(inner)} parts, {len(self.rooms)} announced")
            total = sum(n for _, n in inner)
            return "rooms", [contents_part(o, round(nbytes * n / total), self.rooms.pop(0),
                                           f"{what}: item {k}: part {j}", self.heads)
                             for j, (o, n) in enumerate(inner)]
        elif self.rooms:
            return "room", contents_part(obj, nbytes, self.rooms.pop(0), f"{what}: item {k}", self.heads)
        if self.textures:
            tid, _etag, blob = check_contents_part(obj, f"{what}: item {k}")
            if tid != self.textures[0]:
                raise CodecError(f"{what}: item {k}: texture {tid} where {self.textures[0]} was announced")
            self.textures.pop(0)
            return "texture", (tid, WALLTEX.decode(blob, f"wall texture {tid}"), nbytes)
        if self.objects > 0:
            self.objects -= 1
            frame = obj
            if not isinstance(frame, dict) or type(frame.get("id")) is not int:
                raise CodecError(f"{what}: item {k} is not an object frame")
            return "object", decode_frame(frame, frame["id"], self.form, nbytes, f"{what}: object")
        part, etag, got = decode_start_part(obj, f"{what}: item {k}")
        if part == "objects":
            assert isinstance(got, int)
            self.objects = got
            return "objects", got
        if part in ("contents", "walltex"):
            assert isinstance(got, list)
            (self.rooms if part == "contents" else self.textures).extend(got)
            return part, list(got)
        assert isinstance(got, bytes)
        body = got
        label = f"{what}: {part}"
        if part in ("path", "pathhead"):
            return part, (decode_path_any(body, label), nbytes)
        if part == "topology":
            dec = decode_topology_compact if body[:4] == TOPOLOGY_COMPACT_MAGIC else decode_topology
            return "topology", replace(dec(body, label), nbytes=nbytes)
        if part == "walls":
            return "walls", (decode_walls(body, label), nbytes)
        if part in ("cell", "record"):  # a record: the bundle does not bring all the cell's objects
            return part, replace(decode_cell(body, label, etag), nbytes=nbytes)
        if part == "index":
            return "index", replace(decode_cell_index(body, label, etag), nbytes=nbytes)
        if part == "boxes":
            return "boxes", decode_object_boxes(body, label, nbytes)
        return "manifest", (decode_manifest(body, label, etag), nbytes)
