"""The compact topology's version 4 (``shared/roomcompact.py``): no cell names, portals
column by column, a rectangle as two corners and a mask; versions 3 and 2 still read.
And the replay's flag for the start bundle's first pose first (the bundle itself:
``tests/test_roomstart.py``)."""

from __future__ import annotations

from typing import Any

import msgpack
import numpy as np
import pytest

from walkstream.shared.codec.rawlzma import compress_raw, decompress_raw
from walkstream.shared.errors import CodecError
from walkstream.shared.roomcompact import (
    decode_topology_compact,
    encode_topology_compact,
    prism_planes,
)
from walkstream.shared.roomwire import ContentsRef, RoomRecord, Topology


def _cell(cid: int, x0: float) -> RoomRecord:
    outline = np.array([[x0, 0.0], [x0 + 4.0, 0.0], [x0 + 4.0, 3.0], [x0, 3.0]])
    return RoomRecord(id=cid, kind="room", name=f"Room {cid}", room=None, storey=0, outline=outline, zmin=0.0,
                      zmax=3.0, planes=prism_planes(outline, 0.0, 3.0), portals=(), neighbours=(),
                      contents=ContentsRef(10 * cid, 0, 0, 100 * cid, 0, 0.0))


# a door in a wall along y (off the millimetre grid: rounded outward), a door in a wall
# along x drawn the other way round, a stair's horizontal opening, a slanted quad that
# two corners do not span, a triangle
PORTALS: list[np.ndarray] = [
    np.array([[4.0, 1.0004, 0.0], [4.0, 1.9003, 0.0], [4.0, 1.9003, 2.1], [4.0, 1.0004, 2.1]]),
    np.array([[2.9, 3.0, 2.1], [2.9, 3.0, 0.0], [2.1, 3.0, 0.0], [2.1, 3.0, 2.1]]),
    np.array([[1.0, 1.0, 3.0], [2.0, 1.0, 3.0], [2.0, 2.5, 3.0], [1.0, 2.5, 3.0]]),
    np.array([[4.0, 0.5, 0.0], [4.0, 0.9, 0.2], [4.0, 0.9, 2.0], [4.0, 0.5, 2.1]]),
    np.array([[4.0, 2.2, 0.0], [4.0, 2.8, 0.0], [4.0, 2.5, 1.0]]),
]


def _topology() -> Topology:
    portals = tuple((k, "door" if k != 2 else "stair", 1, 2, p) for k, p in enumerate(PORTALS))
    return Topology(storeys=((0, "Level 1", 0.0, 3.0),), cells=(_cell(1, 0.0), _cell(2, 4.0)), portals=portals,
                    stairs=())


def _outward(p: np.ndarray) -> np.ndarray:
    """What every version stores: each coordinate rounded away from the centroid, in mm."""
    x = p * 1000.0
    c = x.mean(axis=0)
    out = np.where(x > c, np.ceil(x), np.where(x < c, np.floor(x), np.rint(x)))
    return np.where(np.abs(x - c) < 1e-3, np.rint(x), out) / 1000.0


def _payload(body: bytes) -> Any:
    return msgpack.unpackb(decompress_raw(body[5:], "t", 1 << 20), strict_map_key=False)


def _v4(obj: Any) -> bytes:
    return b"WSTC\x04" + compress_raw(msgpack.packb(obj))


def test_rectangles_go_as_two_corners_and_come_back_exactly() -> None:
    body = encode_topology_compact(_topology())
    assert body[:5] == b"WSTC\x04"
    stored = _payload(body)
    assert "name" not in stored["cells"] and isinstance(stored["portals"], dict)
    # the three rectangles as two corners (six numbers) and a mask; the others whole
    masks = stored["portals"]["mask"]
    assert [m is not None for m in masks] == [True, True, True, False, False]
    assert [len(p) for p in stored["portals"]["polygon"]] == [6, 6, 6, 12, 9]
    back = decode_topology_compact(body, "t")
    for (pid, kind, a, b, poly), (qid, qkind, qa, qb, q) in zip(_topology().portals, back.portals, strict=True):
        assert (pid, kind, a, b) == (qid, qkind, qa, qb)
        assert np.array_equal(q, _outward(poly)), pid  # vertex for vertex, in order
    # the names are left out (the packed topology has them); everything else as before
    assert [c.name for c in back.cells] == ["", ""]
    assert [c.contents.nbytes for c in back.cells] == [100, 200] and back.cells[0].neighbours == (2,)


def _rows(p: np.ndarray) -> list[int]:
    q = np.rint(p * 1000.0).astype(np.int64)
    return np.diff(q, axis=0, prepend=np.zeros((1, 3), np.int64)).reshape(-1).tolist()


def test_version_3_bodies_still_decode_with_their_names() -> None:
    """A body as version 3 wrote it (names, portals as rows of vertices) reads as it did."""
    t = _topology()
    v4 = _payload(encode_topology_compact(t))
    cols = v4["portals"]
    ids = np.cumsum(cols["id"]).tolist()
    rows = [[i, cols["kind"][k], cols["a"][k], cols["b"][k], _rows(_outward(PORTALS[k]))] for k, i in enumerate(ids)]
    v3 = {**v4, "cells": {**v4["cells"], "name": [c.name for c in t.cells]}, "portals": rows}
    back = decode_topology_compact(b"WSTC\x03" + compress_raw(msgpack.packb(v3)), "v3")
    assert [c.name for c in back.cells] == ["Room 1", "Room 2"]
    new = decode_topology_compact(encode_topology_compact(t), "v4")
    assert all(np.array_equal(p[4], q[4]) for p, q in zip(back.portals, new.portals, strict=True))


@pytest.mark.parametrize(("change", "words"), [
    (lambda p: {**p, "mask": [9, *p["mask"][1:]]}, ("portals[0].mask", "0 to 7")),
    (lambda p: {**p, "mask": ["x", *p["mask"][1:]]}, ("portals[0].mask",)),
    (lambda p: {**p, "polygon": [p["polygon"][0][:5], *p["polygon"][1:]]}, ("portals[0].polygon", "two corners")),
    (lambda p: {**p, "polygon": [[1.5] * 6, *p["polygon"][1:]]}, ("portals[0].polygon", "integers")),
    (lambda p: {**p, "a": p["a"][:-1]}, ("portals.a", "expected 5")),
    (lambda p: {k: v for k, v in p.items() if k != "mask"}, ("missing field", "mask")),
    (lambda p: 7, ("portals", "map of columns")),
    (lambda p: [[0, 0, 1, 2]], ("portals[0]", "expected [id, kind, a, b, polygon]")),
    (lambda p: {**p, "kind": [99, *p["kind"][1:]]}, ("t:",)),
])
def test_damaged_portal_columns_are_one_line_codec_errors(change: Any, words: tuple[str, ...]) -> None:
    obj = _payload(encode_topology_compact(_topology()))
    with pytest.raises(CodecError) as e:
        decode_topology_compact(_v4({**obj, "portals": change(obj["portals"])}), "t")
    msg = str(e.value)
    assert "\n" not in msg and all(w in msg for w in words), msg


def test_the_replay_asks_for_the_first_pose_first_only_where_the_walker_stands() -> None:
    import argparse

    from walkstream.cmd_replay import add_replay_arguments, config_from_args

    parser = argparse.ArgumentParser()
    add_replay_arguments(parser)
    parser.add_argument("--report", default="report")
    assert config_from_args(parser.parse_args([])).posed_start
    for flags in (["--no-start-pose"], ["--start-hold", "0"], ["--no-start-heads"], ["--no-start-contents"]):
        assert not config_from_args(parser.parse_args(flags)).posed_start, flags
