"""A start bundle's parts in order, read by the client's own start decoder (tests' support).

The tests that check a bundle's order want each part's name and body, not the frames a
part announces (objects, an interior's contents, wall textures): :func:`start_parts`
decodes the whole answer with :class:`~walkstream.client.net.startitems.StartDecoder`
(so a frame that does not match what its part announced fails the test) and keeps the
parts alone.
"""

from __future__ import annotations

from typing import Any

import msgpack

from walkstream.client.net.startitems import StartDecoder

__all__ = ["start_parts"]

_FRAMES = ("object", "room", "rooms", "texture")
"""What the decoder yields for the frames that follow a part."""


def start_parts(content: bytes, *, heads: bool = False, form: str = "params") -> list[tuple[str, Any]]:
    """``(part, body)`` for each part of a start bundle's msgpack answer ``content``, in order.

    ``body`` is as the client decodes it: the ids listed for ``walltex`` and
    ``contents``, the count for ``objects``, ``(sides, nbytes)`` for ``walls``, a record
    for ``cell``/``record``.  ``heads``: whether the bundle was asked with ``heads`` (an
    interior's contents may then come as heads and packs).  Fails when a part's frames
    are short.
    """
    decoder = StartDecoder(form, heads, "bundle")
    unpacker = msgpack.Unpacker(raw=False)
    unpacker.feed(content)
    out = [item for item in (decoder(obj, 0) for obj in unpacker) if item[0] not in _FRAMES]
    assert decoder.short() is None, decoder.short()
    return out
