"""Drawing a frame: culling, LOD allocation by ACH, the polygon budget, devices, renderers.

One frame's order: culling (what can be seen at all: :mod:`walkstream.shared.frustum`,
and indoors :mod:`walkstream.shared.portals`) -> :mod:`.allocate`
(which LOD each visible object gets) under the budget of :mod:`.budget` -> the frame
drawn by :mod:`.frames` (or timed by a cost model of :mod:`.devices`).
:mod:`.meshes` is the mesh renderer both use.  Culling is pure numpy in ``shared/`` since the
server culls too (the first view of an interior start bundle).
"""

from walkstream.client.draw.allocate import Allocation, allocate_ach, allocate_distance
from walkstream.client.draw.budget import BudgetController
from walkstream.client.draw.devices import Device, make_device
from walkstream.client.draw.frames import FrameRenderer
from walkstream.client.draw.meshes import MeshRenderer, render_lods_figure

__all__ = [
    "Allocation",
    "allocate_ach",
    "allocate_distance",
    "BudgetController",
    "Device",
    "make_device",
    "FrameRenderer",
    "MeshRenderer",
    "render_lods_figure",
]
