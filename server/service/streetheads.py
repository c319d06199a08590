"""A city start bundle's first view: the first cell's objects its first pose draws, the boxes of the others.

A city frame is perfect when every object of its cell's PVS that it would draw is in
(:mod:`~walkstream.shared.codec.objectboxes`).  A walker that stands at its start
until its first view is complete (the client's start hold) needs, of the first cell's
PVS, only the objects the frustum of the path's first pose keeps: about half (Kouvola's
drive: 80 of 140).  With ``heads`` the bundle sends the first cell's record and index
tile, the manifest, those objects, and then the boxes of the first cell's other
objects, before the records ahead and the rest of the objects.

The server culls with the client's view (its viewport and vertical field of view, as
the interior start does) but the client does not trust it: it culls every missing
object's box itself with each frame.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from walkstream.server.service.scenes import Scene
from walkstream.shared.camera import camera, perspective
from walkstream.shared.codec.objectboxes import as_sent, encode_object_boxes
from walkstream.shared.frustum import frustum_cull
from walkstream.shared.paths import RecordedPath
from walkstream.shared.roomview import RoomView

__all__ = ["BOX_MARGIN_M", "POSE_STEP_S", "STREET_VIEW_NEAR_M", "STREET_VIEW_FAR_M", "first_view_plan", "object_boxes_body", "sent_boxes"]

STREET_VIEW_NEAR_M = 0.5
"""The near plane of the server's street view (the client's street near plane)."""

BOX_MARGIN_M = 0.5
"""A box sent is the stored one widened this much on every side: a street piece is
stored flat at z 0 but drawn a few centimetres above (``STREET_Z``), an area at its
kind's height; the box must hold what the client rebuilds."""

POSE_STEP_S = 0.25
"""Seconds between two poses of the path the bundle's order follows."""

STREET_VIEW_FAR_M = 100_000.0
"""The far plane of the server's street view: beyond any city, so the server keeps at
least what the client's frustum keeps."""


def first_view_plan(scene: Scene, path: str, view: RoomView, lead_s: float, cells: list[int],
                    with_objects: list[int]) -> list[tuple[str, Any, float]]:
    """What a city bundle sends after the path, in order, when the client holds its start
    for its first view: ``("cell", id, t)``, ``("index", tile, t)``, ``("manifest", None,
    t)``, ``("objects", ids, t)`` and ``("boxes", ids, t)`` items, ``t`` the seconds into
    the path of the pose that first needs the item (``lead_s`` for those after the poses).

    The path's poses every :data:`POSE_STEP_S` up to ``lead_s`` are walked in turn; each
    new cell the path enters brings its record (and its index tile when new), then the
    objects of its PVS that pose's frustum keeps and not sent yet, highest ACH first, then
    the boxes of its other objects not sent yet (the manifest follows the first cell's
    record and tile: its grammar rebuilds the objects).  Then the records
    (and tiles) of ``cells`` not sent yet, then the objects of ``with_objects``' PVS not
    sent yet (the first cell's by ACH, then each next cell's new ones)."""
    p = RecordedPath.from_msgpack(scene.path(path, "msgpack").content, f"path {path!r}")
    w, h = view.size
    proj = perspective(view.fov_deg, w / h, STREET_VIEW_NEAR_M, STREET_VIEW_FAR_M).astype(np.float64)
    items: list[tuple[str, Any, float]] = []
    now = 0.0  # the pose the items are for
    tiles: set[tuple[int, int]] = set()
    records: set[int] = set()
    sent: set[int] = set()  # objects sent
    boxed: set[int] = set()  # objects whose boxes were sent

    def record(cid: int) -> None:
        records.add(cid)
        items.append(("cell", cid, now))
        tile = scene.cell_tile[cid]
        if tile not in tiles:
            tiles.add(tile)
            items.append(("index", tile, now))

    steps = int(np.floor(min(lead_s, p.duration) / POSE_STEP_S + 1e-9)) + 1
    for k in range(steps):
        now = k * POSE_STEP_S
        xyz, yaw, pitch = p.at(now)
        eye = np.asarray(xyz, np.float64)
        cid = scene.locator.locate(float(eye[0]), float(eye[1]))
        if cid is None:
            continue
        new_cell = cid not in records
        if new_cell:
            record(cid)
            if not k:
                items.append(("manifest", None, now))  # the grammar rebuilds the objects
        c = scene.reader.cell(cid)
        order = [o for o in c.pvs[np.argsort(-c.ach, kind="stable")].tolist() if o not in sent]
        if not order:
            continue
        vp = proj @ camera(eye, float(yaw), float(pitch)).astype(np.float64)
        # culled as the client will cull the boxes sent: widened, rounded outward
        keep = frustum_cull(*sent_boxes(scene, order), vp)
        drawn = [o for o, kk in zip(order, keep.tolist(), strict=True) if kk]
        if drawn:
            items.append(("objects", drawn, now))
            sent.update(drawn)
        if new_cell:
            others = [o for o in order if o not in sent and o not in boxed]
            if others:
                items.append(("boxes", others, now))
                boxed.update(others)
    now = min(lead_s, p.duration)
    if not any(n == "manifest" for n, _, _ in items):
        items.append(("manifest", None, now))
    for cid in cells:
        if cid not in records:
            record(cid)
    rest = []
    for cid in with_objects:
        c = scene.reader.cell(cid)
        rest += [o for o in c.pvs[np.argsort(-c.ach, kind="stable")].tolist() if o not in sent and o not in rest]
    if rest:
        items.append(("objects", rest, now))
    return items


def sent_boxes(scene: Scene, ids: list[int]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(lo, hi)`` ``(n, 3)``: the boxes of objects ``ids`` as the client decodes them
    from a ``boxes`` part: the stored ones widened by :data:`BOX_MARGIN_M`, rounded outward."""
    info = scene.reader.object_info(ids)
    box = np.array([info[i].bbox for i in ids], np.float64).reshape(-1, 6)
    return as_sent(box[:, :3] - BOX_MARGIN_M, box[:, 3:] + BOX_MARGIN_M)


def object_boxes_body(scene: Scene, ids: list[int]) -> bytes:
    """The ``boxes`` part's body: :func:`sent_boxes` of objects ``ids``
    (:func:`~walkstream.shared.codec.objectboxes.encode_object_boxes`)."""
    return encode_object_boxes(ids, *sent_boxes(scene, ids))
