"""Visibility-list clusters against today's delta-coded lists (``walkstream bench clusters``).

Per scene database: the cells' lists clustered along their adjacency
(:func:`walkstream.server.bake.pvsclusters.cluster_lists`, after m-LOMA), then, from
the real encoders (the record the service sends for each cell,
:meth:`walkstream.server.service.scenes.Scene.cell`; that record with ``cl`` and the rest,
:func:`walkstream.shared.codec.pvsclusters.clustered_cell_to_wire`, and the cluster
records, :func:`walkstream.shared.codec.pvsclusters.encode_cluster`):

- **cell records**: the bytes of every cell's record, delta-coded as served today
  against clustered (cluster records counted once);
- what the delta-coded records spend on ids and on ACH (the part clusters cannot
  share: each cell's ACH of each object stays in its own record);
- **walk traffic**: for each recorded path, the records of the cells it enters (the
  path sampled every 0.25 s, each cell once) and, clustered, the clusters those cells
  name, each fetched once: raw bytes (what ``GET .../cells/{id}`` sends, one record
  per answer, not compressed); as gzip-compressed streamed answers made as the
  cells batch makes them (gzip on, as the client asks) in batches of
  :data:`BATCH_CELLS` cells in walk order (a cluster in the batch of the first cell
  naming it: no request of its own, in favour of the clusters) and as one stream for
  the whole walk (gzip at its best); and what that one stream costs for the ids
  alone and for the ACH alone (delta-coded).

Every check that the clustered lists are the cells' lists (expanded, equal) runs here
too: a table is only printed for clusters that give the same PVS.
"""

from __future__ import annotations

import time
import zlib
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import msgpack
import numpy as np

from walkstream.server.bake.pvsclusters import ClusterSettings, ListClusters, cluster_lists
from walkstream.server.service.routers.objects import CHUNK_BYTES
from walkstream.server.service.scenes import Scene
from walkstream.shared.cells import CellLocator
from walkstream.shared.codec.ints import unpack_ints
from walkstream.shared.codec.pvsclusters import (
    clustered_cell_to_wire,
    decode_cluster,
    decode_clustered_cell,
    encode_cluster,
)
from walkstream.shared.errors import InputError
from walkstream.shared.paths import RecordedPath
from walkstream.shared.scene.cellkinds import cell_kind

__all__ = [
    "WALK_STEP_S",
    "BATCH_CELLS",
    "walk_cells",
    "cluster_figures",
    "run_clusters_bench",
    "format_clusters_table",
    "plot_clusters",
]

WALK_STEP_S = 0.25
"""Seconds between the samples of a recorded path that find the cells it enters."""
BATCH_CELLS = 4
"""Cells per batch in the batched figure (the client's smallest cells batch)."""


def _packed(obj: Any) -> bytes:
    # as the service packs a record (server/service/http.py dump_msgpack)
    data: bytes = msgpack.packb(obj, use_bin_type=True)
    return data


def walk_cells(locator: CellLocator, path: RecordedPath, step_s: float = WALK_STEP_S) -> list[int]:
    """The cells ``path`` enters, in order, each once (sampled every ``step_s`` seconds)."""
    ts = np.arange(0.0, path.duration + step_s, step_s)
    xyz, _, _ = path.sample(np.minimum(ts, path.duration))
    ids = locator.locate_many(np.asarray(xyz)[:, :2])
    return list(dict.fromkeys(int(c) for c in ids if c >= 0))


def _gzip_stream(bodies: Sequence[bytes]) -> int:
    """Bytes of one gzip-compressed streamed answer of ``bodies``, made as the service
    makes it: the records joined into chunks of about ``CHUNK_BYTES``, gzip level 6, a
    sync flush after each chunk (``server/service/http.py``, ``routers/objects.py``)."""
    co = zlib.compressobj(6, zlib.DEFLATED, 31)
    n = 0
    chunk: list[bytes] = []
    size = 0
    for b in bodies:
        chunk.append(b)
        size += len(b)
        if size >= CHUNK_BYTES:
            n += len(co.compress(b"".join(chunk))) + len(co.flush(zlib.Z_SYNC_FLUSH))
            chunk, size = [], 0
    if chunk:
        n += len(co.compress(b"".join(chunk))) + len(co.flush(zlib.Z_SYNC_FLUSH))
    return n + len(co.flush())


def cluster_figures(db: Path, settings: ClusterSettings | None = None) -> dict[str, Any]:
    """Cell-record and walk-traffic bytes of ``db``, delta-coded and clustered.

    Returns
    -------
    dict
        ``scene, cells, pvs_mean, clusters, cluster_mean, named_mean, covered`` (share of
        the (cell, object) pairs that clusters hold), ``delta_bytes, delta_ids, delta_ach``
        (every record, and the ids' and ACH's packed fields in it), ``cl_cells, cl_clusters``
        (clustered records, cluster records once), ``cluster_s`` (clustering seconds) and
        ``walks``: per path ``{name, cells, clusters, delta, clustered, delta_gz4,
        clustered_gz4, delta_gz, clustered_gz, ids_raw, ach_raw, ids_gz, ach_gz}`` (raw
        bytes, gzip in batches, one gzip stream; the delta-coded records' ids and ACH
        fields alone, raw and in one gzip stream).
    """
    scene = Scene.load(db)
    try:
        r = scene.reader
        infos = [c for c in r.cells() if cell_kind(c.kind).visibility == "pvs"]
        paths = {n: RecordedPath.from_msgpack(r.path_blob(n)) for n in r.path_names()}
        if not infos:
            raise InputError(f"{db}: no cell with a PVS")
        # the delta-coded records: the very bytes the service sends for each cell
        delta = {c.id: scene.cell(c.id, "msgpack").content for c in infos}
    finally:
        scene.close()
    pvs = {c.id: c.pvs for c in infos}
    t0 = time.perf_counter()
    lc = cluster_lists(pvs, {c.id: c.neighbours.tolist() for c in infos}, settings)
    cluster_s = time.perf_counter() - t0
    cl_bodies = {k: encode_cluster(k, ids) for k, ids in lc.clusters.items()}
    # the client's side: clusters decoded from their bytes, each cell's clustered record
    # decoded and expanded with them must give its PVS and ACH exactly
    received = dict(decode_cluster(b, f"cluster {k}") for k, b in cl_bodies.items())
    clustered: dict[int, bytes] = {}
    fields: dict[int, tuple[bytes, bytes]] = {}
    for c in infos:
        wire = msgpack.unpackb(delta[c.id])
        fields[c.id] = (_packed(wire["pvs"]), _packed(wire["ach"]))
        clustered[c.id] = _packed(clustered_cell_to_wire(wire, lc.cell_clusters[c.id], lc.rest[c.id]))
        _, ids, units = decode_clustered_cell(clustered[c.id], received, f"cell {c.id}")
        if not (np.array_equal(ids, c.pvs) and units.tolist() == unpack_ints(wire["ach"], "cell", "ach")):
            raise AssertionError(f"{db}: cell {c.id}: the clustered record does not give its PVS and ACH")
    pairs = sum(len(c.pvs) for c in infos)
    in_clusters = sum(len(lc.clusters[int(k)]) for ks in lc.cell_clusters.values() for k in ks)
    locator = CellLocator([c.id for c in infos], [c.boundary for c in infos])
    walks = [
        _walk(name, walk_cells(locator, p), delta, clustered, cl_bodies, lc, fields) for name, p in paths.items()
    ]
    return {
        "scene": Path(db).stem,
        "cells": len(infos),
        "pvs_mean": pairs / len(infos),
        "clusters": len(lc.clusters),
        "cluster_mean": float(np.mean([len(v) for v in lc.clusters.values()])) if lc.clusters else 0.0,
        "named_mean": float(np.mean([len(v) for v in lc.cell_clusters.values()])),
        "covered": in_clusters / pairs if pairs else 0.0,
        "delta_bytes": sum(map(len, delta.values())),
        "delta_ids": sum(len(f[0]) for f in fields.values()),
        "delta_ach": sum(len(f[1]) for f in fields.values()),
        "cl_cells": sum(map(len, clustered.values())),
        "cl_clusters": sum(map(len, cl_bodies.values())),
        "cluster_s": cluster_s,
        "walks": walks,
    }


def _walk(
    name: str,
    cells: list[int],
    delta: dict[int, bytes],
    clustered: dict[int, bytes],
    cl_bodies: dict[int, bytes],
    lc: ListClusters,
    fields: dict[int, tuple[bytes, bytes]],
) -> dict[str, Any]:
    """One walk's record traffic: its cells' records, and clustered, the clusters they name once."""
    seen: set[int] = set()
    batches: list[tuple[list[bytes], list[bytes]]] = []
    for n, c in enumerate(cells):
        if n % BATCH_CELLS == 0:
            batches.append(([], []))
        plain, stream = batches[-1]
        # a cluster travels before the first cell that names it (the client expands on arrival)
        for k in lc.cell_clusters[c].tolist():
            if k not in seen:
                seen.add(k)
                stream.append(cl_bodies[k])
        stream.append(clustered[c])
        plain.append(delta[c])
    every_plain = [b for p, _ in batches for b in p]
    every_stream = [b for _, s in batches for b in s]
    return {
        "name": name,
        "cells": len(cells),
        "clusters": len(seen),
        "delta": sum(map(len, every_plain)),
        "clustered": sum(map(len, every_stream)),
        "delta_gz": _gzip_stream(every_plain),
        "clustered_gz": _gzip_stream(every_stream),
        "delta_gz4": sum(_gzip_stream(p) for p, _ in batches),
        "clustered_gz4": sum(_gzip_stream(s) for _, s in batches),
        # what the one gzip stream spends on each part: the ids alone and the ACH alone
        "ids_raw": sum(len(fields[c][0]) for c in cells),
        "ach_raw": sum(len(fields[c][1]) for c in cells),
        "ids_gz": _gzip_stream([fields[c][0] for c in cells]),
        "ach_gz": _gzip_stream([fields[c][1] for c in cells]),
    }


def run_clusters_bench(dbs: Sequence[Path], settings: ClusterSettings | None = None) -> list[dict[str, Any]]:
    """:func:`cluster_figures` of every database, in order."""
    for db in dbs:
        if not Path(db).is_file():
            raise InputError(f"{db}: no such scene database")
    return [cluster_figures(Path(db), settings) for db in dbs]


def _ratio(a: int, b: int) -> str:
    return f"{a / b:.3f}" if b else "-"


def format_clusters_table(rows: Sequence[dict[str, Any]]) -> str:
    """Two markdown tables: cell records per scene, and record traffic per scene and walk."""
    out = [
        "| scene | cells | PVS mean | clusters | objects/cluster | clusters/cell | pairs in clusters "
        "| delta-coded records | of which ids / ACH | clustered records + clusters | clustered / delta | clustering s |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        total = r["cl_cells"] + r["cl_clusters"]
        out.append(
            f"| {r['scene']} | {r['cells']:,} | {r['pvs_mean']:.1f} | {r['clusters']:,} | {r['cluster_mean']:.1f} "
            f"| {r['named_mean']:.2f} | {100 * r['covered']:.1f} % | {r['delta_bytes']:,} "
            f"| {r['delta_ids']:,} / {r['delta_ach']:,} | {r['cl_cells']:,} + {r['cl_clusters']:,} = {total:,} "
            f"| {_ratio(total, r['delta_bytes'])} | {r['cluster_s']:.1f} |"
        )
    out += [
        "",
        "| scene | walk | cells entered | clusters fetched | delta-coded bytes | clustered bytes | clustered / delta "
        "| gzip, batches of 4: delta | clustered | clustered / delta "
        "| gzip, one stream: delta | clustered | clustered / delta | ids alone: raw → one gzip stream | ACH alone: raw → one gzip stream |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        for w in r["walks"]:
            out.append(
                f"| {r['scene']} | {w['name']} | {w['cells']} | {w['clusters']} | {w['delta']:,} | {w['clustered']:,} "
                f"| {_ratio(w['clustered'], w['delta'])} "
                f"| {w['delta_gz4']:,} | {w['clustered_gz4']:,} | {_ratio(w['clustered_gz4'], w['delta_gz4'])} "
                f"| {w['delta_gz']:,} | {w['clustered_gz']:,} "
                f"| {_ratio(w['clustered_gz'], w['delta_gz'])} | {w['ids_raw']:,} → {w['ids_gz']:,} "
                f"| {w['ach_raw']:,} → {w['ach_gz']:,} |"
            )
    return "\n".join(out)


def plot_clusters(rows: Sequence[dict[str, Any]], out: Path) -> Path:
    """Bars of clustered / delta-coded bytes per scene: all cell records, the walks' raw
    record traffic, in gzip batches and as one gzip stream (below 1: clusters are smaller)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = [r["scene"] for r in rows]
    series = {
        "cell records (all cells)": [(r["cl_cells"] + r["cl_clusters"]) / r["delta_bytes"] for r in rows],
        "walks, raw": [
            sum(w["clustered"] for w in r["walks"]) / max(1, sum(w["delta"] for w in r["walks"])) for r in rows
        ],
        "walks, gzip batches of 4": [
            sum(w["clustered_gz4"] for w in r["walks"]) / max(1, sum(w["delta_gz4"] for w in r["walks"]))
            for r in rows
        ],
        "walks, one gzip stream": [
            sum(w["clustered_gz"] for w in r["walks"]) / max(1, sum(w["delta_gz"] for w in r["walks"]))
            for r in rows
        ],
    }
    fig, ax = plt.subplots(figsize=(1.6 + 1.4 * len(rows), 4.2))
    x = np.arange(len(rows))
    width = 0.8 / len(series)
    for n, (label, vals) in enumerate(series.items()):
        ax.bar(x + (n - (len(series) - 1) / 2) * width, vals, width, label=label)
    ax.axhline(1.0, color="k", lw=0.8)
    ax.set_xticks(x, names)
    ax.set_ylabel("clustered / delta-coded bytes")
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=2)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
