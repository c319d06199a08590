"""A crossing scene's topology for the walk: the interior's rooms with each entrance's street cell joined in.

A crossing scene holds cells of both visibility models: street cells with a PVS
(and ACH per object), room cells with portals, joined at an entrance portal (street
cell <-> doorway).  The walk (:mod:`walkstream.client.walk.loop`) runs the portal
walk over the interior's topology with each entrance's street cell added
(:func:`crossing_topology`), so that it passes from the doorway to the street and in.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from walkstream.shared.roomwire import ContentsRef, Entrance, RoomRecord, Topology

__all__ = ["crossing_topology"]


def crossing_topology(topology: Topology, entrances: tuple[Entrance, ...]) -> Topology:
    """The interior's topology with each entrance's street cell added as a cell of its own
    (no planes: never located by them; no contents), its one portal the entrance: the
    portal walk then passes from the doorway to the street and from the street in."""
    portals = {p[0]: p for p in topology.portals}
    extra: list[RoomRecord] = []
    for e in entrances:
        pid, kind, a, b, poly = portals[e.portal]
        door = next(r for c in topology.cells if c.id == e.doorway for r in c.portals if r.id == e.portal)
        extra.append(RoomRecord(
            id=e.street, kind="street", name="street", room=None, storey=0, outline=np.zeros((0, 2)),
            zmin=-1e9, zmax=1e9, planes=np.zeros((0, 4)), portals=(replace(door, cell=e.doorway),),
            neighbours=(e.doorway,), contents=ContentsRef(0, 0, 0, 0, 0, 0.0),
        ))
    return replace(topology, cells=(*topology.cells, *extra))
