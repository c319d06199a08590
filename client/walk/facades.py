"""Facade textures in the frame loop: which boxes carry them, which get baked next, what they cost.

A part of the ``allocate`` step (:mod:`.allocate`), on the street only:

1. :func:`bake_facades`, before the ACH allocation: the buildings the last frame drew
   as their LOD0 box or at LOD1 without facade images are baked, nearest first, one face at a
   time (:class:`~walkstream.client.draw.facades.FacadeBaker`) while the frame's bake
   credit lasts: each frame adds ``facade_bake_share`` of its triangle budget to the
   credit, each face's bake takes the LOD2 triangles it drew.  Those triangles are
   this frame's: they come off the allocation's budget and go into the triangles the
   device charges, so a cost model (``pda``) pays for the bake in the frame that does it.
2. The allocation sees no LOD1 of a building whose images are held (:func:`facade_avail`):
   its box with facades shows the windows LOD1 lacks, for fewer triangles.
3. :func:`choose_facades`, after it: every building drawn as its LOD0 box whose images
   are held is drawn with them, nearest first while the facade texture budget
   (``facade_budget_bytes``) lasts; its faces turned to the eye are textured quads,
   two triangles and one draw each.  The images held are dropped least recently drawn
   first once they pass the budget.

The images of a building are made once from the geometry it was rebuilt to and kept
while the budget holds them: nothing crosses the link.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from walkstream.client.draw.facades import FacadeBaker, FacadeJob, FacadeSet
from walkstream.client.draw.quads import Quad
from walkstream.client.walk.state import Frame, WalkState
from walkstream.shared.errors import RenderError
from walkstream.shared.portals import box_distance

__all__ = ["FacadeState", "bake_facades", "choose_facades", "facade_avail", "facade_quads", "release_facades"]

CREDIT_FRAMES = 2
"""The bake credit saved up is at most this many frames' share (no burst after a quiet spell)."""
MIN_PIECE = 48
"""Triangles of a face a frame may draw even when the budget leaves none above the
visible lowest LODs (about 3 ms on ``pda``, within the 10 % of a 25 fps frame)."""


@dataclass
class FacadeState:
    """What the frame loop keeps of facade textures from frame to frame."""

    baker: FacadeBaker | None = None
    sets: OrderedDict[int, FacadeSet] = field(default_factory=OrderedDict)
    """Buildings' images held, least recently drawn first."""
    held_bytes: int = 0
    job: FacadeJob | None = None
    """The building being baked."""
    wants: list[int] = field(default_factory=list)
    """Buildings the last frame drew as a plain box, nearest first: the next to bake."""
    credit: float = 0.0
    """Triangles the bake may still draw."""
    last_quads: int = 0
    """Quads the last frame drew (their triangles are kept off the next allocation)."""
    baked_faces: int = 0
    baked_buildings: int = 0
    bake_triangles: int = 0
    """LOD2 triangles drawn by every bake of the walk."""
    dropped: int = 0
    """Buildings' images dropped for the budget."""
    error: str | None = None
    """Why no image could be made (no OpenGL here): the boxes are drawn plain."""


def _geoms_by_id(w: WalkState) -> dict[int, Any]:
    return {g.id: g for g in w.objects.geoms}


def _has_facades(g: Any) -> bool:
    """A building: a LOD0 box and a LOD2 of its own (a flat object shares one mesh)."""
    m0, m2 = g.meshes[0], g.meshes[2]
    return m0 is not None and m2 is not None and m0 is not m2 and m2.triangles > m0.triangles


def bake_facades(w: WalkState, f: Frame, room: int) -> int:
    """Draw the next piece of the face under way (see the module docstring; ``room``: the
    frame's budget left above the visible objects' lowest LODs); returns the LOD2
    triangles drawn, which the frame pays for."""
    st: FacadeState | None = w.facades
    if st is None or st.error is not None:
        return 0
    cfg = w.config
    share = cfg.facade_bake_share * max(f.budget, 0)
    st.credit = min(st.credit + share, CREDIT_FRAMES * share)
    if st.job is None:
        geoms = _geoms_by_id(w)
        while st.wants and st.job is None:
            g = geoms.get(st.wants.pop(0))
            if g is not None and g.id not in st.sets and _has_facades(g):
                if st.baker is None:
                    r = w.renderer
                    try:
                        st.baker = FacadeBaker(None if r is None else r.ctx, cfg.facade_texels_per_m)
                    except RenderError as exc:  # no OpenGL: plain boxes, said in the summary
                        st.error = str(exc)
                        return 0
                st.job = st.baker.job(g.id, g.meshes[0], g.meshes[2])
    job = st.job
    if job is None or st.baker is None or st.credit <= 0:
        return 0
    # a face's triangles spread over frames: at most the credit, and no more than the
    # budget leaves above the visible lowest LODs (or a small piece where it leaves none)
    faces = len(job.images)
    n = st.baker.bake_face(job, max(1, int(min(st.credit, max(room, MIN_PIECE)))))
    st.credit -= n
    st.bake_triangles += n
    st.baked_faces += len(job.images) - faces
    if job.done:
        s = job.result()
        st.job = None
        st.sets[s.id] = s
        st.held_bytes += s.nbytes
        st.baked_buildings += 1
    return n


def choose_facades(w: WalkState, f: Frame) -> None:
    """The frame's facade-textured boxes (``f.facades``, ``f.facade_quads``) and the
    buildings to bake next (see the module docstring)."""
    st: FacadeState | None = w.facades
    if st is None or f.alloc is None:
        return
    o = w.objects
    lods = f.lods
    box = np.flatnonzero((lods == 0) | (lods == 1))
    if not len(box):
        st.wants, st.last_quads = [], 0
        return
    order = box[np.argsort(box_distance(o.lo[box], o.hi[box], f.eye), kind="stable")]
    budget = w.config.facade_budget_bytes
    used = 0
    chosen: list[FacadeSet] = []
    wants: list[int] = []
    for k in order.tolist():
        g = o.geoms[k]
        s = st.sets.get(g.id)
        if s is None:
            if _has_facades(g) and (st.job is None or st.job.id != g.id):
                wants.append(g.id)
            continue
        if lods[k] != 0:  # drawn at LOD1 (its images arrived after the allocation)
            continue
        if used + s.nbytes > budget:
            continue
        used += s.nbytes
        chosen.append(s)
        st.sets.move_to_end(g.id)
    keep = {s.id for s in chosen}
    for oid in list(st.sets):  # least recently drawn first
        if st.held_bytes <= budget:
            break
        if oid not in keep:
            st.held_bytes -= st.sets.pop(oid).nbytes
            st.dropped += 1
    st.wants = wants
    quads = [q for s in chosen for q in s.quads(f.eye)]
    f.facades = chosen
    f.facade_quads = quads
    st.last_quads = len(quads)
    # a facade is a quad as an impostor is: two triangles and one draw
    f.triangles += 2 * len(quads)
    f.drawn += len(quads)


def facade_avail(w: WalkState) -> NDArray[np.bool_]:
    """The objects' available LODs for the allocation, LOD1 left out where the facade
    images are held: a box with its facades shows the windows LOD1 lacks, for 165 fewer
    triangles, so such a building is drawn as that box or at LOD2."""
    st: FacadeState | None = w.facades
    o = w.objects
    if st is None or not st.sets or not len(o.geoms):
        return o.avail
    held = np.fromiter((g.id in st.sets for g in o.geoms), bool, len(o.geoms))
    out = o.avail.copy()
    out[held, 1] = False
    return out


def facade_quads(f: Frame) -> list[Quad]:
    """The frame's facade quads (drawn before the impostors' and the walls')."""
    out: list[Quad] = f.facade_quads
    return out


def release_facades(w: WalkState) -> None:
    """Release the baker's GL objects (the walk is over)."""
    st: FacadeState | None = w.facades
    if st is not None and st.baker is not None:
        st.baker.release()
        st.baker = None
