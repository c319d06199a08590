"""Material colours shared by the client renderer and the glTF export.

Material ids are the ``Mesh.materials`` values written by the building grammar and
the street builder.  The table is plain data so that the renderer, the exporter and
any report draw a given material in the same colour.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["MATERIALS", "PALETTE", "UNKNOWN_RGB", "material_name", "material_rgb"]

#: ``(id, name, (r, g, b))`` per material id, sRGB 0-255; the id is the row index.
MATERIALS: tuple[tuple[int, str, tuple[int, int, int]], ...] = (
    (0, "wall", (222, 204, 170)),  # warm beige
    (1, "window", (72, 86, 102)),  # dark blue-grey
    (2, "door", (112, 74, 46)),  # brown
    (3, "roof", (116, 84, 82)),  # dark red-grey
    (4, "ledge", (204, 204, 200)),  # ledge / cornice: light grey
    (5, "street", (92, 94, 98)),  # asphalt grey
    (6, "crossroad", (110, 110, 116)),  # a slightly different grey, so junctions read
    (7, "square", (200, 186, 158)),  # paving beige
    (8, "party_wall", (192, 174, 142)),  # slightly darker than a wall
    # interiors (IFC elements and generated interiors): light surfaces, darker fittings
    (9, "floor", (181, 150, 112)),  # wooden floor, seen from above
    (10, "ceiling", (240, 238, 232)),  # the underside of a slab
    (11, "inner_wall", (236, 229, 214)),  # partition and inner wall faces
    (12, "slab", (188, 186, 180)),  # slab edges, foundations
    (13, "furniture", (146, 104, 66)),  # desks, shelves, cabinets
    (14, "fabric", (76, 96, 138)),  # chairs, sofas, beds
    (15, "stair", (160, 160, 168)),  # treads and stringers
    (16, "glass", (156, 196, 214)),  # window panes (drawn opaque)
    (17, "frame", (246, 246, 240)),  # door and window frames
    (18, "metal", (104, 106, 112)),  # railings, beams, members
    (19, "fixture", (214, 218, 222)),  # sanitary and kitchen fittings, coverings
    # the ground plane under a scene with outdoor space (shared/ground.py)
    (20, "ground", (146, 156, 118)),  # dry grass and earth, darker than any paving
    # typed areas on the ground (shared/areas.py), one per area kind
    (21, "area_built", (178, 170, 160)),  # residential, commercial, industrial land: pale grey-brown
    (22, "area_farmland", (196, 190, 128)),  # fields, orchards, allotments
    (23, "area_grass", (122, 170, 92)),  # parks, lawns, meadows
    (24, "area_wood", (72, 122, 70)),  # forest, wood, scrub
    (25, "area_sport", (150, 186, 120)),  # pitches, tracks
    (26, "area_sand", (222, 206, 160)),  # sand, beach, bare rock
    (27, "area_parking", (150, 150, 156)),  # parking: lighter than the street
    (28, "area_pedestrian", (206, 196, 182)),  # plazas and pedestrian areas
    (29, "area_water", (104, 150, 204)),  # lakes, rivers, ponds
)

#: Colour of a material id outside the table: loud magenta, so that a grammar bug
#: shows up in a picture instead of passing as a plausible grey.
UNKNOWN_RGB: tuple[int, int, int] = (255, 0, 255)


def _table() -> NDArray[np.uint8]:
    # 256 rows so any uint8 id indexes without a bounds check; unknown ids get magenta.
    t = np.empty((256, 3), np.uint8)
    t[:] = UNKNOWN_RGB
    for i, (mid, _, rgb) in enumerate(MATERIALS):
        assert mid == i, "MATERIALS must be listed in id order"
        t[mid] = rgb
    t.flags.writeable = False
    return t


#: ``(256, 3) uint8`` read-only lookup table: ``PALETTE[material_id]`` is its sRGB colour.
PALETTE: NDArray[np.uint8] = _table()


def material_rgb(materials: ArrayLike) -> NDArray[np.uint8]:
    """Colours of material ids.

    Parameters
    ----------
    materials : (n,) integer array
        Material ids (``Mesh.materials``).  Ids outside 0..255 or not in
        :data:`MATERIALS` get :data:`UNKNOWN_RGB`.

    Returns
    -------
    (n, 3) uint8
        sRGB colour per id (a new, writable array).
    """
    m = np.asarray(materials).reshape(-1).astype(np.int64)
    out = PALETTE[np.clip(m, 0, 255)]  # fancy indexing copies, so the result is writable
    out[(m < 0) | (m > 255)] = UNKNOWN_RGB
    return out


def material_name(material_id: int) -> str:
    """Name of a material id (``"unknown"`` when it is not in :data:`MATERIALS`)."""
    if 0 <= material_id < len(MATERIALS):
        return MATERIALS[material_id][1]
    return "unknown"
