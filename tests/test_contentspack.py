"""An interior's first view as one LZMA pack (``shared/codec/contentspack.py``), the
start bundle's decoder reading one (``client/net/startitems.py``), and the compact
topology leaving out planes within a millimetre of their outline's prism
(``shared/roomcompact.py``)."""

from __future__ import annotations

import zlib

import msgpack
import numpy as np
import pytest

from walkstream.client.net.startitems import StartDecoder
from walkstream.shared.codec.cellbatch import pack_contents_part, pack_head_part
from walkstream.shared.codec.cellhead import encode_cell_head
from walkstream.shared.codec.cellmesh import encode_cell_mesh, inflate_cell_mesh
from walkstream.shared.codec.cellpieces import decode_cell_pieces
from walkstream.shared.codec.contentspack import (
    COLUMNS_FORMAT,
    PACK_FORMAT,
    is_pack,
    pack_parts,
    unpack_parts,
)
from walkstream.shared.codec.rawlzma import compress_raw, decompress_raw
from walkstream.shared.errors import CodecError
from walkstream.shared.roomcompact import (
    decode_topology_compact,
    encode_topology_compact,
    prism_planes,
)
from walkstream.shared.roomwire import ContentsRef, RoomRecord, Topology


def _blob(seed: int, boxes: int = 6) -> bytes:
    """A cell's stored blob: ``boxes`` unit boxes (12 triangles each) at random places."""
    rng = np.random.default_rng(seed)
    corners = np.array([[i & 1, (i >> 1) & 1, (i >> 2) & 1] for i in range(8)], np.float64)
    faces = np.array([[0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6], [0, 1, 4], [1, 5, 4],
                      [2, 6, 3], [3, 6, 7], [0, 4, 2], [2, 4, 6], [1, 3, 5], [3, 7, 5]])
    parts = [(k, k % 3, corners * rng.uniform(0.2, 2.0, 3) + rng.uniform(0, 20, 3).round(3), faces)
             for k in range(boxes)]
    return encode_cell_mesh(parts)


def test_a_pack_gives_back_its_parts_and_costs_less_than_the_parts_alone() -> None:
    blobs = {c: _blob(c) for c in (3, 4, 5)}
    pieces = decode_cell_pieces(blobs[4])
    keep = np.arange(len(pieces.parts)) < 2
    body, missing = encode_cell_head(pieces, keep)
    parts = [pack_contents_part(3, "e3", inflate_cell_mesh(blobs[3])), pack_head_part(4, "e4", body, missing),
             pack_contents_part(5, "e5", blobs[5])]
    packed = pack_parts(parts)
    obj = msgpack.unpackb(packed, raw=False)
    assert is_pack(obj) and obj["pack"] == PACK_FORMAT and obj["parts"] == 3
    got = unpack_parts(obj)
    assert [o for o, _ in got] == [msgpack.unpackb(p, raw=False) for p in parts]
    assert [n for _, n in got] == [len(p) for p in parts]
    assert len(packed) < sum(len(p) for p in parts)
    # the start bundle's decoder: one item for the pack, the cells in the order announced
    dec = StartDecoder("params", heads=True)
    assert dec({"part": "contents", "etag": None, "cells": [3, 4, 5, 4]}, 10) == ("contents", [3, 4, 5, 4])
    kind, rooms = dec(obj, len(packed))
    assert kind == "rooms" and [c for c, _ in rooms] == [3, 4, 5] and dec.rooms == [4]
    assert rooms[1][1].missing and len(rooms[1][1].parts) == len(pieces.parts)
    assert sum(m.nbytes for _, m in rooms) == pytest.approx(len(packed), abs=2)


def _damaged(obj: dict[str, object], **change: object) -> dict[str, object]:
    return {**obj, **change}


def test_a_damaged_pack_is_a_codec_error_never_a_traceback() -> None:
    parts = [pack_contents_part(c, f"e{c}", _blob(c, 2)) for c in (1, 2)]
    obj = msgpack.unpackb(pack_parts(parts), raw=False)
    body = obj["body"]
    raw = b"".join(parts)
    cases = {
        "cut": _damaged(obj, body=body[: len(body) // 2]),
        "noise": _damaged(obj, body=bytes(len(body))),
        "too few said": _damaged(obj, parts=1),
        "too many said": _damaged(obj, parts=3),
        "no parts": _damaged(obj, parts=0),
        "other format": _damaged(obj, pack="walkstream-contentspack/9"),
        "extra key": _damaged(obj, extra=1),
        "not a map inside": _damaged(obj, parts=1, body=compress_raw(msgpack.packb([1, 2]))),
        "half a part": _damaged(obj, body=compress_raw(raw[:-3])),
    }
    for name, bad in cases.items():
        with pytest.raises(CodecError):
            unpack_parts(bad, name)
    # more parts than the bundle announced
    dec = StartDecoder("params", heads=True)
    dec({"part": "contents", "etag": None, "cells": [1]}, 10)
    with pytest.raises(CodecError, match="announced"):
        dec(obj, 100)
    with pytest.raises(ValueError):
        pack_parts([])


def _cell(cid: int, outline: np.ndarray, planes: np.ndarray) -> RoomRecord:
    return RoomRecord(id=cid, kind="room", name=f"c{cid}", room=None, storey=0, outline=outline, zmin=0.0,
                      zmax=3.0, planes=planes, portals=(), neighbours=(), contents=ContentsRef(0, 0, 0, 0, 0, 0.0))


def test_planes_within_a_millimetre_of_the_outlines_prism_are_left_out() -> None:
    # an IFC space's wall 0.4 mm off the millimetre grid: its plane is not its rounded outline's
    exact = np.array([[0.0, 0.0], [4.3836, 0.0], [4.3836, 2.825], [0.0, 2.825]])
    near = prism_planes(exact, 0.0, 3.0)
    far = near.copy()
    far[1, 3] -= 0.002  # 2 mm: a plane of its own
    topo = Topology(storeys=((0, "g", 0.0, 3.0),),
                    cells=(_cell(1, exact, near), _cell(2, exact + [10.0, 0.0], far)), portals=(), stairs=())
    back = decode_topology_compact(encode_topology_compact(topo), "topology")
    a, b = back.cells
    assert np.allclose(a.planes, prism_planes(np.round(exact * 1000) / 1000, 0.0, 3.0))
    assert np.abs(a.planes - near).max() <= 1e-3
    assert np.allclose(b.planes, far, atol=1e-12)


def test_the_compact_topology_is_written_as_lzma_and_read_as_zlib_too() -> None:
    exact = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 3.0], [0.0, 3.0]])
    topo = Topology(storeys=((0, "g", 0.0, 3.0),), cells=(_cell(1, exact, prism_planes(exact, 0.0, 3.0)),),
                    portals=(), stairs=())
    body = encode_topology_compact(topo)
    assert body[:5] == b"WSTC\x04"
    old = b"WSTC\x02" + zlib.compress(decompress_raw(body[5:], "t", 1 << 20), 9)
    a, b = decode_topology_compact(body, "v4"), decode_topology_compact(old, "v2")
    assert a.cells[0].name == b.cells[0].name == "" and np.array_equal(a.cells[0].planes, b.cells[0].planes)
    for bad in (body[:-4], b"WSTC\x04" + bytes(20), b"WSTC\x09" + body[5:]):
        with pytest.raises(CodecError):
            decode_topology_compact(bad, "damaged")


def test_columns_give_every_part_back_byte_for_byte() -> None:
    """A pack of alike meshes goes field by field (smaller) and reads back to the very
    parts, etags too; a part whose body is no inflated mesh rides along as it is."""
    rng = np.random.default_rng(5)

    def mesh(n: int, extra: bool) -> bytes:
        m = {"format": "walkstream-cellmesh/1", "lo": [0.5, 1.0, -2.0], "parts": 1,
             "positions": rng.integers(0, 40, 3 * n, dtype=np.uint8).tobytes(),
             "indices": bytes(range(n % 200))}
        if extra:
            m["rects"] = b"\x01\x02"
        return b"N" + msgpack.packb(m, use_bin_type=True)

    parts = [pack_contents_part(3, "v-contents:3-cellmesh", mesh(300, False)),
             pack_head_part(7, "v-contents:7-cellmesh", mesh(200, True), b"\x05\x06"),
             pack_contents_part(9, "an-etag-of-its-own", b"Xnot-a-mesh"),
             pack_contents_part(11, "v-contents:11-cellmesh", mesh(250, False))]
    packed = pack_parts(parts)
    obj = msgpack.unpackb(packed, raw=False)
    assert obj["pack"] == COLUMNS_FORMAT
    assert [msgpack.packb(o, use_bin_type=True) for o, _ in unpack_parts(obj)] == parts
    assert [n for _, n in unpack_parts(obj)] == [len(p) for p in parts]
    plain = msgpack.unpackb(pack_parts(parts, columns=False), raw=False)
    assert plain["pack"] == PACK_FORMAT and len(plain["body"]) > len(obj["body"])
    # damaged columns: one row's value gone is a CodecError, not a wrong part
    rows, columns, etags = msgpack.unpackb(decompress_raw(obj["body"], "t", 1 << 24), raw=False)
    # the etags that follow the server's pattern around the cell id are left out
    assert etags == ["v-contents", "cellmesh"]
    assert [r[0]["etag"] for r in rows] == [None, None, "an-etag-of-its-own", None]
    columns["positions"].pop()
    bad = {**obj, "body": compress_raw(msgpack.packb([rows, columns, etags], use_bin_type=True))}
    with pytest.raises(CodecError):
        unpack_parts(bad)
