"""What the service keeps of an interior scene: its topology, its cell records, its cell contents.

Built once when the scene is loaded (a damaged interior stops the start): every
cell's :class:`~walkstream.shared.roomwire.RoomRecord` is assembled from the database's
rooms, portals and contents sizes, and the topology (Mulloni et al.'s topological
file) is encoded in both representations.  Room records and contents blobs are
encoded or read on first use and kept in a byte-bounded LRU.  Everything is keyed by
the scene version, so it never needs invalidating.
"""

from __future__ import annotations

import gzip
from collections.abc import Sequence
from functools import cached_property

from numpy.typing import ArrayLike

from walkstream.server.service.contentsform import ContentsStream
from walkstream.server.service.http import Encoded, Rep, encode, etag_for
from walkstream.server.service.lru import LRU
from walkstream.server.store import CellInfo, SceneReader
from walkstream.shared.codec.cellbatch import (
    CELLBATCH_MAX_CELLS,
    pack_contents_part,
    pack_head_part,
)
from walkstream.shared.codec.cellmesh import inflate_cell_mesh
from walkstream.shared.content.cellmesh import KIND as CELLMESH
from walkstream.shared.errors import ApiError, CodecError
from walkstream.shared.portalgraph import PortalGraph
from walkstream.shared.roomcompact import (
    TOPOLOGY_COMPACT_MEDIA,
    decode_topology_compact,
    encode_topology_compact,
)
from walkstream.shared.roomview import RoomLocator, RoomView, cells_seen
from walkstream.shared.roomwire import (
    TOPOLOGY_PACKED_MEDIA,
    ContentsRef,
    Entrance,
    PortalRef,
    RoomRecord,
    Topology,
    decode_topology,
)

__all__ = ["InteriorState"]

_CACHE_BYTES = 64 << 20


class InteriorState:
    """The interior parts of one scene (see the module docstring).

    Parameters
    ----------
    reader:
        The scene's database.
    cells:
        Its cells, as the service already read them.
    """

    def __init__(self, reader: SceneReader, cells: Sequence[CellInfo]) -> None:
        self.reader = reader
        self.version = reader.version
        self.name = reader.meta.name
        rooms = reader.rooms()
        info = reader.contents_info()
        portals = reader.portals()
        refs: dict[int, list[PortalRef]] = {c.id: [] for c in cells}
        for p in portals:
            # an entrance joins a street cell (no room record) to a doorway
            if p.a in refs:
                refs[p.a].append(PortalRef(p.id, p.kind, p.polygon, p.b))
            if p.b in refs:
                refs[p.b].append(PortalRef(p.id, p.kind, p.polygon, p.a))
        self.records: dict[int, RoomRecord] = {}
        for c in cells:
            r = rooms[c.id]
            ci = info.get(c.id)
            contents = ci if ci is not None else ContentsRef(0, 0, 0, 0, 0, 0.0)
            self.records[c.id] = RoomRecord(
                id=c.id, kind=c.kind, name=r.name, room=r.room, storey=r.storey, outline=c.boundary,
                zmin=c.zmin, zmax=c.zmax, planes=r.planes, portals=tuple(refs[c.id]),
                neighbours=tuple(int(n) for n in c.neighbours), contents=contents,
            )
        topology = Topology(
            storeys=tuple((s.id, s.name, s.zmin, s.zmax) for s in reader.storeys()),
            cells=tuple(self.records[c.id] for c in cells),
            portals=tuple((p.id, p.kind, p.a, p.b, p.polygon) for p in portals),
            stairs=tuple((s.portal, s.lower, s.upper, s.path) for s in reader.stairs()),
        ).to_wire()
        self.topology: dict[Rep, Encoded] = {
            rep: encode(topology, rep, self.version, "topology") for rep in ("msgpack", "json")
        }
        # mtime 0: the same bytes (and ETag) from every start of the service
        packed = gzip.compress(self.topology["msgpack"].content, 9, mtime=0)
        self.topology_packed = Encoded(packed, TOPOLOGY_PACKED_MEDIA, etag_for(self.version, "topology", "msgpack-gzip"))
        """The topology's msgpack body gzip-compressed (``walkstream-topology/1+gzip``)."""
        compact = encode_topology_compact(decode_topology(self.topology["msgpack"].content, "topology"))
        self.topology_compact = Encoded(compact, TOPOLOGY_COMPACT_MEDIA, etag_for(self.version, "topology", "c4"))
        """The topology in millimetres, planes rebuilt from outlines (``walkstream-topology/2``)."""
        entrances = [Entrance(e.portal, e.building, e.street, e.doorway, e.shell, e.placement).to_wire() for e in reader.entrances()]
        self.entrances: dict[Rep, Encoded] = {
            rep: encode(entrances, rep, self.version, "entrances") for rep in ("msgpack", "json")
        }
        """The entrances joining streets to rooms (a crossing scene's; empty for an interior)."""
        self._cache = LRU(_CACHE_BYTES)

    def has(self, cid: int) -> bool:
        """Whether the interior has cell ``cid``."""
        return cid in self.records

    def _check(self, cid: int) -> None:
        if cid not in self.records:
            raise ApiError(f"scene {self.name!r} has no cell {cid}", status=404, detail={"cell": cid})

    def cached_room(self, cid: int, rep: Rep) -> Encoded | None:
        """The encoded record of cell ``cid`` if it is cached."""
        value: Encoded | None = self._cache.get(("room", cid, rep))
        return value

    def room(self, cid: int, rep: Rep) -> Encoded:
        """The encoded :class:`~walkstream.shared.roomwire.RoomRecord` of cell ``cid``."""
        self._check(cid)
        enc = self.cached_room(cid, rep)
        if enc is None:
            enc = encode(self.records[cid].to_wire(), rep, self.version, f"room:{cid}")
            self._cache.put(("room", cid, rep), enc, len(enc.content))
        return enc

    def cached_contents(self, cid: int) -> Encoded | None:
        """Cell ``cid``'s contents if they are cached."""
        value: Encoded | None = self._cache.get(("contents", cid))
        return value

    def contents(self, cid: int) -> Encoded:
        """Cell ``cid``'s contents blob as stored (reads the database on a cache miss)."""
        self._check(cid)
        enc = self.cached_contents(cid)
        if enc is None:
            blob = self.reader.contents(cid)
            enc = Encoded(blob, CELLMESH.wire, etag_for(self.version, f"contents:{cid}", CELLMESH.name))
            self._cache.put(("contents", cid), enc, len(blob))
        return enc

    def contents_forms(self, cid: int, inflate: bool) -> list[bytes]:
        """Cell ``cid``'s part of a contents stream (:mod:`~walkstream.shared.codec.cellbatch`)
        in each form it may take, the first the one to send without a choice: its blob
        as stored; or (``inflate``, for a stream gzip-compressed as a whole) inflated to
        its ``N`` form so the cells share one dictionary, then as stored
        (:mod:`~walkstream.server.service.contentsform` picks the cheaper)."""
        enc = self.contents(cid)
        stored = pack_contents_part(cid, enc.etag, enc.content)
        if not inflate:
            return [stored]
        try:
            blob = inflate_cell_mesh(enc.content, f"contents of cell {cid}")
        except CodecError:  # a damaged stored blob goes as stored: the client says so
            return [stored]
        return [pack_contents_part(cid, enc.etag, blob), stored]

    def contents_part(self, cid: int, inflate: bool, stream: ContentsStream | None = None) -> bytes:
        """Cell ``cid``'s part of a contents stream (:meth:`contents_forms`): with
        ``stream`` (the mirror of the answer's gzip stream) the form that costs fewer
        bytes there."""
        forms = self.contents_forms(cid, inflate)
        return forms[0] if stream is None else stream.cheaper(*forms)

    def head_forms(self, cid: int, body: bytes, missing: bytes, inflate: bool) -> list[bytes]:
        """Cell ``cid``'s head (:mod:`~walkstream.shared.codec.cellhead`) as a part of a
        contents stream, in each form it may take (as :meth:`contents_forms`)."""
        etag = self.contents(cid).etag
        part = pack_head_part(cid, etag, body, missing)
        if not inflate:
            return [part]
        return [pack_head_part(cid, etag, inflate_cell_mesh(body, f"head of cell {cid}"), missing), part]

    @cached_property
    def view_model(self) -> tuple[PortalGraph, RoomLocator]:
        """The portal graph and locator of the compact topology as the client decodes it
        (the server culls as the client will)."""
        topo = decode_topology_compact(self.topology_compact.content, "topology")
        return PortalGraph.from_topology(topo), RoomLocator(topo.cells)

    def first_view(
        self, poses: Sequence[tuple[ArrayLike, float, float]], view: RoomView, max_bytes: int,
        closed: frozenset[int] = frozenset(),
    ) -> tuple[list[int], list[int]]:
        """The cells a client walking with ``view`` sees from ``poses`` (``(eye, yaw,
        pitch)``, the first where the walk starts, the others where it may lead) while
        their stored contents stay within ``max_bytes`` (the first cell always); cells
        without contents are left out.  Returns ``(those cells, those of them the first
        pose itself sees)``: the second is what this gives for ``poses[:1]`` (its cells
        come first in the order, so the byte bound cuts them alike), from one culling
        walk per pose.

        Order: the first view's cells as the culling found them (nearest first), then
        each next pose's new ones.  (Ordering the first view's cells by how long they
        stay in view, which helps when the walk goes straight on, made the office
        tour's first perfect frame later, 3.21 s against 3.17 s: the tour turns.)

        ``closed``: the virtual walls whose textures the bundle brings, closed in the
        first pose's walk (:mod:`~walkstream.server.service.firstwalls`).
        """
        graph, locator = self.view_model
        seen = cells_seen(graph, locator, poses, view)
        if closed and seen:
            seen[0] = cells_seen(graph, locator, poses[:1], view, closed)[0]
        order = list(dict.fromkeys(c for cells in seen for c in cells))
        out: list[int] = []
        total = 0
        for cid in order:
            nbytes = self.records[cid].contents.nbytes
            if not nbytes:
                continue
            if out and (total + nbytes > max_bytes or len(out) >= CELLBATCH_MAX_CELLS):
                break
            out.append(cid)
            total += nbytes
        firsts = set(seen[0]) if seen else set()
        return out, [c for c in out if c in firsts]
