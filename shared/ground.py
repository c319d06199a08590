"""The ground plane under a scene with outdoor space: its height, its colour, its quad.

Every city source puts the ground at the scene's datum, ``z = 0``
(:data:`GROUND_Z`): buildings stand on it and streets lie
:data:`~walkstream.shared.streets.STREET_Z` above it.  There is no terrain model, so
the plane is flat.  The client's renderer (:class:`~walkstream.client.draw.meshes.MeshRenderer`)
and the ground truth (:class:`~walkstream.client.truth.render.TruthRenderer`) draw the
same plane, each with its own shader, in the ``ground`` material of the palette.

The plane is not an object: it has no id, is never streamed and never in a PVS.  Both
renderers draw it right after the clear with the depth test off (so it writes no
depth) and everything else over it; where it shows, the object-id images read 0
(nothing), as the sky did.  So it hides nothing, never fights with a street or an
area in depth, and leaves every id comparison (perfect frames, missing pixels by
cause) as it was: only the colour below the horizon changes, from the sky's to the
ground's.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["GROUND_MATERIAL", "GROUND_Z", "ground_quad"]

#: Height of the ground plane, metres: the scene's datum, where the sources put the ground.
GROUND_Z = 0.0

#: Palette id of the ground's colour (:data:`~walkstream.shared.palette.MATERIALS`).
GROUND_MATERIAL = 20


def ground_quad(eye: ArrayLike, reach: float, z: float = GROUND_Z) -> NDArray[np.float32]:
    """The plane's four corners around the eye, counter-clockwise seen from above.

    Parameters
    ----------
    eye : (3,) float
        The camera position; the quad is centred under it.
    reach : float
        Half the quad's side, metres: twice the far plane covers whatever a frame
        can see, in any direction, however wide its field of view.
    z : float
        The plane's height.

    Returns
    -------
    (4, 3) float32
        Corners; triangles ``(0, 1, 2)`` and ``(0, 2, 3)`` face up.
    """
    e = np.asarray(eye, np.float64).reshape(3)
    r = float(reach)
    xy = e[:2] + np.array([[-r, -r], [r, -r], [r, r], [-r, r]])
    return np.column_stack([xy, np.full(4, float(z))]).astype(np.float32)
