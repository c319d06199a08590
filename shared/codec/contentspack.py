"""Several contents parts as one LZMA-compressed frame: an interior's first view in one dictionary.

The start bundle of an interior brings the contents of every cell the first pose sees,
and its first perfect frame waits for all of them (on the duplex, ten cells down five
doorways).  Sent one part at a time in the answer's gzip stream, each cell goes in the
cheaper of two forms (:mod:`~walkstream.server.service.contentsform`): inflated, so that
it shares gzip's 32 kB window with the cells before it, or as stored, compressed on its
own (lzma on the larger cells).  Neither form gets both LZMA's better coding and a
dictionary over the whole view.  One LZMA2 stream over the inflated parts does: the
duplex's first view (two heads and eight whole cells) costs 19.7 kB in the gzip stream
part by part and 17.3 kB as one pack.

A pack is the msgpack map::

    {"pack": "walkstream-contentspack/1", "parts": n, "body": bin}

``body`` is a raw LZMA2 stream (:mod:`~walkstream.shared.codec.rawlzma`) of ``n`` contents
parts (:mod:`~walkstream.shared.codec.cellbatch`: ``{cell, etag, body}`` or a head's
``{cell, etag, body, missing}``) packed one after the other, each exactly as it would
go alone.  A reader unpacks the ``n`` parts and reads each as if it had come alone; a
pack's parts are all in when the pack is, so a client that needs every one of them
(a first perfect frame) waits no longer for it, and one that could use the first
early waits for the last.

Column by column (``walkstream-contentspack/2``): the same map, its ``body`` the raw
LZMA2 stream of the msgpack array ``[rows, columns, etags]``.  Each part's inflated
cell mesh (``body`` ``N`` + a msgpack map, :mod:`~walkstream.shared.codec.cellmesh`)
is taken apart field by field: ``rows`` holds one ``[part, keys]`` per part, the
part's map with ``body`` nil and ``keys`` its mesh's field names in order (``true``:
every column's, in the columns' order; ``[part, nil]``: the part as it is, its body
not an inflated mesh); ``columns`` maps each field name to the list of that field's
values over the parts that have it, in part order; ``etags`` is nil or ``[before,
after]``, and a row's etag nil stands for ``before:ID-after`` with ID its cell id (the
server's etags name the scene version, ``contents:ID`` and the representation, so one
pattern gives them all).  A cell's positions then sit beside the other cells'
positions, its indices beside theirs, and LZMA's matches and literal coding find more
alike: the duplex's first view 15,885 -> 15,289 B.  The reader packs every part back,
byte for byte the part that went in (:func:`pack_parts` sends this form only when it
does, and only when it is smaller), and reads them as from the first form.

Decoding is bounded: at most :data:`MAX_PACK_BYTES` inflated, exactly ``n`` parts,
nothing after the last; any failure is a :class:`~walkstream.shared.errors.CodecError`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import msgpack

from walkstream.shared.codec.rawlzma import compress_raw, decompress_raw
from walkstream.shared.errors import CodecError

__all__ = ["PACK_FORMAT", "COLUMNS_FORMAT", "MAX_PACK_BYTES", "MAX_PACK_PARTS", "pack_parts", "is_pack",
           "unpack_parts"]

PACK_FORMAT = "walkstream-contentspack/1"
"""The ``pack`` field of a pack, its parts one after the other."""

COLUMNS_FORMAT = "walkstream-contentspack/2"
"""The ``pack`` field of a pack whose cell meshes go field by field (column by column)."""

MAX_PACK_BYTES = 64 << 20
"""Most bytes a pack's body inflates to."""

MAX_PACK_PARTS = 1 << 10
"""Most parts in one pack."""

_KEYS = frozenset({"pack", "parts", "body"})


def pack_parts(parts: Sequence[bytes], columns: bool = True) -> bytes:
    """The packed msgpack map of a pack of ``parts`` (each a packed contents part):
    column by column (:data:`COLUMNS_FORMAT`) where ``columns``, that form gives the
    parts back byte for byte and is smaller, else one after the other.

    Raises
    ------
    ValueError
        No part, or more than :data:`MAX_PACK_PARTS`.
    """
    if not 0 < len(parts) <= MAX_PACK_PARTS:
        raise ValueError(f"a pack holds 1 to {MAX_PACK_PARTS} parts, got {len(parts)}")
    raw = b"".join(parts)
    fmt, body = PACK_FORMAT, compress_raw(raw)
    table = _columns(parts) if columns else None
    if table is not None:
        cbody = compress_raw(table)
        if len(cbody) < len(body) and _rows_back(table, "contents pack") == raw:
            fmt, body = COLUMNS_FORMAT, cbody
    data: bytes = msgpack.packb({"pack": fmt, "parts": len(parts), "body": body}, use_bin_type=True)
    return data


def _columns(parts: Sequence[bytes]) -> bytes | None:
    """``[columns, rows]`` packed (see the module's doc), or None where a part is not a
    msgpack map."""
    columns: dict[str, list[Any]] = {}
    rows: list[list[Any]] = []
    for p in parts:
        obj = msgpack.unpackb(p, raw=False)
        if not isinstance(obj, dict):
            return None
        body = obj.get("body")
        mesh = None
        if isinstance(body, bytes) and body[:1] == b"N":
            try:
                mesh = msgpack.unpackb(body[1:], raw=False)
            except (msgpack.UnpackException, ValueError):
                mesh = None
        if not isinstance(mesh, dict) or not all(isinstance(k, str) for k in mesh):
            rows.append([obj, None])
            continue
        for k, v in mesh.items():
            columns.setdefault(k, []).append(v)
        rows.append([{k: (None if k == "body" else v) for k, v in obj.items()}, list(mesh)])
    order = list(columns)
    for row in rows:  # most meshes have every field, in the same order: one ``true`` says so
        if row[1] == order:
            row[1] = True
    etags = _etag_pattern([r[0] for r in rows])
    if etags is not None:  # each etag the server's pattern around its cell id: left out
        for row in rows:
            if row[0].get("etag") == _etag_of(etags, row[0].get("cell")):
                row[0] = {**row[0], "etag": None}
    data: bytes = msgpack.packb([rows, columns, etags], use_bin_type=True)
    return data


def _etag_pattern(parts: list[dict[Any, Any]]) -> list[str] | None:
    """``[before, after]`` such that the first part's etag is ``before:ID-after`` (ID its
    cell id), or None."""
    for part in parts:
        etag, cell = part.get("etag"), part.get("cell")
        if isinstance(etag, str) and type(cell) is int and etag.count(f":{cell}-") == 1:
            return etag.split(f":{cell}-")
    return None


def _etag_of(pattern: list[str], cell: Any) -> str | None:
    """The etag ``pattern`` gives ``cell`` (None: no int cell)."""
    return f"{pattern[0]}:{cell}-{pattern[1]}" if type(cell) is int else None


def _rows_back(table: bytes, what: str) -> bytes:
    """The parts of a :data:`COLUMNS_FORMAT` body (inflated), packed back one after the other."""
    try:
        obj = msgpack.unpackb(table, raw=False, max_bin_len=len(table), max_str_len=len(table),
                              max_array_len=len(table), max_map_len=len(table), max_ext_len=0)
    except (msgpack.UnpackException, ValueError) as exc:
        raise CodecError(f"{what}: damaged columns ({exc})") from exc
    if not (isinstance(obj, list) and len(obj) == 3 and isinstance(obj[0], list) and isinstance(obj[1], dict)):
        raise CodecError(f"{what}: columns must be [rows, columns, etags]")
    rows, columns, etags = obj
    if etags is not None and not (isinstance(etags, list) and len(etags) == 2
                                  and all(isinstance(e, str) for e in etags)):
        raise CodecError(f"{what}: the etags' pattern must be nil or [before, after]")
    if not all(isinstance(v, list) for v in columns.values()):
        raise CodecError(f"{what}: a column that is not a list")
    at = dict.fromkeys(columns, 0)
    out: list[bytes] = []
    for row in rows:
        if not (isinstance(row, list) and len(row) == 2 and isinstance(row[0], dict)):
            raise CodecError(f"{what}: a row that is not [part, keys]")
        part, keys = row
        if etags is not None and "etag" in part and part["etag"] is None:
            part = {**part, "etag": _etag_of(etags, part.get("cell"))}
        if keys is True:
            keys = list(columns)
        if keys is not None:
            if not (isinstance(keys, list) and "body" in part and part["body"] is None):
                raise CodecError(f"{what}: a row's mesh keys without its body")
            mesh: dict[Any, Any] = {}
            for k in keys:
                if k not in at or at[k] >= len(columns[k]) or k in mesh:
                    raise CodecError(f"{what}: mesh field {k!r} missing from the columns")
                mesh[k] = columns[k][at[k]]
                at[k] += 1
            part = {k: (b"N" + msgpack.packb(mesh, use_bin_type=True) if k == "body" else v)
                    for k, v in part.items()}
        out.append(msgpack.packb(part, use_bin_type=True))
    if any(at[k] != len(columns[k]) for k in columns):
        raise CodecError(f"{what}: values left in the columns")
    return b"".join(out)


def is_pack(obj: Any) -> bool:
    """Whether an unpacked stream object is a pack (a map with a ``pack`` field)."""
    return isinstance(obj, dict) and "pack" in obj


def unpack_parts(obj: Any, what: str = "contents pack") -> list[tuple[Any, int]]:
    """The parts of an unpacked pack, in order, each with its packed size in bytes.

    Raises
    ------
    CodecError
        Not a pack of this format, a damaged body, more than :data:`MAX_PACK_BYTES`
        inflated, or not exactly the parts it says (each a map).
    """
    if not isinstance(obj, dict) or set(obj) != _KEYS or obj["pack"] not in (PACK_FORMAT, COLUMNS_FORMAT):
        raise CodecError(f"{what}: not a {PACK_FORMAT} or {COLUMNS_FORMAT} map")
    n, body = obj["parts"], obj["body"]
    if type(n) is not int or not 0 < n <= MAX_PACK_PARTS or not isinstance(body, bytes):
        raise CodecError(f"{what}: parts must be 1 to {MAX_PACK_PARTS} and body bytes")
    raw = decompress_raw(body, what, MAX_PACK_BYTES)
    if obj["pack"] == COLUMNS_FORMAT:
        raw = _rows_back(raw, what)
        if len(raw) > MAX_PACK_BYTES:
            raise CodecError(f"{what}: more than {MAX_PACK_BYTES} bytes packed back")
    u = msgpack.Unpacker(raw=False, max_buffer_size=max(len(raw), 1), max_map_len=8, max_array_len=0,
                         max_str_len=1 << 12, max_bin_len=len(raw), max_ext_len=0, strict_map_key=True)
    u.feed(raw)
    out: list[tuple[Any, int]] = []
    pos = 0
    try:
        for o in u:
            out.append((o, u.tell() - pos))
            pos = u.tell()
            if len(out) > n:
                break
    except (msgpack.UnpackException, ValueError) as exc:
        raise CodecError(f"{what}: damaged part {len(out)} ({exc})") from exc
    if len(out) != n or pos != len(raw):
        raise CodecError(f"{what}: {len(out)} whole parts where {n} were said")
    if not all(isinstance(o, dict) for o, _ in out):
        raise CodecError(f"{what}: a part that is not a map")
    return out
