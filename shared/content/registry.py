"""Content kinds: what the objects and cells of a scene carry, each named in one module.

A new content kind (impostor images, wall textures) is one new module and one registry
line on each side.  Here, the module (beside :mod:`.params`, :mod:`.mesh` and
:mod:`.cellmesh`) defines one :class:`~walkstream.shared.content.kind.ContentKind`
that names every place the kind has a name: whether it belongs to an object or a
cell; the store's table and columns, and the scene feature that creates the table
when it is not a core one; how it travels (the ``form`` of ``POST .../objects`` that
streams it and its frame key, or the media type its own route answers with); the
client cache kind it is held under; and its decoder.  The registry line adds its
``KIND`` to :data:`CONTENT_KINDS` below, which the store (:meth:`SceneReader.content_blobs
<walkstream.server.store.reader.SceneReader.content_blobs>`), the service (the forms
it accepts), the wire (each form's payload key) and the client cache (its kinds and
their eviction order) read.  On the client, a module of :mod:`walkstream.client.content`
says what the cache holds of it and how it is uploaded to the GPU, and one line of
:mod:`walkstream.client.content.registry` registers it by the same name.  What it takes
beyond that is its own work, not bookkeeping: the DDL of its table (a new optional
table under a new feature, :data:`walkstream.server.store.OPTIONAL_TABLES`), the bake
step that writes it, the route that serves it when it is not an object form, and the
name in the typed literals that mypy checks (the cache's ``Kind``, the service's
``Form``).  ``tests/test_content.py`` checks that every registered kind names all its
parts and that the store, the service, the wire and the cache take exactly the
registered kinds.

>>> [k.name for k in CONTENT_KINDS]
['params', 'mesh', 'cellmesh', 'impostor', 'walltex']
>>> by_form("lod2").cache_kind, content_kind("cellmesh").table
('mesh', 'contents')
"""

from __future__ import annotations

from walkstream.shared.content import cellmesh, impostor, mesh, params, walltex
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
    impostor.KIND,
    walltex.KIND,
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
