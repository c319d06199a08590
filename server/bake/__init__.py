"""The bake: a scene source becomes a scene database.

Load the source (GeoJSON footprints or a generated city), cut the navigation space
into view cells, store every object's compact parameters, then render each cell's
object-ID cube maps to find its PVS and ACH.  Cells are independent tasks: they run
in this process, in ``workers`` local processes, or on a Dask cluster; in every case
this process alone writes the database, so a kill loses at most the cells in flight
and the next bake with the same settings resumes from the cells already stored.

The modules, in the order of the flow: :mod:`.settings`, :mod:`.cells` (with
:mod:`.streetcells`, :mod:`.gridcells`), :mod:`.viewpoints`, :mod:`.samples`,
:mod:`.visibility` (the ID-buffer renderer), :mod:`.workers` (the PVS tasks),
:mod:`.navgraph` and :mod:`.walks` (the default recorded paths), :mod:`.mapplot` (a top
view); the one bake of every scene kind: :mod:`.pipeline` (:func:`bake`: read, plan),
:mod:`.plan` (cells by kind), :mod:`.driver` (bakes them, resumes), :mod:`.chunks`
(the one chunk runner: this process, local processes or Dask); interiors
:mod:`.interior`, crossing scenes :mod:`.crossing`; impostor images :mod:`.impostorsettings`,
:mod:`.impostorplan` (which objects, which images), :mod:`.impostorrender` (the images),
:mod:`.impostors` (the driver's step).
"""

from walkstream.server.bake.impostorsettings import ImpostorSettings
from walkstream.server.bake.pipeline import bake
from walkstream.server.bake.settings import DEFAULT_OCCLUDER_LOD, DEFAULT_RESOLUTION, BakeSettings
from walkstream.server.bake.workers import cell_task

__all__ = [
    "DEFAULT_RESOLUTION",
    "DEFAULT_OCCLUDER_LOD",
    "BakeSettings",
    "ImpostorSettings",
    "cell_task",
    "bake",
]
