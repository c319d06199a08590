"""Culled pixels: what a frame kept, checked against the truth of everything, pixel by pixel.

The figures of a walk with rooms (an interior, or a crossing's streets and rooms).
A frame *keeps* what it drew -- room parts, city objects at whatever LOD (the LOD
choice is not culling) -- and what it waited for: the parts of a visible cell whose
contents had not arrived, the objects of its visible set not yet built (late, not
culled).  A pixel is **culled** when the truth of everything
(:class:`~walkstream.client.truth.render.TruthRenderer`) shows something the frame did
not keep there and the kept things alone show something more than :data:`TIE_M`
farther (or nothing).  The tolerance is for coincident surfaces, not for culling: the
bake gives the outside cell whole triangles that also lie, clipped, in the rooms (a
ground-floor slab's top face under every room's floor, a few micrometres apart after
quantisation), and which of two such surfaces wins a pixel is the depth buffer's coin
toss.  The keys that show anywhere are the **truly visible** ones, against which the
triangles drawn are compared (tightness).

Both frames are drawn with the fog the frame was drawn at (an interior's budget
fog, noted with the frame): fragments farther from the eye are not drawn, so what the
fog hides on purpose is not a miss.

A pose in solid geometry is **refused**, not compared: where the eye comes nearer
to a room surface than :data:`SOLID_NEAR` near planes
(:class:`~walkstream.client.truth.solid.SolidProbe`: the eye in a wall's face, or the
near plane cutting a wall), the frame looks through the cut into what lies behind,
which no walker sees; it is counted (``refused_poses``), not counted as culled.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.client.truth.notes import FrameNote
from walkstream.client.truth.render import TruthRenderer, object_key
from walkstream.client.truth.solid import SolidProbe
from walkstream.client.truth.standin import wall_stand_in

__all__ = ["TIE_M", "SOLID_NEAR", "CulledRow", "INTERIOR_FIGURES", "CROSSING_FIGURES", "TruthCheck", "check_kept", "kept_keys", "culled_figures"]

#: Depth difference (metres) below which two surfaces count as the same surface.
TIE_M = 0.005

#: A pose is in solid geometry when a room surface is nearer to the eye than this many
#: near planes (0.15 m at the rooms' 0.1 m): the near plane's corners are 1.39 near
#: planes away (60 degrees, 4:3), so a surface that near may be cut; a walk keeps 0.3 m.
SOLID_NEAR = 1.5

#: The ``truth`` figures of an interior walk (rooms only) in ``report.json``.
INTERIOR_FIGURES = ("frames", "culled_pixels", "culled_frames", "pinholes", "refused_poses", "fog_hidden_pct",
                    "tightness_mean", "tightness_p95")
#: The ``truth`` figures of a crossing walk (city objects and rooms) in ``report.json``.
CROSSING_FIGURES = ("frames", "unknown", "culled_pixels", "culled_frames", "pinholes", "refused_poses",
                    "worst_frame")


@dataclass(frozen=True)
class CulledRow:
    """One noted frame's culled pixels (pinholes apart), or its refusal."""

    frame: int
    t: float
    culled_pixels: int
    pinholes: int
    refused: bool


@dataclass(frozen=True)
class TruthCheck:
    """One frame checked against the truth.

    ``missed_pixels`` show a culled key (see the module docstring); ``missed``
    names those keys; ``visible`` are the keys that show at all and
    ``visible_triangles`` their triangles.
    """

    missed_pixels: int
    missed: frozenset[tuple[int, int]]
    visible: frozenset[tuple[int, int]]
    visible_triangles: int
    pinholes: int = 0
    """Missed pixels that are single pixels (no missed neighbour) where the eight
    neighbours all show a kept part nearer, or one of them a kept part at the same
    depth (within 1 %): a crack between two pieces of a wall seen through at one
    pixel, or a piece of the outside cell lying on a kept surface's edge; not a cell
    culled (that shows through a portal's whole area)."""
    mask: NDArray[np.bool_] | None = None
    """``(h, w)`` the missed pixels (row 0 at the top)."""
    depth: NDArray[np.float64] | None = None
    """``(h, w)`` the truth's depth, metres."""
    pinhole_mask: NDArray[np.bool_] | None = None
    """``(h, w)`` the missed pixels that are pinholes (a part of :attr:`mask`)."""
    ids: NDArray[np.int64] | None = None
    """``(h, w)`` the truth's key index per pixel (-1: nothing)."""


def check_kept(
    truth: TruthRenderer, kept: Iterable[tuple[int, int]], eye: ArrayLike, view: ArrayLike, fog_m: float = math.inf
) -> TruthCheck:
    """Compare the keys a frame kept (room parts ``(cell, part)``, objects by
    :func:`~walkstream.client.truth.render.object_key`) with the truth of one camera."""
    keep = truth.flags(kept)
    ids, depth = truth.render(eye, view, None, fog_m)
    shown = ids >= 0
    culled = shown & ~keep[np.maximum(ids, 0)]
    pinholes = 0
    holes = np.zeros_like(culled)
    if culled.any():
        _, kdepth = truth.render(eye, view, keep, fog_m)
        culled &= kdepth > depth + TIE_M
        # a pinhole: no missed neighbour, and every neighbour nearer than the miss
        pad = np.pad(culled, 1)
        dpad = np.pad(depth, 1, constant_values=np.inf)
        h, w = culled.shape
        alone = culled.copy()
        nearer = np.ones_like(culled)
        same = np.zeros_like(culled)
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                if dy or dx:
                    nb = (slice(1 + dy, 1 + dy + h), slice(1 + dx, 1 + dx + w))
                    alone &= ~pad[nb]
                    nearer &= dpad[nb] < depth
                    with np.errstate(invalid="ignore"):
                        same |= np.abs(dpad[nb] - depth) <= 0.01 * depth
        holes = alone & (nearer | same)
        pinholes = int(np.count_nonzero(holes))
    seen = np.unique(ids[shown])
    return TruthCheck(
        missed_pixels=int(np.count_nonzero(culled)),
        missed=frozenset(truth.keys[i] for i in np.unique(ids[culled]).tolist()),
        visible=frozenset(truth.keys[i] for i in seen.tolist()),
        visible_triangles=int(truth.triangles[seen].sum()),
        pinholes=pinholes,
        mask=culled,
        depth=depth,
        pinhole_mask=holes,
        ids=ids,
    )


def kept_keys(truth: TruthRenderer, note: FrameNote) -> tuple[list[tuple[int, int]], list[tuple[int, int]]]:
    """``(drawn, kept)``: the keys a noted frame drew, and those it drew or waited for
    (every part of a waiting cell, every object of its visible set not built)."""
    drawn = [*note.parts, *(object_key(i) for i, _, _ in note.drawn)]
    waiting = set(note.waiting)
    late = np.setdiff1d(note.pvs, note.built) if note.pvs is not None else np.zeros(0, np.int64)
    kept = drawn + [object_key(i) for i in late.tolist()] + [k for k in truth.keys if k[0] in waiting]
    return drawn, kept


def culled_figures(
    truth: TruthRenderer,
    notes: Sequence[FrameNote],
    figures: Sequence[str],
    progress: Callable[[int, int], None] | None = None,
    solid: SolidProbe | None = None,
    rows: list[CulledRow] | None = None,
) -> dict[str, Any]:
    """The ``truth`` figures of a walk with rooms: ``figures`` of :data:`INTERIOR_FIGURES` or
    :data:`CROSSING_FIGURES`.

    ``frames`` noted; ``unknown``: those that knew no visible set yet (not compared);
    ``refused_poses``: those whose eye was in solid geometry by ``solid`` (not
    compared, see the module docstring); ``culled_pixels`` (a key culled that shows: must be 0) and ``culled_frames``
    (frames with any), the ``pinholes`` apart; ``worst_frame`` (the frame with the most
    culled pixels, or None); ``fog_hidden_pct`` (the share of the pixels the fog hides
    on purpose: shown without fog, not with it); ``tightness_mean`` and
    ``tightness_p95`` (triangles drawn over truly visible); with virtual walls drawn,
``wall_pixels``: pixels the truth shows behind a wall drawn as its texture (stood in
for by the texture, not culled: :func:`~.standin.wall_stand_in`).  ``rows``, when given,
    gets one :class:`CulledRow` per compared or refused frame (the report's plot).
    """
    culled = frames_culled = pinholes = refused = walls = 0
    worst: tuple[int, int] = (0, -1)
    fog_share: list[float] = []
    tight: list[float] = []
    for k, note in enumerate(notes):
        if progress is not None:
            progress(k + 1, len(notes))
        if note.pvs is None:
            continue
        if solid is not None and math.isfinite(solid.nearest(note.eye, SOLID_NEAR * truth.near)):
            refused += 1
            if rows is not None:
                rows.append(CulledRow(note.frame, note.t, 0, 0, True))
            continue
        drawn, kept = kept_keys(truth, note)
        chk = check_kept(truth, kept, note.eye, note.view, note.fog)
        miss = chk.missed_pixels - chk.pinholes
        if note.walls and chk.mask is not None and chk.depth is not None and miss > 0:
            # behind a virtual wall drawn as its texture: stood in for, not culled
            stood = chk.mask & ~chk.pinhole_mask if chk.pinhole_mask is not None else chk.mask
            stood = stood & wall_stand_in(note.walls, truth.proj, note.view, truth.size, chk.depth)
            n = int(np.count_nonzero(stood))
            miss -= n
            walls += n
        culled += miss
        frames_culled += miss > 0
        pinholes += chk.pinholes
        if rows is not None:
            rows.append(CulledRow(note.frame, note.t, miss, chk.pinholes, False))
        if miss > worst[0]:
            worst = (miss, note.frame)
        if "fog_hidden_pct" in figures and math.isfinite(note.fog):
            ids_all, _ = truth.render(note.eye, note.view)
            ids_fog, _ = truth.render(note.eye, note.view, None, note.fog)
            fog_share.append(float(np.mean((ids_all >= 0) & (ids_fog < 0))))
        drawn_tris = sum(truth.triangles[truth.index[d]] for d in drawn if d in truth.index)
        if chk.visible_triangles:
            tight.append(drawn_tris / chk.visible_triangles)
    out = {
        "frames": len(notes),
        "unknown": sum(1 for n in notes if n.pvs is None),
        "culled_pixels": int(culled),
        "culled_frames": int(frames_culled),
        "pinholes": int(pinholes),
        "refused_poses": int(refused),
        "worst_frame": None if worst[1] < 0 else {"frame": worst[1], "culled_pixels": worst[0]},
        "fog_hidden_pct": 100.0 * float(np.mean(fog_share)) if fog_share else 0.0,
        "tightness_mean": float(np.mean(tight)) if tight else 0.0,
        "tightness_p95": float(np.percentile(tight, 95)) if tight else 0.0,
    }
    got = {k: out[k] for k in figures}
    if any(n.walls for n in notes):  # only then: a walk without walls keeps its figures
        got["wall_pixels"] = int(walls)
    return got
