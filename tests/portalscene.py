"""An interior's culling against its id truth, pose by pose, for the portal tests.

:class:`PortalScene` holds a baked interior's compact topology (as the client gets
it), every cell's contents and a :class:`~walkstream.client.truth.render.TruthRenderer`
of the whole building; :meth:`PortalScene.frame` culls one pose with the visible
screen areas (the parts by their boxes, then by their triangles, as the client culls) and
compares what it kept with the truth; :func:`walk_every_door`
sums that over the frames at every door, opening and stair.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from walkstream.client.truth.culled import TruthCheck, check_kept
from walkstream.client.truth.render import TruthRenderer
from walkstream.server.service.interiors import InteriorState
from walkstream.server.store import SceneReader
from walkstream.shared.camera import camera
from walkstream.shared.codec.cellmesh import CellMesh
from walkstream.shared.codec.cellpieces import decode_cell_pieces
from walkstream.shared.partcull import PartRects, cull_parts
from walkstream.shared.portalgraph import PortalGraph
from walkstream.shared.portals import cull_portals, frustum_cells
from walkstream.shared.roomcompact import decode_topology_compact
from walkstream.shared.roomview import cell_of, stack_planes
from walkstream.shared.trianglecull import refine_parts

__all__ = ["EYE", "SIZE", "PortalScene", "walk_every_door"]

SIZE = (160, 120)
EYE = 1.6


class PortalScene:
    """An interior's topology, every cell's contents, the id truth and the poses."""

    def __init__(self, db: Path, ctx: Any) -> None:
        with SceneReader.open(db) as r:
            state = InteriorState(r, list(r.cells()))
            # the compact topology, as the client gets it (portals rounded outward to mm)
            self.topology = decode_topology_compact(state.topology_compact.content, "topology")
            self.meshes: dict[int, CellMesh] = {c.id: decode_cell_pieces(r.contents(c.id)) for c in self.topology.cells}
        self.graph = PortalGraph.from_topology(self.topology)
        inside = [c for c in self.topology.cells if c.kind != "outside" and len(c.planes)]
        self.ids, self.planes = stack_planes(inside)
        self.boxes = {
            cid: (np.array([p.bbox[0] for p in m.parts]).reshape(-1, 3), np.array([p.bbox[1] for p in m.parts]).reshape(-1, 3))
            for cid, m in self.meshes.items()
        }
        self.truth = TruthRenderer(size=SIZE, rooms=self.meshes, near=0.1, far=100.0, two_sided=True, ctx=ctx)
        self.proj = self.truth.proj
        #: parts the boxes kept and their triangles dropped, over every frame (as the client culls)
        self.triangle_culled = 0

    def frame(self, eye: np.ndarray, yaw: float, pitch: float = 0.0, naive: bool = False,
              mode: str = "portals") -> tuple[TruthCheck, int, np.ndarray] | None:
        """The worst check over the cells that hold the eye (on a shared plane, either)."""
        hit = np.flatnonzero(cell_of(self.planes, eye))
        if not len(hit):
            return None
        view = camera(eye, yaw, pitch).astype(np.float64)
        worst: tuple[TruthCheck, int, np.ndarray] | None = None
        for h in hit.tolist():
            start = int(self.ids[h])
            if mode == "portals":
                pc = cull_portals(self.graph, start, eye, view, self.proj, SIZE, naive=naive)
                rects = PartRects()  # shared by the two tests, as the client does
                keep = cull_parts("portals", pc.order, self.boxes, eye, view, self.proj, SIZE, vsas=pc.vsas,
                                  rects=rects)
                if not naive:
                    self.triangle_culled += refine_parts(keep, self.meshes, pc.vsas, view, self.proj, SIZE,
                                                         rects=rects)
            else:
                cells = frustum_cells(self.graph, start, eye, self.proj @ view)
                keep = cull_parts(mode, cells, self.boxes, eye, view, self.proj, SIZE)
            kept = [(c, k) for c, m in keep.items() for k in np.flatnonzero(m).tolist()]
            chk = check_kept(self.truth, kept, eye, view)
            if worst is None or chk.missed_pixels - chk.pinholes > worst[0].missed_pixels - worst[0].pinholes:
                worst = (chk, start, view)
        return worst

    def poses(self) -> Iterator[tuple[np.ndarray, float, float]]:
        """Frames at every door, opening and stair (module docstring), a few per portal."""
        yaws = (0.0, math.pi, 0.8, -0.8, math.pi + 0.8, math.pi - 0.8)
        rows = {int(p): i for i, p in reversed(list(enumerate(self.graph.portal.tolist())))}
        for j, (pid, kind, _a, _b, poly) in enumerate(self.topology.portals):
            if kind == "window":
                continue
            n = self.graph.plane[rows[pid], :3]
            if abs(n[2]) > 0.9:
                continue  # a floor portal: the stair frames below walk through it
            if float(np.asarray(poly)[:, 2].min()) + EYE > float(np.asarray(poly)[:, 2].max()) + 0.5:
                continue  # high in a wall (over a low wall): no eye stands in it
            c = np.asarray(poly).mean(axis=0)
            c[2] = min(float(np.asarray(poly)[:, 2].min()) + EYE, c[2] + 0.3)
            yaw = math.atan2(n[1], n[0])
            for i, d in enumerate((-0.01, 0.0, 0.01)):
                yield c + d * n, yaw + yaws[(i + j) % len(yaws)], 0.0
            t = np.array([-n[1], n[0], 0.0])
            for d in (-0.4, 0.4):  # along the wall that holds the door, from either side
                yield c + d * n, math.atan2(t[1], t[0]) * (1 if d > 0 else -1) + (0 if d > 0 else math.pi), 0.0
        for _portal, _lo, _up, path in self.topology.stairs:
            p = np.asarray(path)
            for i in range(len(p) - 1):
                e = 0.5 * (p[i] + p[i + 1]) + np.array([0.0, 0.0, EYE])
                dv = p[i + 1] - p[i]
                yaw = math.atan2(dv[1], dv[0])
                pitch = math.atan2(dv[2], math.hypot(dv[0], dv[1]))
                yield e, yaw, pitch
                yield e, yaw + math.pi, -pitch

    def leaks(self, chk: TruthCheck, eye: np.ndarray, view: np.ndarray, start: int, samples: int = 24) -> int:
        """How many of (up to ``samples``) missed pixels are seen along a ray that leaves
        the cells (anywhere on its way) other than through a portal: where the source's spaces stop short of
        their walls (duplex's IFC spaces leave gaps of up to 16 cm), the walls' faces
        lie beyond every cell's reach and no portal graph can see them; such a miss is
        the bake's space partition, not the culling."""
        assert chk.mask is not None and chk.depth is not None
        rows, cols = np.nonzero(chk.mask)
        pick = np.linspace(0, len(rows) - 1, min(samples, len(rows))).astype(int)
        inv = np.linalg.inv(self.proj @ view)
        fwd = -view[2, :3]
        n = 0
        for r, c in zip(rows[pick].tolist(), cols[pick].tolist(), strict=True):
            ndc = np.array([(c + 0.5) / SIZE[0] * 2 - 1, 1 - (r + 0.5) / SIZE[1] * 2, -1.0, 1.0])
            q = inv @ ndc
            d = q[:3] / q[3] - eye
            d /= np.linalg.norm(d)
            reach = float(chk.depth[r, c]) / float(d @ fwd)
            t = np.arange(0.0, max(reach - 0.08, 0.0), 0.01)
            pts = eye + t[:, None] * d
            held = np.any(np.all(np.einsum("nkj,tj->tnk", self.planes[:, :, :3], pts) + self.planes[None, :, :, 3] <= 1e-6, axis=2), axis=1)
            exits = np.flatnonzero(held[:-1] & ~held[1:]) + 1  # every step out of the cells
            if not held[0]:
                exits = np.concatenate([[0], exits])
            # the crossing lies within half a step (5 mm) before the first point outside
            if any(not self._near_portal(pts[i] - 0.005 * d) for i in exits.tolist()):
                n += 1
        return n

    def _near_portal(self, p: np.ndarray, tol: float = 0.01) -> bool:
        g = self.graph
        dist = np.abs(g.plane[:, :3] @ p + g.plane[:, 3])
        inb = np.all((p >= g.lo - tol) & (p <= g.hi + tol), axis=1)
        return bool(np.any((dist <= tol) & inb))

    def release(self) -> None:
        self.truth.release()


def walk_every_door(scene: PortalScene, naive: bool = False) -> dict[str, int]:
    out = {"frames": 0, "missed": 0, "pinholes": 0, "leaks": 0, "bad_frames": 0}
    for eye, yaw, pitch in scene.poses():
        got = scene.frame(eye, yaw, pitch, naive=naive)
        if got is None:
            continue
        chk, start, view = got
        out["frames"] += 1
        out["pinholes"] += chk.pinholes
        real = chk.missed_pixels - chk.pinholes
        if real > 0 and not naive:
            # rays along the walls' insides: a few sampled rays graze a corner where the
            # 1 cm steps cannot tell; three quarters of them through a gap is a gap
            leaks = scene.leaks(chk, eye, view, start)
            if leaks >= 0.75 * min(24, chk.missed_pixels):
                out["leaks"] += real
                continue
        out["missed"] += real
        out["bad_frames"] += real > 0
    return out


