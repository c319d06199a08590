"""Check the blob framing of an ``.osm.pbf`` file before osmium reads it.

libosmium stops quietly at a file cut short inside a blob (a truncated download), so a
damaged extract read as "no usable feature", or as a smaller city than it is.  A PBF
file is a run of blobs, each a 4-byte big-endian header length, a ``BlobHeader``
message (its field 3, ``datasize``, is the blob's length) and the blob; walking the
lengths alone (no decompression, a few microseconds per blob) finds a file that ends
inside one.
"""

from __future__ import annotations

import struct
from pathlib import Path

from walkstream.shared.errors import SourceError

__all__ = ["check_pbf_framing"]

#: The format's own limits: a BlobHeader under 64 KiB, a blob under 32 MiB.
_MAX_HEADER = 64 << 10
_MAX_BLOB = 32 << 20


def _varint(buf: bytes, pos: int) -> tuple[int, int]:
    value = shift = 0
    while pos < len(buf):
        byte = buf[pos]
        pos += 1
        value |= (byte & 0x7F) << shift
        if not byte & 0x80:
            return value, pos
        shift += 7
        if shift > 63:
            break
    raise ValueError("bad varint")


def _datasize(header: bytes) -> int:
    """Field 3 (``datasize``) of a BlobHeader message."""
    pos = 0
    while pos < len(header):
        key, pos = _varint(header, pos)
        field, wire = key >> 3, key & 7
        if wire == 0:
            value, pos = _varint(header, pos)
            if field == 3:
                return value
        elif wire == 2:
            size, pos = _varint(header, pos)
            pos += size
        else:
            raise ValueError(f"wire type {wire}")
    raise ValueError("no datasize")


def check_pbf_framing(path: Path) -> None:
    """Raise :class:`SourceError` (naming the file, the blob and the byte) unless every
    blob of the ``.osm.pbf`` file is whole.
    """
    size = path.stat().st_size
    with path.open("rb") as fh:
        pos = blob = 0
        while pos < size:
            head = fh.read(4)
            if len(head) < 4:
                raise SourceError(f"{path}: damaged .osm.pbf: ends inside the length of blob {blob} (byte {pos})")
            (hlen,) = struct.unpack(">I", head)
            header = fh.read(hlen) if hlen <= _MAX_HEADER else b""
            if hlen > _MAX_HEADER or len(header) < hlen:
                raise SourceError(
                    f"{path}: damaged .osm.pbf: blob {blob} at byte {pos} has a header of {hlen} bytes, "
                    f"{size - pos - 4} left in the file"
                )
            try:
                dsize = _datasize(header)
            except ValueError as exc:
                raise SourceError(f"{path}: damaged .osm.pbf: blob {blob} at byte {pos}: bad header ({exc})") from exc
            end = pos + 4 + hlen + dsize
            if dsize > _MAX_BLOB or end > size:
                raise SourceError(
                    f"{path}: damaged .osm.pbf: blob {blob} at byte {pos} needs {dsize} bytes, "
                    f"the file ends {end - size} bytes short (truncated?)"
                )
            fh.seek(end)
            pos, blob = end, blob + 1
