"""The faster portal walk (shared/portals.py) against the reference walk (benchmarks/portalwalk.py).

The walk was made faster without changing what it culls: on random poses in the
generated office (anywhere in a cell, and on and beside its portals' planes, where the
clipping and the pass-through take over) and in open halls large enough for the
reference walk's lazy projection waves, both walks must give the same render queue, the same VSAs
per cell in the same order, the same depths and counts, and so the same parts drawn;
the portal and box rectangles must be the same as the reference walk's to the pixel.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from walkstream.benchmarks.portals import hall_topology
from walkstream.benchmarks.portalwalk import cull_portals_reference, rects_reference
from walkstream.server.service.interiors import InteriorState
from walkstream.server.store import SceneReader
from walkstream.shared import portals
from walkstream.shared.camera import camera, perspective
from walkstream.shared.codec.cellmesh import decode_cell_mesh
from walkstream.shared.partcull import cull_parts
from walkstream.shared.portalgraph import PortalGraph
from walkstream.shared.portals import PortalCull, cull_portals
from walkstream.shared.roomview import cell_of, stack_planes
from walkstream.shared.roomwire import decode_topology
from walkstream.shared.screenrects import BOX_EDGES, box_rects, point_rects

SIZE = (160, 120)


def _same(a: PortalCull, b: PortalCull) -> None:
    assert a.order == b.order
    assert a.vsas == b.vsas
    assert a.depth == b.depth
    assert (a.portals, a.tested) == (b.portals, b.tested)


@pytest.fixture(scope="module")
def office(office_db: Path) -> dict[str, Any]:
    with SceneReader.open(office_db) as r:
        state = InteriorState(r, list(r.cells()))
        topology = decode_topology(state.topology["msgpack"].content, "topology")
        meshes = {c.id: decode_cell_mesh(r.contents(c.id)) for c in topology.cells}
    inside = [c for c in topology.cells if c.kind != "outside" and len(c.planes)]
    ids, planes = stack_planes(inside)
    boxes = {
        cid: (np.array([p.bbox[0] for p in m.parts]).reshape(-1, 3), np.array([p.bbox[1] for p in m.parts]).reshape(-1, 3))
        for cid, m in meshes.items()
    }
    return {"topology": topology, "graph": PortalGraph.from_topology(topology), "inside": inside,
            "ids": ids, "planes": planes, "boxes": boxes}


def _poses(office: dict[str, Any], n: int, seed: int) -> list[tuple[np.ndarray, float, float]]:
    """Random eyes: anywhere in a random cell, and within 2 cm of a random portal's plane."""
    rng = np.random.default_rng(seed)
    graph: PortalGraph = office["graph"]
    out = []
    while len(out) < n:
        if rng.random() < 0.5:
            c = office["inside"][int(rng.integers(len(office["inside"])))]
            o = np.asarray(c.outline)
            lo = np.array([*o.min(axis=0), c.zmin])
            hi = np.array([*o.max(axis=0), c.zmax])
            eye = lo + rng.random(3) * (hi - lo)
        else:
            r = int(rng.integers(len(graph.target)))
            poly = graph.poly[r]
            eye = poly[int(rng.integers(len(poly)))] + rng.random() * (poly.mean(axis=0) - poly[0])
            eye = eye + graph.plane[r, :3] * rng.choice([0.0, 0.003, -0.003, 0.02, -0.02])
            eye[2] = max(eye[2], float(poly[:, 2].min()) + 0.2)
        yaw, pitch = float(rng.uniform(-math.pi, math.pi)), float(rng.uniform(-0.6, 0.6))
        out.append((eye, yaw, pitch))
    return out


@pytest.mark.parametrize(("options", "lazy"), [
    ({}, False),
    ({}, True),
    ({"fog_m": 6.0}, True),
    ({"max_depth": 2, "max_vsas": 1}, False),
    ({"naive": True}, False),
])
def test_walk_keeps_round_ones_cells_vsas_and_parts_in_the_office(
    office: dict[str, Any], options: dict[str, Any], lazy: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``lazy``: the office's portals turned into ints a cell at a time, as a large building's are."""
    if lazy:
        monkeypatch.setattr(portals, "_LIST_ALL", 0)
    proj = perspective(60.0, SIZE[0] / SIZE[1], 0.1, 100.0).astype(np.float64)
    graph: PortalGraph = office["graph"]
    frames = visible = 0
    for eye, yaw, pitch in _poses(office, 150, seed=len(options) + 10 * lazy):
        hit = np.flatnonzero(cell_of(office["planes"], eye))
        if not len(hit):
            continue
        start = int(office["ids"][hit[0]])
        view = camera(eye, yaw, pitch).astype(np.float64)
        new = cull_portals(graph, start, eye, view, proj, SIZE, **options)
        old = cull_portals_reference(graph, start, eye, view, proj, SIZE, **options)
        _same(new, old)
        frames += 1
        visible += len(new.order)
        fog = options.get("fog_m", math.inf)
        kept = cull_parts("portals", new.order, office["boxes"], eye, view, proj, SIZE, vsas=new.vsas, fog_m=fog)
        ref = cull_parts("portals", old.order, office["boxes"], eye, view, proj, SIZE, vsas=old.vsas, fog_m=fog)
        assert kept.keys() == ref.keys() and all(np.array_equal(kept[c], ref[c]) for c in kept)
    # the poses are not all degenerate: many frames, and more than the viewer's cell seen
    assert frames >= 60 and visible > 2 * frames, (frames, visible)


def test_rectangles_match_round_ones_to_the_pixel(office: dict[str, Any]) -> None:
    """Portal polygons and part boxes, clipped or not, naive or not."""
    proj = perspective(60.0, SIZE[0] / SIZE[1], 0.1, 100.0).astype(np.float64)
    graph: PortalGraph = office["graph"]
    lo = np.concatenate([b[0] for b in office["boxes"].values()])
    hi = np.concatenate([b[1] for b in office["boxes"].values()])
    bits = (np.arange(8)[:, None] >> np.arange(3)[None, :]) & 1
    corners = np.where(bits[None] == 1, hi[:, None], lo[:, None])
    crossing = 0
    for eye, yaw, pitch in _poses(office, 40, seed=7):
        view = camera(eye, yaw, pitch).astype(np.float64)
        for naive in (False, True):
            got = point_rects(graph.poly, graph.edges, view, proj, SIZE, 0.03, naive)
            want = rects_reference(graph.poly, graph.edges, view, proj, SIZE, 0.03, naive)
            assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])
        rect, front = box_rects(lo, hi, view, proj, SIZE)
        want = rects_reference(corners, BOX_EDGES, view, proj, SIZE, 0.03)
        assert np.array_equal(rect, want[0]) and np.array_equal(front, want[1])
        depth = -(corners @ view[:3, :3].T + view[:3, 3])[..., 2]
        crossing += int(np.sum((depth.min(axis=1) < 0.03) & (depth.max(axis=1) >= 0.03)))
    assert crossing > 0  # the clipped branch was compared too


@pytest.mark.parametrize("k", [6, 24])
def test_walk_keeps_round_ones_cells_in_open_halls(k: int) -> None:
    """24 x 24 has 2,208 directed portals: the reference walk projects those a wave at a time."""
    graph = PortalGraph.from_topology(hall_topology(k))
    proj = perspective(60.0, SIZE[0] / SIZE[1], 0.1, 1000.0).astype(np.float64)
    rng = np.random.default_rng(k)
    for _ in range(6):
        eye = np.array([*rng.uniform(0.1, 4.0 * k - 0.1, 2), 1.6])
        start = int(np.floor(eye[1] / 4.0) * k + np.floor(eye[0] / 4.0))
        view = camera(eye, float(rng.uniform(-math.pi, math.pi)), 0.0).astype(np.float64)
        for fog in (math.inf, 20.0):
            _same(cull_portals(graph, start, eye, view, proj, SIZE, fog_m=fog),
                  cull_portals_reference(graph, start, eye, view, proj, SIZE, fog_m=fog))
