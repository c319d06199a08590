"""The HTTP API: scene list, manifest, start bundle, recorded paths, cell index, locate, cells, interiors, objects, health, metrics.

Cell index, cell records, start bundle
--------------------------------------
``GET /v1/scenes/{scene}/index/{i}/{j}`` is the cell index of tile ``(i, j)`` of the
manifest's ``index`` grid (``.../index`` the whole scene): every cell's convex
outline, eye-height range and neighbours, compact (centimetre deltas).  A cell record
``GET .../cells/{id}`` carries only what is the cell's own: its PVS (delta-coded ids)
and ACH (units of 1/65535); ``POST .../cells`` with ``{"ids": [...]}`` streams several
records (concatenated msgpack, in the order asked).  ``GET /v1/start?path=NAME``
(or ``viewpoint=``, or ``x=&y=``) streams a start bundle: path, first cell, index
tiles, manifest and the first cell's objects in one round trip (see
:mod:`walkstream.server.service.routers.start`).  The record formats are in
:mod:`walkstream.shared.wire`.

Every route under ``/v1`` answers in msgpack (``application/msgpack``) unless the
request's ``Accept`` prefers ``application/json``; every response carries
``Vary: Accept``.  Whatever is keyed by a scene version (manifest, path, locate,
cell) has a strong ``ETag`` naming version, resource and representation, and
``Cache-Control: public, max-age=31536000, immutable``; a matching
``If-None-Match`` gets ``304``.  Errors are always JSON ``{"error": message,
"detail": ...}``.

Object stream framing
---------------------
``POST /v1/scenes/{scene}/objects`` with body ``{"ids": [int, ...]}`` (msgpack when
the ``Content-Type`` is ``application/msgpack``, JSON otherwise; at most
:data:`MAX_IDS` = 1000 ids, else 422; at most 4 MiB of frames, else 413 with
``detail.limit_bytes`` and ``detail.ids_that_fit``) answers with a *streamed* body
made of **plain concatenated msgpack objects, one per id in the order asked**
(repeats included), with no length prefix or separator: msgpack is
self-delimiting, so a client feeds the bytes to ``msgpack.Unpacker`` as they
arrive and gets each object as soon as its last byte is in.  Each object is the map
``{"id": int, "kind": str, "params": bin}`` where ``params`` is the stored record
(:func:`shared.codec.decode_building` / :func:`shared.codec.decode_street`, or
:func:`shared.codec.decode_object` for either).  The server hands the frames to the
transport in chunks of about :data:`CHUNK_BYTES`, never splitting the order.  The
headers ``X-Scene-Version`` and ``X-Object-Count`` come first.  With
``Accept: application/json`` the body is instead a JSON array, streamed one element
per line, of ``{"id", "kind", "params": base64}``.

Interiors (manifest ``kind: interior``) add ``GET /v1/scenes/{scene}/topology``, ``GET
/v1/scenes/{scene}/rooms/{cell}`` and ``GET /v1/scenes/{scene}/rooms/{cell}/contents``
(see :mod:`walkstream.server.service.routers.rooms`); ``locate`` takes a height ``z``
there.

All ids are checked before the first byte is sent: an unknown id gives a 404 that
lists the unknown ids, never a truncated stream.

Mesh form (for comparison only)
-------------------------------
``POST /v1/scenes/{scene}/objects?form=lod2`` answers with the same framing, but
each map is ``{"id": int, "kind": str, "mesh": bin}`` where ``mesh`` is the object's
LOD2 mesh, rebuilt on the server (buildings with the scene's grammar, street pieces
as their flat surface) and encoded by :func:`shared.codec.encode_mesh` (decode with
:func:`shared.codec.decode_mesh`); with ``Accept: application/json`` the elements
are ``{"id", "kind", "mesh": base64}``.  It exists so that a client's
``--stream meshes`` mode can measure what sending geometry instead of parameters
costs in bytes and quality, which is the paper's central claim; meshes are about a
thousand times larger than parameters.  ``form=params`` is the default and the
format described above; any other form is a 422 naming it.
"""

from walkstream.server.service.routers import (
    cells,
    impostors,
    index,
    objects,
    ops,
    paths,
    rooms,
    scenes,
    start,
    walls,
)

__all__ = ["ROUTERS", "cells", "impostors", "index", "objects", "ops", "paths", "rooms", "scenes", "start", "walls"]

ROUTERS = (
    scenes.router,
    start.router,
    paths.router,
    index.router,
    cells.router,
    rooms.router,
    impostors.router,
    walls.router,
    objects.router,
    ops.router,
)
"""Every router, in the order their routes are documented."""
