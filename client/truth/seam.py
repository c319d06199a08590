"""Seam at a wall's zone border: the frame-to-frame change of a virtual wall's pixels when its zone texture switches, against plain motion.

Each side of a virtual wall carries one texture per zone (:mod:`walkstream.shared.walls`);
a viewer walking along the wall crosses from one zone into the next and the wall shows
the next zone's texture.  Swapped in one frame, every pixel of the wall jumps by the
difference of two pictures sampled a zone width apart: a seam.  The client blends the
two textures around the border instead (:func:`~walkstream.shared.walls.zone_mix`,
``--wall-zone-blend``).  This module measures what is left, on the client's pictures of
the compared frames (the colour truth's client picture, walls painted in as the client
drew them, :mod:`walkstream.client.truth.roomcolour`), for each pair of successive
compared frames, as the impostors' pop is measured (:mod:`walkstream.client.truth.pop`):

- a wall's **pixels** in a frame are those its quad covers in front of the parts drawn
  (:func:`wall_pixels`: the ray of each pixel meets the quad nearer than the depth
  drawn there);
- its **change** is the mean over the pixels it covers in either frame of
  ``|b - a|`` in linear RGB (:func:`~walkstream.client.truth.pop.object_change`);
- a **switching** wall is one drawn in both frames, at the same opacity, whose textures
  differ: ``hard`` when its zone changed with no blend in either frame, ``blend`` when
  the zones or their shares changed with a blend in at least one;
- a **plain-motion** wall is one drawn in both frames with the same textures at the
  same shares and opacity: its pixels change only as the camera moves.

A wall whose opacity changed (the blend between texture and geometry as the viewer
comes near) is neither.  The figure (:func:`~walkstream.client.truth.pop.summarise_pop`
with the kinds ``blend`` and ``hard``): the switching walls' mean change over the
plain-motion walls' mean change (``ratio``); at most 1, the switch is no more visible
than the motion itself: no seam.  The figures are the report's ``truth.seam``.

What makes a switching wall's change is told apart on a third picture, the frame
**held still**: the same frame with each switching wall showing the textures and shares
it showed the frame before (:func:`still_quads`).  From the frame before to it the
wall changes by the camera's **motion** alone; from it to the frame, by the **look**
alone (the texture swap and the shares of the blend).  ``ratio_own`` is the switching
walls' change over their own motion's on the same frame pairs: at most 1, the
switch adds nothing a viewer sees beyond the wall's own motion.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from walkstream.client.draw.quads import Quad, cross_fade
from walkstream.client.truth.pop import object_change
from walkstream.shared.walls import NO_WARP, WallWarp

__all__ = ["SEAM_KINDS", "SeamMeter", "SeamWall", "seam_figures", "still_quads", "wall_pixels"]

SEAM_KINDS = ("blend", "hard")
"""The kinds of switching walls (module docs)."""


@dataclass(frozen=True)
class SeamWall:
    """One wall side as a frame drew it: which side (``portal``, ``side``), its zone's
    texture id, the neighbour zone's texture blended in (-1: none) at ``mix``, its
    opacity and ``(4, 3)`` corners (bottom-left, bottom-right, top-right, top-left)."""

    portal: int
    side: int
    image: int
    mix_image: int
    mix: float
    alpha: float
    corners: NDArray[np.float64]
    warps: tuple[WallWarp, WallWarp] = (NO_WARP, NO_WARP)
    """How its texture and the neighbour's were laid on the wall (``DrawnWall.warps``)."""

    @property
    def look(self) -> tuple[int, int, float]:
        """What it shows: its texture, the neighbour's and its share (none: ``(image, -1, 0)``)."""
        return (self.image, self.mix_image, round(self.mix, 6)) if self.mix > 0 else (self.image, -1, 0.0)


def wall_pixels(
    walls: Sequence[SeamWall],
    view: NDArray[np.floating],
    proj: NDArray[np.floating],
    depth: NDArray[np.float64],
) -> NDArray[np.int64]:
    """``(h, w)`` the index in ``walls`` of the wall each pixel shows (-1: none).

    A pixel shows a wall where its ray meets the wall's quad in front of the eye and
    no farther than the depth drawn there (``depth`` ``(h, w)``, eye-space depth, row 0
    at the top; ``inf`` where nothing was drawn), as the quads are painted: depth
    tested against the parts, later walls over earlier ones.
    """
    h, w = depth.shape
    x = (2.0 * (np.arange(w) + 0.5) / w - 1.0) / float(proj[0, 0])
    y = (1.0 - 2.0 * (np.arange(h) + 0.5) / h) / float(proj[1, 1])
    ray = np.stack(np.broadcast_arrays(x[None, :], y[:, None], -np.ones((h, 1))), axis=-1)  # depth 1 along -z
    out = np.full((h, w), -1, np.int64)
    v = np.asarray(view, np.float64)
    for k, wall in enumerate(walls):
        c = (v[:3, :3] @ np.asarray(wall.corners, np.float64).T).T + v[:3, 3]  # eye space
        o, du, dv = c[0], c[1] - c[0], c[3] - c[0]
        n = np.cross(du, dv)
        den = ray @ n
        with np.errstate(divide="ignore", invalid="ignore"):
            s = float(o @ n) / den  # eye-space depth of the hit
        q = ray * s[..., None] - o
        u = (q @ du) / float(du @ du)
        t = (q @ dv) / float(dv @ dv)
        hit = np.isfinite(s) & (s > 0) & (u >= 0) & (u <= 1) & (t >= 0) & (t <= 1)
        hit &= s <= depth * (1.0 + 1e-4) + 1e-4
        out[hit] = k
    return out


@dataclass
class SeamMeter:
    """Fed every compared frame in order; keeps the switching and plain-motion changes
    (the fields :func:`~walkstream.client.truth.pop.summarise_pop` reads)."""

    switching: list[float] = field(default_factory=list)
    """One change per switching wall per frame pair."""
    kinds: list[str] = field(default_factory=list)
    """Each switching change's kind (:data:`SEAM_KINDS`)."""
    plain: list[float] = field(default_factory=list)
    """One change per plain-motion wall per frame pair."""
    pairs: int = 0
    """Frame pairs with at least one switching wall."""
    motion: list[float] = field(default_factory=list)
    """Each switching change's part from the camera's motion alone (the frame before to
    the frame held still; NaN where no still picture was given)."""
    look: list[float] = field(default_factory=list)
    """Each switching change's part from the look alone (the frame held still to the frame)."""
    _last: tuple[NDArray[np.uint8], NDArray[np.int64], list[SeamWall]] | None = None

    def earlier(self, walls: Sequence[SeamWall]) -> list[SeamWall | None]:
        """For each of ``walls`` the look it had in the frame added last where it switched
        since (drawn in both at the same opacity, its textures or shares changed), else None."""
        if self._last is None:
            return [None] * len(walls)
        before = {(x.portal, x.side): x for x in self._last[2]}
        out: list[SeamWall | None] = []
        for b in walls:
            a = before.get((b.portal, b.side))
            out.append(a if a is not None and a.alpha == b.alpha and a.look != b.look else None)
        return out

    def add(self, rgb: NDArray[np.uint8], walls: Sequence[SeamWall], pixels: NDArray[np.int64],
            still: NDArray[np.uint8] | None = None) -> None:
        """Compare a frame (its client picture ``(h, w, 3)`` sRGB, its walls and their
        :func:`wall_pixels`) with the one added before it; ``still`` ``(h, w, 3)``, the
        frame held still (module docs), splits each switching change into motion and look."""
        prev, self._last = self._last, (rgb, pixels.copy(), list(walls))
        if prev is None:
            return
        p_rgb, p_pix, p_walls = prev
        # one id per wall side over both frames (its place among them, + 1)
        ident: dict[tuple[int, int], int] = {}
        for x in [*p_walls, *walls]:
            ident.setdefault((x.portal, x.side), len(ident) + 1)

        def ids(pix: NDArray[np.int64], ws: Sequence[SeamWall]) -> NDArray[np.uint32]:
            lut = np.array([0, *[ident[(x.portal, x.side)] for x in ws]], np.uint32)
            return lut[pix + 1]

        change, count = object_change(p_rgb, ids(p_pix, p_walls), rgb, ids(pixels, walls))
        nan = np.full(len(change), np.nan)
        moved, looked = nan, nan
        if still is not None:  # the still picture's walls stand where this frame's do
            moved = object_change(p_rgb, ids(p_pix, p_walls), still, ids(pixels, walls))[0]
            moved = np.pad(moved, (0, max(0, len(change) - len(moved))), constant_values=np.nan)
            looked = object_change(still, ids(pixels, walls), rgb, ids(pixels, walls))[0]
            looked = np.pad(looked, (0, max(0, len(change) - len(looked))), constant_values=np.nan)
        before = {(x.portal, x.side): x for x in p_walls}
        switch: list[tuple[str, float]] = []
        for b in walls:
            key = (b.portal, b.side)
            a, i = before.get(key), ident[key]
            if a is None or a.alpha != b.alpha or i >= len(change) or count[i] == 0:
                continue  # new, fading against the geometry, or seen in neither frame
            if a.look == b.look:
                self.plain.append(float(change[i]))
            else:
                switch.append(("blend" if a.mix > 0 or b.mix > 0 else "hard", float(change[i])))
                self.motion.append(float(moved[i]))
                self.look.append(float(looked[i]))
        self.pairs += bool(switch)
        self.kinds.extend(kind for kind, _ in switch)
        self.switching.extend(c for _, c in switch)


def still_quads(walls: Sequence[SeamWall], earlier: Sequence[SeamWall | None],
                images: dict[int, NDArray[np.uint8]]) -> list[Quad] | None:
    """The quads of a frame's ``walls`` held still: each wall with an ``earlier`` look
    (:meth:`SeamMeter.earlier`) shows it, slid as it was, the others their own (``images``
    by texture id; None where an image is missing: no still picture then).  A slide's
    change is so counted with the look's, not the motion's."""
    out: list[Quad] = []
    for b, a in zip(walls, earlier, strict=True):
        w = b if a is None else a
        rgba = images.get(w.image)
        other = images.get(w.mix_image) if w.mix > 0 else None
        if rgba is None or (w.mix > 0 and other is None):
            return None
        out += cross_fade(b.corners, -1 - w.image, rgba, -1 - w.mix_image, other, b.alpha, w.mix, w.warps)
    return out


def seam_figures(meter: SeamMeter) -> dict[str, float | None]:
    """The split of the switching walls' change (module docs): ``motion_mean`` and
    ``look_mean`` (linear RGB), and ``ratio_own``, the switching walls' mean change over
    their own motion's, on the pairs with a still picture (None without any)."""
    m, k = np.asarray(meter.motion, np.float64), np.asarray(meter.look, np.float64)
    s = np.asarray(meter.switching, np.float64)
    ok = np.isfinite(m) & np.isfinite(k) if m.size == s.size else np.zeros(s.size, bool)
    if not ok.any():
        return {"motion_mean": None, "look_mean": None, "ratio_own": None, "split": 0}
    mm = float(m[ok].mean())
    return {"motion_mean": mm, "look_mean": float(k[ok].mean()),
            "ratio_own": float(s[ok].mean() / mm) if mm > 0 else None, "split": int(ok.sum())}
