"""Part of the frame step ``visible`` outdoors: the textures of the rings the walker enters next.

A city baked with ``--virtual-walls`` rings regions of street cells with four textured
walls (:mod:`walkstream.server.bake.ringwalls`).  While a ring wall in view has no
texture the frame draws the far field behind it as geometry
(:func:`~walkstream.client.walk.walls.ring_walls`), so every texture of the next ring
should be held when the walker crosses into its region.  Measured frame by frame on the
village's walk, the frames drawing a far field were, after the walk's start, mostly
those just after the walker entered a new region: the next ring's textures were asked
for from the eye moved on *in a straight line* at its velocity, looking the same way,
at the streamer's need times, which add a turn's cost to the cells after a turn.  A
walker who turns into a side street is not where that eye is, and looks elsewhere.

So the next rings' textures are asked for **where the walker will enter them**
(:func:`ring_textures_ahead`): for each cell of another ring on the streamer's predicted
route within :data:`~walkstream.client.walk.walls.WALL_AHEAD_S`'s last horizon, from the
point of that cell nearest the eye, at the time the route reaches it by distance alone
(:attr:`~walkstream.client.stream.streamer.Streamer.need_records`: a turn makes a cell
less likely, not later), every wall of its ring facing that point: those the view shows
looking the same way at that time, the others :data:`TURNED_LAG_S` later (the walker
may turn to them as it enters); and from that point on at the walker's velocity, the
zones it walks along at the later horizons of the walls it will see (a walker entering
a region alongside a wall crosses a zone about every second: the ring becomes the
current one, whose own horizons ask for those zones, only as it enters).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.client.stream.cellmap import nearest_point
from walkstream.shared.walls import WallSide, WallTable

__all__ = ["TURNED_LAG_S", "ring_textures_ahead", "ring_zones_ahead"]

TURNED_LAG_S = 0.5
"""How much later than the walls in view a wall's zone ahead is asked for that the view
shows only after a turn (after those the walker sees as it walks on)."""


def ring_zones_ahead(
    table: WallTable,
    sides: Sequence[WallSide],
    ring: Sequence[int],
    eye: ArrayLike,
    eyes: ArrayLike,
    horizons: Sequence[float],
    in_view: Callable[[list[int], NDArray[np.float64]], NDArray[np.bool_]],
    want: Callable[[int, float], None],
) -> None:
    """Want the zones of the current ring's walls (``ring``, indices of ``sides``) that the
    eye ``(3,)`` moved on to ``eyes`` ``(h, 3)`` at ``horizons`` (seconds) walks into: of
    the walls the view shows from there looking the same way at that horizon, of the
    others :data:`TURNED_LAG_S` later (the walker may turn to them).  Only the walls in
    view were asked for before; on the village the far field drawn at a zone change
    within a ring was then mostly of a wall seen only after a turn (0.07 -> 0.01 object a
    frame)."""
    e = np.asarray(eye, np.float64).reshape(3)
    ahead = np.asarray(eyes, np.float64).reshape(-1, 3)
    if not len(ring) or not len(ahead):
        return
    walls = list(ring)
    zones, _d, weights = table.views(ahead)
    for h, t in enumerate(horizons[:len(ahead)]):
        shown = in_view(walls, ahead[h] - e)
        for j, k in enumerate(walls):
            if weights[h, k] > 0.0:
                want(sides[k].textures[int(zones[h, k])], float(t) if shown[j] else float(t) + TURNED_LAG_S)


def ring_textures_ahead(
    table: WallTable,
    sides: Sequence[WallSide],
    rings: Mapping[int, Sequence[int]],
    street: int | None,
    eye: ArrayLike,
    velocity: ArrayLike,
    route: Mapping[int, float],
    outlines: Mapping[int, NDArray[np.float64]],
    horizons: Sequence[float],
    in_view: Callable[[list[int], NDArray[np.float64]], NDArray[np.bool_]],
    want: Callable[[int, float], None],
) -> int:
    """Want the textures of the rings the walker enters within the last of ``horizons``
    (seconds; the module docstring), and, from where it enters, those of the zones it
    walks into at the later horizons.

    ``table`` and ``sides`` are the scene's wall sides, ``rings`` each ringed cell's
    sides (indices), ``street`` the viewer's cell, ``eye`` ``(3,)`` and ``velocity``
    ``(2,)`` (m/s) the viewer's; ``route`` the cells ahead and when the route reaches
    them (seconds, by distance), ``outlines`` the cells' outlines ``(n, 2)``;
    ``in_view(walls, moved)`` says which of ``walls`` the view shows from the eye moved
    by ``moved`` ``(3,)``, looking the same way, ``want(texture, need)`` asks for one.
    Returns how many cells ahead were looked at."""
    e = np.asarray(eye, np.float64).reshape(3)
    v = np.asarray(velocity, np.float64).reshape(2)
    here = rings.get(-1 if street is None else int(street), ())
    mine = {sides[k].textures for k in here}  # the current ring's walls: wanted by its own horizons
    n = 0
    for c, t in sorted(route.items(), key=lambda kv: kv[1]):
        if t < 0.0 or t > horizons[-1] or c == street or c not in rings:
            continue
        theirs = [k for k in rings[c] if sides[k].textures not in mine]
        outline = outlines.get(c)
        if not theirs or outline is None:
            continue
        n += 1
        at = np.array([*nearest_point(outline, e[:2]), e[2]])
        # from where it enters, on at its velocity: the zones it walks along next, before
        # the ring is the current one and its own horizons take over
        later = [h for h in horizons if h > t]
        eyes = np.array([at, *[at + np.array([*(v * (h - t)), 0.0]) for h in later]])
        zones, _d, weights = table.views(eyes)
        for row, need in enumerate([float(t), *later]):
            seen = in_view(theirs, eyes[row] - e)
            for j, k in enumerate(theirs):
                if weights[row, k] > 0.0 and (row == 0 or seen[j]):
                    want(sides[k].textures[int(zones[row, k])], need if seen[j] else need + TURNED_LAG_S)
    return n
