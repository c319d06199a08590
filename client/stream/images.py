"""The impostor images' lane of the request scheduler: the images the frame wants, fetched in batches.

A scene baked with ``--impostors`` lists, in a cell's record, the images of the
buildings the cell may draw as impostors (:class:`~walkstream.shared.impostorwire.CellImpostors`).
The frame loop says which of them it wants and when (:meth:`ImpostorImages.want`:
the image of the viewer's direction bin of each listed building, needed *now* in the
current cell, and in the cells ahead at their predicted need times); this lane offers
them to the one :class:`~walkstream.client.stream.scheduler.RequestScheduler` in order
of need (:func:`offered_need`: the current cell's before anything due now, a cell
ahead's just before that cell's parameters), so a far building's image goes out before
its parameters, and caches each decoded image
(premultiplied RGBA) under ``("impostor", image id)`` at its texels' bytes.

The lane joins the scheduler only when something is first wanted: a scene without
impostors never wants an image, so its walks keep one lane and the very same
requests.

The same lane carries an interior's wall textures (``kind="walltex"``: textured
virtual walls, :mod:`walkstream.client.walk.walls`), fetched by ``POST
.../walls/textures`` and cached under ``("walltex", texture id)``: one image stack.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from walkstream.client.net.api import SceneClient
from walkstream.client.stream.cache import Cache
from walkstream.client.stream.scheduler import Flight, Offer, RequestScheduler
from walkstream.client.tasks import reap
from walkstream.shared.errors import ApiError, InputError, StreamCut

__all__ = ["AHEAD_LEAD_S", "IMAGE_LEAD_S", "WALL_BATCH", "WALL_LAG_S", "WALL_SPAN_S", "ImpostorImages", "offered_need"]

IMAGE_LEAD_S = -1.0
"""The need (seconds from now) an image of the current cell is offered at: before
anything the streamers need now (see :func:`offered_need`)."""

AHEAD_LEAD_S = 0.1
"""How much earlier than its cell's need an image of a cell ahead is offered."""

MAX_BATCH = 16
"""Images asked for in one request."""

MAX_REQUESTS = 2
"""This lane's requests on the link at once."""

_FETCH = {"impostor": "impostors", "walltex": "wall_textures"}
"""Content kind -> the API client's batch call (and the request's name on the scheduler)."""

WALL_LAG_S = 0.05
"""How much later than its need a wall texture is offered: a texture needed now goes
just after the contents due now (a wall without its texture is drawn as geometry, a
cell without its contents is a hole) and before any prefetch."""

WALL_SPAN_S = 0.5
"""Wall textures in one request: those needed within this many seconds of the first."""

WALL_BATCH = 2
"""Wall textures needed ahead (not now) in one request; those needed now go together,
up to :data:`MAX_BATCH`.  A texture is about 0.9 kB, an eighth of a second at 56 kbit/s:
a wall that comes into view when the walker turns waits for at most two requests of two
ahead of it.  With 16 to a request it could wait behind two requests of textures the
walk would need later (up to 2 s of the link), its wall stayed open and the cells behind
it, to the fog, were missing.  The production hall's tour: 96.5 -> 97.0 % perfect frames
(one ahead texture a request: 97.9 %, but the small test hall's walk fell to 99.4 %;
one a request for every texture: 98.1 % and 96.5 %)."""

IMAGE_BYTES = 12_000.0
"""An image's bytes on the wire before one has arrived (the scheduler's cover counts them)."""


def offered_need(need_s: float) -> float:
    """The need an image is offered at, given when it is needed (seconds from now).

    The current cell's images (needed now, 0) go :data:`IMAGE_LEAD_S` before anything
    the streamers need now; an image of a cell ahead just before the parameters that
    cell needs at the same time (:data:`AHEAD_LEAD_S`), but never before what is needed
    now: the first perfect frame waits for the current cell's parameters, not images.
    """
    if need_s <= 0.0:
        return IMAGE_LEAD_S
    return max(need_s - AHEAD_LEAD_S, AHEAD_LEAD_S / 2.0)


class ImpostorImages:
    """One lane of the link: impostor images (see the module docstring).

    Parameters
    ----------
    api
        The walk's API client.
    cache
        The walk's cache (images go under ``impostor``).
    scheduler
        The link's request scheduler, joined on the first want.
    """

    def __init__(self, api: SceneClient, cache: Cache, scheduler: RequestScheduler, *, kind: str = "impostor") -> None:
        if kind not in _FETCH:
            raise InputError(f"image lane: kind {kind!r:.40}, expected one of {', '.join(_FETCH)}")
        self.kind = kind
        """The content kind carried (``impostor`` or ``walltex``): the cache kind and the request."""
        self.api = api
        self.cache = cache
        self.scheduler = scheduler
        self.wanted: dict[int, float] = {}
        """Images wanted and not held, by need (seconds from now)."""
        self._asked: set[int] = set()
        self._coming: set[int] = set()  # brought by another way (the start bundle): not asked for
        self._now: set[Flight] = set()  # requests of textures needed now
        self._joined = False
        self._image_bytes = IMAGE_BYTES
        self.received = 0
        """Images received."""
        self.bytes_received = 0
        """Their bytes on the wire."""
        self.requests = 0
        """Requests made."""
        self.refused = False
        """The service refused a request (a scene without impostors): nothing more is asked."""
        self.started = False
        """Whether the walk's first cell had all its parameters once: until then the frame
        wants no image (:func:`~walkstream.client.walk.impostors.frame_impostors`)."""

    def held(self, image: int) -> bool:
        """Whether ``image`` is in the cache."""
        return self.cache.has(self.kind, image)

    def image(self, image: int) -> object | None:
        """The decoded image (premultiplied RGBA), or None when it is not held."""
        return self.cache.peek(self.kind, image) if self.held(image) else None

    def want(self, images: Mapping[int, float]) -> None:
        """The images wanted now (image id -> need, seconds from now); those held are dropped."""
        self.wanted = {int(i): float(t) for i, t in images.items() if not self.held(int(i))}
        if self.wanted and not self.refused:
            if not self._joined:
                self.scheduler.join(self)
                self._joined = True
            self.scheduler.dispatch()

    def adopt(self, image: int, rgba: Any, nbytes: int) -> None:
        """An image that came another way (a start bundle's wall texture): cached and
        counted as received, as if this lane had fetched it."""
        self.cache.put(self.kind, int(image), rgba, max(int(getattr(rgba, "nbytes", 1)), 1))
        self.received += 1
        self.bytes_received += int(nbytes)
        self.wanted.pop(int(image), None)

    def expect(self, images: set[int], coming: bool = True) -> None:
        """Images on their way another way (a start bundle's ``walltex`` part), not asked
        for while they come (``coming``), or no longer so: asking for one too would
        take the link from the bundle bringing it (two copies at once, both late)."""
        if coming:
            self._coming |= {int(i) for i in images}
        else:
            self._coming -= {int(i) for i in images}
            if self.wanted and not self.refused and self._joined:
                self.scheduler.dispatch()

    async def close(self) -> None:
        """Cancel this lane's requests (the walk ended) and wait for them to end."""
        self.refused = True  # nothing more is asked
        tasks = [f.task for f in self.scheduler.flights(self) if f.task is not None]
        await reap(tasks)

    # -- the scheduler's lane ------------------------------------------------------

    def offer(self) -> Offer | None:
        """The next batch of wanted images not asked for yet, needed before what is due now."""
        if self.refused:
            return None
        todo = sorted((t, i) for i, t in self.wanted.items()
                      if i not in self._asked and i not in self._coming and not self.held(i))
        if not todo:
            return None
        need = todo[0][0]
        urgent = self._urgent(need)
        if self.in_flight() >= MAX_REQUESTS + urgent:
            return None
        if self.kind == "impostor":
            ids = [i for _, i in todo[:MAX_BATCH]]
            offered = offered_need(need)  # by when their cell is needed
        else:
            # wall textures: those needed now just after the contents due now, those
            # ahead at their need; a request holds WALL_BATCH of them (needed within
            # WALL_SPAN_S of the first), so one wanted now is not queued behind far ones
            n = MAX_BATCH if need <= 0.0 else WALL_BATCH
            ids = [i for t, i in todo[:n] if t <= need + WALL_SPAN_S]
            offered = max(need, 0.0) + WALL_LAG_S
        return Offer(offered, lambda: self._start(ids, now=need <= 0.0), urgent=bool(urgent))

    def _urgent(self, need: float) -> int:
        """1 when wall textures needed now may take a request beyond :data:`MAX_REQUESTS`
        and beyond the link's slots (:attr:`~.scheduler.Offer.urgent`): none of this
        lane's requests on the link holds textures needed now.  A wall that comes into
        view as the walker turns is then not queued behind the textures of walls needed
        later, nor behind a prefetch of cell contents; else 0."""
        if self.kind != "walltex" or need > 0.0:
            return 0
        return int(not any(f in self._now for f in self.scheduler.flights(self)))

    def in_flight(self) -> int:
        """This lane's requests on the link."""
        return len(self.scheduler.flights(self))

    def outstanding_bytes(self) -> float:
        """Images asked for and not received, at the mean image's bytes."""
        return sum(len(f.left) for f in self.scheduler.flights(self)) * self._image_bytes

    def _start(self, ids: list[int], now: bool = False) -> None:
        self._asked.update(ids)
        self.requests += 1
        f = self.scheduler.launch(self, _FETCH[self.kind], ids, self._fetch)
        if now:
            self._now.add(f)

    async def _fetch(self, f: Flight) -> None:
        try:
            async for iid, rgba, nbytes in getattr(self.api, _FETCH[self.kind])(f.ids):
                f.left.discard(iid)
                self.cache.put(self.kind, iid, rgba, max(int(rgba.nbytes), 1))
                self.received += 1
                self.bytes_received += int(nbytes)
                self._image_bytes = 0.8 * self._image_bytes + 0.2 * max(int(nbytes), 1)
                self.wanted.pop(iid, None)
        except ApiError:
            self.refused = True  # a scene without impostors (or images it does not hold)
        except StreamCut:
            pass  # what did not come is wanted again at the next want
        finally:
            self.scheduler.landed(f)
            self._now.discard(f)
            self._asked.difference_update(f.ids)
        if not self.refused:
            self.scheduler.dispatch()
