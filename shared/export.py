"""Export meshes to binary glTF (``.glb``) for inspection in any 3D viewer."""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np

from walkstream.shared.errors import InputError, RenderError
from walkstream.shared.palette import material_rgb
from walkstream.shared.records import Mesh

__all__ = ["Z_UP_TO_Y_UP", "export_glb"]

#: glTF is y-up and our scenes are z-up: a -90 degree turn about x stands them upright.
Z_UP_TO_Y_UP = np.array([[1, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, 0], [0, 0, 0, 1]], dtype=np.float64)
Z_UP_TO_Y_UP.flags.writeable = False


def export_glb(
    meshes: Sequence[Mesh],
    path: str | os.PathLike[str],
    names: Sequence[str] | None = None,
    y_up: bool = True,
) -> int:
    """Write meshes to a binary glTF file, one node per mesh.

    Vertex colours come from :data:`~walkstream.shared.palette.PALETTE` by material id, so the
    file looks like the client's render.  Meshes without triangles are left out
    (glTF has no empty primitives).

    Parameters
    ----------
    meshes : sequence of Mesh
        Scene-local geometry; ``(n, 3) float32`` positions and normals,
        ``(m, 3) uint32`` indices.
    path : path-like
        Output ``.glb`` file (overwritten).
    names : sequence of str, optional
        Node names, one per mesh (default ``mesh_<i>``).
    y_up : bool
        Give every node the :data:`Z_UP_TO_Y_UP` transform so viewers, which assume
        glTF's y-up, show the scene standing; the geometry itself stays z-up.

    Returns
    -------
    int
        Bytes written.

    Raises
    ------
    InputError
        When no mesh has a triangle (glTF cannot hold an empty scene).
    RenderError
        When trimesh cannot build the file.
    """
    import trimesh  # optional dependency: only needed when exporting

    if names is not None and len(names) != len(meshes):
        raise InputError(f"export_glb.names: expected {len(meshes)} names, got {len(names)}")
    scene = trimesh.Scene()
    transform = Z_UP_TO_Y_UP if y_up else np.eye(4)
    for i, mesh in enumerate(meshes):
        if mesh.triangles == 0:
            continue
        rgba = np.empty((len(mesh.positions), 4), np.uint8)
        rgba[:, :3] = material_rgb(mesh.materials)
        rgba[:, 3] = 255
        # process=False: keep vertices as given (merging them would average the flat
        # normals and drop the hard edges).
        tm = trimesh.Trimesh(
            vertices=np.asarray(mesh.positions, dtype=np.float64),
            faces=np.asarray(mesh.indices, dtype=np.int64),
            vertex_normals=np.asarray(mesh.normals, dtype=np.float64),
            vertex_colors=rgba,
            process=False,
        )
        name = names[i] if names is not None else f"mesh_{i}"
        scene.add_geometry(tm, node_name=name, geom_name=name, transform=transform)
    if not scene.geometry:
        raise InputError(f"export_glb: no triangles to export in {len(meshes)} meshes")
    try:
        data = scene.export(file_type="glb")
    except Exception as exc:  # map the dependency's errors at the edge
        raise RenderError(f"export_glb: trimesh could not write glTF: {exc}") from exc
    with open(os.fspath(path), "wb") as f:
        f.write(data)
    return len(data)
