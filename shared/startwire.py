"""The start bundle's parts on the wire: their names, and each part's header checked.

start part
    ``{part, etag, body: bin}``: one resource of the start bundle (``etag`` nil or,
    in msgpack, missing where the part has none), ``body`` being
    exactly what the resource's own endpoint sends (``part`` one of
    :data:`START_PARTS`); the ``objects`` part is ``{part, etag: null, count}``
    followed in the stream by ``count`` object frames; an interior's ``contents``
    part is ``{part, etag: null, cells: [ids]}`` followed by one contents part
    ``{cell, etag, body}`` per cell (:mod:`walkstream.shared.codec.cellbatch`); the
    ``walltex`` part (an interior baked with ``--virtual-walls``, asked with
    ``walls=true``) is ``{part, etag: null, textures: [ids]}`` followed by one part
    ``{cell: texture id, etag, body}`` per texture, as the wall textures' batch sends
    them; the ``walls`` part's body is what ``GET .../walls`` sends (every wall side).
    A city's cell record comes as a ``cell`` part when the bundle's objects hold its
    whole PVS, as a ``record`` part (the same body) when they do not: the client then
    does not wait for the bundle to bring that cell's objects.
"""

from __future__ import annotations

from collections import Counter
from typing import Any

from walkstream.shared.codec.cellbatch import CELLBATCH_MAX_CELLS
from walkstream.shared.errors import CodecError

__all__ = ["START_PARTS", "START_MAX_TEXTURES", "decode_start_part"]

START_PARTS: tuple[str, ...] = ("pathhead", "path", "topology", "walls", "walltex", "contents", "cell", "record",
                                "index", "manifest", "objects", "boxes")
"""What a start bundle may hold, in the order the service sends it (an interior's
``pathhead``, when asked, in place of ``path``, and with ``pose`` a second ``pathhead``
among the contents' frames, after the first pose's view; ``walls`` and ``walltex``, when
asked, on an interior)."""

START_MAX_TEXTURES = 64
"""The most wall textures a start bundle's ``walltex`` part may list."""


def decode_start_part(obj: Any, what: str) -> tuple[str, str | None, bytes | int | list[int]]:
    """``(part, etag, body)`` of one unpacked part of a start bundle, checked.

    For the ``objects`` part, ``body`` is the number of object frames that follow; for
    ``contents``, the ids of the cells whose contents parts follow, in order (a cell
    named twice comes first as its head, :mod:`~walkstream.shared.codec.cellhead`); for
    ``walltex``, the ids of the wall textures whose parts follow, in order.
    """
    if (
        not isinstance(obj, dict)
        or obj.get("part") not in START_PARTS
        or not (obj.get("etag") is None or isinstance(obj.get("etag"), str))
    ):
        raise CodecError(f"{what}: not {{part, etag, body}} with a known part")
    if obj["part"] == "objects":
        count = obj.get("count")
        if type(count) is not int or not 0 <= count <= 1 << 20:
            raise CodecError(f"{what}: objects part without a count")
        return "objects", None, count
    if obj["part"] == "contents":
        cells = obj.get("cells")
        if (
            not isinstance(cells, list)
            or len(cells) > 2 * CELLBATCH_MAX_CELLS
            or not all(type(c) is int and c >= 0 for c in cells)
            or len(set(cells)) > CELLBATCH_MAX_CELLS
            or max(Counter(cells).values(), default=0) > 2
        ):
            raise CodecError(f"{what}: contents part without its cells (ids >= 0, each at most twice: a head, "
                             f"then whole; at most {CELLBATCH_MAX_CELLS} cells)")
        return "contents", None, list(cells)
    if obj["part"] == "walltex":
        ids = obj.get("textures")
        if (
            not isinstance(ids, list)
            or len(ids) > START_MAX_TEXTURES
            or not all(type(i) is int and i >= 0 for i in ids)
            or len(set(ids)) != len(ids)
        ):
            raise CodecError(f"{what}: walltex part without its textures (distinct ids >= 0, "
                             f"at most {START_MAX_TEXTURES})")
        return "walltex", None, list(ids)
    if not isinstance(obj.get("body"), bytes):
        raise CodecError(f"{what}: {obj['part']} part without a body")
    return obj["part"], obj.get("etag"), obj["body"]
