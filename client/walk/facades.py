"""Facade textures in the frame loop: which boxes carry them, which get baked next, what they cost.

A part of the ``allocate`` step (:mod:`.allocate`), on the street only:

1. :func:`bake_facades`, before the ACH allocation: the buildings the last frame drew
   as their LOD0 box or at LOD1 without facade images are baked, nearest first, one face at a
   time (:class:`~walkstream.client.draw.facades.FacadeBaker`) while the frame's bake
   credit lasts: each frame adds ``facade_bake_share`` of its triangle budget to the
   credit, each face's bake takes the LOD2 triangles it drew.  Those triangles are
   this frame's: they come off the allocation's budget and go into the triangles the
   device charges, so a cost model (``pda``) pays for the bake in the frame that does it.
   Under the real clock (``gl``) the bake runs instead after the frame is shown, in the
   time left before the next tick (:func:`bake_in_slack`, called by the frame loop):
   off the frame's critical path, whole faces while the slowest face so far fits.
2. The allocation sees no LOD1 of a building whose images are held (:func:`facade_avail`):
   its box with facades shows the windows LOD1 lacks, for fewer triangles.
3. :func:`choose_facades`, after it: every building drawn as its LOD0 box whose images
   are held is drawn with them, nearest first while the facade texture budget
   (``facade_budget_bytes``) lasts; its faces turned to the eye are textured quads,
   two triangles and one draw each.  The images held are dropped least recently drawn
   first once they pass the budget.
4. With ``facade_lookalike`` (the default), in the same step: a building the allocation
   drew at LOD2 whose box with its pictures looks like LOD2 from the eye (the relief's
   parallax and the texel each within a pixel, :mod:`walkstream.client.draw.lookalike`)
   is drawn as that box instead (no face turned to the eye seen more obliquely than
   ``facade_grazing_deg``), for 12 triangles and two a face turned to the eye where
   LOD2 draws ~1,200; buildings at LOD2 far enough for a texel to be within a pixel are
   wanted for the bake after the boxes.  This is the lever on a device whose budget
   draws LOD2 nearly everywhere (``gl``).

The images of a building are made once from the geometry it was rebuilt to and kept
while the budget holds them: nothing crosses the link.
"""

from __future__ import annotations

import math
import time
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from walkstream.client.draw.facades import FacadeBaker, FacadeJob, FacadeSet
from walkstream.client.draw.lookalike import (
    FaceGeometry,
    buildings_alike,
    face_geometry,
    texel_distance,
)
from walkstream.client.draw.quads import Quad
from walkstream.client.walk.state import Frame, WalkState
from walkstream.shared.errors import RenderError
from walkstream.shared.portals import box_distance

__all__ = ["FacadeState", "bake_facades", "bake_in_slack", "choose_facades", "facade_avail", "facade_quads", "release_facades"]

CREDIT_FRAMES = 2
"""The bake credit saved up is at most this many frames' share (no burst after a quiet spell)."""
SLACK_MARGIN_S = 0.004
"""Seconds of a frame's slack the bake leaves unused (the event loop's own work, timer jitter)."""
SLACK_DECAY = 0.9
"""Per frame, the share of the slowest face time kept (one slow face, the first one's
shader and framebuffer among them, does not stop the bake for long)."""
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
    shapes: dict[int, FaceGeometry] = field(default_factory=dict)
    """The held buildings' faces as the look-alike test reads them."""
    face_s: float = 0.005
    """Seconds the slowest recent face took to bake (the real clock's bake plans by it)."""
    slack_triangles: int = 0
    """LOD2 triangles baked in frames' slack (the real clock)."""
    swapped: int = 0
    """Buildings the last frame drew as their box with pictures instead of LOD2."""


def _geoms_by_id(w: WalkState) -> dict[int, Any]:
    return {g.id: g for g in w.objects.geoms}


def _has_facades(g: Any) -> bool:
    """A building: a LOD0 box and a LOD2 of its own (a flat object shares one mesh)."""
    m0, m2 = g.meshes[0], g.meshes[2]
    return m0 is not None and m2 is not None and m0 is not m2 and m2.triangles > m0.triangles


def _next_job(w: WalkState, st: FacadeState) -> FacadeJob | None:
    """The building under way, or the next wanted one started (None: none wanted, or no
    OpenGL here: ``st.error`` says so)."""
    if st.job is None:
        geoms = _geoms_by_id(w)
        while st.wants and st.job is None:
            g = geoms.get(st.wants.pop(0))
            if g is not None and g.id not in st.sets and _has_facades(g):
                if st.baker is None:
                    r = w.renderer
                    try:
                        st.baker = FacadeBaker(None if r is None else r.ctx, w.config.facade_texels_per_m)
                    except RenderError as exc:  # no OpenGL: plain boxes, said in the summary
                        st.error = str(exc)
                        return None
                st.job = st.baker.job(g.id, g.meshes[0], g.meshes[2])
    return st.job


def _bake_piece(st: FacadeState, job: FacadeJob, max_triangles: int | None) -> int:
    """Bake the next piece of ``job`` (:meth:`FacadeBaker.bake_face`), keep the set once
    done; returns the LOD2 triangles drawn."""
    assert st.baker is not None
    faces = len(job.images)
    n = st.baker.bake_face(job, max_triangles)
    st.bake_triangles += n
    st.baked_faces += len(job.images) - faces
    if job.done:
        s = job.result()
        st.job = None
        st.sets[s.id] = s
        st.shapes[s.id] = face_geometry(s.images)
        st.held_bytes += s.nbytes
        st.baked_buildings += 1
    return n


def bake_facades(w: WalkState, f: Frame, room: int) -> int:
    """Draw the next piece of the face under way (see the module docstring; ``room``: the
    frame's budget left above the visible objects' lowest LODs); returns the LOD2
    triangles drawn, which the frame pays for.  Under the real clock the bake runs in the
    frame's slack instead (:func:`bake_in_slack`) and this draws nothing."""
    st: FacadeState | None = w.facades
    if st is None or st.error is not None or w.config.clock == "real":
        return 0
    share = w.config.facade_bake_share * max(f.budget, 0)
    st.credit = min(st.credit + share, CREDIT_FRAMES * share)
    job = _next_job(w, st)
    if job is None or st.baker is None or st.credit <= 0:
        return 0
    # a face's triangles spread over frames: at most the credit, and no more than the
    # budget leaves above the visible lowest LODs (or a small piece where it leaves none)
    n = _bake_piece(st, job, max(1, int(min(st.credit, max(room, MIN_PIECE)))))
    st.credit -= n
    return n


def bake_in_slack(w: WalkState, slack_s: float) -> int:
    """Under the real clock: bake whole faces in the ``slack_s`` seconds the frame left
    before the next tick, off the frame's critical path: a face starts only when the
    slowest recent face (:attr:`FacadeState.face_s`) fits in what is left, so the next
    frame does not start late.  Returns the LOD2 triangles drawn."""
    st: FacadeState | None = w.facades
    if st is None or st.error is not None or w.indoors:
        return 0
    t0 = time.perf_counter()
    drawn = 0
    st.face_s *= SLACK_DECAY
    while True:
        left = slack_s - (time.perf_counter() - t0)
        if left < SLACK_MARGIN_S + st.face_s:
            break
        job = _next_job(w, st)
        if job is None or st.baker is None:
            break
        t1 = time.perf_counter()
        drawn += _bake_piece(st, job, None)
        st.face_s = max(st.face_s, time.perf_counter() - t1)
    st.slack_triangles += drawn
    return drawn


def _focal_px(w: WalkState) -> float:
    """The frame's focal length in pixels (vertical)."""
    return float(w.proj[1, 1]) * w.size[1] / 2.0


def choose_facades(w: WalkState, f: Frame) -> None:
    """The frame's facade-textured boxes (``f.facades``, ``f.facade_quads``), the LOD2
    buildings drawn as such a box instead, and the buildings to bake next (see the module
    docstring)."""
    st: FacadeState | None = w.facades
    if st is None or f.alloc is None:
        return
    o = w.objects
    lods = f.lods
    lookalike = w.config.facade_lookalike
    cand = np.flatnonzero((lods >= 0) if lookalike else ((lods == 0) | (lods == 1)))
    st.swapped = 0
    if not len(cand):
        st.wants, st.last_quads = [], 0
        return
    dist = box_distance(o.lo[cand], o.hi[cand], f.eye)
    order = np.argsort(dist, kind="stable")
    focal = _focal_px(w)
    alike: dict[int, bool] = {}
    if lookalike:  # the held buildings at LOD2, tested in one pass
        ids = [o.geoms[k].id for k in cand[lods[cand] == 2].tolist() if o.geoms[k].id in st.shapes]
        cos = math.cos(math.radians(w.config.facade_grazing_deg))
        alike = dict(zip(ids, buildings_alike([st.shapes[i] for i in ids], f.eye, focal, cos,
                                              w.config.facade_parallax_px).tolist(), strict=True))
    far = texel_distance(1.0 / w.config.facade_texels_per_m, focal)
    budget = w.config.facade_budget_bytes
    used = 0
    chosen: list[FacadeSet] = []
    wants: list[int] = []
    later: list[int] = []
    for j in order.tolist():
        k = int(cand[j])
        g = o.geoms[k]
        s = st.sets.get(g.id)
        full = lods[k] == 2
        if s is None:
            if _has_facades(g) and (st.job is None or st.job.id != g.id) and (not full or dist[j] >= far):
                (later if full else wants).append(g.id)
            continue
        if lods[k] == 1:  # drawn at LOD1 (its images arrived after the allocation)
            continue
        if used + s.nbytes > budget:
            continue
        if full:
            if not alike.get(g.id, False):
                continue
            # LOD2 -> the box with its pictures: the allocation's triangles less the difference
            lods[k] = 0
            f.triangles -= int(o.tri[k, 2] - o.tri[k, 0])
            st.swapped += 1
        used += s.nbytes
        chosen.append(s)
        st.sets.move_to_end(g.id)
    keep = {s.id for s in chosen}
    for oid in list(st.sets):  # least recently drawn first
        if st.held_bytes <= budget:
            break
        if oid not in keep:
            st.held_bytes -= st.sets.pop(oid).nbytes
            st.shapes.pop(oid, None)
            st.dropped += 1
    st.wants = wants + later
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
