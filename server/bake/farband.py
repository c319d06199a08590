"""The far field at the client's pixel size: a horizon band rendered beside the cube.

What the default bake misses a walker sees is mostly far and small on screen (``walkstream bench
pvs-misses``, docs/benchmarks.md): a sliver of a building 300 m off beside a nearer
facade, a street piece at the horizon, covering a few of the client's pixels (640
over 60 degrees, 10.7 a degree) and under one of the bake's (128 over 90 degrees, 1.4
a degree).  Seen from the eye itself, three quarters of those pixels show at the
client's pixel size and not at the bake's.  Rendering the whole cube at the client's
pixel size costs 75 times the pixels; the far field needs it only near the horizon,
where everything far stands.  With ``far_band`` set, each sample point is rendered a
second time as a horizon band (:meth:`~walkstream.server.bake.faceset.FaceSet.band`):
the four sideways faces, ``far_pixels`` across 90 degrees, ``far_band`` degrees above
and below the horizon.  Everything within the view distance is drawn, the near
occluders too, so the band adds only what is really seen from a sample point, at a
finer pixel.

Two options close what the band still misses on a walk (docs/benchmarks.md, "The band
at the middle of the street"): ``far_axis`` renders the band also at points along each
cell's long axis (:func:`~walkstream.server.bake.workers.band_points`), where a walker
sees far buildings past the near facades that the outline points hug; ``far_edges``
draws the band's triangle edges again after its fill (the renderer's ``edge_pass``),
so a street piece hundreds of metres ahead, thinner than a band pixel, is not lost
between the pixel centres.

An object's pixels in the band count toward its ACH scaled to the cube's pixel size
(``(resolution / far_pixels)**2``), at least one pixel for an object only the band
shows, so that the coverage hints keep the cube's scale.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from walkstream.server.bake.settings import BakeSettings
from walkstream.server.bake.visibility import VisibilityRenderer
from walkstream.shared.arrays import I64
from walkstream.shared.records import Mesh

if TYPE_CHECKING:
    import moderngl

__all__ = ["band_renderer", "merge_band_counts"]


def band_renderer(
    meshes: Sequence[Mesh], ids: I64 | NDArray[np.integer[Any]], settings: BakeSettings,
    ctx: moderngl.Context | None = None,
) -> VisibilityRenderer | None:
    """The band's renderer for ``settings`` (None when ``far_band`` is off)."""
    if not settings.far_band:
        return None
    return VisibilityRenderer(
        meshes, ids, resolution=settings.far_pixels, band=settings.far_band,
        view_distance=settings.view_distance, ctx=ctx, edge_pass=settings.far_edges,
    )


def merge_band_counts(
    ids: I64, pixels: I64, band_ids: I64, band_pixels: I64, settings: BakeSettings
) -> tuple[I64, I64]:
    """The cube's counts with the band's added, scaled to the cube's pixel size.

    Parameters
    ----------
    ids, pixels : (k,) int64
        The cube's ids (ascending) and pixels.
    band_ids, band_pixels : (m,) int64
        The band's.

    Returns
    -------
    ids, pixels : (u,) int64
        Every id either saw, ascending; an id only the band saw has at least 1 pixel.

    >>> s = BakeSettings(resolution=128, far_band=3.0, far_pixels=1280)
    >>> merge_band_counts(np.array([1, 2]), np.array([50, 9]), np.array([2, 7]), np.array([300, 20]), s)
    (array([1, 2, 7]), array([50, 12,  1]))
    """
    scale = (settings.resolution / settings.far_pixels) ** 2
    u = np.union1d(ids, band_ids).astype(np.int64)
    out = np.zeros(len(u), np.int64)
    out[np.searchsorted(u, ids)] += pixels
    out[np.searchsorted(u, band_ids)] += np.maximum(np.rint(band_pixels * scale), 1).astype(np.int64)
    return u, out
