"""The dense visibility field (Brosnan et al., section 3): a full spin at every point of a 2D lattice.

A lattice of points every ``spacing`` metres is laid over the scene; a point is a
*field point* when its square (the ``spacing`` x ``spacing`` square around it) holds
free space, i.e. space outside every building footprint grown by the bake's wall
margin.  Every field point is rendered where it stands, or, when it stands inside a
building, at a point of its square's free part (so no sample is ever taken inside a
building, and every bit of free space lies in some field point's square).  At each
field point the bake's ID renderer (:class:`~.visibility.VisibilityRenderer`, the
one the PVS cells use, on a real GPU as well) renders the six faces of a cube at
two eye heights, the eye height and the top of the eye range: a full spin up and
down.  Each point keeps its visible set with the pixels each object covers
(:class:`PointSets`, compressed sparse rows: 8 bytes per (point, object) pair).

The field is rendered in blocks of points by the one chunk runner
(:func:`~.chunks.run_chunks`: this process, local processes or Dask); every block is
saved to the field's folder as it comes (``<database>.field/<key>/``), so a killed
bake resumes with the blocks done, and a bake of the same scene with other section
settings (``--redundancy``, ``--min-size``) reuses the whole field.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import shapely
from numpy.typing import NDArray

from walkstream.server.bake.chunks import run_chunks
from walkstream.server.bake.settings import BakeSettings
from walkstream.server.bake.workers import field_task, release_renderer
from walkstream.server.sources.scene import SourceScene
from walkstream.shared.arrays import F64, I64
from walkstream.shared.errors import InputError

__all__ = [
    "FIELD_BLOCK",
    "FIELD_HEIGHTS",
    "FieldLattice",
    "PointSets",
    "bake_field",
    "built_space",
    "field_folder",
    "field_lattice",
    "lattice_from",
    "points_meeting",
    "rotate_xy",
]

FIELD_BLOCK = 64
"""Field points per task (and per saved block)."""

FIELD_HEIGHTS = (1.7, 2.0)
"""The heights every field point is rendered at: the eye height and the top of the eye range."""

_MAX_POINTS = 4_000_000


@dataclass(frozen=True)
class FieldLattice:
    """The field points of a scene: lattice positions and where each is rendered.

    Attributes
    ----------
    origin : (x0, y0)
        Scene-local position of lattice point ``(0, 0)``.
    spacing : float
        Metres between lattice points.
    shape : (ny, nx)
        Lattice rows (y) and columns (x).
    index : (n,) int64
        Each field point's lattice position, ``row * nx + col``, ascending.
    eyes : (n, 2) float64
        Where each field point is rendered (the point itself when it is free).
    heights : (2,) float64
        The eye heights every point is rendered at.
    angle : float
        The lattice's rows run at this angle (radians, counter-clockwise) to the
        scene's x axis: ``origin``, ``spacing`` and ``shape`` are in the lattice's own
        frame, the scene rotated by ``-angle`` about (0, 0); ``eyes`` and :meth:`xy`
        are in the scene's.
    """

    origin: tuple[float, float]
    spacing: float
    shape: tuple[int, int]
    index: I64
    eyes: F64
    heights: tuple[float, float]
    angle: float = 0.0

    def __len__(self) -> int:
        return len(self.index)

    def grid(self) -> I64:
        """``(ny, nx)`` field point number of every lattice position, ``-1`` where none."""
        g = np.full(self.shape[0] * self.shape[1], -1, np.int64)
        g[self.index] = np.arange(len(self.index))
        return g.reshape(self.shape)

    def xy(self) -> F64:
        """``(n, 2)`` lattice position of every field point, scene-local metres."""
        r, c = np.divmod(self.index, self.shape[1])
        out: F64 = np.stack([self.origin[0] + c * self.spacing, self.origin[1] + r * self.spacing], axis=1)
        return self.to_scene(out)

    def subset(self, keep: NDArray[np.bool_]) -> FieldLattice:
        """The same lattice with only the field points ``keep`` (``(n,)`` bool) says."""
        k = np.asarray(keep, bool)
        return FieldLattice(self.origin, self.spacing, self.shape, self.index[k], self.eyes[k], self.heights, self.angle)

    def to_scene(self, xy: F64) -> F64:
        """``(n, 2)`` points of the lattice's frame in the scene's (rotated by :attr:`angle`)."""
        return rotate_xy(xy, self.angle)


@dataclass(frozen=True)
class PointSets:
    """Every field point's visible set with pixel counts, as compressed sparse rows.

    Point ``k`` sees objects ``ids[offsets[k]:offsets[k + 1]]`` (ascending), covering
    ``pixels[...]`` pixels over its images.
    """

    offsets: I64
    ids: I64
    pixels: I64

    def __len__(self) -> int:
        return len(self.offsets) - 1

    def of(self, k: int) -> tuple[I64, I64]:
        """``(ids, pixels)`` of point ``k``."""
        a, b = int(self.offsets[k]), int(self.offsets[k + 1])
        return self.ids[a:b], self.pixels[a:b]

    def union(self, points: I64) -> tuple[I64, I64]:
        """``(ids, pixels)``: the objects any of ``points`` sees (ascending), pixels summed."""
        pts = np.asarray(points, np.int64)
        if len(pts) == 0:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        a, b = self.offsets[pts], self.offsets[pts + 1]
        lens = b - a
        take = np.repeat(a - np.cumsum(lens) + lens, lens) + np.arange(int(lens.sum()))
        u, inv = np.unique(self.ids[take], return_inverse=True)
        px = np.bincount(inv.reshape(-1), weights=self.pixels[take], minlength=len(u)).astype(np.int64)
        return u.astype(np.int64), px

    def sizes(self) -> I64:
        """``(n,)`` objects each point sees."""
        out: I64 = np.diff(self.offsets)
        return out

    @property
    def nbytes(self) -> int:
        """Bytes of the compact store (int32 ids and uint32 pixels, int64 offsets)."""
        return 8 * len(self.ids) + 8 * len(self.offsets)


def field_lattice(
    scene: SourceScene,
    spacing: float,
    heights: tuple[float, float],
    *,
    margin: float = 0.3,
    bbox: tuple[float, float, float, float] | None = None,
    within: shapely.Geometry | None = None,
    angle: float = 0.0,
) -> FieldLattice:
    """The field points of ``scene`` every ``spacing`` metres (see the module docstring).

    The lattice covers ``bbox`` (default: the bounding box of the buildings and the
    street pieces) from its lower-left corner.  With ``within`` (the view cells a
    field samples, ``--sampling field``) the lattice is anchored at whole multiples
    of ``spacing`` instead, so that a cell's field points do not depend on the rest
    of the scene, and only the points whose square meets ``within`` are kept.

    With ``angle`` (radians) the lattice's rows run at that angle to the x axis
    (sections aligned to the streets): it is laid in the scene rotated by ``-angle``
    over the rotated box of ``bbox`` (or of the scene), keeping the points whose
    squares meet that box.

    Raises
    ------
    InputError
        A bad spacing, an empty scene without ``bbox``, or a lattice too large.
    """
    if not angle:
        return lattice_from(_built(scene, margin), spacing, heights, bbox=bbox if within is None else None,
                            within=within, scene=scene)
    if within is not None:
        raise InputError("field lattice: a rotated lattice is laid over the scene's box, not over cells")
    if bbox is None:
        rings = [b.rings[0] for b in scene.buildings] + [st.ring for st in scene.streets]
        if not rings:
            raise InputError(f"scene {scene.name!r} has no buildings or streets: give a bbox")
        pts = np.concatenate(rings)
        bbox = (*pts.min(axis=0), *pts.max(axis=0))
    box = shapely.Polygon(rotate_xy(np.asarray(shapely.box(*bbox).exterior.coords)[:-1], -angle))
    blocked = _built(scene, margin)
    if blocked is not None:
        blocked = shapely.transform(blocked, lambda xy: rotate_xy(xy, -angle))
        shapely.prepare(blocked)
    lat = lattice_from(blocked, spacing, heights, within=box)
    return FieldLattice(lat.origin, lat.spacing, lat.shape, lat.index, rotate_xy(lat.eyes, angle), lat.heights, float(angle))


def rotate_xy(xy: F64, angle: float) -> F64:
    """``(n, 2)`` points rotated by ``angle`` radians (counter-clockwise) about (0, 0)."""
    pts = np.asarray(xy, np.float64)
    if not angle:
        return pts
    c, s = math.cos(angle), math.sin(angle)
    out: F64 = np.column_stack([c * pts[:, 0] - s * pts[:, 1], s * pts[:, 0] + c * pts[:, 1]])
    return out


def lattice_from(
    blocked: shapely.Geometry | None,
    spacing: float,
    heights: tuple[float, float],
    *,
    bbox: tuple[float, float, float, float] | None = None,
    within: shapely.Geometry | None = None,
    scene: SourceScene | None = None,
) -> FieldLattice:
    """:func:`field_lattice` given the built space ``blocked`` (footprints grown by the margin).

    One of ``bbox``, ``within`` or ``scene`` (its bounding box) places the lattice.
    """
    s = float(spacing)
    if not (math.isfinite(s) and s > 0):
        raise InputError(f"--field-spacing: expected a positive number of metres, got {spacing}")
    if within is not None:
        if shapely.is_empty(within):
            raise InputError("the field's cells are empty: no free space to sample")
        bx0, by0, bx1, by1 = shapely.bounds(within)
        # whole multiples of the spacing: the squares that meet the region's box
        x0, y0 = math.floor(bx0 / s + 0.5) * s, math.floor(by0 / s + 0.5) * s
        x1, y1 = math.ceil(bx1 / s - 0.5) * s, math.ceil(by1 / s - 0.5) * s
    elif bbox is None:
        if scene is None:
            raise InputError("field lattice: give a scene, a bbox or the cells")
        rings = [b.rings[0] for b in scene.buildings] + [st.ring for st in scene.streets]
        if not rings:
            raise InputError(f"scene {scene.name!r} has no buildings or streets: give a bbox")
        pts = np.concatenate(rings)
        (x0, y0), (x1, y1) = pts.min(axis=0), pts.max(axis=0)
    else:
        x0, y0, x1, y1 = (float(v) for v in bbox)
    nx = int(math.floor((x1 - x0) / s + 1e-9)) + 1
    ny = int(math.floor((y1 - y0) / s + 1e-9)) + 1
    if nx * ny > _MAX_POINTS:
        raise InputError(f"--field-spacing {s:g}: a lattice of {nx} x {ny} points is too large; space it wider")
    r, c = np.divmod(np.arange(nx * ny, dtype=np.int64), nx)
    x, y = x0 + c * s, y0 + r * s
    eyes = np.stack([x, y], axis=1)
    keep = np.ones(nx * ny, bool)
    if within is not None:
        keep &= _meets(within, x, y, s)
    # a point renders where it stands when that is free (and, with cells, in them);
    # else at a point of the free part of its square, or not at all
    stay = keep.copy()
    if blocked is not None:
        stay &= ~shapely.contains_xy(blocked, x, y)
    if within is not None:
        stay &= shapely.intersects_xy(within, x, y)
    todo = np.flatnonzero(keep & ~stay)
    if len(todo):
        h = s / 2.0
        free = shapely.box(x[todo] - h, y[todo] - h, x[todo] + h, y[todo] + h)
        if within is not None:
            free = shapely.intersection(free, within)
        if blocked is not None:
            free = shapely.difference(free, blocked)
        ok = ~shapely.is_empty(free) & (shapely.area(free) > 1e-6 * s * s)
        if ok.any():
            # a point of the free part that lies inside it (a polygon's representative point)
            eyes[todo[ok]] = shapely.get_coordinates(shapely.point_on_surface(free[ok]))
        stay[todo[ok]] = True
    idx = np.flatnonzero(stay).astype(np.int64)
    return FieldLattice((float(x0), float(y0)), s, (ny, nx), idx, eyes[idx], (float(heights[0]), float(heights[1])))


def _meets(region: shapely.Geometry, x: F64, y: F64, s: float) -> NDArray[np.bool_]:
    """Whether each lattice point's square meets ``region`` in more than an edge or a corner.

    A point exactly on the region's outline (its square straddles it) meets it; a
    square that only touches the outline does not (a hair shrunk, so the test does
    not hang on rounding).
    """
    h = s / 2.0 - 1e-7 * s
    squares = shapely.box(x - h, y - h, x + h, y + h)
    shapely.prepare(region)
    out: NDArray[np.bool_] = shapely.intersects(region, squares)
    return out


def points_meeting(lattice: FieldLattice, region: shapely.Geometry) -> NDArray[np.bool_]:
    """``(n,)`` whether each field point's square meets ``region`` (scene-local) in more
    than an edge or a corner (a turned lattice's squares are turned with it)."""
    r, c = np.divmod(lattice.index, lattice.shape[1])
    x = lattice.origin[0] + c * lattice.spacing
    y = lattice.origin[1] + r * lattice.spacing
    if lattice.angle:
        region = shapely.transform(region, lambda xy: rotate_xy(xy, -lattice.angle))
    return _meets(region, x.astype(np.float64), y.astype(np.float64), lattice.spacing)


def built_space(footprints: Sequence[shapely.Geometry], margin: float) -> shapely.Geometry | None:
    """The footprints' union grown by ``margin`` (where no field point is rendered), prepared."""
    if not len(footprints):
        return None
    u = shapely.union_all(shapely.make_valid(np.array(list(footprints), dtype=object)))
    grown = shapely.buffer(u, float(margin), quad_segs=2) if margin > 0 else u
    shapely.prepare(grown)
    return grown


def _built(scene: SourceScene, margin: float) -> shapely.Geometry | None:
    return built_space([shapely.Polygon(b.rings[0], b.rings[1:]) for b in scene.buildings], margin)


def field_folder(output: str | os.PathLike[str], key: str) -> Path:
    """Where the field of a bake of ``output`` keeps its blocks: ``<output>.field/<key>``."""
    return Path(os.fspath(output) + ".field") / key


def bake_field(
    lattice: FieldLattice,
    scene: SourceScene,
    settings: BakeSettings,
    key: str,
    folder: Path,
    *,
    workers: int = 1,
    scheduler: str | None = None,
    progress: Callable[[int, int], None] | None = None,
    max_points: int | None = None,
) -> PointSets | None:
    """Render the field of ``lattice`` (resuming the blocks saved in ``folder``).

    Parameters
    ----------
    lattice, scene, settings:
        The field points, the scene and the renderer's settings (resolution,
        occluder LOD, view distance, edge pass).
    key:
        Names the scene and those settings (a worker keeps its renderer while it stays).
    folder:
        Where each block is saved as it comes (:func:`field_folder`).
    workers, scheduler:
        As :func:`~.chunks.run_chunks`.
    progress:
        Called with ``(points done, points total)``.
    max_points:
        Stop after about this many new points (for tests of interruption and resume);
        None is returned then.

    Returns
    -------
    PointSets or None
        The field, or None when ``max_points`` stopped it first.
    """
    folder.mkdir(parents=True, exist_ok=True)
    n = len(lattice)
    blocks = [(b, lattice.eyes[s : s + FIELD_BLOCK]) for b, s in enumerate(range(0, n, FIELD_BLOCK))]
    done = {b for b, _ in blocks if (folder / f"{b:06d}.npz").exists()}
    todo = [(b, e, lattice.heights) for b, e in blocks if b not in done]
    if max_points is not None:
        todo = todo[: max(0, math.ceil(max_points / FIELD_BLOCK))]
    done_points = sum(len(e) for b, e in blocks if b in done)
    count = done_points
    if progress is not None:
        progress(count, n)
    for results in run_chunks(field_task, todo, (scene, settings, key), size=1, workers=workers,
                              scheduler=scheduler, release=release_renderer):
        for b, offsets, ids, pixels in results:
            tmp = folder / f"{b:06d}.tmp.npz"
            np.savez_compressed(tmp, offsets=offsets, ids=ids, pixels=pixels)
            os.replace(tmp, folder / f"{b:06d}.npz")
            done.add(b)
            count += len(offsets) - 1
        if progress is not None:
            progress(count, n)
    if len(done) < len(blocks):
        return None
    return _load(folder, len(blocks))


def _load(folder: Path, blocks: int) -> PointSets:
    offs, ids, pix = [np.zeros(1, np.int64)], [], []
    base = 0
    for b in range(blocks):
        with np.load(folder / f"{b:06d}.npz") as z:
            o = z["offsets"].astype(np.int64)
            offs.append(o[1:] + base)
            base += int(o[-1])
            ids.append(z["ids"].astype(np.int64))
            pix.append(z["pixels"].astype(np.int64))
    return PointSets(np.concatenate(offs), np.concatenate(ids) if ids else np.zeros(0, np.int64),
                     np.concatenate(pix) if pix else np.zeros(0, np.int64))
