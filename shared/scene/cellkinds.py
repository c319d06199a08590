"""Every kind of view cell, each with its visibility model: one table both sides read.

A scene is cells and contents.  What a viewer standing in a cell may see is found in
one of two ways, and which one is a property of the cell's kind, not of the scene:

* ``pvs``: baked.  The bake renders ID buffers from sample points in the cell and keeps
  the objects seen with their average coverage (the cell's PVS with ACH, Marvie et
  al.); the client fetches the cell's record and draws its PVS.  Street, crossroad,
  square and grid cells, and sections: axis-aligned rectangles grown over a dense
  visibility field (Brosnan et al.), whose PVS is the union of their field points'.
* ``portals``: walked per frame.  The cell is a convex volume whose doors and windows
  are portals; the client walks the portal graph from the viewer's cell through the
  visible screen areas (Mulloni et al.) and draws the contents of the cells reached.
  Room, doorway and outside cells.

A scene may hold cells of both models, joined by portals (a building's entrance joins a
street cell to a doorway cell), so code that needs "which visible-set step applies
here" asks :func:`visibility_of` for the current cell's kind instead of the scene's
kind.  A new kind of cell is one row of :data:`CELL_KIND_TABLE`; the store's ``cells``
table takes exactly the kinds listed (its CHECK constraint is built from
:data:`CELL_KINDS`, so a new kind needs a new schema version).

>>> visibility_of("street"), visibility_of("room")
('pvs', 'portals')
>>> cell_kind("doorway").located_in_3d, cell_kind("outside").locatable
(True, False)
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from walkstream.shared.errors import InputError

__all__ = [
    "Visibility",
    "VISIBILITY_MODELS",
    "CellKind",
    "CELL_KIND_TABLE",
    "CELL_KINDS",
    "LOCATABLE_KINDS",
    "cell_kind",
    "visibility_of",
]

Visibility = Literal["pvs", "portals"]
"""How a cell's visible set is found: its baked PVS with ACH, or the portal walk."""

VISIBILITY_MODELS: tuple[Visibility, ...] = ("pvs", "portals")
"""Every visibility model."""


@dataclass(frozen=True, slots=True)
class CellKind:
    """One kind of view cell.

    Attributes
    ----------
    name : str
        As stored in the ``cells`` table and sent in the cell index.
    visibility : {"pvs", "portals"}
        How the visible set of a cell of this kind is found (see the module docstring).
    locatable : bool
        Whether a viewer can be located in it (``outside``, everything seen through an
        interior's windows, holds no viewer).
    located_in_3d : bool
        Whether a point is located in it by its height as well (interior cells stack
        storeys over each other: ``zmin <= z < zmax`` decides); otherwise its outline
        on the ground alone decides.
    """

    name: str
    visibility: Visibility
    locatable: bool = True
    located_in_3d: bool = False

    def __post_init__(self) -> None:
        if self.visibility not in VISIBILITY_MODELS:
            raise InputError(
                f"cell kind {self.name!r}: visibility {self.visibility!r}, expected one of {VISIBILITY_MODELS}"
            )


CELL_KIND_TABLE: tuple[CellKind, ...] = (
    CellKind("crossroad", "pvs"),
    CellKind("street", "pvs"),
    CellKind("square", "pvs"),
    CellKind("grid", "pvs"),
    CellKind("room", "portals", located_in_3d=True),
    CellKind("doorway", "portals", located_in_3d=True),
    CellKind("outside", "portals", locatable=False),
    CellKind("section", "pvs"),
)
"""Every kind of view cell, in the order the bake numbers cells by kind.

Interiors use ``room`` (a convex part of a room), ``doorway`` (the opening of a door or
inner window through a thick wall, so that an eye standing in it is in a cell) and
``outside`` (one per interior: everything seen through windows and outer doors; no
viewer is ever located in it).  ``section`` is a rectangle grown over a dense
visibility field (Brosnan et al.).  The order may only grow at the end: the cell ids
of every baked scene follow it."""

_BY_NAME: dict[str, CellKind] = {k.name: k for k in CELL_KIND_TABLE}

CELL_KINDS: tuple[str, ...] = tuple(k.name for k in CELL_KIND_TABLE)
"""The names of every kind of view cell, in the order the bake numbers cells by kind."""

LOCATABLE_KINDS: frozenset[str] = frozenset(k.name for k in CELL_KIND_TABLE if k.locatable)
"""The kinds a viewer can be located in (every kind but ``outside``)."""


def cell_kind(name: str) -> CellKind:
    """The kind called ``name``.

    Raises
    ------
    InputError
        Not a kind of :data:`CELL_KIND_TABLE`.
    """
    kind = _BY_NAME.get(name)
    if kind is None:
        raise InputError(f"cell kind {name!r:.40}: expected one of {', '.join(CELL_KINDS)}")
    return kind


def visibility_of(name: str) -> Visibility:
    """The visibility model of cell kind ``name``: ``pvs`` or ``portals``.

    The question a frame loop asks of the current cell to choose its visible-set step.

    Raises
    ------
    InputError
        An unknown kind.
    """
    return cell_kind(name).visibility
