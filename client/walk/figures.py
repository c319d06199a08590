"""A walk's per-frame figures beyond the frame log: the visible set's model, the rooms, the fog, the culling.

One record for every scene (:class:`WalkFrames`); each scene's summary reads what it
needs of it (``client/report/interior.py``, ``client/report/crossing.py``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from walkstream.client.report.framelog import FrameLog

__all__ = ["MODEL_PVS", "MODEL_PORTALS", "WalkFrames"]

MODEL_PVS = 0
"""The frame's visible set came from the street cell's PVS."""

MODEL_PORTALS = 1
"""The frame's visible set came from the portal walk of a room cell."""

@dataclass
class WalkFrames:
    """Per-frame figures of a walk beyond the frame log."""

    model: list[int] = field(default_factory=list)
    """:data:`MODEL_PVS` or :data:`MODEL_PORTALS`."""
    room: list[int] = field(default_factory=list)
    """The room cell holding the eye (-1 when none does)."""
    rooms_visible: list[int] = field(default_factory=list)
    """Room cells visible (drawn or waiting)."""
    objects_visible: list[int] = field(default_factory=list)
    """City objects in the visible PVS (an entrance's building left out)."""
    fog_m: list[float] = field(default_factory=list)
    """The fog in force (after the budget's lever indoors)."""
    budget: list[int] = field(default_factory=list)
    """The budget of the frame log (0 where no lever takes it)."""
    cull_s: list[float] = field(default_factory=list)
    """CPU seconds (``time.thread_time``) of the rooms' culling: from the frame's visible
    step to its parts to draw (the portal walk and the streamer's tick, the parts
    culling, the triangle test, the fog budget), the streamer's planning left out."""
    walk_s: list[float] = field(default_factory=list)
    """Of :attr:`cull_s`, the portal walks for the frame's view
    (:attr:`~walkstream.client.stream.rooms.RoomStreamer.walk_s`)."""
    triangle_s: list[float] = field(default_factory=list)
    """Of :attr:`cull_s`, the triangle test of the kept parts
    (:mod:`walkstream.shared.trianglecull`; 0 where it is not made)."""
    portals: list[int] = field(default_factory=list)
    """Portals opened by the portal walk."""
    tightened: int = 0
    """Frames on which the visible cells did not fit the memory budget at the default
    fog, so the fog was tightened until they did (the paper's use of fog)."""
    triangle_culled: int = 0
    """Parts the boxes kept and their triangles dropped, over all frames
    (:mod:`walkstream.shared.trianglecull`)."""
    fog_below_portal: int = 0
    """Frames whose budget fog was nearer than the nearest portal the portal walk looked
    through: everything beyond the viewer's own room fogged out (said in the report)."""
    path_wait_s: float = 0.0
    """Seconds the walker stood at the end of the path's head (the start bundle's
    ``pathhead``) because the whole path had not arrived yet."""
    start_hold_s: float = 0.0
    """Seconds the walker stood at the path's start until its first view was complete
    (:attr:`~walkstream.client.config.ReplayConfig.start_hold_s`)."""
    loaded: dict[int, frozenset[int]] = field(default_factory=dict)
    """Frames in an entrance's doorway: the room cells whose contents were in memory."""
    prefetch_from: float | None = None
    """Walk time at which the interior's prefetch before an entrance began (None: never)."""
    impostors: list[int] = field(default_factory=list)
    """Impostors drawn per frame (street frames, a scene with impostors; empty otherwise)."""
    texture_bytes: list[int] = field(default_factory=list)
    """Bytes of the impostor textures each frame drew (one count per image)."""

    facades: list[int] = field(default_factory=list)
    """Boxes drawn with facade textures per frame (street frames with facades on; empty otherwise)."""
    facade_quads: list[int] = field(default_factory=list)
    """Facade quads drawn per frame (two triangles each)."""
    facade_bake: list[int] = field(default_factory=list)
    """LOD2 triangles each frame drew baking facade textures."""
    facade_bytes: list[int] = field(default_factory=list)
    """Bytes of the facade textures each frame drew."""
    facade_swaps: list[int] = field(default_factory=list)
    """Of :attr:`facades`, the buildings drawn so instead of LOD2 (they look alike)."""

    walls: list[int] = field(default_factory=list)
    """Virtual walls drawn as textures per frame (an interior with walls; empty otherwise)."""
    walls_closed: list[int] = field(default_factory=list)
    """Of those, the walls that closed the portal walk (drawn at full opacity)."""
    wall_bytes: list[int] = field(default_factory=list)
    """Bytes of the wall textures each frame drew."""
    geometry: list[int] = field(default_factory=list)
    """Street frames: the city objects drawn as geometry per frame (no quad counted: the
    walls', the facades' and the impostors' are not geometry); empty indoors."""
    far_field: list[int] = field(default_factory=list)
    """Outdoors, per frame: 1 when a ring wall in view had no texture yet and the frame
    drew the ring's far field as geometry instead, else 0."""
    texture_missing: list[int] = field(default_factory=list)
    """Outdoors, per frame: ring walls in view with no texture and nothing drawn for them
    (a scene baked before the far field was stored)."""
    lod_changes: int = 0
    """Street frames: LOD changes of objects drawn as geometry in both of two successive
    frames (:meth:`note_lods`)."""
    lod_flips: int = 0
    """Of :attr:`lod_changes`, those back to the LOD the object had before its previous
    change (back and forth: a pop each way)."""
    lod_object_s: float = 0.0
    """Seconds times objects drawn as geometry in both of two successive frames (the
    per-object rate's denominator)."""
    _lod_last: tuple[float, NDArray[np.int64], NDArray[np.int64]] | None = None
    _lod_before: dict[int, int] = field(default_factory=dict)

    def note_lods(self, t: float, ids: NDArray[np.int64], lods: NDArray[np.int64]) -> None:
        """Count the LOD changes between the last street frame noted and this one at walk
        time ``t``: ``ids`` ``(k,)`` the objects, ``lods`` ``(k,)`` their LODs (-1: not drawn)."""
        drawn = lods >= 0
        cur_ids, cur = ids[drawn].astype(np.int64), lods[drawn].astype(np.int64)
        last, self._lod_last = self._lod_last, (t, cur_ids, cur)
        if last is None:
            return
        t0, ids0, lods0 = last
        both, i0, i1 = np.intersect1d(ids0, cur_ids, assume_unique=True, return_indices=True)
        self.lod_object_s += len(both) * max(t - t0, 0.0)
        moved = np.flatnonzero(lods0[i0] != cur[i1])
        self.lod_changes += len(moved)
        for k in moved.tolist():  # few a frame
            obj, was, now = int(both[k]), int(lods0[i0[k]]), int(cur[i1[k]])
            self.lod_flips += self._lod_before.get(obj) == now
            self._lod_before[obj] = was

    def lod_figures(self) -> dict[str, float]:
        """``lod_changes``, ``lod_flips`` (:meth:`note_lods`) and ``lod_changes_per_object_s``
        (changes per object drawn, per second); empty when no street frame was noted."""
        if self._lod_last is None:
            return {}
        rate = self.lod_changes / self.lod_object_s if self.lod_object_s > 0 else 0.0
        return {"lod_changes": self.lod_changes, "lod_flips": self.lod_flips, "lod_changes_per_object_s": rate}

    def wall_figures(self) -> dict[str, float]:
        """Wall textures drawn per frame (mean, max), closed walls per frame, the share of
        frames drawing any and their texture bytes per frame (mean, max); empty when no
        frame was counted."""
        if not self.walls:
            return {}
        n, c, b = (np.asarray(v, np.float64) for v in (self.walls, self.walls_closed, self.wall_bytes))
        return {
            "walls_mean": float(n.mean()),
            "walls_max": int(n.max()),
            "walls_closed_mean": float(c.mean()),
            "frames_with_walls": float((n > 0).mean()),
            "wall_texture_bytes_mean": float(b.mean()),
            "wall_texture_bytes_max": int(b.max()),
            **self.geometry_figures(),
            **({"far_field_frames": float(np.mean(self.far_field))} if self.far_field else {}),
            **({"texture_missing_frames": float(np.mean(np.asarray(self.texture_missing) > 0))}
               if self.texture_missing else {}),
        }

    def geometry_figures(self) -> dict[str, float]:
        """``geometry_objects_mean``: city objects drawn as geometry per frame (street
        frames; the effective culling's numerator), empty when no street frame was counted."""
        return {"geometry_objects_mean": float(np.mean(self.geometry))} if self.geometry else {}

    def facade_figures(self) -> dict[str, float]:
        """Boxes with facades and their quads per frame (mean), the share of frames drawing
        any, the bake's triangles per frame (mean, max) and the texture bytes a frame drew
        (mean, max); empty when no frame was counted."""
        if not self.facades:
            return {}
        n, q, k, b = (np.asarray(v, np.float64) for v in (self.facades, self.facade_quads, self.facade_bake,
                                                           self.facade_bytes))
        return {
            "facades_mean": float(n.mean()),
            "lookalike_mean": float(np.mean(self.facade_swaps)) if self.facade_swaps else 0.0,
            "facade_quads_mean": float(q.mean()),
            "frames_with_facades": float((n > 0).mean()),
            "bake_triangles_mean": float(k.mean()),
            "bake_triangles_max": int(k.max()),
            "frames_baking": float((k > 0).mean()),
            "texture_bytes_mean": float(b.mean()),
            "texture_bytes_max": int(b.max()),
        }

    def impostor_figures(self) -> dict[str, float]:
        """Impostors drawn per frame (mean, max), the share of frames drawing any, and the
        texture bytes a frame drew (mean, max); empty when no frame drew one."""
        if not any(self.impostors):
            return {}
        n, b = np.asarray(self.impostors, np.float64), np.asarray(self.texture_bytes, np.float64)
        return {
            "impostors_mean": float(n.mean()),
            "impostors_max": int(n.max()),
            "frames_with_impostors": float((n > 0).mean()),
            "texture_bytes_mean": float(b.mean()),
            "texture_bytes_max": int(b.max()),
        }

    def switches(self, t: NDArray[np.float64]) -> list[tuple[float, str]]:
        """``(walk time, model)`` each time the visible set's model changes (the first frame's too)."""
        out: list[tuple[float, str]] = []
        last = None
        for k, m in enumerate(self.model):
            if m != last:
                out.append((float(t[k]), "pvs" if m == MODEL_PVS else "portals"))
                last = m
        return out

    def figures(self) -> dict[str, float]:
        """Median, p95, p99 and max culling milliseconds per frame (CPU), the medians of its
        portal walk and triangle test, and portals opened per frame."""
        if not self.cull_s:
            return {}
        ms = np.asarray(self.cull_s) * 1e3
        return {
            "culling_ms_median": float(np.median(ms)),
            "culling_ms_p95": float(np.percentile(ms, 95)),
            "culling_ms_p99": float(np.percentile(ms, 99)),
            "culling_ms_max": float(ms.max()),
            "culling_walk_ms_median": float(np.median(self.walk_s)) * 1e3,
            "culling_triangles_ms_median": float(np.median(self.triangle_s)) * 1e3,
            "portals_mean": float(np.mean(self.portals)),
            "portals_max": int(np.max(self.portals)),
        }

    def series(self, log: FrameLog) -> dict[str, NDArray[np.float64]]:
        """Per frame: visible cells, portals opened, triangles, culling ms, fog m (the report's plot)."""
        return {
            "cells": np.asarray(log.pvs, np.float64),
            "portals": np.asarray(self.portals, np.float64),
            "triangles": np.asarray(log.triangles, np.float64),
            "cull_ms": 1e3 * np.asarray(self.cull_s, np.float64),
            "fog_m": np.asarray(self.fog_m, np.float64),
        }
