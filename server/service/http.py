"""HTTP representations: content negotiation, encoding, strong ETags and 304s, compressed streams.

Every route under ``/v1`` answers in msgpack unless the request's ``Accept``
prefers JSON; whatever is keyed by a scene version has a strong ``ETag`` naming
version, resource and representation and a year-long immutable Cache-Control.
A streamed answer (objects, cell records, the start bundle) is gzip-compressed
(``Content-Encoding: gzip``) when the request's ``Accept-Encoding`` allows it,
flushed after every piece so that a client decodes each item as soon as its
bytes are in (:func:`stream_response`): the repeated keys of msgpack frames
compress to about half.
"""

from __future__ import annotations

import hashlib
import json
import math
import re
import zlib
from collections.abc import AsyncIterator
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, Literal

import msgpack
from fastapi import Request, Response
from fastapi.responses import StreamingResponse

from walkstream.shared.wire import (
    JSON,
    MSGPACK,
    MSGPACK_TYPES,
)

__all__ = [
    "cached",
    "IMMUTABLE",
    "Rep",
    "negotiate",
    "etag_for",
    "etag_matches",
    "dump_json",
    "dump_msgpack",
    "Encoded",
    "encode",
    "accepts_gzip",
    "stream_response",
    "content_digest",
]

IMMUTABLE = "public, max-age=31536000, immutable"
"""Cache-Control of everything keyed by a scene version."""

Rep = Literal["msgpack", "json"]
"""A representation: msgpack (default) or JSON."""

_MEDIA: dict[str, str] = {"msgpack": MSGPACK, "json": JSON}

# an ETag's resource part is written as is when it is made of these, else hashed
# (ETags may not hold spaces or quotes, and recorded path names may)
_SAFE_TAG = re.compile(r"[A-Za-z0-9._:+-]{1,120}")




# ---------------------------------------------------------------------------
# representations, ETags
# ---------------------------------------------------------------------------


def negotiate(accept: str | None) -> Rep:
    """The representation an ``Accept`` header asks for.

    msgpack unless ``application/json`` has a higher quality than every msgpack
    type; a missing header, ``*/*`` or types the service does not serve also give
    msgpack (the default), never a 406.
    """
    if not accept:
        return "msgpack"
    # clients send few distinct headers, so parsing is cached; odd long ones are not,
    # so that they cannot fill the cache with large strings
    return _negotiate_cached(accept) if len(accept) <= 256 else _negotiate(accept)


@lru_cache(maxsize=256)
def _negotiate_cached(accept: str) -> Rep:
    return _negotiate(accept)


def _qualities(header: str) -> list[tuple[str, float]]:
    """``(token, quality)`` of each part of an ``Accept``-like header (lower case; q 1 by
    default, 0 when it does not parse)."""
    out = []
    for part in header.split(","):
        token, *params = part.split(";")
        q = 1.0
        for p in params:
            key, _, value = p.partition("=")
            if key.strip().lower() == "q":
                try:
                    q = float(value.strip())
                except ValueError:
                    q = 0.0
                if not math.isfinite(q):
                    q = 0.0
        out.append((token.strip().lower(), q))
    return out


def _negotiate(accept: str) -> Rep:
    q_json = q_msgpack = -1.0
    for media, q in _qualities(accept):
        if media == JSON:
            q_json = max(q_json, q)
        elif media in MSGPACK_TYPES:
            q_msgpack = max(q_msgpack, q)
    return "json" if q_json > 0 and q_json > q_msgpack else "msgpack"


def etag_for(version: str, resource: str, rep: str) -> str:
    """A strong ETag naming the scene version, the resource and the representation."""
    tag = resource if _SAFE_TAG.fullmatch(resource) else "h" + content_digest(resource.encode())
    return f'"{version}-{tag}-{rep}"'


def etag_matches(if_none_match: str | None, etag: str) -> bool:
    """Whether an ``If-None-Match`` header matches ``etag`` (weak comparison, RFC 9110)."""
    if not if_none_match:
        return False
    if if_none_match.strip() == "*":
        return True
    for t in if_none_match.split(","):
        t = t.strip()
        if t.startswith("W/"):
            t = t[2:]
        if t == etag:
            return True
    return False


def content_digest(data: bytes) -> str:
    """First 20 hex digits of the sha256 of ``data`` (what an ETag is made of)."""
    return hashlib.sha256(data).hexdigest()[:20]


def dump_json(obj: Any) -> bytes:
    """Compact UTF-8 JSON; refuses NaN and infinities (they are not JSON)."""
    return json.dumps(obj, separators=(",", ":"), ensure_ascii=False, allow_nan=False).encode()


def dump_msgpack(obj: Any) -> bytes:
    """msgpack with ``bin`` for bytes and float64 for floats."""
    data: bytes = msgpack.packb(obj, use_bin_type=True)
    return data


@dataclass(frozen=True, slots=True)
class Encoded:
    """A response body ready to send: bytes, media type and ETag."""

    content: bytes
    media_type: str
    etag: str


def encode(obj: Any, rep: Rep, version: str, resource: str) -> Encoded:
    """Encode ``obj`` in representation ``rep`` with its ETag."""
    content = dump_json(obj) if rep == "json" else dump_msgpack(obj)
    return Encoded(content, _MEDIA[rep], etag_for(version, resource, rep))


def cached(request: Request, enc: Encoded, cache_control: str = IMMUTABLE) -> Response:
    """A response for a pre-encoded body, or 304 when ``If-None-Match`` matches its ETag."""
    headers = {"ETag": enc.etag, "Cache-Control": cache_control, "Vary": "Accept"}
    if etag_matches(request.headers.get("if-none-match"), enc.etag):
        return Response(status_code=304, headers=headers)
    return Response(enc.content, media_type=enc.media_type, headers=headers)


# ---------------------------------------------------------------------------
# compressed streams
# ---------------------------------------------------------------------------


def accepts_gzip(accept_encoding: str | None) -> bool:
    """Whether an ``Accept-Encoding`` header allows ``gzip`` (quality above 0).

    >>> accepts_gzip("gzip, deflate"), accepts_gzip("identity"), accepts_gzip("gzip;q=0")
    (True, False, False)
    """
    return any(coding in ("gzip", "*") and q > 0 for coding, q in _qualities(accept_encoding or ""))


async def _gzipped(pieces: AsyncIterator[bytes], level: int = 6) -> AsyncIterator[bytes]:
    """gzip the pieces, flushing after each so the receiver can decode all that came."""
    co = zlib.compressobj(level, zlib.DEFLATED, 31)
    async for p in pieces:
        out = co.compress(p) + co.flush(zlib.Z_SYNC_FLUSH)
        if out:
            yield out
    yield co.flush()


def stream_response(
    request: Request, pieces: AsyncIterator[bytes], media_type: str, headers: dict[str, str], level: int = 6
) -> StreamingResponse:
    """A streamed answer, gzip-compressed (zlib ``level``) when the request's
    ``Accept-Encoding`` allows it."""
    headers = {**headers, "Vary": "Accept, Accept-Encoding"}
    if accepts_gzip(request.headers.get("accept-encoding")):
        headers["Content-Encoding"] = "gzip"
        return StreamingResponse(_gzipped(pieces, level), media_type=media_type, headers=headers)
    return StreamingResponse(pieces, media_type=media_type, headers=headers)
