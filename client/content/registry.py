"""The client side of every content kind, registered by the kind's name.

One entry per kind of :data:`walkstream.shared.content.registry.CONTENT_KINDS`
(``tests/test_content.py`` checks they match): a new content kind adds its client
module (what the cache holds of it, its GPU upload) and one line here.
"""

from __future__ import annotations

from walkstream.client.content.base import ClientContent
from walkstream.client.content.cellmesh import CELLMESH_CONTENT
from walkstream.client.content.impostor import IMPOSTOR_CONTENT
from walkstream.client.content.objects import MESH_CONTENT, PARAMS_CONTENT
from walkstream.client.content.walltex import WALLTEX_CONTENT
from walkstream.shared.content.registry import by_form
from walkstream.shared.errors import InputError

__all__ = ["CLIENT_CONTENT", "client_content", "client_content_for_form"]

CLIENT_CONTENT: dict[str, ClientContent] = {
    c.kind.name: c
    for c in (
        PARAMS_CONTENT,
        MESH_CONTENT,
        CELLMESH_CONTENT,
        IMPOSTOR_CONTENT,
        WALLTEX_CONTENT,
    )
}
"""Content kind name -> its client side."""


def client_content(name: str) -> ClientContent:
    """The client side of content kind ``name``.

    Raises
    ------
    InputError
        No client side is registered under ``name``.
    """
    content = CLIENT_CONTENT.get(name)
    if content is None:
        raise InputError(f"content kind {name!r:.40}: expected one of {', '.join(CLIENT_CONTENT)}")
    return content


def client_content_for_form(form: str) -> ClientContent:
    """The client side of the content kind an objects request's ``form`` streams."""
    return client_content(by_form(form).name)
