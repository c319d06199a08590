"""What decides a bake's impostor images: D, A, S, N, the target view and the codec.

Kept apart from :class:`~.settings.BakeSettings` on purpose: a bake without
``--impostors`` must write the very settings record (and so the content hash, the
scene version and every ETag) it wrote before impostors existed; with
``--impostors`` the record gains one key, ``impostors``, holding these fields.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

from walkstream.shared.codec.image import IMAGE_CODECS
from walkstream.shared.errors import InputError
from walkstream.shared.impostors import PROJECTIONS

__all__ = [
    "DEFAULT_COMPLEX_TRIANGLES",
    "DEFAULT_IMPOSTOR_DISTANCE",
    "DEFAULT_IMPOSTOR_ERROR",
    "DEFAULT_IMPOSTOR_SIZE",
    "ImpostorSettings",
]

#: D, metres: a building at least this far from every point of a cell is far from it
#: (measured with ``walkstream bake --impostors`` on the demo city: see docs/benchmarks.md)
DEFAULT_IMPOSTOR_DISTANCE = 250.0
#: A, degrees: the largest angle under which a point of an object may move
DEFAULT_IMPOSTOR_ERROR = 2.0
#: S, texels: the largest image side (the paper's PocketGL limit, 128)
DEFAULT_IMPOSTOR_SIZE = 128
#: N: buildings with more triangles than this at LOD2 are impostors wherever the bound allows
DEFAULT_COMPLEX_TRIANGLES = 12000


@dataclass(frozen=True, slots=True)
class ImpostorSettings:
    """Everything that decides a bake's impostor images (part of its settings record)."""

    distance: float = DEFAULT_IMPOSTOR_DISTANCE
    error_deg: float = DEFAULT_IMPOSTOR_ERROR
    size: int = DEFAULT_IMPOSTOR_SIZE
    complex_triangles: int = DEFAULT_COMPLEX_TRIANGLES
    view_height: int = 480
    """Height of the target view, pixels (the client's default 640 x 480)."""
    fov_deg: float = 60.0
    """Vertical field of view of the target view, degrees (the client's default)."""
    codec: str = "webp-lossless"
    quality: int = 90
    """Quality of the lossy codecs (``webp``, ``avif``)."""
    sampling: str = "point"
    """How a texel is sampled: ``point`` (its centre, as the truth samples a pixel) or
    ``area`` (the mean of 2 x 2 samples); :mod:`~.impostorrender`."""
    projection: str = "ortho"
    """How an image is projected (:data:`~walkstream.shared.impostors.PROJECTIONS`):
    ``ortho`` along its bin's direction, or ``perspective`` from its level's sampling
    eye (:func:`~walkstream.shared.impostors.eye_distance`)."""

    def check(self) -> ImpostorSettings:
        """Raise InputError naming the first bad setting."""
        if not (math.isfinite(self.distance) and self.distance > 0):
            raise InputError(f"--impostor-distance: expected a positive number of metres, got {self.distance}")
        if not (math.isfinite(self.error_deg) and 0 < self.error_deg < 45):
            raise InputError(f"--impostor-error: expected 0 < degrees < 45, got {self.error_deg}")
        if self.size < 8 or self.size > 1024 or self.size & (self.size - 1):
            raise InputError(f"--impostor-size: expected a power of two 8..1024, got {self.size}")
        if self.complex_triangles < 1:
            raise InputError(f"--complex-triangles: expected >= 1, got {self.complex_triangles}")
        if self.codec not in IMAGE_CODECS:
            raise InputError(f"impostor codec {self.codec!r}: expected one of {', '.join(IMAGE_CODECS)}")
        if self.sampling not in ("point", "area"):
            raise InputError(f"--impostor-sampling: expected point or area, got {self.sampling!r}")
        if self.projection not in PROJECTIONS:
            raise InputError(f"--impostor-projection: expected one of {', '.join(PROJECTIONS)}, got {self.projection!r}")
        if not 1 <= self.quality <= 100:
            raise InputError(f"impostor quality: expected 1..100, got {self.quality}")
        if self.view_height < 1 or not 0 < self.fov_deg < 180:
            raise InputError("impostor target view: expected a height >= 1 and 0 < fov < 180")
        return self

    def record(self) -> dict[str, Any]:
        """The fields as they enter the bake's settings record (``projection`` only when
        not ``ortho``: an orthographic bake writes the record, and so the scene version
        and every ETag, it wrote before the choice existed)."""
        out = asdict(self)
        if out["projection"] == "ortho":
            del out["projection"]
        return out
