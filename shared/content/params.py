"""Content kind ``params``: the procedural parameters of a building or a street piece.

What the bake stores per object (``objects.params``, :mod:`walkstream.shared.codec.params`)
and streams as it is (``form=params``, frame key ``params``); the client rebuilds the
geometry from it with the grammar (its three LODs) and caches it under ``params``.
"""

from __future__ import annotations

from walkstream.shared.codec.params import decode_object
from walkstream.shared.content.kind import ContentKind

__all__ = ["KIND"]

KIND = ContentKind(
    name="params",
    owner="object",
    table="objects",
    key_column="id",
    column="params",
    feature=None,
    form="params",
    wire="params",
    cache_kind="params",
    decode=decode_object,
)
"""The ``params`` content kind."""
