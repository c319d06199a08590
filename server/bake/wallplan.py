"""Textured virtual walls of an interior: where they stand, their zones, what stays geometry.

The bake places the walls itself (``--virtual-walls``): :func:`~.rooms.room_layout`
cuts every convex room part whose area is over ``2 S**2`` (``S``, the pitch,
``--wall-pitch``, 8 m by default) into a grid of about ``S`` by ``S`` cells, and the
faces between two of them become portals of kind ``wall``.  A room of ordinary size
(an office, a corridor piece) is never cut: a scene with no open space gets no walls.

This module plans what each wall side needs (:func:`plan_walls`), from the cells on
its two sides:

- **Wall distance and zones.**  The side's viewer cell is ``D`` deep (the farthest
  point of its outline from the wall).  Textures are used from ``x_T = D / 3`` on,
  fading in over a blend zone of ``D / 16`` (so a viewer in a cell's middle sees
  every wall of it as texture); the side is cut into
  ``n = ceil(L / (2 x_T tan A))`` zones (:func:`~walkstream.shared.walls.zone_count`,
  the paper's equations (3) and (4)), each sampled at its middle ``3 D / 4`` in
  front of the wall (between ``x_T`` and the cell's far side) at eye height.
- **What stays geometry.**  An object (any element but the building's shell: walls,
  slabs, roofs, coverings) that crosses a wall's plane within the wall is never on
  that wall's textures (the paper's rule: part of it is in front of the wall; the
  texture has a transparent hole where it stands, so its geometry behind the wall's
  plane shows through the quad), and the cells on both sides hold it whole instead
  of clipped at the wall
  (:func:`whole_crossing`), so it is drawn as geometry from either side.  The
  shell is clipped at the wall like any cell boundary: the floor and ceiling behind
  a wall are on its texture.

:func:`~.walls.bake_walls` is the driver's step: the textures not yet stored rendered
and encoded in chunks by the one chunk runner (:func:`~.wallrender.wall_task`), then
every side's row with its texture ids.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from walkstream.server.bake.roomcontents import Part, weld
from walkstream.server.bake.roomlayout import RoomLayout
from walkstream.server.sources.interior import InteriorScene
from walkstream.shared.codec.image import IMAGE_MEDIA, MAX_IMAGE_SIDE
from walkstream.shared.errors import InputError
from walkstream.shared.impostors import texels_needed
from walkstream.shared.walldepth import check_depth_grid
from walkstream.shared.walls import DEFAULT_WALL_ERROR_DEG, WallSide, zone_count

__all__ = [
    "SHELL_KINDS",
    "WALL_CHUNK",
    "WallJob",
    "WallPlan",
    "WallSettings",
    "parse_wall_quality",
    "plan_walls",
    "texture_height",
    "texture_width",
    "whole_crossing",
]

SHELL_KINDS = frozenset({"wall", "slab", "roof", "covering"})
"""Element kinds clipped at a virtual wall like at any cell boundary (the building's shell)."""

WALL_CHUNK = 32
"""Textures per task (a renderer's start, every element uploaded, is paid once per process)."""


@dataclass(frozen=True)
class WallSettings:
    """``--virtual-walls`` settings: ``pitch`` (grid spacing, m), ``error_deg`` (the angle
    of error A), ``texels_per_m`` (texture resolution), ``max_side`` (texels), ``codec``.

    16 texels per metre in lossless WebP: a texture of the production hall's 6 m walls is
    about 0.9 kB (1.75 kB at 32 texels per metre), and a walk wants a new one every second
    or so at 56 kbit/s, where the 1.75 kB textures filled three quarters of the link.
    Lossless against lossy WebP at quality 90 (``--wall-quality 90``) on the hall's tour:
    texture bytes +4.6 %, colour error median 1.01 -> 0.83 %, ΔE00 2.70 -> 1.71, every
    frame perfect both ways (docs/benchmarks.md).

    Outdoors (a city's street or grid cells, :mod:`~.ringwalls`): ``keep`` (``--wall-keep
    K``), the objects a cell keeps as geometry before a ring of walls carries the rest,
    ``ring_min`` (``--wall-ring-min``, m), the ring's least distance from the cells it
    surrounds, and ``region`` (``--wall-region``, m), the largest group of neighbouring
    cells that share one ring;
    outdoor textures are ``outdoor_texels_per_m`` (4: a ring's wall is tens of metres
    long and seen from at least ``ring_min``; on the village's walk 8 texels a metre at
    WebP quality 75 sent 17 % more texture bytes for a colour error median 0.99 -> 0.79 %,
    and the later textures left the far field drawn as geometry on 21 % of the frames,
    not 4 %) and at most ``outdoor_max_side``
    texels wide, encoded by ``outdoor_codec`` at WebP quality ``outdoor_quality`` (75: the
    textures of a ring's long walls are 1-4 kB at 90, and a walker along a street needs a
    new one on each wall beside it every second or so; 75 takes about 40 % off their
    bytes).  Lossless WebP (``--wall-quality lossless``) sent 12 % more texture bytes on the
    village's walk and 7 % fewer on the squares', for a colour error median 0.99 -> 0.80 %
    and 0.89 -> 0.84 %, but West Oakland's ``SE`` walk kept 98.9 % perfect frames with it
    (100 % at 75): not the default (docs/benchmarks.md).
    ``quality`` (90) is the lossy codecs' quality indoors (``--wall-quality Q``).

    Fidelity from the target view (``--wall-view H``, ``view_height``; 0: the fixed
    densities above): each side's texels a metre so that a texel is at most a pixel of a
    view ``H`` pixels high at ``fov_deg`` from the side's nearest viewing distance, times
    the magnification the client's warp lays on it there (:func:`texture_width`), capped
    at ``max_side`` on both axes.  ``--wall-texels T``, ``--wall-max-side S`` and
    ``--wall-quality Q|lossless`` set the fixed density, the cap and the codec indoors and
    outdoors alike (:meth:`with_texture`)."""

    pitch: float = 8.0
    error_deg: float = DEFAULT_WALL_ERROR_DEG
    texels_per_m: float = 16.0
    max_side: int = 512
    codec: str = "webp-lossless"
    keep: int = 8
    ring_min: float = 10.0
    region: float = 40.0
    outdoor_texels_per_m: float = 4.0
    outdoor_max_side: int = 256
    quality: int = 90
    outdoor_quality: int = 75
    outdoor_codec: str = "webp"
    depth_grid: int = 0
    """``--wall-depth G``: each texture's ``G`` x ``G`` inverse-depth grid stored after it
    (:mod:`walkstream.shared.walldepth`; 0: none)."""
    view_height: int = 0
    """``--wall-view H``: the target view's height, pixels, that sizes each side's texture
    (0: the fixed ``texels_per_m``)."""
    fov_deg: float = 60.0
    """The target view's vertical field of view, degrees (the client's default)."""

    def check(self) -> WallSettings:
        """These settings, or a one-line :class:`InputError` naming the bad one."""
        if not (math.isfinite(self.error_deg) and 0.5 <= self.error_deg <= 45.0):
            raise InputError(f"--wall-error: expected 0.5 to 45 degrees, got {self.error_deg}")
        if not (math.isfinite(self.pitch) and 2.0 <= self.pitch <= 200.0):
            raise InputError(f"--wall-pitch: expected 2 to 200 m, got {self.pitch}")
        if not (isinstance(self.keep, int) and 0 <= self.keep <= 100_000):
            raise InputError(f"--wall-keep: expected 0 to 100000 objects, got {self.keep}")
        if not (math.isfinite(self.ring_min) and 1.0 <= self.ring_min <= 2000.0):
            raise InputError(f"--wall-ring-min: expected 1 to 2000 m, got {self.ring_min}")
        if not (math.isfinite(self.region) and 0.0 <= self.region <= 10_000.0):
            raise InputError(f"--wall-region: expected 0 to 10000 m, got {self.region}")
        for name, q in (("quality", self.quality), ("outdoor quality", self.outdoor_quality)):
            if not (isinstance(q, int) and 1 <= q <= 100):
                raise InputError(f"wall {name}: expected 1 to 100, got {q!r:.20}")
        check_depth_grid(self.depth_grid)
        if not (isinstance(self.view_height, int) and 0 <= self.view_height <= 8192):
            raise InputError(f"--wall-view: expected 0 (fixed texels a metre) to 8192 pixels, got {self.view_height!r:.20}")
        if not (math.isfinite(self.fov_deg) and 1.0 <= self.fov_deg <= 170.0):
            raise InputError(f"wall view field: expected 1 to 170 degrees, got {self.fov_deg}")
        for t in (self.texels_per_m, self.outdoor_texels_per_m):
            if not (math.isfinite(t) and 0.1 <= t <= 256.0):
                raise InputError(f"--wall-texels: expected 0.1 to 256 texels a metre, got {t}")
        for m in (self.max_side, self.outdoor_max_side):
            if not (isinstance(m, int) and 8 <= m <= MAX_IMAGE_SIDE):
                raise InputError(f"--wall-max-side: expected 8 to {MAX_IMAGE_SIDE} texels, got {m!r:.20}")
        for codec in (self.codec, self.outdoor_codec):
            if codec not in IMAGE_MEDIA:
                raise InputError(f"wall codec: expected one of {', '.join(IMAGE_MEDIA)}, got {codec!r}")
        return self

    def record(self) -> dict[str, Any]:
        """What the database's settings record (a change is a different bake)."""
        return {"pitch": self.pitch, "error_deg": self.error_deg, "texels_per_m": self.texels_per_m,
                "max_side": self.max_side, "codec": self.codec,
                # only when asked: a bake without depths records what it always did
                **({"depth_grid": self.depth_grid} if self.depth_grid else {}),
                **self._view_record(), **({"quality": self.quality} if self.quality != 90 else {})}

    def _view_record(self) -> dict[str, Any]:
        return {"view_height": self.view_height, "fov_deg": self.fov_deg} if self.view_height else {}

    def with_texture(self, *, texels: float | None = None, max_side: int | None = None,
                     quality: int | str | None = None) -> WallSettings:
        """These settings with the texture flags (``--wall-texels``, ``--wall-max-side``,
        ``--wall-quality``) set indoors and outdoors alike; ``quality`` ``"lossless"``
        is lossless WebP, a number lossy WebP at that quality; ``None`` leaves a field as it is."""
        out = self
        if texels is not None:
            out = dataclasses.replace(out, texels_per_m=float(texels), outdoor_texels_per_m=float(texels))
        if max_side is not None:
            out = dataclasses.replace(out, max_side=max_side, outdoor_max_side=max_side)
        if quality == "lossless":
            out = dataclasses.replace(out, codec="webp-lossless", outdoor_codec="webp-lossless")
        elif quality is not None:
            out = dataclasses.replace(out, quality=int(quality), outdoor_quality=int(quality), codec="webp",
                                      outdoor_codec="webp")
        return out

    def outdoors(self) -> WallSettings:
        """These settings for a city's rings: the outdoor texture resolution in force."""
        return dataclasses.replace(self, texels_per_m=self.outdoor_texels_per_m, max_side=self.outdoor_max_side,
                                   quality=self.outdoor_quality, codec=self.outdoor_codec)

    def record_outdoors(self) -> dict[str, Any]:
        """What a city's database records (a change is a different bake)."""
        return {"error_deg": self.error_deg, "keep": self.keep, "ring_min": self.ring_min, "region": self.region,
                "texels_per_m": self.outdoor_texels_per_m, "max_side": self.outdoor_max_side,
                "codec": self.outdoor_codec, "quality": self.outdoor_quality, **({"depth_grid": self.depth_grid} if self.depth_grid else {}),
                **self._view_record()}


WallJob = tuple[int, tuple[Any, ...], int, int, tuple[int, ...]]
"""One texture to make: ``(texture id, side row, zone, width, excluded element ids)``;
the side row is :meth:`WallSide.to_row` without textures, the height follows from the width."""


@dataclass
class WallPlan:
    """Every wall side (texture ids filled in), the textures to make, and per portal the
    elements crossing it (kept whole as geometry)."""

    sides: list[WallSide]
    jobs: list[WallJob]
    crossing: dict[int, tuple[int, ...]]


def _depth(outline: np.ndarray, p0: np.ndarray, n: np.ndarray) -> float:
    """How far the cell's outline reaches from the wall line, on the side opposite ``n``."""
    return float(np.max(-((outline - p0) @ n)))


def plan_walls(scene: InteriorScene, layout: RoomLayout, settings: WallSettings) -> WallPlan:
    """The walls' sides, zones and textures (the module docstring); the same on every run,
    so texture ids are the same on resume."""
    alpha = math.radians(settings.error_deg)
    cells = {c.id: c for c in layout.cells}
    objects = [e for e in scene.elements if e.kind not in SHELL_KINDS and len(e.triangles)]
    boxes = np.array([[*e.vertices.min(axis=0), *e.vertices.max(axis=0)] for e in objects]).reshape(-1, 6)
    sides: list[WallSide] = []
    jobs: list[WallJob] = []
    crossing: dict[int, tuple[int, ...]] = {}
    for p in layout.portals:
        if p.kind != "wall":
            continue
        poly = p.polygon
        z0, z1 = float(poly[:, 2].min()), float(poly[:, 2].max())
        bottom = poly[np.isclose(poly[:, 2], z0)][:, :2]
        e0, e1 = bottom[0], bottom[-1]
        length = float(np.hypot(*(e1 - e0)))
        if length < 0.5:
            continue
        u = (e1 - e0) / length
        n = np.array([-u[1], u[0]])
        # objects whose box crosses the wall's plane within the wall: geometry on both sides
        if len(objects):
            t0, t1 = (boxes[:, :2] - e0) @ u, (boxes[:, 3:5] - e0) @ u
            d = np.stack([(boxes[:, [0, 1]] - e0) @ n, (boxes[:, [3, 1]] - e0) @ n,
                          (boxes[:, [0, 4]] - e0) @ n, (boxes[:, [3, 4]] - e0) @ n], axis=1)
            hit = ((d.min(axis=1) < -1e-6) & (d.max(axis=1) > 1e-6) & (np.maximum(t0, t1) > 0)
                   & (np.minimum(t0, t1) < length) & (boxes[:, 5] > z0) & (boxes[:, 2] < z1))
            crossing[p.id] = tuple(sorted(objects[i].id for i in np.flatnonzero(hit)))
        else:
            crossing[p.id] = ()
        for side, (viewer, hidden) in enumerate(((p.a, p.b), (p.b, p.a))):
            a, b = e0, e1
            nn = n
            # the hidden cell to the left of a -> b
            cb = cells[hidden].outline.mean(axis=0)
            if float((cb - a) @ nn) < 0:
                a, b, nn = b, a, -nn
            depth = _depth(cells[viewer].outline, a, nn)
            if depth < 0.5:
                continue
            x_t = depth / 3.0
            zones = zone_count(length, x_t, alpha)
            floor = float(cells[viewer].zmin)
            ws = WallSide(p.id, side, (float(a[0]), float(a[1])), (float(b[0]), float(b[1])), z0, z1, floor,
                          x_t, depth / 16.0, 0.75 * depth, alpha, zones)
            width = texture_width(length, z1 - z0, x_t, 0.75 * depth, settings)
            ids = tuple(range(len(jobs), len(jobs) + zones))
            row = tuple(ws.to_row())
            jobs += [(tid, row, k, width, crossing[p.id]) for k, tid in enumerate(ids)]
            sides.append(dataclasses.replace(ws, textures=ids))
    return WallPlan(sides, jobs, crossing)


def parse_wall_quality(text: str | None) -> int | str | None:
    """``--wall-quality``'s value: ``"lossless"``, a WebP quality 1-100, or None when not
    given; anything else a one-line :class:`InputError`."""
    if text is None:
        return None
    t = str(text).strip().lower()
    if t == "lossless":
        return t
    try:
        q = int(t)
    except ValueError:
        q = 0
    if not 1 <= q <= 100:
        raise InputError(f"--wall-quality: expected 1 to 100 or lossless, got {str(text)!r:.30}")
    return q


WARP_SHARE = 0.5
"""The client's default warp share (``--wall-parallax``, :func:`~walkstream.shared.walls.zone_warp`):
a texture sampled from ``x_s`` is laid ``x_s / (x_s (1 - R) + x R)`` times larger for a
viewer at ``x``, so its texels are that much larger on the screen."""


def texture_width(length: float, tall: float, near: float, sample: float, settings: WallSettings) -> int:
    """Texels across a texture of a wall side ``length`` by ``tall`` metres, first seen as
    texture from ``near`` metres and sampled from ``sample`` metres in front of it.

    With ``settings.view_height`` 0: ``texels_per_m`` a metre.  Otherwise a texel is at
    most a pixel of the target view at ``near``: the view's pixels a metre there
    (:func:`~walkstream.shared.impostors.texels_needed`) times the warp's magnification at
    ``near`` (:data:`WARP_SHARE`; at least 1).  Between 8 and ``max_side``, the height
    (:func:`texture_height`) at most ``max_side`` too."""
    if settings.view_height:
        near = max(near, 0.5)
        k = sample / (sample * (1.0 - WARP_SHARE) + near * WARP_SHARE) if sample > 0 else 1.0
        per_m = float(texels_needed(0.5, near, settings.view_height, settings.fov_deg)) * max(k, 1.0)
    else:
        per_m = settings.texels_per_m
    cap = min(settings.max_side, settings.max_side * length / max(tall, 1e-6))
    return int(max(1, min(cap, max(8, round(length * per_m)))))


def texture_height(side: WallSide, width: int) -> int:
    """Texels of a texture ``width`` wide over the wall's height (its aspect kept)."""
    return max(4, round(width * (side.z1 - side.z0) / max(side.length, 1e-6)))


def whole_crossing(
    parts: dict[int, list[Part]], scene: InteriorScene, layout: RoomLayout, crossing: dict[int, tuple[int, ...]]
) -> dict[int, list[Part]]:
    """Each cell's contents with the objects crossing its virtual walls whole (not
    clipped at the wall): they are drawn as geometry from either side."""
    if not any(crossing.values()):
        return parts
    by_id = {e.id: e for e in scene.elements}
    want: dict[int, set[int]] = {}
    for p in layout.portals:
        for eid in crossing.get(p.id, ()):
            want.setdefault(p.a, set()).add(eid)
            want.setdefault(p.b, set()).add(eid)
    out = dict(parts)
    for cid, eids in want.items():
        kept = [q for q in out.get(cid, []) if q[0] not in eids]
        for eid in sorted(eids):
            e = by_id[eid]
            for m in np.unique(e.materials).tolist():
                v, t = weld(e.soup[e.materials == m])
                kept.append((int(eid), int(m), v, t))
        out[cid] = kept
    return out
