"""The client's view of the walkstream HTTP API: typed records, bounded decoding, retries.

Everything the server sends is untrusted bytes: every body is unpacked with hard
limits (:func:`~walkstream.shared.codec.unpack_bounded`, or a bounded ``msgpack.Unpacker`` for
the object stream) and checked field by field, so a corrupt or hostile response is
an :class:`ApiError` (and fetched again), never a crash.

Idempotent requests (manifest, path, locate, cell) are retried with capped
exponential backoff on transport errors, 5xx answers and undecodable bodies: a
server restart or a dropped connection mid-walk costs time, not the walk.  The
object stream is *not* retried here: :meth:`SceneClient.objects` yields each object
as soon as its last byte arrives and raises :class:`StreamCut` when the stream
ends early or turns bad, so the caller re-queues exactly the ids it did not get
(nothing lost, nothing duplicated).

The client only knows an :class:`httpx.AsyncClient`; whether it talks to a server
over real sockets or to the app in-process is decided by whoever builds it.
"""

from __future__ import annotations

import math
import random
from collections.abc import AsyncIterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import httpx
import msgpack

from walkstream.client.clock import Clock
from walkstream.shared.codec.cellmesh import CellMesh, decode_cell_mesh
from walkstream.shared.errors import ApiError, CodecError, StreamCut
from walkstream.shared.paths import RecordedPath
from walkstream.shared.wire import (
    MSGPACK,
    CellRecord,
    Manifest,
    ObjectFrame,
    RoomRecord,
    Topology,
    decode_cell,
    decode_frame,
    decode_locate,
    decode_manifest,
    decode_room,
    decode_scene_list,
    decode_topology,
)

__all__ = [
    "SceneClient",
]


_MAX_FRAME = 32 << 20  # one object frame (an LOD2 mesh of a large block fits)












@dataclass
class TransferStats:
    """What the client observed of the link (it is never told the link's settings)."""

    rtt_s: float = math.nan
    """Smoothed time from sending a small request to its answer's headers."""
    bandwidth_bps: float = math.nan
    """Smoothed body throughput of object streams, bits per second."""
    retries: int = 0
    cut_streams: int = 0
    samples: list[tuple[float, float]] = field(default_factory=list)

    def observe_rtt(self, seconds: float) -> None:
        """Fold one request/headers time into the estimate."""
        if seconds > 0 and math.isfinite(seconds):
            self.rtt_s = seconds if math.isnan(self.rtt_s) else 0.7 * self.rtt_s + 0.3 * seconds

    def observe_transfer(self, nbytes: int, seconds: float) -> None:
        """Fold one body transfer (bytes after the first chunk, and its duration) in."""
        if nbytes >= 512 and seconds > 1e-6 and math.isfinite(seconds):
            bps = nbytes * 8.0 / seconds
            self.bandwidth_bps = (
                bps if math.isnan(self.bandwidth_bps) else 0.7 * self.bandwidth_bps + 0.3 * bps
            )


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
    ) -> None:
        self.http = http
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
                if r.status_code in ok:
                    return r
                if r.status_code < 500:
                    raise _req_error(what, r)
                err: Exception = _req_error(what, r)
            except httpx.TransportError as exc:  # refused, reset, cut off, timed out
                err = exc
            if attempt >= self.max_attempts:
                raise ApiError(f"{what}: gave up after {attempt} attempts ({err})")
            await self._backoff(attempt)

    async def _backoff(self, attempt: int) -> None:
        self.stats.retries += 1
        lo, hi = self.backoff
        delay = min(hi, lo * 2 ** (attempt - 1)) * (0.75 + 0.5 * self._rng.random())
        await self.clock.sleep(delay)

    async def _get_decoded(self, url: str, what: str, decode: Any, **kw: Any) -> Any:
        """GET and decode, fetching again when the body cannot be decoded (corrupt/truncated)."""
        attempt = 0
        while True:
            attempt += 1
            r = await self._get(url, what, **kw)
            try:
                return r, decode(r)
            except CodecError as exc:
                if attempt >= self.max_attempts:
                    raise ApiError(f"{what}: undecodable answer ({exc})") from exc
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
            lambda r: (RecordedPath.from_msgpack(r.content, what), len(r.content)),
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

    async def topology(self) -> Topology:
        """The interior's topology: storeys, cells (plane sets), portals, stairs."""
        what = f"scene {self.scene!r} topology"
        _, t = await self._get_decoded(self._url("/topology"), what, lambda r: decode_topology(r.content, what))
        return t

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
            self._url(f"/rooms/{cid}/contents"), what, lambda r: decode_cell_mesh(r.content, what)
        )
        return mesh

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
        body = msgpack.packb({"ids": ids})
        url = self._url("/objects") + ("" if form == "params" else f"?form={form}")
        got = 0
        what = f"objects stream ({len(ids)} ids)"
        t0 = self.clock.now()
        try:
            async with self.http.stream(
                "POST",
                url,
                content=body,
                headers={"Content-Type": MSGPACK, "Accept": MSGPACK},
            ) as r:
                self.stats.observe_rtt(self.clock.now() - t0)
                if r.status_code != 200:
                    await r.aread()
                    if 400 <= r.status_code < 500:
                        raise _req_error(what, r)
                    raise StreamCut(f"{what}: HTTP {r.status_code}", 0)
                unpacker = msgpack.Unpacker(
                    raw=False,
                    max_buffer_size=_MAX_FRAME,
                    max_array_len=16,
                    max_map_len=8,
                    max_str_len=64,
                    max_bin_len=_MAX_FRAME,
                    max_ext_len=0,
                    strict_map_key=True,
                )
                consumed = 0
                first_chunk_t: float | None = None
                first_chunk_bytes = 0
                body_bytes = 0
                async for chunk in r.aiter_raw():
                    if first_chunk_t is None:
                        first_chunk_t = self.clock.now()
                        first_chunk_bytes = len(chunk)
                    body_bytes += len(chunk)
                    unpacker.feed(chunk)
                    for obj in unpacker:
                        pos = unpacker.tell()
                        frame = self._check_frame(obj, ids, got, form, pos - consumed, what)
                        consumed = pos
                        got += 1
                        yield frame
                if first_chunk_t is not None:
                    self.stats.observe_transfer(
                        body_bytes - first_chunk_bytes, self.clock.now() - first_chunk_t
                    )
        except (httpx.TransportError, httpx.StreamError) as exc:
            self.stats.cut_streams += 1
            raise StreamCut(f"{what}: cut after {got} objects ({exc})", got) from exc
        except (msgpack.UnpackException, ValueError) as exc:
            # includes msgpack's BufferFull / limits: corrupt bytes, fetch again
            self.stats.cut_streams += 1
            raise StreamCut(f"{what}: corrupt after {got} objects ({exc})", got) from exc
        if got < len(ids):
            self.stats.cut_streams += 1
            raise StreamCut(f"{what}: ended after {got} of {len(ids)} objects", got)

    @staticmethod
    def _check_frame(
        obj: Any, ids: list[int], k: int, form: str, nbytes: int, what: str
    ) -> ObjectFrame:
        if k >= len(ids):
            raise StreamCut(f"{what}: more objects than asked", k)
        try:
            return decode_frame(obj, ids[k], form, nbytes, f"{what}: object {k}")
        except CodecError as exc:
            raise StreamCut(str(exc), k) from exc
