"""The cell-contents codec, versions 1 to 4 side by side (a table of ``walkstream bench interiors``).

Per source, the same interior baked four times (``walkstream-cellmesh/1``: every
triangle, 16 bits over each cell's box; ``/2``: planar polygons on a 1 mm grid; ``/3``:
``/2`` with boxes and axis rectangles in their own fields; ``/4``, the default: ``/3``
with the remaining triangles sharing their corners), for all cells
and for the **start cells** (those the tour's first pose sees within the 40 m fog,
through the portals in the frustum, as the RoomStreamer asks for them before the first
perfect frame): bytes of the blobs each on its own, bytes of the blobs compressed
jointly (each inflated to its ``N`` form, concatenated, the smaller of zlib 9 and lzma
6), bytes of the **gzip stream** ``POST .../rooms/contents`` sends for them (every part
``{cell, etag, body}`` with the body inflated, gzip level 9, flushed after each part:
what the link carries), triangles after decoding, the median client-CPU milliseconds
to decode one cell, and the seconds the bake spent encoding.
"""

from __future__ import annotations

import lzma
import time
import zlib
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from walkstream.server.bake.pipeline import bake_interior
from walkstream.server.service.interiors import InteriorState
from walkstream.server.sources.interior import InteriorScene
from walkstream.server.sources.read import read_source
from walkstream.server.store import SceneReader
from walkstream.shared.camera import camera, perspective
from walkstream.shared.codec.cellmesh import decode_cell_mesh
from walkstream.shared.errors import InputError
from walkstream.shared.paths import RecordedPath
from walkstream.shared.portalgraph import PortalGraph
from walkstream.shared.portals import cull_portals
from walkstream.shared.roomview import cell_of, stack_planes
from walkstream.shared.roomwire import decode_topology

__all__ = ["start_cells", "codec_figures", "codec_rows", "codec_table"]


def start_cells(db: Path, fog_m: float = 40.0) -> list[int]:
    """The cells visible from the tour's first pose (portal culling at 640 x 480, within ``fog_m``)."""
    with SceneReader.open(db) as r:
        state = InteriorState(r, list(r.cells()))
        topo = decode_topology(state.topology["msgpack"].content, f"{db}: topology")
        tour = RecordedPath.from_msgpack(r.path_blob("tour"))
    inside = [c for c in topo.cells if c.kind != "outside" and len(c.planes)]
    ids, planes = stack_planes(inside)
    xyz, yaw, pitch = tour.at(0.0)
    eye = np.asarray(xyz, np.float64)
    hit = np.flatnonzero(cell_of(planes, eye))
    if len(hit) == 0:
        return []
    proj = perspective(60.0, 4.0 / 3.0, 0.1, 100.0).astype(np.float64)
    view = camera(eye, float(yaw), float(pitch)).astype(np.float64)
    graph = PortalGraph.from_topology(topo)
    return list(cull_portals(graph, int(ids[hit[0]]), eye, view, proj, (640, 480), fog_m=fog_m).order)


def _joint(blobs: Sequence[bytes]) -> int:
    """Bytes of the blobs' ``N`` forms compressed together (the smaller of zlib and lzma)."""
    inflate = decode_cell_mesh.__globals__["_decompress"]
    raw = b"".join(inflate(b, "cell") for b in blobs)
    return min(len(zlib.compress(raw, 9)), len(lzma.compress(raw, preset=6))) + 1


def _batch_gzip(state: InteriorState, ids: Sequence[int]) -> int:
    """Bytes of the gzip stream the contents batch sends for ``ids`` (as ``routers/rooms.py``
    and ``service/http.py`` make it: inflated bodies, level 9, a sync flush after each part)."""
    co = zlib.compressobj(9, zlib.DEFLATED, 31)
    n = 0
    for cid in ids:
        n += len(co.compress(state.contents_part(cid, inflate=True))) + len(co.flush(zlib.Z_SYNC_FLUSH))
    return n + len(co.flush())


def codec_figures(db: Path, cells: Sequence[int] | None = None) -> dict[str, Any]:
    """Bytes (separately, jointly, as the batch's gzip stream), triangles and median decode
    ms of ``db``'s cells (all, or ``cells``)."""
    with SceneReader.open(db) as r:
        ids = list(r.contents_info()) if cells is None else list(cells)
        blobs = [r.contents(c) for c in ids]
        gz = _batch_gzip(InteriorState(r, list(r.cells())), ids) if ids else 0
    tris = 0
    ms = []
    for b in blobs:
        t0 = time.perf_counter()
        cm = decode_cell_mesh(b)
        ms.append(1e3 * (time.perf_counter() - t0))
        tris += cm.triangles
    return {
        "cells": len(ids),
        "bytes": sum(len(b) for b in blobs),
        "joint": _joint(blobs) if blobs else 0,
        "gzip": gz,
        "triangles": tris,
        "decode_ms": float(np.median(ms)) if ms else 0.0,
    }


def codec_rows(source: Path, db_v3: Path, v3_encode_s: float, folder: Path) -> list[dict[str, Any]]:
    """Bake ``source`` with versions 1 to 3 beside ``db_v3`` (the default bake, version 4) and measure all four."""
    scene = read_source(source)
    if not isinstance(scene, InteriorScene):
        raise InputError(f"{source}: not an interior (IFC or a walkstream-interior file)")
    runs = []
    for version in (1, 2, 3):
        db = folder / f"{source.stem}.cellmesh{version}.db"
        summary = bake_interior(scene, source, db, cellmesh_version=version)
        runs.append((version, db, float(summary.get("contents_encode_s", 0.0))))
    start = start_cells(db_v3)
    rows = []
    for version, db, enc in (*runs, (4, db_v3, v3_encode_s)):
        rows.append(
            {
                "source": source.name,
                "version": version,
                "all": codec_figures(db),
                "start": codec_figures(db, start),
                "encode_s": enc,
            }
        )
    return rows


def codec_table(rows: Sequence[dict[str, Any]]) -> str:
    """The codec figures as a table (one row per source and version)."""
    head = (
        f"{'source':<19}{'codec':>6}{'cells':>6}{'bytes':>9}{'joint':>9}{'gzip':>9}{'tris':>8}{'dec ms':>8}"
        f"{'start':>6}{'bytes':>8}{'joint':>8}{'gzip':>8}{'tris':>7}{'encode s':>9}"
    )
    lines = [head, "-" * len(head)]
    for r in rows:
        a, s = r["all"], r["start"]
        lines.append(
            f"{r['source'][:18]:<19}{'/' + str(r['version']):>6}{a['cells']:>6}{a['bytes']:>9,}{a['joint']:>9,}"
            f"{a['gzip']:>9,}{a['triangles']:>8,}{a['decode_ms']:>8.2f}{s['cells']:>6}{s['bytes']:>8,}{s['joint']:>8,}{s['gzip']:>8,}"
            f"{s['triangles']:>7,}{r['encode_s']:>9.2f}"
        )
    lines.append(
        "(cellmesh /1: 16 bits over each cell's box; /2: planar polygons on a 1 mm grid; /3: /2 with boxes and "
        "axis rectangles; joint = all the blobs' N forms compressed together; gzip = the contents batch's gzip "
        "stream (what the link carries); start = the cells the tour's first pose sees within 40 m; "
        "dec ms = median per cell, client CPU)"
    )
    return "\n".join(lines)
