"""A small open hall in the ``walkstream-interior`` format: one large room full of furniture.

The virtual walls' tests and measurements use it (one room ``width`` by ``depth``
metres, few walls, many parts).  ``python tests/openhall.py OUT.json [W D]`` writes one.
"""

from __future__ import annotations

import json
import sys
from typing import Any

import numpy as np

from walkstream.server.sources.interiormesh import FURNITURE_KINDS


def open_hall(width: float = 40.0, depth: float = 24.0, *, spacing: float = 2.0, seed: int = 1,
              crossing: list[tuple[float, float]] | None = None) -> dict[str, Any]:
    """One storey, one room ``width`` x ``depth`` m, 4.5 m high, four outer walls (a door
    in the south one), furniture on a jittered grid every ``spacing`` metres (a path of
    1.5 m kept clear around the edge); ``crossing`` adds shelves at those ``(x, y)``."""
    rng = np.random.default_rng(seed)
    x0, y0 = 600000.0, 5340000.0
    out = [[x0, y0], [x0 + width, y0], [x0 + width, y0 + depth], [x0, y0 + depth]]
    t = 0.2
    walls = []
    for k in range(4):
        a, b = out[k], out[(k + 1) % 4]
        openings = [{"id": "d0", "kind": "door", "offset": 2.0, "width": 1.0, "sill": 0.0, "head": 2.1,
                     "swing": 1}] if k == 0 else []
        walls.append({"id": f"w{k}", "storey": 0, "from": a, "to": b, "thickness": t, "exterior": True,
                      "openings": openings})
    grow = [[x0 - t, y0 - t], [x0 + width + t, y0 - t], [x0 + width + t, y0 + depth + t], [x0 - t, y0 + depth + t]]
    # an office's furniture (the production hall's machines, robots and racks are its own
    # preset's: a few hundred triangles each would make this small hall a heavy one)
    kinds = [k for k in FURNITURE_KINDS if k not in ("plant", "machine", "robot", "rack")] or list(FURNITURE_KINDS)
    furniture = []
    for i, x in enumerate(np.arange(2.5, width - 2.0, spacing)):
        for j, y in enumerate(np.arange(2.5, depth - 2.0, spacing)):
            jx, jy = rng.uniform(-0.3, 0.3, 2)
            furniture.append({"id": f"f{i}.{j}", "kind": str(kinds[(i * 7 + j * 3) % len(kinds)]), "storey": 0,
                              "at": [x0 + float(x + jx), y0 + float(y + jy)], "yaw": float(rng.uniform(0, 6.28))})
    for n, (x, y) in enumerate(crossing or []):
        furniture.append({"id": f"x{n}", "kind": "shelf", "storey": 0, "at": [x0 + x, y0 + y], "yaw": 0.0})
    return {
        "format": "walkstream-interior", "version": 1, "name": f"hall-{width:g}x{depth:g}", "crs": "EPSG:32633",
        "slab": 0.25,
        "storeys": [{"name": "0", "elevation": 0.0, "height": 4.5}],
        "rooms": [{"id": "hall", "name": "hall", "storey": 0, "outline": out}],
        "walls": walls,
        "slabs": [{"id": "s0", "storey": 0, "outline": grow, "holes": []},
                  {"id": "s1", "storey": 1, "outline": grow, "holes": []}],
        "stairs": [],
        "furniture": furniture,
    }


if __name__ == "__main__":
    w, d = (float(sys.argv[2]), float(sys.argv[3])) if len(sys.argv) > 3 else (40.0, 24.0)
    with open(sys.argv[1], "w") as fh:
        json.dump(open_hall(w, d), fh)
