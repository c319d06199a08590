"""View cells: the regions of the navigation space that each get one baked PVS.

:func:`make_cells` picks the partition a scene gets: street cells
(:mod:`.streetcells`) where the scene has streets, else grid cells
(:mod:`.gridcells`).  A new kind of cell is a module beside them and a branch here.
"""

from __future__ import annotations

from walkstream.server.bake.gridcells import grid_cells
from walkstream.server.bake.streetcells import street_cells
from walkstream.server.bake.viewcell import ViewCell
from walkstream.server.sources.scene import SourceScene
from walkstream.shared.errors import InputError

__all__ = ["make_cells"]


def make_cells(
    scene: SourceScene,
    mode: str = "auto",
    *,
    max_length: float = 40.0,
    cell_size: float = 40.0,
    eye_height: float = 1.7,
    height_range: tuple[float, float] = (1.5, 2.0),
    min_free: float = 0.15,
    bbox: tuple[float, float, float, float] | None = None,
) -> list[ViewCell]:
    """View cells of a scene: street cells or grid cells.

    Parameters
    ----------
    scene:
        The scene.
    mode:
        ``"street"`` (:func:`street_cells`), ``"grid"`` (:func:`grid_cells`) or
        ``"auto"``: street cells when the scene has street pieces, else grid cells.
    max_length, eye_height:
        Passed to :func:`street_cells`.
    cell_size, min_free, bbox:
        Passed to :func:`grid_cells`.
    height_range:
        Passed to both.

    Raises
    ------
    InputError
        For an unknown mode, ``"street"`` on a scene without street data, or a
        parameter out of range.
    """
    if mode not in ("auto", "street", "grid"):
        raise InputError(f"cell mode must be 'auto', 'street' or 'grid', got {mode!r}")
    if mode == "street" or (mode == "auto" and scene.streets):
        return street_cells(
            scene, max_length=max_length, eye_height=eye_height, height_range=height_range
        )
    return grid_cells(
        scene, cell_size=cell_size, height_range=height_range, min_free=min_free, bbox=bbox
    )
