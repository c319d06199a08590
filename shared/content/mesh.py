"""Content kind ``mesh``: an object's LOD2 mesh, rebuilt by the service from its parameters.

The ``--stream meshes`` comparison: the service rebuilds the object's stored
parameters (``objects.params``) at LOD2 and sends the mesh (``form=lod2``, frame key
``mesh``, :mod:`walkstream.shared.codec.mesh`); the client draws it as it is and caches
the downloaded bytes under ``mesh``.
"""

from __future__ import annotations

from walkstream.shared.codec.mesh import decode_mesh
from walkstream.shared.content.kind import ContentKind

__all__ = ["KIND"]

KIND = ContentKind(
    name="mesh",
    owner="object",
    table="objects",
    key_column="id",
    column="params",
    feature=None,
    form="lod2",
    wire="mesh",
    cache_kind="mesh",
    decode=decode_mesh,
)
"""The ``mesh`` content kind (built from the same stored column as ``params``)."""
