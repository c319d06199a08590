"""What names a content kind: its store table, wire record, cache kind and decoder (one record)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal

__all__ = ["ContentKind"]


@dataclass(frozen=True, slots=True)
class ContentKind:
    """One kind of content and every place it has a name.

    Attributes
    ----------
    name : str
        The kind's name (also its ETag's representation tag where it has its own route).
    owner : {"object", "cell", "image"}
        What the id of an item is: an object id, a cell id, or an image id of its own
        (an impostor image, listed by the cell records).
    table, key_column, column : str
        The store's table, the column of the owner's id, and the column of the bytes.
    feature : str or None
        The scene feature whose optional tables include ``table``; None for a core table.
    form : str or None
        The ``form`` of ``POST .../objects`` (and the start bundle) that streams it;
        None when it has its own route.
    wire : str
        Its wire record: the key of the payload in an object frame, or the media type
        of the blob its route answers with.
    cache_kind : str
        The client cache's kind for it (the cache is keyed by ``(cache_kind, id)``).
    decode : callable
        ``decode(data, what)``: the bounded decoder of one item's bytes (raises
        :class:`~walkstream.shared.errors.CodecError` naming ``what``).
    """

    name: str
    owner: Literal["object", "cell", "image"]
    table: str
    key_column: str
    column: str
    feature: str | None
    form: str | None
    wire: str
    cache_kind: str
    decode: Callable[[bytes, str], Any]
