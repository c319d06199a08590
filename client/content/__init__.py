"""The client side of each content kind: what the cache holds, the GPU upload; registered by kind.

The modules: :mod:`.base` (the protocol a kind's client side follows), :mod:`.objects`
(``params`` and ``mesh``: an object's LODs), :mod:`.cellmesh` (an interior cell's
parts), :mod:`.impostor` (an impostor image), :mod:`.registry` (every kind's client side by name).
"""

from walkstream.shared.exports import lazy_exports

_EXPORTS = {
    "ClientContent": "walkstream.client.content.base",
    "CLIENT_CONTENT": "walkstream.client.content.registry",
    "client_content": "walkstream.client.content.registry",
    "client_content_for_form": "walkstream.client.content.registry",
}

__all__ = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
