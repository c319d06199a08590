"""What the client does with one content kind: what the cache holds of it, and its GPU upload."""

from __future__ import annotations

from collections.abc import Hashable
from typing import Any, Protocol

from walkstream.shared.content.kind import ContentKind
from walkstream.shared.records import Mesh

__all__ = ["Uploader", "ClientContent"]


class Uploader(Protocol):
    """The renderer's buffer side (:class:`~walkstream.client.draw.frames.FrameRenderer`)."""

    def has(self, key: Hashable) -> bool: ...  # pragma: no cover - a protocol

    def upload(self, key: Hashable, mesh: Mesh) -> None: ...  # pragma: no cover - a protocol


class ClientContent(Protocol):
    """One content kind on the client (one module of :mod:`walkstream.client.content`)."""

    @property
    def kind(self) -> ContentKind:
        """The shared description: store table, wire record, cache kind, decoder."""
        ...  # pragma: no cover - a protocol

    def cache_entry(self, payload: bytes, decoded: Any) -> tuple[Any, int]:
        """``(value, nbytes)``: what the cache holds of an item that arrived as
        ``payload`` and decoded to ``decoded``, and the bytes it counts for it."""
        ...  # pragma: no cover - a protocol

    def gpu_key(self, item: int, part: int) -> Hashable:
        """The renderer's key of part ``part`` (a LOD, or a part of a cell) of ``item``;
        keys of different kinds never collide."""
        ...  # pragma: no cover - a protocol

    def upload(self, renderer: Uploader, item: int, part: int, mesh: Mesh) -> Hashable:
        """Upload ``mesh`` as part ``part`` of ``item`` unless already there; its key."""
        ...  # pragma: no cover - a protocol
