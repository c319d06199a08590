"""The dense reference of ``walkstream bench visibility``, kept on disk between runs.

The reference (64 points per cell at 512 px, no culling) takes a minute per cell on
llvmpipe; its counts depend only on what it draws and from where, so they are stored
per cell under a key of the scene's LOD2 meshes, the cell's reference points, the
resolution and the view distance.
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from walkstream.shared.arrays import I64
from walkstream.shared.records import Mesh

__all__ = ["scene_digest", "reference_cache_key", "default_cache_dir"]


def scene_digest(meshes: Sequence[Mesh], ids: I64) -> str:
    """A digest of what the reference renders: every mesh's vertices and triangles and its id."""
    h = hashlib.sha256(np.ascontiguousarray(ids, np.int64).tobytes())
    for m in meshes:
        h.update(np.ascontiguousarray(m.positions, np.float32).tobytes())
        h.update(np.ascontiguousarray(m.indices, np.uint32).tobytes())
    return h.hexdigest()


def reference_cache_key(digest: str, points: NDArray[np.float64], resolution: int, view_distance: float) -> str:
    """The file name (no suffix) of one cell's reference counts.

    Parameters
    ----------
    digest:
        :func:`scene_digest` of the scene's LOD2 meshes and ids (what the reference draws).
    points : (p, 3) float
        The cell's reference viewpoints (they follow from the cell, its height range,
        the footprints and the seed, so they stand for all of them).
    resolution, view_distance:
        Cube-face pixels and far plane of the reference.
    """
    h = hashlib.sha256(f"visref-1|{digest}|{int(resolution)}|{float(view_distance)!r}|".encode())
    h.update(np.ascontiguousarray(points, np.float64).tobytes())
    return h.hexdigest()[:32]


def default_cache_dir() -> Path:
    """Where ``bench visibility`` keeps reference counts: ``$XDG_CACHE_HOME/walkstream/visibility-reference``."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "walkstream" / "visibility-reference"
