"""Content kinds: what the objects and cells of a scene carry, each named in one module.

A new content kind is one new module and one registry line.  The module (beside
:mod:`.params`, :mod:`.mesh` and :mod:`.cellmesh`) defines one
:class:`~walkstream.shared.content.kind.ContentKind`:
its name; whether it belongs to an object or to a cell; where the store keeps it (a
table and column, and the scene feature that creates the table when it is not a core
table); how it travels (the ``form`` of ``POST .../objects`` that streams it, or its
own route's media type, and the key or media type of its wire record); the client
cache kind it is held under; and its decoder.  Adding its module's ``KIND`` to
:data:`CONTENT_KINDS` below is the registry line: the store (which tables hold
content), the service (the forms it accepts), the client cache (its kinds and their
eviction order) and the wire (the payload key of each form) all read this tuple, and
``tests/test_content.py`` checks that every kind names all its parts and that each of
those accepts exactly the registered kinds.  The client's GPU upload and draw of each
kind are registered by the same name in :mod:`walkstream.client.content`.  What the
new kind still needs besides: its table's DDL in the store's schema (a new optional
table keyed by a new feature), the bake step that writes it, and the route that
serves it when it is not an object form.

>>> [k.name for k in CONTENT_KINDS]
['params', 'mesh', 'cellmesh']
>>> by_form("lod2").cache_kind, content_kind("cellmesh").table
('mesh', 'contents')
"""

from __future__ import annotations

from walkstream.shared.content import cellmesh, mesh, params
from walkstream.shared.content.kind import ContentKind
from walkstream.shared.errors import InputError

__all__ = [
    "CONTENT_KINDS",
    "content_kind",
    "by_form",
    "object_forms",
    "cache_kinds",
    "frame_keys",
]


CONTENT_KINDS: tuple[ContentKind, ...] = (
    params.KIND,
    mesh.KIND,
    cellmesh.KIND,
)
"""Every content kind, in the order the client cache evicts them (first to last)."""

_BY_NAME = {k.name: k for k in CONTENT_KINDS}
_BY_FORM = {k.form: k for k in CONTENT_KINDS if k.form is not None}


def content_kind(name: str) -> ContentKind:
    """The content kind called ``name``.

    Raises
    ------
    InputError
        Not a registered kind.
    """
    kind = _BY_NAME.get(name)
    if kind is None:
        raise InputError(f"content kind {name!r:.40}: expected one of {', '.join(_BY_NAME)}")
    return kind


def by_form(form: str) -> ContentKind:
    """The content kind an objects request's ``form`` streams.

    Raises
    ------
    InputError
        No registered kind has that form.
    """
    kind = _BY_FORM.get(form)
    if kind is None:
        raise InputError(f"objects form {form!r:.40}: expected one of {', '.join(object_forms())}")
    return kind


def object_forms() -> tuple[str, ...]:
    """The forms of ``POST .../objects``: one per object content kind, in registry order."""
    return tuple(_BY_FORM)


def cache_kinds() -> tuple[str, ...]:
    """The client cache kinds of the content kinds, in registry order."""
    return tuple(k.cache_kind for k in CONTENT_KINDS)


def frame_keys() -> dict[str, str]:
    """The key of an object frame's payload, per form."""
    return {form: k.wire for form, k in _BY_FORM.items()}
