"""Wall textures with a depth grid: a textured depth mesh instead of one flat quad (``--wall-depth G``).

A virtual wall's texture is the render from its zone's sampling point; laid on the
wall's quad it is right for one depth only.  A **textured depth mesh** (Sillion,
Drettakis and Bodelet 1997; Decoret et al. 1999) stores a coarse ``G`` x ``G`` grid of
depths with the texture: each of the ``(G + 1)^2`` vertices at the *nearest* depth the
texture shows within half a cell of it (the mean lands between a facade and the far
field and both slide: ``benchmarks/walldepth.py`` measured it), in 8 bits of the
inverse depth ``x_s / (x_s + p)`` (``x_s`` the sampling point's distance from the wall,
``p`` the depth behind it), rows differenced and deflated.

**Bytes.** The grid rides after the image's bytes as a trailer (:func:`attach_depth`:
payload, its length in 2 bytes, the magic ``WDG1``), so it travels wherever the
texture does (the database's ``wall_textures.data``, its ETag, the batch and the start
bundle) and a texture baked without it is byte for byte what it was.  Image decoders
stop at the image's own end (WebP's RIFF length), so a client that does not know the
trailer still decodes the image.

**Mesh.** :func:`depth_mesh` puts each vertex back where the sampling point saw it,
``at + (wall point - at) / inv``, and gives it the projective texture coordinates
``(u q, t q, q)`` with ``q = 1 / inv``: across a triangle whose corners stand at
different depths, ``u q``, ``t q`` and ``q`` are affine in the position, so dividing by
the interpolated ``q`` shows exactly the texel the sampling point saw each point
through.  Each row's runs of cells whose four corners share one depth (the sky, a
facade square on) are merged into one quad, and the same run on the rows below it too.
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from walkstream.shared.errors import CodecError, InputError
from walkstream.shared.walls import WallSide

__all__ = [
    "DEPTH_CAP",
    "DEPTH_MAGIC",
    "WALL_DEPTH_GRIDS",
    "WallImage",
    "attach_depth",
    "check_depth_grid",
    "depth_mesh",
    "encode_depth",
    "grid_reduce",
    "mesh_triangles",
    "split_depth",
    "vertex_depths",
    "with_depth",
]

WALL_DEPTH_GRIDS: tuple[int, ...] = (0, 4, 8, 16)
"""Grid sizes ``--wall-depth`` accepts (0: no depth, one flat quad)."""

DEPTH_MAGIC = b"WDG1"
"""The trailer's last four bytes."""

DEPTH_CAP = 1000.0
"""Depths beyond this, metres behind the wall (the sky included), are stored here: the
mesh stays finite, and the warped quad under it shows what lies past the far plane."""

_LEVELS = 255


def check_depth_grid(grid: int) -> int:
    """``grid`` if ``--wall-depth`` accepts it, else a one-line :class:`InputError`."""
    if isinstance(grid, bool) or not isinstance(grid, int) or grid not in WALL_DEPTH_GRIDS:
        raise InputError(f"--wall-depth: expected one of {', '.join(map(str, WALL_DEPTH_GRIDS))}, got {grid!r:.20}")
    return grid


def vertex_depths(behind: NDArray[np.floating], x_s: float, grid: int) -> NDArray[np.float64]:
    """``(grid + 1, grid + 1)`` inverse depths ``x_s / (x_s + p)`` at the vertices (row 0
    at the top) of the render's per-sample depth ``behind`` ``(h, w)`` (metres behind the
    wall, ``inf`` where nothing was drawn): the largest, the nearest, within half a cell
    of each vertex, no smaller than :data:`DEPTH_CAP`'s."""
    p = np.minimum(np.asarray(behind, np.float64), DEPTH_CAP)
    return grid_reduce(x_s / (x_s + p), grid)


def grid_reduce(
    values: NDArray[np.float64], grid: int, reduce: Callable[[NDArray[np.float64]], Any] = np.max
) -> NDArray[np.float64]:
    """``(grid + 1, grid + 1)``: ``reduce`` of the samples of ``values`` ``(h, w)`` within
    half a cell of each vertex of a ``grid`` x ``grid`` mesh over them (row 0 at the top)."""
    h, w = values.shape
    out = np.empty((grid + 1, grid + 1))
    rows, cols = np.linspace(0, h, grid + 1), np.linspace(0, w, grid + 1)
    hr, hc = h / grid / 2, w / grid / 2
    for i, r in enumerate(rows):
        r0, r1 = int(max(r - hr, 0)), int(min(r + hr, h)) + 1
        for j, c in enumerate(cols):
            out[i, j] = reduce(values[r0:r1, int(max(c - hc, 0)):int(min(c + hc, w)) + 1])
    return out


def encode_depth(inv: NDArray[np.float64]) -> bytes:
    """The payload of a vertex grid ``inv`` ``(g + 1, g + 1)``: ``g`` in one byte, then the
    8-bit inverse depths (at least 1), row differences, deflated."""
    g = inv.shape[0] - 1
    q = np.clip(np.round(np.asarray(inv) * _LEVELS), 1, _LEVELS).astype(np.int64)
    diff = np.diff(q, axis=1, prepend=0) % 256
    return bytes([g]) + zlib.compress(diff.astype(np.uint8).tobytes(), 9)


def attach_depth(image: bytes, payload: bytes) -> bytes:
    """``image`` with the depth ``payload`` (:func:`encode_depth`) as its trailer."""
    return image + payload + struct.pack("<H", len(payload)) + DEPTH_MAGIC


def split_depth(blob: bytes, what: str = "wall texture") -> tuple[bytes, NDArray[np.float64] | None]:
    """``(image bytes, inverse-depth grid (g + 1, g + 1) or None)`` of a stored texture; a
    blob without the trailer is all image.  A damaged trailer is a :class:`CodecError`."""
    if len(blob) < 6 or blob[-4:] != DEPTH_MAGIC:
        return blob, None
    (n,) = struct.unpack("<H", blob[-6:-4])
    if n < 2 or n + 6 > len(blob):
        raise CodecError(f"{what}: depth trailer of {n} bytes does not fit")
    payload = blob[-6 - n:-6]
    g = payload[0]
    if g not in WALL_DEPTH_GRIDS or g == 0:
        raise CodecError(f"{what}: depth grid {g} is not one of {WALL_DEPTH_GRIDS[1:]}")
    try:
        raw = zlib.decompressobj().decompress(payload[1:], (g + 1) ** 2 + 1)
    except zlib.error as exc:
        raise CodecError(f"{what}: depth grid does not inflate ({exc})") from None
    if len(raw) != (g + 1) ** 2:
        raise CodecError(f"{what}: depth grid of {len(raw)} bytes, expected {(g + 1) ** 2}")
    q = np.cumsum(np.frombuffer(raw, np.uint8).reshape(g + 1, g + 1).astype(np.int64), axis=1) % 256
    if (q == 0).any():
        raise CodecError(f"{what}: depth grid holds an inverse depth of 0")
    return blob[:-6 - n], q.astype(np.float64) / _LEVELS


class WallImage(np.ndarray):
    """A decoded wall texture (premultiplied RGBA ``(h, w, 4) uint8``) that carries its
    inverse-depth grid (:attr:`depth`) and, once built, its mesh (:attr:`mesh`)."""

    depth: NDArray[np.float64] | None = None
    mesh: NDArray[np.float32] | None = None

    def __array_finalize__(self, obj: object) -> None:
        self.depth = getattr(obj, "depth", None)
        self.mesh = getattr(obj, "mesh", None)


def with_depth(rgba: NDArray[np.uint8], inv: NDArray[np.float64] | None) -> NDArray[np.uint8]:
    """``rgba`` as it is without a grid, else a :class:`WallImage` holding ``inv``."""
    if inv is None:
        return rgba
    out = np.asarray(rgba).view(WallImage)
    out.depth = inv
    out.mesh = None
    return out


def depth_mesh(side: WallSide, zone: int, inv: NDArray[np.float64]) -> NDArray[np.float32]:
    """``(n, 6) float32`` triangles (position, projective texture coordinates ``u q, t q, q``;
    ``t`` 0 at the image's top) of zone ``zone``'s texture of ``side`` with vertex inverse
    depths ``inv`` ``(g + 1, g + 1)`` (row 0 at the top), flat runs of a row merged, and
    with the same run on the rows below."""
    at = side.sample_point(zone)
    g = inv.shape[0] - 1
    t = np.linspace(0.0, 1.0, g + 1)
    s, top = np.meshgrid(t, t)  # top: 0 on row 0 (the wall's top)
    wall = np.stack([side.p0[0] + side.along[0] * s * side.length, side.p0[1] + side.along[1] * s * side.length,
                     side.z1 - top * (side.z1 - side.z0)], -1)
    q = 1.0 / np.asarray(inv, np.float64)
    pos = at + (wall - at) * q[..., None]
    vert = np.concatenate([pos, (s * q)[..., None], (top * q)[..., None], q[..., None]], -1)
    flat = (inv[:-1, :-1] == inv[:-1, 1:]) & (inv[:-1, :-1] == inv[1:, :-1]) & (inv[:-1, :-1] == inv[1:, 1:])
    tris: list[NDArray[np.float64]] = []

    def quad(i0: int, i1: int, j0: int, j1: int) -> None:
        # top-left, bottom-left, bottom-right, top-right of the cells rows i0..i1, columns j0..j1
        c = vert[[i0, i1, i1, i0], [j0, j0, j1, j1]]
        tris.append(c[[0, 1, 2, 0, 2, 3]])

    open_runs: dict[tuple[int, int, float], int] = {}  # a flat run -> the row it started on
    for i in range(g + 1):
        runs: set[tuple[int, int, float]] = set()
        j = 0
        while i < g and j < g:
            k = j + 1
            if flat[i, j]:  # a run of cells on one plane parallel to the wall: one quad
                while k < g and flat[i, k] and inv[i, k] == inv[i, j]:
                    k += 1
                runs.add((j, k, float(inv[i, j])))
            else:
                quad(i, i + 1, j, k)
            j = k
        # the same run on the rows below joins it (one plane): emit those that end here
        for key in [r for r in open_runs if r not in runs]:
            quad(open_runs.pop(key), i, key[0], key[1])
        for key in runs:
            open_runs.setdefault(key, i)
    return np.concatenate(tris).astype(np.float32) if tris else np.zeros((0, 6), np.float32)


def mesh_triangles(mesh: NDArray[np.float32] | None) -> int:
    """Triangles of a mesh (:func:`depth_mesh`; 0 for None)."""
    return 0 if mesh is None else len(mesh) // 3
