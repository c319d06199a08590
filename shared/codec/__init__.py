"""Compact wire and storage codecs for scene records.

Everything that leaves the bake goes through this package: building and street
parameters (msgpack arrays with centimetre-quantised, delta-coded coordinates),
potentially visible sets with their ACH (LEB128 varints, ACH in units of 1/65535),
id sets (cell neighbours) and cell boundaries.

The client decodes bytes it received over the network, so every decoder is
*bounded*: the input size is checked first, msgpack is unpacked with explicit
``max_*_len`` limits, every field is type- and range-checked, and any failure is
raised as :class:`~walkstream.shared.errors.CodecError` naming what was being decoded.  No
decoder lets a raw ``msgpack``/``KeyError``/``TypeError`` escape, and none allocates
more than a small multiple of its input size.

Formats (version 1)
-------------------
building
    msgpack array ``[header, id, ax, ay, counts, coords, heights, floors, fh_cm,
    style, source_id]``.  ``header = 1 << 5 | nb_format << 2 | coord_format``.
    ``ax, ay`` is the first exterior vertex in integer centimetres (the anchor);
    ``counts`` the vertex count (an int for one ring, a list for several);
    ``coords`` the ``2 (N - 1)`` per-vertex x/y deltas in centimetres chained over
    all rings (see :func:`encode_building` for the four coordinate formats);
    ``heights`` the neighbour heights in centimetres over all ``N`` vertices, sparse
    ``[i, h, i, h, ...]`` (format 0) or run-length ``[h, run, h, run, ...]``
    (format 1).
street
    msgpack array ``[header, id, n, ax, ay, coords, width_cm, source_id]`` with
    ``header = 2 << 5 | kind << 2 | coord_format``.
pvs
    ``b"\x01"`` then unsigned LEB128 varints ``k, id_0, id_1 - id_0, ...,
    units_0, ..., units_{k-1}`` with ids ascending and the units summing to
    exactly 65535 (``k > 0``).
ids
    unsigned LEB128 varints of the ascending ids, delta coded (empty set: ``b""``).
polygon
    msgpack array of ``[x, y]`` float64 pairs.

The modules: :mod:`.bounded` (bounded unpacking), :mod:`.varint`, :mod:`.params`
(buildings and streets), :mod:`.pvs` (PVS, ids, polygons), :mod:`.mesh` (meshes).
"""

from walkstream.shared.codec.bounded import unpack_bounded
from walkstream.shared.codec.mesh import MESH_FORMAT, decode_mesh, encode_mesh
from walkstream.shared.codec.params import (
    decode_building,
    decode_object,
    decode_street,
    encode_building,
    encode_street,
)
from walkstream.shared.codec.pvs import (
    ACH_UNITS,
    decode_ids,
    decode_polygon,
    decode_pvs,
    encode_ids,
    encode_polygon,
    encode_pvs,
    pvs_size,
    quantise_ach,
)
from walkstream.shared.codec.varint import decode_varints, encode_varints

__all__ = [
    "ACH_UNITS",
    "quantise_ach",
    "encode_pvs",
    "decode_pvs",
    "pvs_size",
    "encode_ids",
    "decode_ids",
    "encode_polygon",
    "decode_polygon",
    "unpack_bounded",
    "encode_varints",
    "decode_varints",
    "encode_building",
    "decode_building",
    "encode_street",
    "decode_street",
    "decode_object",
    "MESH_FORMAT",
    "encode_mesh",
    "decode_mesh",
]
