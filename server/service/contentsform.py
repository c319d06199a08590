"""Each cell's form in a gzip-compressed contents stream: whichever costs fewer bytes there.

A contents stream (a batch, ``GET .../contents?ids=``, or the start bundle's first view)
compressed as a whole used to carry every cell inflated to its ``N`` form, so that the
cells share one gzip dictionary (the mirrored homes of duplex.ifc compress against each
other).  But the bake stores each blob in the smaller of zlib and lzma, and on the
large cells lzma beats gzip by 10 to 12 %, dictionary or not: FZK-Haus's first view
(its start room, 8.4 kB stored, and its outside cell, 8.0 kB) came to 9.4 and 8.9 kB in
the stream, and the whole start bundle to 22.4 kB where 20.4 kB do (0.28 s at 56 kbit/s
before the first perfect frame).

:class:`ContentsStream` mirrors the answer's gzip stream (the same level and window,
flushed after each part as :func:`~walkstream.server.service.http.stream_response`
does) and, for each cell, compresses both forms of its part on copies of the mirror and
keeps the smaller; the chosen copy becomes the mirror.  Both forms decode the same way
on the client (the blob's tag byte says how it is compressed), carry the same ETag and
the same cell, so the choice changes bytes only.  The mirror follows the stream from
its first contents part (the start bundle's path and topology before it are not fed),
so the choice is the best one for a stream that starts there: close, never wrong.
"""

from __future__ import annotations

import zlib

__all__ = ["STREAM_LEVEL", "ContentsStream"]

STREAM_LEVEL = 9
"""The zlib level of every gzip-compressed contents stream (the batch route's and the
interior start bundle's)."""


class ContentsStream:
    """A mirror of a gzip-compressed contents stream that picks each part's cheaper form.

    Parameters
    ----------
    level:
        The stream's zlib level (:data:`STREAM_LEVEL`).
    """

    def __init__(self, level: int = STREAM_LEVEL) -> None:
        self._co = zlib.compressobj(level, zlib.DEFLATED, 31)
        self.nbytes = 0
        """Compressed bytes of the parts fed so far (the gzip header included)."""

    def feed(self, part: bytes) -> int:
        """Add ``part`` to the mirror as the stream sends it; its compressed bytes."""
        n = len(self._co.compress(part) + self._co.flush(zlib.Z_SYNC_FLUSH))
        self.nbytes += n
        return n

    def cost(self, *parts: bytes) -> int:
        """The fewest compressed bytes one of ``parts`` (alternative forms of the same
        part) would add after what the stream holds so far; nothing is fed."""
        if not parts:
            raise ValueError("cost: no part to weigh")
        return min(len((co := self._co.copy()).compress(p) + co.flush(zlib.Z_SYNC_FLUSH)) for p in parts)

    def cheaper(self, *parts: bytes) -> bytes:
        """The one of ``parts`` (alternative forms of the same part) that adds the fewest
        compressed bytes after what the stream holds so far (the first on a tie); it is
        fed to the mirror."""
        if not parts:
            raise ValueError("cheaper: no part to choose from")
        best: tuple[int, bytes, zlib._Compress] | None = None
        for p in dict.fromkeys(parts):  # the same bytes twice are tried once
            co = self._co.copy()
            n = len(co.compress(p) + co.flush(zlib.Z_SYNC_FLUSH))
            if best is None or n < best[0]:
                best = (n, p, co)
        assert best is not None
        self._co = best[2]
        self.nbytes += best[0]
        return best[1]
