"""``walkstream bench interiors``: the figures of interiors, per IFC model and generated size.

For each source: import seconds (reading and tessellating), bake seconds, cells (and
doorway cells among them; the outside cell not counted), portals, stairs, triangles
(the source's; those in the cells' contents, clipped per cell, with what two cells
share counted in both; those of the outside cell), cells per storey, the database's bytes, the bytes per cell of the
encoded contents against the same meshes as float32 positions and uint32 indices
(mean and max), and the largest position error of the encoding (measured by decoding
every cell, with the bound the format states).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from walkstream.server.bake import bake
from walkstream.server.sources.interiorgen import PRESETS, write_interior
from walkstream.server.sources.read import read_source
from walkstream.server.store import SceneReader
from walkstream.shared.codec.cellmesh import decode_cell_mesh

__all__ = ["default_ifc_files", "generated_sources", "interior_figures", "interiors_table"]


def default_ifc_files() -> list[Path]:
    """The IFC models of ``../shared/data/indoor`` (beside the checkout, or the working folder)."""
    for base in (Path(__file__).resolve().parents[2], Path.cwd().parent, Path.cwd()):
        d = base / "shared" / "data" / "indoor"
        if d.is_dir():
            return sorted(d.glob("*.ifc"))
    return []


def interior_figures(source: Path, db: Path, log: Callable[[str], None] | None = None) -> dict[str, Any]:
    """Import, bake and measure one interior source (see the module docstring)."""
    t0 = time.perf_counter()
    scene = read_source(source)
    import_s = time.perf_counter() - t0
    scene_tris = int(getattr(scene, "triangles", 0))
    del scene
    t1 = time.perf_counter()
    summary = bake(source, db, log=log)
    bake_s = time.perf_counter() - t1
    with SceneReader.open(db) as r:
        info = r.contents_info()
        kinds = {c.id: c.kind for c in r.cells()}
        nbytes = np.array([i.nbytes for i in info.values()], dtype=np.float64)
        raw = np.array([i.raw_bytes for i in info.values()], dtype=np.float64)
        bound = 0.0
        for cid in info:
            cm = decode_cell_mesh(r.contents(cid), f"cell {cid}")
            bound = max(bound, cm.error_bound)
        err = max(i.max_error for i in info.values())
        inside = [c for c, k in kinds.items() if k != "outside"]
        tris = np.array([info[c].triangles for c in inside])
        outside_tris = sum(info[c].triangles for c, k in kinds.items() if k == "outside")
    return {
        "source": source.name,
        "cells": summary["cells_inside"],
        "doorways": summary["doorways"],
        "portals": summary["portals"],
        "stairs": summary["stairs"],
        "rooms": summary["rooms"],
        "source_triangles": scene_tris,
        "cell_triangles": int(tris.sum()),
        "outside_triangles": int(outside_tris),
        "triangles_per_cell": [int(tris.min()), int(tris.max()), float(tris.mean())] if len(tris) else [0, 0, 0.0],
        "portals_per_cell": summary["portals_per_cell"],
        "cells_per_storey": summary["cells_per_storey"],
        "import_s": import_s,
        "bake_s": bake_s,
        "contents_encode_s": float(summary.get("contents_encode_s", 0.0)),
        "db_bytes": summary["db_bytes"],
        "bytes_per_cell_mean": float(nbytes.mean()),
        "bytes_per_cell_max": int(nbytes.max()),
        "raw_per_cell_mean": float(raw.mean()),
        "raw_per_cell_max": int(raw.max()),
        "encoded_over_raw": float(nbytes.sum() / raw.sum()) if raw.sum() else 0.0,
        "max_error_m": err,
        "error_bound_m": bound,
        "portal_sources": summary.get("portal_sources", {}),
        "notes": summary.get("notes", []),
        "tour": summary.get("tour", {}),
    }


def interiors_table(rows: Sequence[dict[str, Any]]) -> str:
    """The figures as a table (one row per source)."""
    head = (
        f"{'source':<19}{'cells':>6}{'(door)':>7}{'portals':>8}{'tris src':>10}{'in cells':>10}{'outside':>9}"
        f"{'tris/cell':>11}{'import s':>9}{'bake s':>8}{'DB bytes':>11}"
        f"{'B/cell mean':>12}{'max':>8}{'raw mean':>10}{'raw max':>11}{'max err mm':>11}"
    )
    lines = [head, "-" * len(head)]
    for r in rows:
        t = r["triangles_per_cell"]
        lines.append(
            f"{r['source'][:18]:<19}{r['cells']:>6}{r['doorways']:>7}{r['portals']:>8}{r['source_triangles']:>10,}"
            f"{r['cell_triangles']:>10,}{r['outside_triangles']:>9,}{f'{t[0]}-{t[1]}':>11}{r['import_s']:>9.2f}"
            f"{r['bake_s']:>8.2f}{r['db_bytes']:>11,}{r['bytes_per_cell_mean']:>12,.0f}{r['bytes_per_cell_max']:>8,}"
            f"{r['raw_per_cell_mean']:>10,.0f}{r['raw_per_cell_max']:>11,}{1000 * r['max_error_m']:>11.3f}"
        )
    lines.append("")
    for r in rows:
        per = ", ".join(f"{k}: {v}" for k, v in r["cells_per_storey"].items())
        tour = r["tour"]
        lines.append(
            f"{r['source']}: cells per storey {per}; portals per cell {r['portals_per_cell'][0]}-"
            f"{r['portals_per_cell'][1]}; encoded/raw {100 * r['encoded_over_raw']:.1f} %; error bound "
            f"{1000 * r['error_bound_m']:.3f} mm; tour {tour.get('seconds', 0):.0f} s through "
            f"{tour.get('visited', 0)} of {tour.get('reachable', 0)} reachable rooms ({tour.get('rooms', 0)} in all)"
        )
        for n in r["notes"]:
            lines.append(f"  note: {n}")
    return "\n".join(lines)


def generated_sources(folder: Path, presets: Sequence[str]) -> list[Path]:
    """Write the generated interiors of ``presets`` into ``folder``; their files."""
    out = []
    for name in presets:
        path = folder / f"{name}.json"
        write_interior(path, PRESETS[name])
        out.append(path)
    return out

