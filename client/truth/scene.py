"""What the ground truth needs of a scene, fetched through the HTTP API on an unshaped path.

The truth must know every object of the scene, not only those some PVS names, and
every room cell's contents (:func:`fetch_contents`), so it asks the service for all of
them -- but not over the walk's link: it talks to the
same server through the *inner* httpx transport (the one the shaped link wraps),
with a client of its own, after the walk is over.  Nothing it fetches is counted in
the link's bytes, and under the simulated clock it runs inside ``clock.busy()``, so
it costs no simulated time.  The answers are decoded by the same bounded decoders
as the client's (:mod:`walkstream.shared.wire`, :mod:`walkstream.shared.codec`).

Object ids: the manifest says how many objects there are, not which ids; the truth
asks for ids from 0 up, a batch at a time, and the service's 404 names the ids it
does not have, so any id scheme is found (every source writes 0 .. n - 1 today, one
pass).
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Sequence
from typing import Any

import httpx
import msgpack
import numpy as np
from numpy.typing import NDArray

from walkstream.client.net.api import SceneClient
from walkstream.shared.areakinds import AREA_Z_LOWEST
from walkstream.shared.areas import build_flat
from walkstream.shared.buildings import build_lod
from walkstream.shared.codec import decode_object
from walkstream.shared.codec.cellmesh import CellMesh
from walkstream.shared.errors import ApiError, CodecError
from walkstream.shared.lsystem.grammar import Grammar, parse_grammar
from walkstream.shared.records import AreaParams, BuildingParams, Mesh, StreetParams
from walkstream.shared.scene.placement import ContentsPlacement
from walkstream.shared.wire import (
    MSGPACK,
    Manifest,
    decode_cell,
    decode_frame,
    decode_locate,
    decode_manifest,
)

__all__ = ["TruthScene", "UnshapedTransport", "fetch_contents"]

_MAX_STREAM = 256 << 20


class UnshapedTransport(httpx.AsyncBaseTransport):
    """The inner transport, borrowed: closing this client must not close the walk's."""

    def __init__(self, inner: httpx.AsyncBaseTransport) -> None:
        self._inner = inner

    async def handle_async_request(self, request: httpx.Request) -> httpx.Response:
        return await self._inner.handle_async_request(request)

    async def aclose(self) -> None:
        return None


class TruthScene:
    """Every object of one scene (parameters), its grammar, and cells on demand.

    Make one with :meth:`fetch`; then :meth:`lod2` builds LOD2 meshes from the
    parameters with the scene's own grammar, and :meth:`cell_pvs` / :meth:`locate`
    answer from the service (cached).
    """

    def __init__(
        self,
        http: httpx.AsyncClient,
        scene: str,
        manifest: Manifest,
        params: dict[int, BuildingParams | StreetParams | AreaParams],
    ) -> None:
        self._http = http
        self.scene = scene
        self.manifest = manifest
        self.params = params
        self._grammar: Grammar | None = None
        self._pvs: dict[int, NDArray[np.int64]] = {}
        self._meshes: dict[int, Mesh] = {}

    @classmethod
    async def fetch(
        cls, transport: httpx.AsyncBaseTransport, base_url: str, scene: str
    ) -> TruthScene:
        """The manifest and every object's parameters of ``scene``, over ``transport`` as it is.

        Raises
        ------
        ApiError
            The service refuses or sends something unusable.
        """
        http = httpx.AsyncClient(
            transport=UnshapedTransport(transport), base_url=base_url, timeout=httpx.Timeout(120.0)
        )
        try:
            r = await http.get(f"/v1/scenes/{scene}", headers={"Accept": MSGPACK})
            _check(r, f"scene {scene!r} manifest")
            manifest = decode_manifest(r.content, f"scene {scene!r} manifest")
            params = await _all_objects(http, scene, manifest)
        except BaseException:
            await http.aclose()
            raise
        return cls(http, scene, manifest, params)

    async def close(self) -> None:
        """Close the truth's own HTTP client (the transport stays the walk's)."""
        await self._http.aclose()

    @property
    def grammar(self) -> Grammar:
        """The scene's building grammar (parsed when first needed: an interior has none to build)."""
        if self._grammar is None:
            self._grammar = parse_grammar(self.manifest.grammar_text)
        return self._grammar

    # -- geometry -------------------------------------------------------------------

    def boxes(self) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]:
        """``(ids, lo, hi)``: every object's bounding box from its parameters (a little generous).

        ``lo``, ``hi`` are ``(n, 3)``: footprint bounds grown by 1 m, from the ground to
        the height plus 2 m (parapets, ledges), so a box never misses the LOD2 mesh.
        """
        ids = np.array(sorted(self.params), np.int64)
        lo = np.zeros((len(ids), 3))
        hi = np.zeros((len(ids), 3))
        for k, i in enumerate(ids.tolist()):
            p = self.params[i]
            ring = p.ring if isinstance(p, StreetParams) else p.rings[0]
            lo[k, :2], hi[k, :2] = ring.min(axis=0) - 1.0, ring.max(axis=0) + 1.0
            hi[k, 2] = (p.top if isinstance(p, BuildingParams) else 0.0) + 2.0
            if isinstance(p, AreaParams):
                lo[k, 2] = min(lo[k, 2], AREA_Z_LOWEST)
        return ids, lo, hi

    def lod2(self, ids: Iterable[int]) -> dict[int, Mesh]:
        """LOD2 meshes of ``ids``, built once each from the parameters with the scene's grammar."""
        out: dict[int, Mesh] = {}
        for i in ids:
            m = self._meshes.get(int(i))
            if m is None:
                p = self.params[int(i)]
                m = build_lod(p, 2, self.grammar) if isinstance(p, BuildingParams) else build_flat(p)
                self._meshes[int(i)] = m
            out[int(i)] = m
        return out

    # -- cells ----------------------------------------------------------------------

    async def cell_pvs(self, cid: int) -> NDArray[np.int64]:
        """The PVS of cell ``cid`` as the service has it."""
        got = self._pvs.get(cid)
        if got is None:
            what = f"cell {cid}"
            r = await self._http.get(f"/v1/scenes/{self.scene}/cells/{cid}", headers={"Accept": MSGPACK})
            _check(r, what)
            got = np.asarray(decode_cell(r.content, what).pvs, np.int64)
            self._pvs[cid] = got
        return got

    async def locate(self, x: float, y: float) -> int | None:
        """The cell at a position, or None outside every cell."""
        what = f"locate ({x:.2f}, {y:.2f})"
        r = await self._http.get(
            f"/v1/scenes/{self.scene}/locate", params={"x": repr(float(x)), "y": repr(float(y))},
            headers={"Accept": MSGPACK},
        )
        _check(r, what)
        return decode_locate(r.content, what)


async def fetch_contents(
    transport: httpx.AsyncBaseTransport,
    base_url: str,
    scene: str,
    cells: Iterable[int],
    clock: Any,
    placements: Sequence[ContentsPlacement] = (),
) -> dict[int, CellMesh]:
    """Room cells ``cells``' contents of ``scene``, decoded, over ``transport`` as it is.

    The one place the truth fetches room contents (by the client's own call,
    :meth:`~walkstream.client.net.api.SceneClient.contents`), one cell at a time;
    a cell one of ``placements`` holds (a crossing's interior, kept in its own frame) is
    placed as the walk's streamer places it.
    """
    out: dict[int, CellMesh] = {}
    async with httpx.AsyncClient(transport=UnshapedTransport(transport), base_url=base_url,
                                 timeout=httpx.Timeout(120.0)) as http:
        api = SceneClient(http, clock, scene)
        for c in cells:
            mesh = await api.contents(int(c))
            placed = next((p for p in placements if p.holds(int(c))), None)
            out[int(c)] = mesh if placed is None else placed.place(mesh)
    return out


def _check(r: httpx.Response, what: str) -> None:
    if r.status_code != 200:
        raise ApiError(f"ground truth: {what}: HTTP {r.status_code}", r.status_code, _detail(r))


def _detail(r: httpx.Response) -> Any:
    try:
        return json.loads(r.content).get("detail")
    except (ValueError, AttributeError):
        return None


async def _all_objects(
    http: httpx.AsyncClient, scene: str, manifest: Manifest
) -> dict[int, BuildingParams | StreetParams | AreaParams]:
    """Every object of the scene: ids from 0 up, in batches, until the manifest's count is found."""
    want = int(manifest.objects)
    batch = max(1, int(manifest.max_ids))
    out: dict[int, BuildingParams | StreetParams | AreaParams] = {}
    start = 0
    # ids beyond 0 .. n - 1 are looked for, but not forever
    limit = 4 * want + 100_000
    while len(out) < want:
        if start > limit:
            raise ApiError(
                f"ground truth: found {len(out)} of the {want} objects of scene {scene!r} "
                f"among ids 0 .. {start - 1}"
            )
        ids = list(range(start, start + batch))
        start += batch
        r = await http.post(
            f"/v1/scenes/{scene}/objects",
            content=msgpack.packb({"ids": ids}),
            headers={"Content-Type": MSGPACK, "Accept": MSGPACK},
        )
        if r.status_code == 404:
            detail = _detail(r)
            unknown = set(detail.get("ids", [])) if isinstance(detail, dict) else set()
            ids = [i for i in ids if i not in unknown]
            if not ids or not unknown:
                continue
            r = await http.post(
                f"/v1/scenes/{scene}/objects",
                content=msgpack.packb({"ids": ids}),
                headers={"Content-Type": MSGPACK, "Accept": MSGPACK},
            )
        _check(r, f"objects ({len(ids)} ids)")
        unpacker = msgpack.Unpacker(
            raw=False, max_buffer_size=_MAX_STREAM, max_array_len=16, max_map_len=8,
            max_str_len=64, max_bin_len=_MAX_STREAM, max_ext_len=0, strict_map_key=True,
        )
        unpacker.feed(r.content)
        got = 0
        try:
            for k, obj in enumerate(unpacker):
                if k >= len(ids):
                    raise CodecError("more objects than asked")
                frame = decode_frame(obj, ids[k], "params", 0, f"object {ids[k]}")
                out[ids[k]] = decode_object(frame.payload, f"object {ids[k]}")
                got += 1
        except (CodecError, msgpack.UnpackException, ValueError) as exc:
            raise ApiError(f"ground truth: objects stream of scene {scene!r}: {exc}") from exc
        if got != len(ids):
            raise ApiError(f"ground truth: asked {len(ids)} objects, got {got}")
    return out
