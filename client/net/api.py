"""The client's view of the walkstream HTTP API: typed records, bounded decoding, retries.

Everything the server sends is untrusted bytes: every body is unpacked with hard
limits (:func:`~walkstream.shared.codec.unpack_bounded`, or a bounded ``msgpack.Unpacker`` for
the object stream) and checked field by field, so a corrupt or hostile response is
an :class:`ApiError` (and fetched again), never a crash.

Idempotent requests (manifest, path, locate, cell, index tile) are retried with
capped exponential backoff on transport errors, 5xx answers and undecodable bodies:
a server restart or a dropped connection mid-walk costs time, not the walk.  The
streams -- objects (:meth:`SceneClient.objects`), cell records in a batch
(:meth:`SceneClient.cells`) and the start bundle (:meth:`SceneClient.start`) -- are
*not* retried here: each item is yielded as soon as its last byte arrives and
:class:`StreamCut` is raised when the stream ends early or turns bad, so the caller
asks again for exactly what it did not get (nothing lost, nothing duplicated).

The client only knows an :class:`httpx.AsyncClient`; whether it talks to a server
over real sockets or to the app in-process is decided by whoever builds it.
"""

from __future__ import annotations

import hashlib
import random
import zlib
from collections.abc import AsyncGenerator, AsyncIterator, Sequence
from typing import Any

import httpx
import msgpack

from walkstream.client.clock import Clock
from walkstream.client.net.startitems import StartDecoder, StartItem, contents_part
from walkstream.client.net.transferstats import TransferStats
from walkstream.shared.codec.cellbatch import check_contents_part
from walkstream.shared.codec.cellmesh import CellMesh
from walkstream.shared.content.cellmesh import KIND as CELLMESH
from walkstream.shared.content.impostor import KIND as IMPOSTOR
from walkstream.shared.content.kind import ContentKind
from walkstream.shared.content.walltex import KIND as WALLTEX
from walkstream.shared.errors import ApiError, CodecError, StreamCut
from walkstream.shared.pathcodec import PATH_Q_MEDIA, decode_path_any
from walkstream.shared.paths import RecordedPath
from walkstream.shared.roomcompact import decode_topology_compact
from walkstream.shared.roomview import RoomView
from walkstream.shared.roomwire import (
    Entrance,
    RoomRecord,
    Topology,
    decode_entrances,
    decode_room,
    decode_topology,
    decode_topology_packed,
)
from walkstream.shared.walls import WallSide, decode_walls
from walkstream.shared.wire import (
    MSGPACK,
    CellIndex,
    CellRecord,
    Manifest,
    ObjectFrame,
    cell_from_wire,
    decode_cell,
    decode_cell_index,
    decode_frame,
    decode_locate,
    decode_manifest,
    decode_scene_list,
)

__all__ = [
    "SceneClient",
]


_MAX_FRAME = 32 << 20  # one object frame (an LOD2 mesh of a large block fits)


def _req_error(what: str, r: httpx.Response) -> ApiError:
    try:
        detail = r.json().get("error", "")
    except Exception:  # noqa: BLE001 - an error body may be anything
        detail = ""
    return ApiError(f"{what}: HTTP {r.status_code} {detail}".rstrip(), r.status_code)


class SceneClient:
    """Typed, retrying access to one scene of a walkstream server.

    Parameters
    ----------
    http:
        The HTTP client (its transport may be shaped; its ``base_url`` is the server).
    clock:
        Drives backoff sleeps and time measurements (real or simulated).
    scene:
        Scene name; ``None`` means the server's only (or first) scene, looked up by
        :meth:`resolve_scene`.
    backoff:
        First and largest retry delay in seconds (doubling in between).
    seed:
        Seeds the backoff jitter (deterministic under the simulated clock).
    compress:
        Ask for the streams gzip-compressed (``Accept-Encoding: gzip``; they are
        inflated here, bounded); False asks for them as they are.
    """

    def __init__(
        self,
        http: httpx.AsyncClient,
        clock: Clock,
        scene: str | None = None,
        *,
        backoff: tuple[float, float] = (0.25, 4.0),
        max_attempts: int = 1_000_000,
        seed: int = 0,
        compress: bool = True,
    ) -> None:
        self.http = http
        self.compress = compress
        self.clock = clock
        self.scene = scene
        self.backoff = backoff
        self.max_attempts = max_attempts
        self.stats = TransferStats()
        self._rng = random.Random(seed)

    # -- plumbing ------------------------------------------------------------

    def _url(self, tail: str) -> str:
        if self.scene is None:
            raise ApiError("no scene chosen yet (call resolve_scene first)")
        return f"/v1/scenes/{self.scene}{tail}"

    async def _get(
        self,
        url: str,
        what: str,
        *,
        headers: dict[str, str] | None = None,
        ok: tuple[int, ...] = (200,),
    ) -> httpx.Response:
        """GET with retries on transport errors and 5xx; 4xx raise at once."""
        attempt = 0
        while True:
            attempt += 1
            t0 = self.clock.now()
            try:
                r = await self.http.get(url, headers={"Accept": MSGPACK, **(headers or {})})
                self.stats.observe_rtt(self.clock.now() - t0)
                if r.status_code < 500:
                    self.stats.reached(self.clock.now())
                if r.status_code in ok:
                    return r
                if r.status_code < 500:
                    raise _req_error(what, r)
                err: Exception = _req_error(what, r)
                self.stats.failed(t0)
            except (httpx.TransportError, httpx.DecodingError) as exc:
                # refused, reset, cut off, timed out; or a body that does not inflate
                err = exc
                if isinstance(exc, httpx.ConnectError | httpx.ConnectTimeout):
                    self.stats.failed(t0)  # no server (a body cut by the link is not an outage)
            if attempt >= self.max_attempts:
                raise ApiError(f"{what}: gave up after {attempt} attempts ({err})")
            await self._backoff(attempt)

    async def _backoff(self, attempt: int) -> None:
        self.stats.retries += 1
        lo, hi = self.backoff
        delay = min(hi, lo * 2 ** (attempt - 1)) * (0.75 + 0.5 * self._rng.random())
        await self.clock.sleep(delay)

    async def _get_decoded(self, url: str, what: str, decode: Any, **kw: Any) -> Any:
        """GET and decode, fetching again when the body cannot be decoded (corrupt/truncated).

        The same body refused twice is no accident of the link (a corrupt or cut body
        does not repeat byte for byte): the client cannot read it, and fetching again
        would only repeat the refusal for ever, so it is an :class:`ApiError` at once.
        """
        attempt = 0
        refused: bytes | None = None
        while True:
            attempt += 1
            r = await self._get(url, what, **kw)
            try:
                return r, decode(r)
            except CodecError as exc:
                body = hashlib.blake2b(r.content, digest_size=16).digest()
                if attempt >= self.max_attempts or body == refused:
                    raise ApiError(f"{what}: undecodable answer ({exc})") from exc
                refused = body
                await self._backoff(attempt)

    # -- endpoints -----------------------------------------------------------

    async def resolve_scene(self) -> str:
        """Pick the scene: the one given, else the server's first scene by name."""
        if self.scene is not None:
            return self.scene

        _, names = await self._get_decoded(
            "/v1/scenes", "scene list", lambda r: decode_scene_list(r.content)
        )
        if not names:
            raise ApiError("the server serves no scene")
        self.scene = names[0]
        return self.scene

    async def manifest(self, etag: str | None = None) -> Manifest | None:
        """The scene manifest; ``None`` when ``etag`` is given and still current (304)."""
        headers = {"If-None-Match": etag} if etag else None
        what = f"scene {self.scene!r} manifest"

        def dec(r: httpx.Response) -> Manifest | None:
            if r.status_code == 304:
                return None
            return decode_manifest(r.content, what, r.headers.get("etag"))

        _, m = await self._get_decoded(self._url(""), what, dec, headers=headers, ok=(200, 304))
        return m

    async def path(self, name: str) -> tuple[RecordedPath, int]:
        """Recorded path ``name`` and its body size in bytes."""
        what = f"path {name!r}"
        _, (p, n) = await self._get_decoded(
            self._url(f"/paths/{name}"),
            what,
            lambda r: (decode_path_any(r.content, what), len(r.content)),
            headers={"Accept": f"{PATH_Q_MEDIA}, {MSGPACK};q=0.5"},  # compact when the server has it
        )
        return p, n

    async def locate(self, x: float, y: float) -> int | None:
        """The id of the cell containing ``(x, y)``, or ``None`` outside every cell."""
        what = f"locate ({x:.2f}, {y:.2f})"

        url = self._url("/locate") + f"?x={x!r}&y={y!r}"
        _, cid = await self._get_decoded(url, what, lambda r: decode_locate(r.content, what))
        return cid

    async def cell(self, cid: int, etag: str | None = None) -> CellRecord | None:
        """Cell ``cid``; ``None`` when ``etag`` is given and still current (304)."""
        what = f"cell {cid}"
        headers = {"If-None-Match": etag} if etag else None

        def dec(r: httpx.Response) -> CellRecord | None:
            if r.status_code == 304:
                return None
            rec = decode_cell(r.content, what, r.headers.get("etag"))
            if rec.id != cid:
                raise CodecError(f"{what}: the answer is cell {rec.id}")
            return rec

        _, rec = await self._get_decoded(
            self._url(f"/cells/{cid}"), what, dec, headers=headers, ok=(200, 304)
        )
        return rec

    # -- interiors ------------------------------------------------------------

    async def topology(self, packed: bool | None = None, compact: bool = True) -> Topology:
        """The interior's topology: storeys, cells (plane sets), portals, stairs; ``packed``
        (default: :attr:`compress`) asks for it compact (``/topology/compact``, in
        millimetres) or, ``compact=False``, gzip-compressed (``/topology/packed``)."""
        what = f"scene {self.scene!r} topology"
        if (self.compress if packed is None else packed) and compact:
            _, t = await self._get_decoded(
                self._url("/topology/compact"), what, lambda r: decode_topology_compact(r.content, what)
            )
        elif self.compress if packed is None else packed:
            _, t = await self._get_decoded(
                self._url("/topology/packed"), what, lambda r: decode_topology_packed(r.content, what)
            )
        else:
            _, t = await self._get_decoded(self._url("/topology"), what, lambda r: decode_topology(r.content, what))
        return t

    async def entrances(self) -> tuple[Entrance, ...]:
        """A crossing scene's entrances (street cell, doorway, the building and its shell)."""
        what = f"scene {self.scene!r} entrances"
        _, got = await self._get_decoded(self._url("/entrances"), what, lambda r: decode_entrances(r.content, what))
        return got

    async def walls(self, cells: Sequence[int] | None = None) -> tuple[WallSide, ...]:
        """The textured virtual walls (``GET .../walls``), with ``cells`` only the rings
        of those street cells (``?cells=``); a scene baked without them answers 404
        (:class:`~walkstream.shared.errors.ApiError`)."""
        what = f"scene {self.scene!r} walls" + (f" of {len(cells)} cells" if cells is not None else "")
        tail = "/walls" if cells is None else "/walls?cells=" + ",".join(str(int(c)) for c in cells)
        _, got = await self._get_decoded(self._url(tail), what, lambda r: decode_walls(r.content, what))
        return got

    async def wall_textures(self, ids: Sequence[int]) -> AsyncIterator[tuple[int, Any, int]]:
        """Wall textures ``ids`` in one request (``POST .../walls/textures``), each yielded as
        ``(texture id, premultiplied RGBA array, bytes on the wire)`` in the order asked.

        Raises
        ------
        StreamCut
            As :meth:`objects`; ``received`` counts the textures yielded.
        ApiError
            4xx: the server refuses the request (a scene baked without walls: 404).
        """
        async for part in self._image_batch(ids, "/walls/textures", "wall textures batch", "texture", WALLTEX, "wall texture"):
            yield part

    async def room(self, cid: int) -> RoomRecord:
        """Interior cell ``cid``'s record."""
        what = f"room cell {cid}"

        def dec(r: httpx.Response) -> RoomRecord:
            rec = decode_room(r.content, what, r.headers.get("etag"))
            if rec.id != cid:
                raise CodecError(f"{what}: the answer is cell {rec.id}")
            return rec

        _, rec = await self._get_decoded(self._url(f"/rooms/{cid}"), what, dec)
        return rec

    async def contents(self, cid: int) -> CellMesh:
        """Interior cell ``cid``'s contents (one immutable response), decoded."""
        what = f"contents of cell {cid}"
        _, mesh = await self._get_decoded(
            self._url(f"/rooms/{cid}/contents"), what, lambda r: CELLMESH.decode(r.content, what)
        )
        return mesh

    # -- cell index -------------------------------------------------------------

    async def contents_batch(self, ids: Sequence[int]) -> AsyncIterator[tuple[int, CellMesh]]:
        """Interior cells ``ids``' contents in one request (``POST .../rooms/contents``),
        each yielded decoded as soon as its part is in, in the order asked; ``nbytes`` is
        the part's share of the (compressed) stream.

        Raises
        ------
        StreamCut
            As :meth:`objects`; ``received`` counts the cells yielded.
        ApiError
            4xx: the server refuses the request.
        """
        ids = [int(i) for i in ids]
        what = f"contents batch ({len(ids)} cells)"
        got = 0

        def check(obj: Any, nbytes: int) -> tuple[int, CellMesh]:
            if got >= len(ids):
                raise CodecError("more cells than asked")
            return contents_part(obj, nbytes, ids[got], f"{what}: part {got}")

        async for part in self._stream("POST", self._url("/rooms/contents"), what, {"ids": ids}, check):
            got += 1
            yield part
        if got < len(ids):
            self.stats.cut_streams += 1
            raise StreamCut(f"{what}: ended after {got} of {len(ids)} cells", got)

    async def impostors(self, ids: Sequence[int]) -> AsyncIterator[tuple[int, Any, int]]:
        """Impostor images ``ids`` in one request (``POST .../impostors``), each yielded as
        ``(image id, premultiplied RGBA array, bytes on the wire)`` as soon as its part
        is in, in the order asked.

        Raises
        ------
        StreamCut
            As :meth:`objects`; ``received`` counts the images yielded.
        ApiError
            4xx: the server refuses the request (a scene baked without impostors: 404).
        """
        async for part in self._image_batch(ids, "/impostors", "impostors batch", "image", IMPOSTOR, "impostor image"):
            yield part

    async def _image_batch(
        self, ids: Sequence[int], tail: str, batch: str, short: str, kind: ContentKind, noun: str
    ) -> AsyncIterator[tuple[int, Any, int]]:
        """Stored images ``ids`` of one set in one request (``POST`` to ``tail``), each yielded
        as ``(image id, premultiplied RGBA array, bytes on the wire)`` in the order asked.

        Parameters
        ----------
        ids:
            The image ids, each once.
        tail:
            The batch route after the scene (``"/impostors"``).
        batch:
            The request in error lines (``"impostors batch"``).
        short:
            One image in error lines (``"image"``).
        kind:
            The content kind decoding one image (``IMPOSTOR``, ``WALLTEX``).
        noun:
            One image in a decoding error (``"impostor image"``).

        Raises
        ------
        StreamCut
            As :meth:`objects`; ``received`` counts the images yielded.
        ApiError
            4xx: the server refuses the request.
        """
        ids = [int(i) for i in ids]
        what = f"{batch} ({len(ids)} {short}s)"
        got = 0

        def check(obj: Any, nbytes: int) -> tuple[int, Any, int]:
            if got >= len(ids):
                raise CodecError(f"more {short}s than asked")
            iid, _etag, body = check_contents_part(obj, f"{what}: part {got}")
            if iid != ids[got]:
                raise CodecError(f"{what}: {short} {iid} where {ids[got]} was asked")
            return iid, kind.decode(body, f"{noun} {iid}"), nbytes

        async for part in self._stream("POST", self._url(tail), what, {"ids": ids}, check):
            got += 1
            yield part
        if got < len(ids):
            self.stats.cut_streams += 1
            raise StreamCut(f"{what}: ended after {got} of {len(ids)} {short}s", got)

    async def cell_index(self, tile: tuple[int, int] | None) -> CellIndex:
        """The cell index of ``tile`` (None: of the whole scene)."""
        what = "cell index" if tile is None else f"cell index tile {tile}"
        tail = "/index" if tile is None else f"/index/{tile[0]}/{tile[1]}"

        def dec(r: httpx.Response) -> CellIndex:
            idx = decode_cell_index(r.content, what, r.headers.get("etag"))
            if idx.tile != tile:
                raise CodecError(f"{what}: the answer is tile {idx.tile}")
            return idx

        _, idx = await self._get_decoded(self._url(tail), what, dec)
        return idx

    async def objects(self, ids: Sequence[int], form: str = "params") -> AsyncIterator[ObjectFrame]:
        """Stream objects ``ids`` in order, each yielded as soon as its last byte is in.

        Raises
        ------
        StreamCut
            The stream failed (transport error, bad status, truncated or corrupt
            bytes, an object other than the one expected); ``received`` tells how many
            were yielded.  Nothing is retried here.
        ApiError
            4xx: the server refuses the request (unknown ids, too many ids).
        """
        ids = [int(i) for i in ids]
        url = self._url("/objects") + ("" if form == "params" else f"?form={form}")
        what = f"objects stream ({len(ids)} ids)"
        got = 0

        def check(obj: Any, nbytes: int) -> ObjectFrame:
            if got >= len(ids):
                raise CodecError("more objects than asked")
            return decode_frame(obj, ids[got], form, nbytes, f"{what}: object {got}")

        async for frame in self._stream("POST", url, what, {"ids": ids}, check, meter=True):
            got += 1
            yield frame
        if got < len(ids):
            self.stats.cut_streams += 1
            raise StreamCut(f"{what}: ended after {got} of {len(ids)} objects", got)

    async def cells(self, ids: Sequence[int]) -> AsyncIterator[CellRecord]:
        """Stream the records of cells ``ids`` in order (``POST .../cells``).

        Raises
        ------
        StreamCut
            As :meth:`objects`; ``received`` counts the records yielded.
        ApiError
            4xx: the server refuses the request.
        """
        ids = [int(i) for i in ids]
        what = f"cells stream ({len(ids)} ids)"
        got = 0

        def check(obj: Any, nbytes: int) -> CellRecord:
            if got >= len(ids):
                raise CodecError("more cells than asked")
            rec = cell_from_wire(obj, f"{what}: cell {got}", nbytes)
            if rec.id != ids[got]:
                raise CodecError(f"{what}: cell {rec.id} where {ids[got]} was asked")
            return rec

        async for rec in self._stream("POST", self._url("/cells"), what, {"ids": ids}, check):
            got += 1
            yield rec
        if got < len(ids):
            self.stats.cut_streams += 1
            raise StreamCut(f"{what}: ended after {got} of {len(ids)} cells", got)

    async def start(
        self,
        *,
        path: str | None = None,
        x: float | None = None,
        y: float | None = None,
        form: str = "params",
        view: RoomView | None = None,
        path_head_s: float | None = None,
        heads: bool = False,
        walls: bool = False,
        pose: bool = False,
    ) -> AsyncGenerator[StartItem, None]:
        """Stream the start bundle (``GET /v1/start``) for a path's start or a position.

        With ``view`` (interiors) the bundle brings the first view's contents; with
        ``path_head_s`` too, only the path's first seconds (``pathhead``, yielded as
        such), the caller fetching the whole path itself; with ``heads`` too, a cell
        the first pose sees in part may come first as its head (a ``room`` item whose
        ``CellMesh.missing`` is not empty, :mod:`~walkstream.shared.codec.cellhead`),
        then whole; the first view's contents may then come as one pack
        (:mod:`~walkstream.shared.codec.contentspack`), yielded a ``room`` item each.  With ``walls``, a scene baked with virtual walls adds its wall sides
        and the first view's wall textures (``walls``, ``walltex``, ``texture`` items).
        With ``pose`` too (and ``path_head_s``, ``heads``), the first ``pathhead`` item is
        the head's first pose alone, and the head comes as a second ``pathhead`` item
        among the ``room`` items, once the first pose's view is in.

        The scene is :attr:`scene` if set, else the server's first; it is set from
        the answer's ``X-Scene`` header as soon as the head arrives.  Items are
        yielded decoded (see :data:`~walkstream.client.net.startitems.StartItem`), each as soon as its last byte is in.

        Raises
        ------
        StreamCut
            The stream failed; what was yielded stays good.
        ApiError
            4xx: unknown scene or path, or a server without the start bundle (404).
        """
        query: dict[str, Any] = {}
        if self.scene is not None:
            query["scene"] = self.scene
        if path is not None:
            query["path"] = path
        if x is not None and y is not None:
            query["x"], query["y"] = repr(float(x)), repr(float(y))
        if form != "params":
            query["form"] = form
        if view is not None:  # an interior's bundle then brings the first view's contents
            query.update(view=f"{view.size[0]}x{view.size[1]}", fov=_num(view.fov_deg), fog=_num(view.fog_m))
            if view.max_depth is not None:  # none: as deep as the fog reaches
                query["depth"] = str(view.max_depth)
            if path is not None and path_head_s is not None:  # the path's head first, the whole after the contents
                query["head"] = _num(path_head_s)
            if path is not None and heads:  # the first view first: cells seen in part, a city's objects drawn
                query["heads"] = "1"  # (each byte of the request goes up before anything comes down)
            if path is not None and path_head_s is not None and heads and pose:  # the first pose, then the view
                query["pose"] = "1"
        if walls:  # a scene baked with walls: the sides and the first view's textures too
            query["walls"] = "true"
        url = str(httpx.URL("/v1/start", params=query))
        what = "start bundle"
        item = StartDecoder(form, heads, what)

        def on_head(r: httpx.Response) -> None:
            name = r.headers.get("x-scene")
            if name and self.scene is None:
                self.scene = name

        async for got in self._stream("GET", url, what, None, item, on_head=on_head):
            if got[0] == "rooms":  # a pack: its cells one by one, all in at once
                for room in got[1]:
                    yield "room", room
            else:
                yield got
        short = item.short()
        if short is not None:
            self.stats.cut_streams += 1
            raise StreamCut(f"{what}: ended {short} short", item.k)

    async def _stream(
        self,
        method: str,
        url: str,
        what: str,
        body: Any,
        check: Any,
        *,
        meter: bool = False,
        on_head: Any = None,
    ) -> AsyncIterator[Any]:
        """Yield ``check(obj, nbytes)`` for each msgpack object of a streamed answer, bounded.

        ``nbytes`` is what the object cost on the wire: its encoded size, scaled by the
        stream's compression ratio so far when the answer is gzip-compressed.

        ``meter`` folds the body's throughput into :attr:`stats` (the object streams,
        long enough to measure).  A transport failure, a bad status or a
        :class:`CodecError` from ``check`` is a :class:`StreamCut`; 4xx an :class:`ApiError`.
        """
        got = 0
        t0 = self.clock.now()
        kw: dict[str, Any] = {
            "headers": {
                "Accept": MSGPACK,
                "Accept-Encoding": "gzip" if self.compress else "identity",
            }
        }
        if body is not None:
            kw["content"] = msgpack.packb(body)
            kw["headers"]["Content-Type"] = MSGPACK
        try:
            async with self.http.stream(method, url, **kw) as r:
                self.stats.observe_rtt(self.clock.now() - t0)
                if r.status_code < 500:
                    self.stats.reached(self.clock.now())
                else:
                    self.stats.failed(t0)
                if r.status_code != 200:
                    await r.aread()
                    if 400 <= r.status_code < 500:
                        raise _req_error(what, r)
                    raise StreamCut(f"{what}: HTTP {r.status_code}", 0)
                if on_head is not None:
                    on_head(r)
                coding = r.headers.get("content-encoding", "identity").lower()
                if coding not in ("identity", "gzip"):
                    raise StreamCut(f"{what}: unknown content encoding {coding!r:.40}", 0)
                inflater = zlib.decompressobj(31) if coding == "gzip" else None
                unpacker = msgpack.Unpacker(
                    raw=False,
                    max_buffer_size=_MAX_FRAME,
                    max_array_len=1 << 20,
                    max_map_len=64,
                    max_str_len=1 << 12,
                    max_bin_len=_MAX_FRAME,
                    max_ext_len=0,
                    strict_map_key=True,
                )
                consumed = 0
                first_chunk_t: float | None = None
                first_chunk_bytes = 0
                body_bytes = 0
                inflated = 0
                async for chunk in r.aiter_raw():
                    if first_chunk_t is None:
                        first_chunk_t = self.clock.now()
                        first_chunk_bytes = len(chunk)
                    body_bytes += len(chunk)
                    pending = chunk
                    while pending:
                        if inflater is None:
                            data, pending = pending, b""
                        else:
                            # bounded: a compressed bomb cannot make more than this at once
                            data = inflater.decompress(pending, _MAX_FRAME)
                            pending = inflater.unconsumed_tail
                        unpacker.feed(data)
                        inflated += len(data)
                        for obj in unpacker:
                            pos = unpacker.tell()
                            # what the item cost on the wire: compressed, its share
                            wire = round((pos - consumed) * body_bytes / max(inflated, 1))
                            try:
                                item = check(obj, wire)
                            except CodecError as exc:
                                raise StreamCut(f"{what}: {exc}", got) from exc
                            consumed = pos
                            got += 1
                            yield item
                if meter and first_chunk_t is not None:
                    self.stats.observe_transfer(
                        body_bytes - first_chunk_bytes, self.clock.now() - first_chunk_t
                    )
        except StreamCut:
            self.stats.cut_streams += 1
            raise
        except (httpx.TransportError, httpx.StreamError, httpx.DecodingError) as exc:
            self.stats.cut_streams += 1
            if got == 0 and isinstance(exc, httpx.ConnectError | httpx.ConnectTimeout):
                self.stats.failed(t0)  # no server to connect to, not a cut stream
            raise StreamCut(f"{what}: cut after {got} items ({exc})", got) from exc
        except (msgpack.UnpackException, ValueError, zlib.error) as exc:
            # includes msgpack's BufferFull / limits: corrupt bytes, fetch again
            self.stats.cut_streams += 1
            raise StreamCut(f"{what}: corrupt after {got} items ({exc})", got) from exc


def _num(v: float) -> str:
    """A query's number in its shortest exact form (``60`` for 60.0: ``repr`` otherwise)."""
    f = float(v)
    return str(int(f)) if f.is_integer() and abs(f) < 1e15 else repr(f)
