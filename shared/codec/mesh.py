"""Triangle meshes on the wire, for the ``--stream meshes`` comparison only.

Rebuilt LOD2 meshes travel only in the ``--stream meshes`` comparison, which
measures what the paper's central claim (send parameters, rebuild on the client)
saves.  So the format is compact but honest, what a sensible mesh streamer would
send: no quantisation of positions beyond float32, no entropy coding, but nothing
the client can recompute exactly either (normals).

mesh (format "walkstream-mesh/1")
    msgpack map ``{"format": "walkstream-mesh/1", "vertices": n, "positions": bin,
    "index_bytes": w, "indices": bin, "materials": bin}``: ``positions`` the
    ``(n, 3)`` float32 little-endian vertex positions; ``indices`` the ``(m, 3)``
    triangles as little-endian unsigned integers of ``w`` bytes, the smallest of 1,
    2, 4 that holds ``n - 1``; ``materials`` one uint8 per triangle.  Normals are
    not sent: :func:`decode_mesh` recomputes flat per-vertex normals from the
    triangles (the meshes of :func:`~walkstream.shared.lsystem.interpret.interpret` and
    :func:`~walkstream.shared.streets.build_street` never share a vertex between faces that
    are not coplanar).  For a mesh that breaks those assumptions the encoder adds
    what cannot be recomputed instead of silently changing the picture:
    ``"vertex_materials"`` (uint8 per vertex, replacing ``materials``) when a
    triangle's vertices have different materials, and ``"normals"`` ((n, 3)
"""

from __future__ import annotations

from typing import Any

import msgpack
import numpy as np
from numpy.typing import NDArray

from walkstream.shared.codec.bounded import checked_int, unpack_bounded
from walkstream.shared.errors import CodecError
from walkstream.shared.records import (
    Mesh,  # noqa: E402  (this section was appended to the module)
    )

__all__ = ["MESH_FORMAT", "encode_mesh", "decode_mesh"]

MESH_FORMAT = "walkstream-mesh/1"
"""The format tag of :func:`encode_mesh` maps."""

_MAX_MESH_BYTES = 1 << 27
_MAX_MESH_VERTICES = 1 << 24
# a recomputed normal within ~2.6 degrees of the mesh's shades the same to the eye
# (float32 positions alone cost up to ~0.01 degrees on metre-sized faces)
_NORMAL_COS_TOLERANCE = 0.999
_MESH_KEYS = frozenset(
    {
        "format",
        "vertices",
        "positions",
        "index_bytes",
        "indices",
        "materials",
        "vertex_materials",
        "normals",
    }
)


def _index_bytes(n_vertices: int) -> int:
    """Width of the smallest unsigned type that holds every index of ``n_vertices``."""
    if n_vertices <= 1 << 8:
        return 1
    if n_vertices <= 1 << 16:
        return 2
    return 4


def _flat_normals(positions: NDArray[np.float32], indices: NDArray[Any]) -> NDArray[np.float32]:
    """Unit per-vertex normals: the area-weighted sum of the incident triangles' normals.

    Every vertex of a flat-shaded mesh lies on one planar face, so the sum points
    along that face's normal.  A vertex no triangle uses (or only degenerate ones)
    gets ``(0, 0, 1)``; it draws nothing.
    """
    n = len(positions)
    out = np.zeros((n, 3), np.float64)
    if n == 0:
        return out.astype(np.float32)
    t = indices.astype(np.int64)
    p = positions.astype(np.float64)
    if len(t):
        a = p[t[:, 0]]
        cross = np.cross(p[t[:, 1]] - a, p[t[:, 2]] - a)  # length = 2 * area
        for corner in range(3):
            for axis in range(3):
                out[:, axis] += np.bincount(t[:, corner], weights=cross[:, axis], minlength=n)
    length = np.sqrt((out * out).sum(axis=1))
    ok = length > 0
    out[ok] /= length[ok, None]
    out[~ok] = (0.0, 0.0, 1.0)
    return out.astype(np.float32)


def encode_mesh(mesh: Mesh) -> bytes:
    """Encode a triangle mesh for streaming (see the "mesh" format above).

    Parameters
    ----------
    mesh:
        The mesh, e.g. ``shared.buildings.build_lod(b, 2, grammar)``.

    Returns
    -------
    bytes
        About ``12 n + 3 w m + m`` bytes for ``n`` vertices and ``m`` triangles
        (``w`` = 1, 2 or 4), plus ~100 bytes of keys.

    Raises
    ------
    CodecError
        Positions are not finite, an index is out of range, or the mesh is larger
        than :func:`decode_mesh` accepts.
    """
    pos = np.ascontiguousarray(mesh.positions, dtype="<f4")
    idx = np.asarray(mesh.indices)
    n, m = len(pos), len(idx)
    if n > _MAX_MESH_VERTICES:
        raise CodecError(f"mesh: {n} vertices, more than the limit of {_MAX_MESH_VERTICES}")
    if not np.isfinite(pos).all():
        raise CodecError("mesh: positions must be finite")
    if m and int(idx.max()) >= n:
        raise CodecError(f"mesh: index {int(idx.max())} out of range for {n} vertices")
    width = _index_bytes(n)
    rec: dict[str, Any] = {
        "format": MESH_FORMAT,
        "vertices": n,
        "positions": pos.tobytes(),
        "index_bytes": width,
        "indices": idx.astype(f"<u{width}").tobytes(),
    }
    vm = np.asarray(mesh.materials, np.uint8)
    tm = vm[idx[:, 0]] if m else np.zeros(0, np.uint8)
    if m and ((vm[idx[:, 1]] != tm) | (vm[idx[:, 2]] != tm)).any():
        rec["vertex_materials"] = vm.tobytes()
    else:
        rec["materials"] = tm.tobytes()
    if m:
        used = np.zeros(n, bool)
        used[idx.reshape(-1)] = True
        given = np.asarray(mesh.normals, np.float64)[used]
        dots = (given * _flat_normals(pos, idx)[used]).sum(axis=1)
        if not (dots >= _NORMAL_COS_TOLERANCE).all():
            rec["normals"] = np.ascontiguousarray(mesh.normals, dtype="<f4").tobytes()
    data: bytes = msgpack.packb(rec, use_bin_type=True)
    if len(data) > _MAX_MESH_BYTES:
        raise CodecError(f"mesh: {len(data)} bytes, more than the limit of {_MAX_MESH_BYTES}")
    return data


def _mesh_bin(rec: dict[str, Any], key: str, size: int, unit: str, what: str) -> bytes:
    v = rec.get(key)
    if not isinstance(v, bytes):
        got = "nothing" if v is None else type(v).__name__
        raise CodecError(f"{what}: {key}: expected bin, got {got}")
    if len(v) != size:
        raise CodecError(f"{what}: {key}: expected {size} bytes ({unit}), got {len(v)}")
    return v


def decode_mesh(data: bytes | bytearray | memoryview, what: str = "mesh") -> Mesh:
    """Decode bytes made by :func:`encode_mesh`.

    Normals are recomputed from the triangles (flat, per vertex) unless the bytes
    carry them; materials are given per vertex, as :class:`~walkstream.shared.records.Mesh`
    holds them (a vertex no triangle uses gets material 0).

    Parameters
    ----------
    data:
        The bytes (untrusted: everything is bounded and checked).
    what:
        What is being decoded, for error messages (``"mesh of object 12"``).

    Raises
    ------
    CodecError
        Not a mesh map, another format, an unknown or missing field, lengths that
        do not match the vertex and triangle counts, an index out of range, or
        positions or normals that are not finite.  The message names the field.
    """
    obj = unpack_bounded(
        data,
        what,
        max_bytes=_MAX_MESH_BYTES,
        # no field is an array; a few elements are let through so that a wrong type
        # is reported by its field name rather than as a msgpack limit
        max_array_len=16,
        max_map_len=len(_MESH_KEYS),
        max_str_len=64,
        max_bin_len=_MAX_MESH_BYTES,
    )
    if not isinstance(obj, dict):
        raise CodecError(f"{what}: expected a map, got {type(obj).__name__}")
    fmt = obj.get("format")
    if fmt != MESH_FORMAT:
        raise CodecError(f"{what}: format: expected {MESH_FORMAT!r}, got {fmt!r:.80}")
    unknown = sorted(str(k) for k in obj if k not in _MESH_KEYS)
    if unknown:
        raise CodecError(f"{what}: unknown field {unknown[0]!r:.80}")
    n = checked_int(obj.get("vertices"), what, "vertices", 0, _MAX_MESH_VERTICES)
    pos_b = _mesh_bin(obj, "positions", 12 * n, f"3 float32 per vertex, {n} vertices", what)
    pos = np.frombuffer(pos_b, "<f4").reshape(n, 3)
    if not np.isfinite(pos).all():
        raise CodecError(f"{what}: positions: not finite")
    width = checked_int(obj.get("index_bytes"), what, "index_bytes", 1, 4)
    if width not in (1, 2, 4):
        raise CodecError(f"{what}: index_bytes: expected 1, 2 or 4, got {width}")
    ib = obj.get("indices")
    if not isinstance(ib, bytes):
        got = "nothing" if ib is None else type(ib).__name__
        raise CodecError(f"{what}: indices: expected bin, got {got}")
    if len(ib) % (3 * width):
        raise CodecError(
            f"{what}: indices: {len(ib)} bytes is not a whole number of triangles "
            f"of {width}-byte indices"
        )
    idx = np.frombuffer(ib, f"<u{width}").reshape(-1, 3)
    m = len(idx)
    if m and int(idx.max()) >= n:
        raise CodecError(f"{what}: indices: index {int(idx.max())} out of range for {n} vertices")
    if ("materials" in obj) == ("vertex_materials" in obj):
        raise CodecError(f"{what}: materials: expected exactly one of materials, vertex_materials")
    if "materials" in obj:
        tm = np.frombuffer(_mesh_bin(obj, "materials", m, f"1 per triangle, {m}", what), np.uint8)
        vm = np.zeros(n, np.uint8)
        for corner in range(3):
            vm[idx[:, corner]] = tm
    else:
        vb = _mesh_bin(obj, "vertex_materials", n, f"1 per vertex, {n}", what)
        vm = np.frombuffer(vb, np.uint8)
    if "normals" in obj:
        nb = _mesh_bin(obj, "normals", 12 * n, f"3 float32 per vertex, {n} vertices", what)
        normals = np.frombuffer(nb, "<f4").reshape(n, 3)
        if not np.isfinite(normals).all():
            raise CodecError(f"{what}: normals: not finite")
    else:
        normals = _flat_normals(pos, idx)
    return Mesh(pos, normals, idx, vm)
