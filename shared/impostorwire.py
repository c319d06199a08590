"""A cell's impostors on the wire: the objects it draws as images, by direction bin.

cell ``imp`` (optional field of a cell record, :mod:`walkstream.shared.wire`)
    ``{d, a, rows, p?}``: the bake's distance ``d`` (centimetres) and error bound
    ``a`` (microradians) the client blends by, ``p: 1`` for perspective images
    (absent: orthographic), and one row per object,
    ``[object, level, az0, n_az, el0, n_el, minx, ..., maxz, image ids...]`` (the box
    in centimetres).  Absent from a cell without impostors, so such a record's bytes
    are what they were before impostors existed.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from walkstream.shared.errors import CodecError
from walkstream.shared.impostors import eye_distance

__all__ = ["ImpostorRow", "CellImpostors", "impostors_from_wire"]


@dataclass(frozen=True, slots=True)
class ImpostorRow:
    """One object a cell draws as an impostor, and its images by direction bin.

    The images of azimuth bins ``az0 .. az0 + n_az - 1`` (modulo the level's count)
    and elevation bins ``el0 .. el0 + n_el - 1`` at ``level``
    (:mod:`walkstream.shared.impostors`): ``images[j * n_az + i]``.  ``box`` is the
    object's ``(minx, miny, minz, maxx, maxy, maxz)`` (metres): the bake measured the
    distance D to its footprint, and its bounding sphere places the quad.
    On the wire: ``[object, level, az0, n_az, el0, n_el, minx, ..., maxz, ids...]``,
    the box in centimetres.
    """

    object: int
    level: int
    az0: int
    n_az: int
    el0: int
    n_el: int
    box: tuple[float, float, float, float, float, float]
    images: tuple[int, ...]

    @property
    def centre(self) -> tuple[float, float, float]:
        """The centre of the box (and of the bounding sphere)."""
        b = self.box
        return ((b[0] + b[3]) / 2.0, (b[1] + b[4]) / 2.0, (b[2] + b[5]) / 2.0)

    @property
    def radius(self) -> float:
        """The bounding sphere's radius: half the box's diagonal."""
        b = self.box
        return float(np.linalg.norm(np.subtract(b[3:], b[:3]))) / 2.0

    def to_wire(self) -> list[int]:
        """The row as sent."""
        cm = [int(round(v * 100.0)) for v in self.box]
        return [self.object, self.level, self.az0, self.n_az, self.el0, self.n_el, *cm, *self.images]

    def image_for(self, ia: int, ie: int) -> int | None:
        """The image of bin ``(ia, ie)`` at :attr:`level`, or None when the cell lists no image for it."""
        n = 8 << self.level  # azimuth bins at the level (shared/impostors.py: 45 degrees / 2**level)
        i, j = (ia - self.az0) % n, ie - self.el0
        if 0 <= i < self.n_az and 0 <= j < self.n_el:
            return self.images[j * self.n_az + i]
        return None


_MAX_IMPOSTOR_LEVEL = 16


def _impostor_row(row: Any, what: str) -> ImpostorRow:
    """An :class:`ImpostorRow` from its wire list, checked."""
    if not isinstance(row, list) or len(row) < 13 or not all(type(v) is int for v in row):
        raise CodecError(f"{what}: an impostor row is not a list of at least 13 integers")
    oid, level, az0, n_az, el0, n_el = row[:6]
    box = tuple(v / 100.0 for v in row[6:12])
    images = tuple(row[12:])
    if oid < 0 or not 0 <= level <= _MAX_IMPOSTOR_LEVEL or min(az0, el0) < 0 or min(n_az, n_el) < 1:
        raise CodecError(f"{what}: impostor row of object {oid}: bad bins")
    if n_az * n_el != len(images) or min(images) < 1 or any(box[k + 3] < box[k] for k in range(3)):
        raise CodecError(f"{what}: impostor row of object {oid}: {len(images)} images for {n_az} x {n_el} bins")
    return ImpostorRow(oid, level, az0, n_az, el0, n_el, box, images)


@dataclass(frozen=True, slots=True)
class CellImpostors:
    """What a cell draws as impostors: the rows, and the bake's distance ``d`` (metres)
    and error bound ``bound`` (radians) the client blends by, and how the images are
    projected (``perspective``: from each level's sampling eye, which the client places
    its quads by; :mod:`walkstream.shared.impostors`).
    On the wire: ``{"d": centimetres, "a": microradians, "rows": [...]}``, with ``"p": 1``
    for perspective images (absent: orthographic, as every record before)."""

    d: float
    bound: float
    rows: tuple[ImpostorRow, ...]
    perspective: bool = False

    def to_wire(self) -> dict[str, Any]:
        """The record's ``imp`` as sent."""
        out: dict[str, Any] = {"d": int(round(self.d * 100.0)), "a": int(round(self.bound * 1e6)),
                               "rows": [r.to_wire() for r in self.rows]}
        if self.perspective:
            out["p"] = 1
        return out

    def eye(self, row: ImpostorRow) -> float:
        """The sampling eye's distance (metres from the centre) of ``row``'s images:
        infinite for orthographic ones."""
        if not self.perspective:
            return math.inf
        return _eye_of(math.dist(row.box[:3], row.box[3:]) / 2.0, row.level, self.bound, self.d)


@functools.lru_cache(maxsize=4096)
def _eye_of(radius: float, level: int, bound: float, d: float) -> float:
    """:func:`~walkstream.shared.impostors.eye_distance` of one image, kept (the client asks every frame)."""
    return float(eye_distance(radius, level, bound, d))


def impostors_from_wire(obj: Any, what: str) -> CellImpostors | None:
    """A record's ``imp`` (None when absent), checked."""
    if obj is None:
        return None
    if not isinstance(obj, dict) or set(obj) - {"p"} != {"d", "a", "rows"}:
        raise CodecError(f"{what}: imp is not a map of d, a, rows and an optional p")
    d, a, rows, p = obj["d"], obj["a"], obj["rows"], obj.get("p", 0)
    if type(d) is not int or type(a) is not int or d <= 0 or a <= 0 or not isinstance(rows, list):
        raise CodecError(f"{what}: imp: d and a must be positive integers and rows a list")
    if p not in (0, 1) or type(p) is not int:
        raise CodecError(f"{what}: imp: p must be 1 (perspective images) or absent")
    return CellImpostors(d / 100.0, a / 1e6, tuple(_impostor_row(r, what) for r in rows), p == 1)
