"""Pop at the impostor switch: the frame-to-frame change of a switching building's pixels against plain motion.

An impostor fades in over its geometry across a short distance
(:func:`~walkstream.client.draw.impostors.impostor_alpha`) so that nothing pops when a
building goes from geometry to image or back.  This module measures it on the frames
the client drew (its own ``gl`` renderer, impostors included), for each pair of
successive compared frames:

- an object's **change** is the mean over its pixels and channels of
  ``|b - a|`` in *linear* RGB (0..1, the colour error's scale,
  :func:`~walkstream.client.truth.colour.srgb_to_linear`), over the pixels it covers
  in *either* frame (its id in the client's id buffer, a building drawn as its image
  where its image painted it): a building that appears, vanishes or changes colour
  between the frames counts all its pixels;
- a **switching** object is one drawn in both frames that switches, of one of three
  kinds: ``blend``, its impostor opacity (0 where it was drawn as geometry alone)
  differs between them and is strictly between 0 and 1 in at least one (within its
  blend); ``hard``, it went from geometry alone to its image alone or back in one frame
  (no blend: ``--impostor-blend 0``, an image arriving at full opacity, or dropped by
  the texture budget); ``image``, it is drawn as an image in both frames but not the
  same one (the viewer's direction crossed into another bin);
- a **plain-motion** object is one drawn in both frames in the same form (the same LOD,
  or the same image) at the same opacity: its pixels change only as the camera moves.

The figure (:func:`summarise_pop`): the mean change of the switching objects over the
mean change of the plain-motion objects over the walk's frame pairs (``ratio``; the
same walk, so the same camera speed; every pair rather than only those with a switch,
because a switch is rare and the plain motion of one pair of frames too often none at
all); at most 1 means the switch is no more visible than the motion itself ("no pop").  A hard switch
puts all of the image-against-geometry difference into one frame; a blend spreads it
over the frames of the blend.

``ratio_matched`` compares each switching change with the plain motion of objects of
the same size on screen instead (the plain-motion mean of objects covering as many
pixels, to within a factor of two: :func:`size_bin`).  The switching buildings are far
ones, a few pixels each, and the change of so small an object is mostly its edge
moving across pixels (on the demo's SE at 160 x 120, plain motion changes a 1-4 pixel
object 0.0085 a frame, a 1,000-pixel one 0.0024): the plain mean of every object is
the wrong yardstick for them, by a factor of about two.

``ratio_own`` compares like with like: the same objects, the same pixels, the same
frame pairs.  The frame is drawn a second time with each switching object as the
frame before drew it (its quads, opacity and image; :func:`held_impostors`), the
*held* frame: what plain motion alone would have shown.  A switching object's
**switch change** is the mean ``|drawn - held|`` over its pixels (what the switch
added that frame), its **motion change** the mean ``|held - previous|`` over the same
pixels (its own plain motion); ``ratio_own`` is the switch changes' mean over the
motion changes' mean, at most 1: the switch adds no more change than the motion does
("no pop").  A pair whose geometry changed LOD too, or appeared or went (the frame
the image starts or stops standing alone), is left out of it and counted
(``lod_changed``): the held frame draws this frame's geometry, so that change would
count as motion.  Why: the switching buildings at the default ``D`` cover 1-5 pixels
at 160 x 120, and their change is mostly their silhouette crossing pixel centres
(0.3-0.6 on the frames it happens, against 0.001 between), so a few such frames of
two buildings set ``ratio`` and ``ratio_matched``; the held frame has them too, and
they cancel.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from walkstream.client.truth.colour import srgb_to_linear

__all__ = [
    "PopFrame", "PopMeter", "held_impostors", "held_objects", "object_change", "own_change", "pop_frame", "size_bin", "summarise_pop",
    "switches",
]


@dataclass(frozen=True)
class PopFrame:
    """What the pop measure keeps of one compared frame."""

    frame: int
    rgb: NDArray[np.uint8]
    """``(h, w, 3)`` the client's picture (sRGB)."""
    ids: NDArray[np.uint32]
    """``(h, w)`` object id + 1 per pixel, 0 where none shows."""
    alpha: dict[int, float]
    """Impostor opacity of each object drawn (0: geometry alone)."""
    form: dict[int, tuple[int, int]]
    """Each object's form: ``(lod, -1)`` for geometry, ``(lod or -1, image)`` with an impostor."""


def pop_frame(
    frame: int,
    rgb: NDArray[np.uint8],
    ids: NDArray[np.uint32],
    drawn: Iterable[tuple[int, int]],
    impostors: Iterable[tuple[int, Any]],
) -> PopFrame:
    """A :class:`PopFrame` of one frame: ``drawn`` ``(object id, lod)`` of its geometry,
    ``impostors`` ``(object id, quad)`` of its images (a quad's image id at ``[1]``, its
    opacity at ``[3]``: :data:`~walkstream.client.draw.quads.Quad`)."""
    lod = {int(i): int(k) for i, k in drawn}
    alpha = dict.fromkeys(lod, 0.0)
    form = {i: (k, -1) for i, k in lod.items()}
    for i, q in impostors:
        i = int(i)
        alpha[i] = float(q[3])
        form[i] = (lod.get(i, -1), int(q[1]))
    return PopFrame(int(frame), rgb, ids, alpha, form)


def object_change(
    a_rgb: NDArray[np.uint8], a_ids: NDArray[np.uint32], b_rgb: NDArray[np.uint8], b_ids: NDArray[np.uint32]
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Each object's change between two frames (see the module docs).

    Parameters
    ----------
    a_rgb, b_rgb : (h, w, 3) uint8
        The two pictures (sRGB).
    a_ids, b_ids : (h, w) uint32
        Object id + 1 per pixel (0: none).

    Returns
    -------
    change : (n,) float64
        Indexed by object id + 1: the mean absolute linear-RGB change over the pixels
        the object covers in either frame (NaN where it covers none).
    pixels : (n,) int64
        Those pixels' count.
    """
    d = np.abs(srgb_to_linear(b_rgb) - srgb_to_linear(a_rgb)).mean(axis=2).ravel()
    a, b = a_ids.astype(np.int64).ravel(), b_ids.astype(np.int64).ravel()
    n = int(max(a.max(initial=0), b.max(initial=0))) + 1
    same = a == b  # a pixel of one object in both frames counts once
    total = np.bincount(a, d, n) + np.bincount(b[~same], d[~same], n)
    count = np.bincount(a, minlength=n) + np.bincount(b[~same], minlength=n)
    with np.errstate(invalid="ignore", divide="ignore"):
        change = total / count
    return change, count.astype(np.int64)


def own_change(
    a_rgb: NDArray[np.uint8], a_ids: NDArray[np.uint32], held: NDArray[np.uint8], b_rgb: NDArray[np.uint8],
    b_ids: NDArray[np.uint32],
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.int64]]:
    """Each object's switch and motion change (see the module docs) between frame ``a``
    and frame ``b``, ``held`` ``(h, w, 3)`` frame ``b`` drawn with the switching objects as
    in ``a``: ``(n,)`` the mean ``|b - held|`` and the mean ``|held - a|`` (linear RGB)
    over the pixels the object covers in either frame (NaN where none), and their count,
    indexed by object id + 1 as :func:`object_change`."""
    lin_h = srgb_to_linear(held)
    switch = np.abs(srgb_to_linear(b_rgb) - lin_h).mean(axis=2).ravel()
    motion = np.abs(lin_h - srgb_to_linear(a_rgb)).mean(axis=2).ravel()
    a, b = a_ids.astype(np.int64).ravel(), b_ids.astype(np.int64).ravel()
    n = int(max(a.max(initial=0), b.max(initial=0))) + 1
    same = a == b

    def per_object(d: NDArray[np.float64]) -> NDArray[np.float64]:
        out: NDArray[np.float64] = (np.bincount(a, d, n) + np.bincount(b[~same], d[~same], n)).astype(np.float64)
        return out

    count = np.bincount(a, minlength=n) + np.bincount(b[~same], minlength=n)
    with np.errstate(invalid="ignore", divide="ignore"):
        return per_object(switch) / count, per_object(motion) / count, count.astype(np.int64)


def switches(prev: PopFrame, cur: PopFrame) -> dict[str, list[int]]:
    """The objects switching between ``prev`` and ``cur`` by kind (``blend``, ``hard``,
    ``image``: the module docs) and ``plain``, those in plain motion."""
    both = prev.alpha.keys() & cur.alpha.keys()
    image = sorted(i for i in both if prev.form[i][1] >= 0 and cur.form[i][1] >= 0 and prev.form[i][1] != cur.form[i][1])
    fade = sorted(i for i in both if prev.alpha[i] != cur.alpha[i] and i not in set(image))
    hard = [i for i in fade if {prev.alpha[i], cur.alpha[i]} == {0.0, 1.0}]
    fade = [i for i in fade if i not in set(hard)]
    plain = sorted(i for i in both if prev.alpha[i] == cur.alpha[i] and prev.form[i] == cur.form[i])
    return {"blend": fade, "hard": hard, "image": image, "plain": plain}


def held_objects(prev: PopFrame, cur: PopFrame) -> list[int]:
    """The switching objects a held frame can show as ``prev`` did (``blend`` and ``image``
    switches whose geometry, or its absence, is the same in both frames; the held frame
    draws ``cur``'s geometry)."""
    sw = switches(prev, cur)
    return [i for i in sw["blend"] + sw["image"] if prev.form[i][0] == cur.form[i][0]]


def held_impostors(
    prev: Iterable[tuple[int, Any]], cur: Iterable[tuple[int, Any]], objects: Iterable[int]
) -> list[tuple[int, Any]]:
    """The ``(object id, quad)`` impostors of a held frame: ``cur``'s, with those of
    ``objects`` (the switching ones, :func:`held_objects`) as ``prev`` drew them."""
    keep = {int(i) for i in objects}
    return [(i, q) for i, q in cur if int(i) not in keep] + [(i, q) for i, q in prev if int(i) in keep]


@dataclass
class PopMeter:
    """Fed every compared frame in order; keeps the switching and plain-motion changes."""

    switching: list[float] = field(default_factory=list)
    """One change per switching object per frame pair."""
    kinds: list[str] = field(default_factory=list)
    """Each switching change's kind: ``blend``, ``hard`` or ``image`` (see the module docs)."""
    plain: list[float] = field(default_factory=list)
    """One change per plain-motion object per frame pair."""
    switching_pixels: list[int] = field(default_factory=list)
    """The pixels each of :attr:`switching` is over."""
    plain_pixels: list[int] = field(default_factory=list)
    """The pixels each of :attr:`plain` is over."""
    pairs: int = 0
    """Frame pairs with at least one switching object."""
    own_switch: list[float] = field(default_factory=list)
    """One switch change per held switching object per frame pair (``ratio_own``, the module docs)."""
    own_motion: list[float] = field(default_factory=list)
    """The same objects' motion change on the same pairs."""
    lod_changed: int = 0
    """Switching ``blend`` or ``image`` changes whose geometry also changed LOD, or appeared
    or went (not held)."""
    _last: PopFrame | None = None

    @property
    def last(self) -> PopFrame | None:
        """The frame added last (the next one is compared with it)."""
        return self._last

    def add(self, cur: PopFrame, held: NDArray[np.uint8] | None = None) -> None:
        """Compare ``cur`` with the frame before it (the previous one added); ``held``:
        ``cur`` drawn with the switching objects of :func:`held_objects` as the frame
        before drew them (:func:`held_impostors`), for ``ratio_own``."""
        prev, self._last = self._last, cur
        if prev is None:
            return
        sw = switches(prev, cur)
        fade, hard, image, plain = sw["blend"], sw["hard"], sw["image"], sw["plain"]
        change, count = object_change(prev.rgb, prev.ids, cur.rgb, cur.ids)
        if held is not None:
            kept = held_objects(prev, cur)
            self.lod_changed += len(fade) + len(image) - len(kept)
            s_own, m_own, n_own = own_change(prev.rgb, prev.ids, held, cur.rgb, cur.ids)
            k = np.asarray(kept, np.int64) + 1
            k = k[k < len(n_own)]
            k = k[n_own[k] > 0]
            self.own_switch.extend(s_own[k].tolist())
            self.own_motion.extend(m_own[k].tolist())

        def take(objs: Sequence[int]) -> tuple[list[float], list[int]]:
            k = np.asarray(objs, np.int64) + 1
            k = k[k < len(change)]
            k = k[count[k] > 0]
            return change[k].tolist(), count[k].tolist()

        (f, fn), (h, hn), (s, sn) = take(fade), take(hard), take(image)
        self.pairs += bool(f or h or s)
        self.switching.extend(f + h + s)
        self.switching_pixels.extend(fn + hn + sn)
        self.kinds.extend(["blend"] * len(f) + ["hard"] * len(h) + ["image"] * len(s))
        p, pn = take(plain)
        self.plain.extend(p)
        self.plain_pixels.extend(pn)


def size_bin(pixels: NDArray[np.int64]) -> NDArray[np.int64]:
    """``(n,)`` the size class of objects covering ``pixels`` ``(n,)``: ``floor(log2(pixels))``."""
    return np.floor(np.log2(np.maximum(np.asarray(pixels, np.float64), 1.0))).astype(np.int64)


def _matched_plain(meter: PopMeter) -> NDArray[np.float64]:
    """``(switching,)`` the plain-motion mean change of objects of each switching change's
    size class (the nearest class that has any plain motion where its own has none)."""
    p = np.asarray(meter.plain, np.float64)
    # a meter without pixel counts (the walls' seam) has no size classes to match
    pb = size_bin(np.asarray(getattr(meter, "plain_pixels", []), np.int64))
    sb = size_bin(np.asarray(getattr(meter, "switching_pixels", []), np.int64))
    if not p.size or not sb.size:
        return np.zeros(0, np.float64)
    classes = np.unique(pb)
    means = np.array([p[pb == c].mean() for c in classes])
    nearest = np.abs(sb[:, None] - classes[None, :]).argmin(axis=1)
    out: NDArray[np.float64] = means[nearest]
    return out


def summarise_pop(meter: PopMeter | Any, kinds_of: Sequence[str] = ("blend", "hard", "image")) -> dict[str, Any]:
    """The ``truth.pop`` figures: frame pairs with a switch, the switching objects' mean and
    p95 change, the plain-motion objects' mean change (linear RGB, 0..1),
    and ``ratio`` (switching mean over plain mean; None without both); ``ratio_matched``
    (switching mean over the mean of the plain motion of objects of each one's size,
    :func:`size_bin`; None where the meter keeps no pixel counts); ``kinds``: per kind
    (``kinds_of``: ``blend``, ``hard``, ``image``) its count, mean change, ratio and
    matched ratio; ``ratio_own`` the switch changes' mean over the same objects' motion
    changes' mean on the same frame pairs, and ``own`` its counts and means (None and
    zeros where the meter was fed no held frames).

    ``meter`` is a :class:`PopMeter` or anything with its ``switching``, ``kinds``,
    ``plain`` and ``pairs`` (the walls' seam, :class:`~walkstream.client.truth.seam.SeamMeter`)."""
    s, p = np.asarray(meter.switching, np.float64), np.asarray(meter.plain, np.float64)
    ref = _matched_plain(meter)

    def matched(sel: NDArray[np.bool_] | slice) -> float | None:
        if not ref.size or not s[sel].size or not ref[sel].mean():
            return None
        return float(s[sel].mean() / ref[sel].mean())

    def stat(a: NDArray[np.float64], f: Any) -> float | None:
        return float(f(a)) if a.size else None

    sm, pm = stat(s, np.mean), stat(p, np.mean)
    own_s = np.asarray(getattr(meter, "own_switch", []), np.float64)
    own_m = np.asarray(getattr(meter, "own_motion", []), np.float64)
    osm, omm = stat(own_s, np.mean), stat(own_m, np.mean)
    kind = np.asarray(meter.kinds, dtype=object)
    kinds = {}
    for k in kinds_of:
        km = stat(s[kind == k], np.mean)
        kinds[k] = {"switching": int((kind == k).sum()), "change_mean": km,
                    "ratio": None if km is None or not pm else km / pm, "ratio_matched": matched(kind == k)}
    return {
        "pairs": meter.pairs,
        "switching": int(s.size),
        "switching_change_mean": sm,
        "switching_change_p95": stat(s, lambda a: np.percentile(a, 95)),
        "plain": int(p.size),
        "plain_change_mean": pm,
        "ratio": None if sm is None or not pm else sm / pm,
        "ratio_matched": matched(slice(None)),
        "ratio_own": None if osm is None or not omm else osm / omm,
        "own": {"switching": int(own_s.size), "switch_change_mean": osm, "motion_change_mean": omm,
                "lod_changed": int(getattr(meter, "lod_changed", 0))},
        "kinds": kinds,
    }

