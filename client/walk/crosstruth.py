"""Ground truth of a crossing walk: every city object and every room part at full detail, nothing culled.

The truth is the interior's id frame (:class:`~walkstream.client.truth.interior.InteriorTruth`)
over the whole scene: each room cell's parts as they are, and each city object as one
part (its LOD2 mesh built from its parameters with the scene's grammar, keyed
``(-1 - id, 0)``); the entrance's building is left out (its parameters are a stand-in
inside the shell, which stands for it).  A noted frame's kept parts are checked pixel
by pixel (:meth:`~walkstream.client.truth.interior.InteriorTruth.check`): a pixel is
**culled** when the truth shows a part the frame neither drew nor waited for there.
The client's LOD choice does not count (a drawn object is kept whatever its LOD),
only what it left out.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import httpx
import numpy as np
from numpy.typing import NDArray

from walkstream.client.net.api import SceneClient
from walkstream.client.truth.interior import InteriorTruth
from walkstream.client.truth.scene import TruthScene, UnshapedTransport
from walkstream.shared.roomwire import Entrance

__all__ = ["UNKNOWN", "crossing_truth"]

UNKNOWN = (-(1 << 62), -1)
"""Noted for a frame that knew no visible set yet (the street cell's record had not
arrived): everything counts as waiting, none of it as culled."""


@dataclass(frozen=True)
class _Part:
    """A city object's LOD2 mesh seen as one room part (what the truth draws)."""

    positions: NDArray[np.float32]
    indices: NDArray[np.uint32]
    triangles: int


@dataclass(frozen=True)
class _Whole:
    parts: tuple[_Part, ...]


async def crossing_truth(
    transport: httpx.AsyncBaseTransport,
    base_url: str,
    scene: str,
    cells: Iterable[int],
    entrance: Entrance,
    notes: Iterable[tuple[int, Any, Any, list[tuple[int, int]], float]],
    size: tuple[int, int],
    fov_deg: float,
    clock: Any,
) -> dict[str, Any]:
    """The replay's ground-truth comparison of a crossing walk (``--truth-every``).

    Every object and every room cell's contents are fetched on the unshaped
    ``transport`` (nothing counted on the walk's link).  Each noted frame ``(index,
    eye, view, kept, fog)`` is checked against the whole scene's id frame, fragments
    beyond ``fog`` not drawn; a noted ``(cell, -1)`` stands for a visible room cell not
    received yet (all its parts count as kept), :data:`UNKNOWN` for a frame that knew no
    visible set yet (not compared: counted as ``unknown``).  Returns the frames noted, the
    ``culled`` pixels (must be 0) and the frames with any, the pinholes apart, and the
    frames compared on each side of the door.
    """
    notes = list(notes)
    ts = await TruthScene.fetch(transport, base_url, scene)
    try:
        ids = [i for i in sorted(ts.params) if i != entrance.building]
        whole: dict[int, Any] = {}
        for oid, m in ts.lod2(ids).items():
            tris = int(len(m.indices))
            whole[-1 - oid] = _Whole((_Part(m.positions, np.asarray(m.indices, np.uint32), tris),))
    finally:
        await ts.close()
    async with httpx.AsyncClient(transport=UnshapedTransport(transport), base_url=base_url,
                                 timeout=httpx.Timeout(120.0)) as http:
        api = SceneClient(http, clock, scene)
        for c in cells:
            mesh = await api.contents(int(c))
            # placed as the walk's streamer places them (contents in the interior's own frame)
            placed = entrance.placement
            whole[int(c)] = placed.place(mesh) if placed is not None and placed.holds(int(c)) else mesh
    truth = InteriorTruth(whole, size, fov_deg=fov_deg, near=0.1, far=2000.0)
    culled = frames_culled = pinholes = 0
    worst: tuple[int, int] = (0, -1)
    try:
        for frame, eye, view, noted, fog in notes:
            if UNKNOWN in noted:
                continue
            drawn = [k for k in noted if k[1] >= 0]
            waiting = {k[0] for k in noted if k[1] < 0}
            kept = drawn + [k for k in truth.keys if k[0] in waiting]
            chk = truth.check(kept, eye, view, fog if math.isfinite(fog) else math.inf)
            miss = chk.missed_pixels - chk.pinholes
            culled += miss
            frames_culled += miss > 0
            pinholes += chk.pinholes
            if miss > worst[0]:
                worst = (miss, int(frame))
    finally:
        truth.release()
    return {
        "frames": len(notes),
        "unknown": sum(1 for n in notes if UNKNOWN in n[3]),
        "culled_pixels": int(culled),
        "culled_frames": int(frames_culled),
        "pinholes": int(pinholes),
        "worst_frame": None if worst[1] < 0 else {"frame": worst[1], "culled_pixels": worst[0]},
    }
