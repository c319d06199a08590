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

Formats (version 1) are described in each module: building and street parameters in
:mod:`.params`; PVS, id sets and polygons in :mod:`.pvs`; meshes in :mod:`.mesh`.

The modules: :mod:`.bounded` (bounded unpacking), :mod:`.varint`, :mod:`.ints` (integer
sequences in the smallest of four encodings), :mod:`.params` (buildings and streets),
:mod:`.pvs` (PVS, ids, polygons), :mod:`.mesh` (meshes), :mod:`.cellmesh` (the quantised
contents of an interior cell, with its error bound), :mod:`.cellbatch` (many cells'
contents in one answer), :mod:`.pvsclusters` (visibility-list clusters and a cell's list
expanded from them, measured by ``walkstream bench clusters``).
"""

from walkstream.shared.codec.bounded import inflate_tagged, unpack_bounded
from walkstream.shared.codec.cellmesh import (
    CELLMESH_FORMAT,
    CellMesh,
    CellPart,
    decode_cell_mesh,
    encode_cell_mesh,
    position_error_bound,
)
from walkstream.shared.codec.cellpieces import PIECE_TRIANGLES, cell_pieces, decode_cell_pieces
from walkstream.shared.codec.ints import INT_FORMATS, pack_ints, unpack_ints
from walkstream.shared.codec.mesh import MESH_FORMAT, decode_mesh, encode_mesh
from walkstream.shared.codec.params import (
    decode_area,
    decode_building,
    decode_object,
    decode_street,
    encode_area,
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
    "inflate_tagged",
    "INT_FORMATS",
    "pack_ints",
    "unpack_ints",
    "encode_varints",
    "decode_varints",
    "encode_building",
    "decode_building",
    "encode_street",
    "decode_street",
    "encode_area",
    "decode_area",
    "decode_object",
    "MESH_FORMAT",
    "encode_mesh",
    "decode_mesh",
    "CELLMESH_FORMAT",
    "CellPart",
    "CellMesh",
    "encode_cell_mesh",
    "decode_cell_mesh",
    "position_error_bound",
    "PIECE_TRIANGLES",
    "cell_pieces",
    "decode_cell_pieces",
]
