"""The interior start bundle's heads (``server/service/firstheads.py``,
``shared/codec/cellhead.py``) on FZK-Haus: the cells its first pose sees in part come
first as the pieces drawn, whole after the others; the walk is perfect sooner and hides
nothing."""

from __future__ import annotations

import asyncio
import json
import zlib
from pathlib import Path
from typing import Any

import httpx
import msgpack
import numpy as np
import pytest

from walkstream.cli import main
from walkstream.server.service.main import create_app
from walkstream.shared.codec.cellbatch import check_contents_part
from walkstream.shared.codec.cellhead import STAND_IN_ELEMENT, decode_cell_head
from walkstream.shared.codec.cellpieces import decode_cell_pieces
from walkstream.shared.codec.contentspack import is_pack, unpack_parts
from walkstream.shared.cullkernels import box_kernel, walk_kernel
from walkstream.shared.startwire import decode_start_part


def _bundle(app: Any, heads: bool) -> tuple[list[tuple[int, dict[str, Any]]], list[int]]:
    """The start bundle's contents parts in order, and the gzip stream's bytes after each part."""
    url = f"/v1/start?path=tour&view=160x120&head=10{'&heads=true' if heads else ''}"

    async def go() -> bytes:
        async with httpx.AsyncClient(transport=httpx.ASGITransport(app=app), base_url="http://t") as c:
            async with c.stream("GET", url, headers={"Accept-Encoding": "gzip"}) as r:
                assert r.status_code == 200
                return b"".join([b async for b in r.aiter_raw()])

    wire = asyncio.run(go())
    # the answer flushes after each part: feed it a chunk at a time to learn where each ends
    d, u = zlib.decompressobj(31), msgpack.Unpacker(raw=False)
    parts: list[tuple[int, dict[str, Any]]] = []
    ends: list[int] = []
    rooms: list[int] = []
    for k in range(0, len(wire), 64):
        u.feed(d.decompress(wire[k : k + 64]))
        for obj in u:
            if rooms:
                # a pack: its parts all in at once (the test's chunk holding its end)
                for o in [o for o, _ in unpack_parts(obj)] if is_pack(obj) else [obj]:
                    assert o["cell"] == rooms.pop(0)
                    parts.append((o["cell"], o))
                    ends.append(k + 64)
            elif obj.get("part") == "contents":
                _, _, cells = decode_start_part(obj, "bundle")
                assert isinstance(cells, list)
                rooms.extend(cells)
    return parts, ends


def test_heads_come_first_and_their_cells_whole_after(fzk_db: tuple[Path, dict[str, Any]]) -> None:
    app = create_app([fzk_db[0]])
    # an interior's service made its compiled culling at the start, before any request
    assert walk_kernel.signatures and box_kernel.signatures
    try:
        plain, plain_ends = _bundle(app, heads=False)
        split, split_ends = _bundle(app, heads=True)
    finally:
        app.state.scenes.close()
    cells = [c for c, _ in plain]
    assert len(set(cells)) == len(cells) and not any("missing" in o for _, o in plain)
    # the same cells (in one pack: in cell-id order), then each head's cell again, whole
    # (in the order the walk's lead needs them whole: firstheads.wholes_order)
    heads = [c for c, o in split if "missing" in o]
    first = [c for c, _ in split[: len(cells)]]
    # (the pack: the first pose's cells in cell-id order, the lead's after it as they were)
    assert any(first[:k] == sorted(cells[:k]) and first[k:] == cells[k:] for k in range(len(cells) + 1))
    wholes = [c for c, _ in split[len(cells):]]
    assert heads and [c for c, _ in split[: len(cells)]] == first and sorted(wholes) == sorted(heads)
    for c, o in split[len(cells):]:
        assert "missing" not in o
        whole = decode_cell_pieces(check_contents_part(o, "whole")[2])
        head_obj = next(h for h in split[: len(cells)] if h[0] == c)[1]
        head = decode_cell_head(head_obj["body"], head_obj["missing"])
        # one part per piece of the whole cell: the pieces drawn, stand-ins boxing the others
        assert len(head.parts) == len(whole.parts) and 0 < len(head.missing) < len(whole.parts)
        for k, (p, q) in enumerate(zip(whole.parts, head.parts, strict=True)):
            lo, hi = p.bbox
            hlo, hhi = q.bbox
            if k in head.missing:
                assert q.element == STAND_IN_ELEMENT and np.all(hlo <= lo) and np.all(hhi >= hi)
            else:
                assert (q.element, q.material) == (p.element, p.material)
    # the first view's parts end sooner on the link (FZK-Haus: the outside cell's shell)
    assert split_ends[len(cells) - 1] < 0.8 * plain_ends[-1]


def _replay(db: Path, out: Path, *extra: str) -> tuple[dict[str, Any], Path]:
    main(["replay", str(db), "--path", "tour", "--bandwidth", "56kbit", "--rtt", "200ms", "--clock", "sim",
          "--size", "160x120", "--device", "desktop2003", "--duration", "4s", "--report", str(out), "--no-plots", *extra])
    return json.loads((out / "report.json").read_text()), out


@pytest.mark.gl  # the truth draws
def test_a_walk_with_heads_is_perfect_sooner_and_hides_nothing(
    fzk_db: tuple[Path, dict[str, Any]], tmp_path: Path, gl_ctx: object
) -> None:
    db = fzk_db[0]
    heads, _ = _replay(db, tmp_path / "heads")
    whole, _ = _replay(db, tmp_path / "whole", "--no-start-heads")
    assert heads["time_to_first_perfect_frame_s"] < min(3.0, whole["time_to_first_perfect_frame_s"] - 0.5)
    assert heads["start_head_cells"] >= 1 and whole["start_head_cells"] == 0
    assert heads["start_contents_cells"] == whole["start_contents_cells"] and heads["redownloads"] == 0
    # walking at once (no hold) turns the walker while the outside cell is still a head:
    # a frame that keeps a stand-in waits for the cell, and no frame hides a pixel
    run, _ = _replay(db, tmp_path / "walk", "--start-hold", "0", "--truth-every", "5")
    assert run["truth"]["frames"] >= 15 and run["truth"]["culled_pixels"] == 0
    # and the colour truth agrees: a pixel the frame waited for (a late cell's part, or one
    # at the same depth) is late, not culled, before the first view too
    causes = run["truth"]["colour"]["causes"]
    assert causes["culled"] == 0 and causes["not_received"] > 0


def test_the_heads_cells_follow_whole_in_the_order_the_walk_needs_them(
    fzk_db: tuple[Path, dict[str, Any]],
) -> None:
    from walkstream.server.service.firstheads import wholes_order
    from walkstream.server.service.scenes import Scene
    from walkstream.server.service.startbundle import room_lead
    from walkstream.shared.roomview import RoomView

    scene = Scene.load(fzk_db[0])
    try:
        interior = scene.interior
        assert interior is not None
        lead, view = room_lead(scene, "tour"), RoomView((160, 120), 60.0, 40.0)
        # a walk standing still needs no cell whole sooner than another: the order stays
        assert wholes_order(interior, [6, 13], [lead[0]] * 3, view) == [6, 13]
        assert wholes_order(interior, [13, 6], [lead[0]] * 3, view) == [13, 6]
        # the tour bends round the stair towards the start room's window: the outside
        # cell's pieces its head lacks are needed before the start room's
        assert wholes_order(interior, [6, 13], lead, view) == [13, 6]
    finally:
        scene.close()
