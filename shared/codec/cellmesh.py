"""The contents of an interior cell as one compact, immutable blob (``walkstream-cellmesh/4``, /3, /2 and /1).

The bake writes version 4 (:data:`CELLMESH_FORMAT`, planar polygons, boxes and axis
rectangles on an absolute 1 mm grid, the remaining triangles sharing their corners:
:mod:`~walkstream.shared.codec.planarmesh` says how and states its error bound, half a
millimetre per coordinate plus float32 rounding); :func:`decode_cell_mesh` reads all
four, so a database baked before keeps working.  What follows describes
version 1 (:data:`CELLMESH_V1`), which :func:`encode_cell_mesh` still writes with
``version=1`` for comparison (``walkstream bench interiors``).  Both start with the
same tag byte saying how the rest is compressed, so a batch can inflate stored blobs
to their ``N`` form and compress many together.

Each interior cell's geometry is a unit the client loads when the cell becomes
visible and flushes later (Mulloni et al.), so it travels as one response: every
part of every building element that lies in the cell (a wall's faces towards the
room, a desk, a slab's floor), each part keeping its element id and material so
that the client can cull parts by bounding box and colour them.

Error bound
-----------
Positions are quantised to :data:`POSITION_BITS` = 16 bits per coordinate relative
to the box of the cell's contents: ``q = round((p - lo) / ext * 65535)``.  Decoding
gives ``lo + q * ext / 65535`` as float32, so every coordinate is within
``ext / 131070`` (half a quantisation step; :func:`position_error_bound`) plus the
float32 rounding of the scene-local value (``2**-24 * |p|``, 6 micrometres at 100 m)
of the original.  A 30 m room is kept to 0.23 mm; a 200 m building's outside cell to
1.5 mm.  ``tests/test_cellmesh.py`` checks the bound on random and real meshes.

Layout
------
The blob is one tag byte saying how the rest is compressed (``Z`` zlib level 9, ``X``
lzma preset 6, ``N`` none: whichever is smallest for this cell) followed by the
msgpack map::

    {"format": "walkstream-cellmesh/1", "lo": [x, y, z], "ext": [ex, ey, ez],
     "parts": p, "elements": bin, "materials": bin, "vertices": bin,
     "triangles": bin, "positions": bin, "indices": bin}

``elements`` are the parts' element ids as zigzag varints of their differences,
``materials`` one byte per part, ``vertices`` and ``triangles`` each part's counts as
varints; ``positions`` the quantised coordinates, axis by axis (all x, then all y,
then all z), each as zigzag varints of the difference to the previous vertex of the
same part; ``indices`` each part's triangle indices (local to the part) as zigzag
varints of the difference to the previous index.  Normals are not sent: the decoder
recomputes them from the faces (the bake welds vertices only between faces of one
plane, so the normals are flat).

Raw size, for comparison: float32 positions and uint32 indices, ``12 * vertices + 12 *
triangles`` bytes (:func:`raw_bytes`).

Why these compressors: on duplex.ifc's 49 cells the map is 448 kB uncompressed, 210 kB
with zlib, 196 kB with lzma (the same at presets 6 and 9, 15 times faster at 6), and
204 to 226 kB with zstandard at levels 19 to 3, so zstandard did not win and the
standard library's two are used; a cell takes whichever is smaller.

Decoding is bounded: the compressed size, the decompressed size (at most
:data:`MAX_CELLMESH_BYTES`), the counts and every index are checked, and any failure
is a :class:`~walkstream.shared.errors.CodecError`.
"""

from __future__ import annotations

import lzma
import zlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import msgpack
import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.shared.codec.bounded import unpack_bounded
from walkstream.shared.codec.varint import encode_varints, unzigzag, varint_field, zigzag
from walkstream.shared.errors import CodecError
from walkstream.shared.records import Mesh, readonly

__all__ = [
    "CELLMESH_FORMAT",
    "CELLMESH_V1",
    "CELLMESH_V2",
    "CELLMESH_V3",
    "POSITION_BITS",
    "MAX_CELLMESH_BYTES",
    "CellPart",
    "CellMesh",
    "encode_cell_mesh",
    "decode_cell_mesh",
    "position_error_bound",
    "raw_bytes",
    "flat_normals",
    "inflate_cell_mesh",
]

CELLMESH_FORMAT = "walkstream-cellmesh/4"
"""The format tag of the cell-contents blobs the bake writes (planar polygons, boxes and
rectangles on a 1 mm grid; the remaining triangles share their corners)."""
CELLMESH_V3 = "walkstream-cellmesh/3"
"""The third version's tag (as version 4, the remaining triangles' corners repeated per
plane): still decoded."""
CELLMESH_V2 = "walkstream-cellmesh/2"
"""The second version's tag (planar polygons on a 1 mm grid, no boxes): still decoded."""
CELLMESH_V1 = "walkstream-cellmesh/1"
"""The first version's tag (every triangle, 16 bits over the cell's box): still decoded."""
POSITION_BITS = 16
"""Bits per quantised coordinate."""
MAX_CELLMESH_BYTES = 64 << 20
"""Largest decompressed cell-contents map a decoder accepts."""

_LEVELS = (1 << POSITION_BITS) - 1
_MAX_VERTICES = 1 << 22
_MAX_PARTS = 1 << 16
_KEYS = frozenset(
    {
        "format",
        "lo",
        "ext",
        "parts",
        "elements",
        "materials",
        "vertices",
        "triangles",
        "positions",
        "indices",
    }
)


def position_error_bound(extent: ArrayLike) -> NDArray[np.float64]:
    """Largest quantisation error per coordinate for a box of ``extent`` metres.

    >>> float(position_error_bound([65.535])[0])
    0.0005
    """
    return np.asarray(extent, dtype=np.float64) / (2.0 * _LEVELS)


def raw_bytes(vertices: int, triangles: int) -> int:
    """Bytes of the same mesh as float32 positions and uint32 indices (the comparison)."""
    return 12 * int(vertices) + 12 * int(triangles)


def flat_normals(positions: NDArray[Any], indices: NDArray[Any]) -> NDArray[np.float32]:
    """Unit vertex normals: the area-weighted mean of the faces that use each vertex.

    Parameters
    ----------
    positions : (n, 3) float
    indices : (m, 3) int

    Returns
    -------
    (n, 3) float32
        Vertices of no face (or only degenerate ones) get ``(0, 0, 1)``.
    """
    p = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    t = np.asarray(indices, dtype=np.int64).reshape(-1, 3)
    vn = np.zeros_like(p)
    if len(t):
        a, b, c = p[t[:, 0]], p[t[:, 1]], p[t[:, 2]]
        fn = np.cross(b - a, c - a)
        for k in range(3):
            np.add.at(vn, t[:, k], fn)
    norm = np.linalg.norm(vn, axis=1)
    ok = norm > 1e-12
    vn[ok] /= norm[ok, None]
    vn[~ok] = (0.0, 0.0, 1.0)
    return vn.astype(np.float32)


@dataclass(frozen=True, slots=True)
class CellPart:
    """The piece of one building element that lies in a cell.

    Attributes
    ----------
    element:
        The element's id (unique in the scene; a wall split over three rooms has
        the same id in all three cells).
    material:
        Material id (:data:`~walkstream.shared.palette.MATERIALS`).
    positions:
        ``(n, 3) float32`` scene-local metres.
    indices:
        ``(m, 3) uint32`` triangles into ``positions``, counter-clockwise from outside.
    """

    element: int
    material: int
    # typed loosely: any numeric array is accepted and converted in __post_init__
    positions: NDArray[Any]
    indices: NDArray[Any]

    def __post_init__(self) -> None:
        object.__setattr__(
            self, "positions", readonly(np.asarray(self.positions, np.float32).reshape(-1, 3))
        )
        object.__setattr__(
            self, "indices", readonly(np.asarray(self.indices, np.uint32).reshape(-1, 3))
        )

    @property
    def triangles(self) -> int:
        """Number of triangles."""
        return int(len(self.indices))

    @property
    def bbox(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``(lo, hi)``: the part's axis-aligned box, ``(3,)`` float64 each."""
        p = self.positions.astype(np.float64)
        if len(p) == 0:
            z = np.zeros(3)
            return z, z
        return p.min(axis=0), p.max(axis=0)

    def mesh(self) -> Mesh:
        """The part as a :class:`~walkstream.shared.records.Mesh` with flat normals."""
        return Mesh(
            self.positions,
            flat_normals(self.positions, self.indices),
            self.indices,
            np.full(len(self.positions), self.material, np.uint8),
        )


@dataclass(frozen=True)
class CellMesh:
    """A decoded cell-contents blob: its parts, the quantisation box and its size."""

    parts: tuple[CellPart, ...]
    lo: tuple[float, float, float]
    extent: tuple[float, float, float]
    nbytes: int = 0
    """Bytes of the encoded blob."""
    grid: float = 0.0
    """Absolute grid step of the positions (metres; ``walkstream-cellmesh/2``), 0 for version 1."""
    missing: tuple[int, ...] = ()
    """A cell's head (:mod:`~walkstream.shared.codec.cellhead`): the indices of the parts
    that are stand-ins for pieces still to come; empty for a whole cell."""
    _cache: dict[str, Any] = field(default_factory=dict, repr=False, compare=False)

    @property
    def triangles(self) -> int:
        """Triangles over all parts."""
        return sum(p.triangles for p in self.parts)

    @property
    def vertices(self) -> int:
        """Vertices over all parts."""
        return sum(len(p.positions) for p in self.parts)

    @cached_property
    def error_bound(self) -> float:
        """Largest quantisation error of any coordinate, metres (half a grid step for version 2)."""
        if self.grid:
            return 0.5 * self.grid
        return float(position_error_bound(self.extent).max())

    def mesh(self) -> Mesh:
        """All parts as one mesh (flat normals, material per vertex)."""
        return Mesh.concat([p.mesh() for p in self.parts])


def encode_cell_mesh(
    parts: Sequence[tuple[int, int, ArrayLike, ArrayLike]],
    *,
    compress: str = "best",
    version: int = 4,
) -> bytes:
    """Encode a cell's parts.

    Parameters
    ----------
    parts:
        ``(element id, material id, positions (n, 3) float, indices (m, 3) int)`` per
        part; parts without triangles are dropped.
    compress:
        ``"zlib"``, ``"lzma"``, ``"none"`` or ``"best"`` (the smallest of the three).
    version:
        4 (:data:`CELLMESH_FORMAT`, planar polygons, boxes and axis rectangles on a 1 mm
        grid, the remaining triangles welded, :mod:`~walkstream.shared.codec.planarmesh`),
        3 (:data:`CELLMESH_V3`, the same with every remaining triangle's corners of its
        own), 2 (:data:`CELLMESH_V2`, without boxes and rectangles) or 1
        (:data:`CELLMESH_V1`, every triangle, 16 bits over the cell's box); 3, 2 and 1
        kept for comparison and old databases.

    Returns
    -------
    bytes
        The blob (see the module docstring).

    Raises
    ------
    CodecError
        Non-finite positions, indices out of range, or too many parts or vertices.
    """
    elements: list[int] = []
    materials: list[int] = []
    pos_list: list[NDArray[np.float64]] = []
    idx_list: list[NDArray[np.int64]] = []
    for k, (element, material, positions, indices) in enumerate(parts):
        p = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
        t = np.asarray(indices, dtype=np.int64).reshape(-1, 3)
        if len(t) == 0:
            continue
        if not np.all(np.isfinite(p)):
            raise CodecError(f"cell mesh part {k} (element {element}): non-finite positions")
        if t.min() < 0 or t.max() >= len(p):
            raise CodecError(f"cell mesh part {k} (element {element}): index out of range")
        if not 0 <= int(material) <= 255:
            raise CodecError(f"cell mesh part {k}: material {material} is not 0..255")
        elements.append(int(element))
        materials.append(int(material))
        pos_list.append(p)
        idx_list.append(t)
    if len(elements) > _MAX_PARTS:
        raise CodecError(f"cell mesh: {len(elements)} parts, at most {_MAX_PARTS}")
    if compress not in ("best", "zlib", "lzma", "none"):
        raise CodecError(f"cell mesh: compress must be best, zlib, lzma or none, got {compress!r}")
    if version in (2, 3, 4):
        from walkstream.shared.codec.planarmesh import encode_planar_body

        rows = list(zip(elements, materials, pos_list, idx_list, strict=True))
        return _compress(msgpack.packb(encode_planar_body(rows, version), use_bin_type=True), compress)
    if version != 1:
        raise CodecError(f"cell mesh: version must be 1, 2, 3 or 4, got {version!r}")
    vcount = np.array([len(p) for p in pos_list], dtype=np.int64)
    tcount = np.array([len(t) for t in idx_list], dtype=np.int64)
    if int(vcount.sum()) > _MAX_VERTICES:
        raise CodecError(f"cell mesh: {int(vcount.sum())} vertices, at most {_MAX_VERTICES}")
    allp = np.concatenate(pos_list) if pos_list else np.zeros((0, 3))
    lo = allp.min(axis=0) if len(allp) else np.zeros(3)
    ext = (allp.max(axis=0) - lo) if len(allp) else np.zeros(3)
    scale = np.where(ext > 0, _LEVELS / np.where(ext > 0, ext, 1.0), 0.0)
    q = np.rint((allp - lo) * scale).astype(np.int64)
    np.clip(q, 0, _LEVELS, out=q)
    vstarts = np.concatenate([[0], np.cumsum(vcount)[:-1]]).astype(np.int64) if len(vcount) else np.zeros(0, np.int64)
    dq = _part_deltas(q, vstarts)
    alli = np.concatenate(idx_list).reshape(-1) if idx_list else np.zeros(0, np.int64)
    istarts = (
        np.concatenate([[0], np.cumsum(tcount * 3)[:-1]]).astype(np.int64)
        if len(tcount)
        else np.zeros(0, np.int64)
    )
    di = _part_deltas(alli, istarts)
    eid = np.asarray(elements, dtype=np.int64)
    body = {
        "format": CELLMESH_V1,
        "lo": [float(v) for v in lo],
        "ext": [float(v) for v in ext],
        "parts": len(elements),
        "elements": encode_varints(zigzag(np.diff(eid, prepend=0))),
        "materials": bytes(np.asarray(materials, dtype=np.uint8)),
        "vertices": encode_varints(vcount.astype(np.uint64)),
        "triangles": encode_varints(tcount.astype(np.uint64)),
        "positions": encode_varints(zigzag(dq.T.reshape(-1))),
        "indices": encode_varints(zigzag(di)),
    }
    return _compress(msgpack.packb(body, use_bin_type=True), compress)


def _compress(packed: bytes, compress: str) -> bytes:
    """The tag byte and the compressed map (``compress`` as :func:`encode_cell_mesh`)."""
    options = {
        "none": lambda: b"N" + packed,
        "zlib": lambda: b"Z" + zlib.compress(packed, 9),
        "lzma": lambda: b"X" + lzma.compress(packed, preset=6),
    }
    if compress == "best":
        return min((f() for f in options.values()), key=len)
    return options[compress]()


def _part_deltas(values: NDArray[np.int64], starts: NDArray[np.int64]) -> NDArray[np.int64]:
    """Differences to the previous row, restarting at 0 at every part start."""
    d = np.diff(values, axis=0, prepend=np.zeros((1,) + values.shape[1:], values.dtype))
    if len(starts) and len(values):
        d[starts] = values[starts]
    return d


def _part_cumsum(d: NDArray[np.int64], starts: NDArray[np.int64]) -> NDArray[np.int64]:
    """Inverse of :func:`_part_deltas`: a running sum restarting at every part start."""
    out = np.cumsum(d, axis=0)
    if len(starts) > 1:
        # the sum runs on over part ends: at each later start it carries what all the
        # parts before it added up to; remove that (as steps, so cumsum spreads them)
        before = out[starts[1:] - 1]
        fix = np.zeros_like(out)
        fix[starts[1:]] = np.diff(before, axis=0, prepend=np.zeros_like(before[:1]))
        out = out - np.cumsum(fix, axis=0)
    return out


def _decompress(blob: bytes, what: str) -> bytes:
    if len(blob) < 2:
        raise CodecError(f"{what}: {len(blob)} bytes is too short for a cell mesh")
    if len(blob) > MAX_CELLMESH_BYTES:
        raise CodecError(f"{what}: {len(blob)} bytes, at most {MAX_CELLMESH_BYTES}")
    tag, rest = blob[:1], blob[1:]
    try:
        if tag == b"N":
            return rest
        if tag == b"Z":
            d = zlib.decompressobj()
            out = d.decompress(rest, MAX_CELLMESH_BYTES)
            if d.unconsumed_tail or not d.eof:
                raise CodecError(f"{what}: truncated or larger than {MAX_CELLMESH_BYTES} bytes")
            return out
        if tag == b"X":
            dx = lzma.LZMADecompressor()
            out = dx.decompress(rest, MAX_CELLMESH_BYTES)
            if not dx.eof:
                raise CodecError(f"{what}: truncated or larger than {MAX_CELLMESH_BYTES} bytes")
            return out
    except (zlib.error, lzma.LZMAError) as exc:
        raise CodecError(f"{what}: damaged compressed data ({exc})") from exc
    raise CodecError(f"{what}: unknown compression tag {tag!r}")


def inflate_cell_mesh(blob: bytes, what: str = "cell mesh") -> bytes:
    """The blob with its body decompressed: tag ``N`` and the bytes that followed ``Z`` or
    ``X`` inflated (bounded as :func:`decode_cell_mesh`); an ``N`` blob comes back as it is.
    Many such blobs compress together better than each on its own (the contents batch)."""
    if blob[:1] == b"N":
        return bytes(blob)
    return b"N" + _decompress(bytes(blob), what)


def decode_cell_mesh(blob: bytes, what: str = "cell mesh") -> CellMesh:
    """Decode and check a cell-contents blob (see the module docstring).

    Raises
    ------
    CodecError
        Damaged, truncated, oversized or inconsistent input.
    """
    packed = _decompress(bytes(blob), what)
    body = unpack_bounded(
        packed, what, max_bytes=MAX_CELLMESH_BYTES, max_array_len=8, max_map_len=24,
        max_bin_len=MAX_CELLMESH_BYTES,
    )
    if isinstance(body, dict) and body.get("format") in (CELLMESH_FORMAT, CELLMESH_V3, CELLMESH_V2):
        return _decode_v2(body, what, len(blob))
    if not isinstance(body, dict) or body.get("format") != CELLMESH_V1:
        raise CodecError(f"{what}: not a {CELLMESH_FORMAT}, {CELLMESH_V3}, {CELLMESH_V2} or {CELLMESH_V1} map")
    if set(body) - _KEYS:
        raise CodecError(f"{what}: unknown keys {sorted(set(body) - _KEYS)}")
    try:
        lo = np.asarray(body["lo"], dtype=np.float64).reshape(3)
        ext = np.asarray(body["ext"], dtype=np.float64).reshape(3)
        n_parts = body["parts"]
    except (KeyError, TypeError, ValueError) as exc:
        raise CodecError(f"{what}: bad or missing lo/ext/parts ({exc})") from exc
    if type(n_parts) is not int or not 0 <= n_parts <= _MAX_PARTS:
        raise CodecError(f"{what}: parts must be 0..{_MAX_PARTS}")
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(ext)) and np.all(ext >= 0)):
        raise CodecError(f"{what}: lo/ext must be finite, ext >= 0")
    mats = body.get("materials")
    if not isinstance(mats, bytes) or len(mats) != n_parts:
        raise CodecError(f"{what}: materials: expected {n_parts} bytes")
    eid = np.cumsum(unzigzag(varint_field(body, "elements", n_parts, what)))
    vcount = varint_field(body, "vertices", n_parts, what).astype(np.int64)
    tcount = varint_field(body, "triangles", n_parts, what).astype(np.int64)
    nv, nt = int(vcount.sum()), int(tcount.sum())
    if nv > _MAX_VERTICES or nt > 4 * _MAX_VERTICES:
        raise CodecError(f"{what}: {nv} vertices / {nt} triangles is too many")
    dq = unzigzag(varint_field(body, "positions", 3 * nv, what)).reshape(3, nv).T
    vstarts = np.concatenate([[0], np.cumsum(vcount)[:-1]]).astype(np.int64) if n_parts else np.zeros(0, np.int64)
    q = _part_cumsum(dq, vstarts)
    if len(q) and (q.min() < 0 or q.max() > _LEVELS):
        raise CodecError(f"{what}: quantised position out of range")
    step = ext / _LEVELS
    pos = (lo + q.astype(np.float64) * step).astype(np.float32)
    di = unzigzag(varint_field(body, "indices", 3 * nt, what))
    istarts = np.concatenate([[0], np.cumsum(tcount * 3)[:-1]]).astype(np.int64) if n_parts else np.zeros(0, np.int64)
    idx = _part_cumsum(di, istarts)
    parts: list[CellPart] = []
    v0 = t0 = 0
    for k in range(n_parts):
        nvk, ntk = int(vcount[k]), int(tcount[k])
        t = idx[3 * t0 : 3 * (t0 + ntk)].reshape(-1, 3)
        if len(t) and (t.min() < 0 or t.max() >= nvk):
            raise CodecError(f"{what}: part {k}: index out of range")
        parts.append(CellPart(int(eid[k]), mats[k], pos[v0 : v0 + nvk], t))
        v0 += nvk
        t0 += ntk
    return CellMesh(
        tuple(parts),
        (float(lo[0]), float(lo[1]), float(lo[2])),
        (float(ext[0]), float(ext[1]), float(ext[2])),
        nbytes=len(blob),
    )


def _decode_v2(body: dict[str, Any], what: str, nbytes: int) -> CellMesh:
    """A version 2, 3 or 4 map as a :class:`CellMesh` (its box measured from the decoded positions)."""
    from walkstream.shared.codec.planardecode import decode_planar_body
    from walkstream.shared.codec.planarmesh import GRID

    parts = tuple(CellPart(e, m, p, t) for e, m, p, t in decode_planar_body(body, what))
    allp = np.concatenate([p.positions for p in parts]).astype(np.float64) if parts else np.zeros((0, 3))
    lo = allp.min(axis=0) if len(allp) else np.zeros(3)
    ext = allp.max(axis=0) - lo if len(allp) else np.zeros(3)
    return CellMesh(
        parts,
        (float(lo[0]), float(lo[1]), float(lo[2])),
        (float(ext[0]), float(ext[1]), float(ext[2])),
        nbytes=nbytes,
        grid=GRID,
    )
