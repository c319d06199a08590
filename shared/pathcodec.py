"""The compact path encoding (``walkstream-path-q/1``): a recorded path in a seventh of its bytes.

A client on a 56 kbit/s link waits for the path before its walk starts; the
``walkstream-path`` msgpack blob (:mod:`walkstream.shared.paths`) spends 5 bytes
per float32 value.  This encoding quantises each column to a fixed step, takes the
differences of consecutive samples (the tours move smoothly, so they are small),
zigzag-varints them column by column and deflates the lot.  On the generated
office's tour (473 samples) 12,251 B become about 1.7 kB.

Layout (media type :data:`PATH_Q_MEDIA`)::

    b"WSPQ" version:u8 zlib(msgpack {name, speed_kmh, n, steps: [6 floats], d: bin})

``steps`` are the quantisation steps of ``t, x, y, z, yaw, pitch`` (defaults
:data:`STEPS`: 1 ms, 1 mm, 1 mm, 1 mm, 1 mrad, 1 mrad); ``d`` holds ``6 n`` zigzag
LEB128 varints: for each column in turn, its first quantised value then the ``n -
1`` differences.  Decoding rebuilds ``value = step * cumsum(d)``.

Error bound: every decoded value is within half its step of the source value (0.5
ms, 0.5 mm, 0.5 mrad by default; for a yaw see below).  When rounding times to 1 ms would make two times
equal (key points closer than 1 ms), the encoder halves the time step until it does
not, so the decoded times always increase strictly and the bound is that step's
half.  Yaw is quantised as it is stored (not wrapped), so the shorter-arc
interpolation between key points is unchanged -- every turn keeps its direction, a
turn of exactly half a circle included: where rounding would tip such a turn the
other way round (its two ends a rounding apart from pi), the encoder moves the
later yaw (and the samples after it that keep that yaw) one step the way the path
turns, so those yaws are within 1.5 steps (1.5 mrad by default) of their source.

A path's head (:func:`head_path_q`, the interior start bundle's ``pathhead``) is a
compact path of its own made from the same quantised values: it decodes to exactly
the whole path's first samples.

Decoding is bounded (the inflated body may not exceed what :data:`MAX_SAMPLES`
samples can take) and every malformed body -- truncated, a zlib bomb, counts that
disagree, a value that does not fit -- raises a one-line
:class:`~walkstream.shared.errors.CodecError`.
"""

from __future__ import annotations

import math
import zlib

import msgpack
import numpy as np

from walkstream.shared.codec import decode_varints, encode_varints, inflate_tagged, unpack_bounded
from walkstream.shared.errors import CodecError, InputError
from walkstream.shared.paths import MAX_SAMPLES, RecordedPath, wrap_angle

__all__ = [
    "PATH_Q_MEDIA",
    "PATH_Q_MAGIC",
    "STEPS",
    "encode_path_q",
    "decode_path_q",
    "decode_path_any",
    "head_path_q",
    "path_error_bound",
]

PATH_Q_MEDIA = "application/vnd.walkstream.path-q1"
"""Media type of the compact path (``walkstream-path-q/1``); ask for it with ``Accept``."""
PATH_Q_MAGIC = b"WSPQ"
"""The first bytes of a compact path (a msgpack path blob starts with a map header)."""
_VERSION = 1
STEPS = (1e-3, 1e-3, 1e-3, 1e-3, 1e-3, 1e-3)
"""Default quantisation steps of ``t`` (s), ``x, y, z`` (m), ``yaw, pitch`` (rad)."""
# 6 columns of at most 10-byte varints per sample, plus the header
_MAX_INFLATED = MAX_SAMPLES * 60 + 4096
_MIN_STEP = 1e-9
_MAX_Q = float(1 << 52)  # quantised values stay exact in float64


def path_error_bound(blob: bytes) -> tuple[float, ...]:
    """The largest difference between a decoded value and its source, per column.

    Half the steps the blob was written with, ``(t, x, y, z, yaw, pitch)``; for the yaw
    one and a half (a half turn's end may be moved a step to keep its direction).
    """
    steps: list[float] = _header(blob, "compact path")["steps"]  # type: ignore[assignment]
    return tuple((1.5 if k == 4 else 0.5) * s for k, s in enumerate(steps))


def encode_path_q(path: RecordedPath, steps: tuple[float, ...] = STEPS) -> bytes:
    """Encode ``path`` compactly (see the module docstring).

    Parameters
    ----------
    path:
        The path.
    steps:
        Six quantisation steps ``(t, x, y, z, yaw, pitch)``, positive.

    Returns
    -------
    bytes
        The ``walkstream-path-q/1`` blob.
    """
    if len(steps) != 6 or not all(math.isfinite(s) and s >= _MIN_STEP for s in steps):
        raise InputError(f"path {path.name!r:.60}: compact encoding: bad steps {steps!r:.80}")
    table = path.table()  # (n, 6)
    st = list(steps)
    # halve the time step until rounding keeps the times strictly increasing
    while True:
        qt = np.rint(table[:, 0] / st[0])
        if np.all(np.diff(qt) > 0) or st[0] <= _MIN_STEP:
            break
        st[0] /= 2.0
    q = np.rint(table / np.asarray(st)[None, :])
    _keep_turns(q[:, 4], table[:, 4], st[4])
    if np.abs(q).max(initial=0.0) >= _MAX_Q:
        raise InputError(f"path {path.name!r:.60}: compact encoding: values too large for the steps")
    qi = q.astype(np.int64)
    d = np.diff(qi, axis=0, prepend=np.zeros((1, 6), np.int64))
    z = ((d << 1) ^ (d >> 63)).astype(np.uint64)  # zigzag
    body = {
        "name": path.name,
        "speed_kmh": path.speed_kmh,
        "n": len(path),
        "steps": [float(s) for s in st],
        "d": encode_varints(z.T.reshape(-1)),
    }
    return PATH_Q_MAGIC + bytes([_VERSION]) + zlib.compress(msgpack.packb(body, use_bin_type=True), 9)


def _keep_turns(qyaw: np.ndarray, yaw: np.ndarray, step: float) -> None:
    """Nudge quantised yaws ``qyaw`` (in place) so that every step between samples turns
    the way the source's does (the shorter arc, an exact half turn as ``wrap_angle`` has it)."""
    want = np.sign(wrap_angle(np.diff(yaw)))
    near = np.abs(np.abs(wrap_angle(np.diff(yaw))) - np.pi) < 4.0 * step
    # only turns near half a circle can tip (rounding moves the others far less than pi);
    # in order, since a nudged yaw starts the next step too
    for i in np.flatnonzero(near).tolist():
        for k in (0.0, 1.0, -1.0, 2.0, -2.0):
            if np.sign(wrap_angle((qyaw[i + 1] + k - qyaw[i]) * step)) == want[i]:
                # the samples after it at the same yaw move with it (standing still stays still)
                j = i + 2
                while j < len(yaw) and yaw[j] == yaw[i + 1]:
                    j += 1
                qyaw[i + 1 : j] += k
                break


def _header(blob: bytes, what: str) -> dict[str, object]:
    raw = inflate_tagged(blob, what, PATH_Q_MAGIC, _VERSION, _MAX_INFLATED, "compact path")
    obj = unpack_bounded(raw, what, max_bytes=_MAX_INFLATED, max_array_len=8, max_map_len=8,
                         max_str_len=1024, max_bin_len=_MAX_INFLATED)
    if not isinstance(obj, dict):
        raise CodecError(f"{what}: expected a map")
    for key in ("name", "n", "steps", "d"):
        if key not in obj:
            raise CodecError(f"{what}: {key}: missing")
    steps = obj["steps"]
    if (not isinstance(steps, list) or len(steps) != 6
            or not all(isinstance(s, float | int) and not isinstance(s, bool) and math.isfinite(s)
                       and s >= _MIN_STEP for s in steps)):
        raise CodecError(f"{what}: steps: expected six positive numbers, got {steps!r:.80}")
    return obj


def _diffs(obj: dict[str, object], what: str) -> np.ndarray:
    """The ``(6, n) int64`` quantised differences of a checked header's body."""
    n = obj["n"]
    if type(n) is not int or not 2 <= n <= MAX_SAMPLES:
        raise CodecError(f"{what}: n: expected 2 to {MAX_SAMPLES} samples, got {n!r:.40}")
    d = obj["d"]
    if not isinstance(d, bytes):
        raise CodecError(f"{what}: d: expected bytes")
    z = decode_varints(d, f"{what}: d")
    if len(z) != 6 * n:
        raise CodecError(f"{what}: d holds {len(z)} values, expected {6 * n} (6 per sample for {n} samples)")
    if (z >= np.uint64(1 << 62)).any():
        raise CodecError(f"{what}: d: a difference is too large")
    zi = z.astype(np.int64)
    return ((zi >> 1) ^ -(zi & 1)).reshape(6, n)


def head_path_q(blob: bytes, seconds: float, what: str = "compact path") -> bytes | None:
    """The compact path of the first ``seconds`` of compact path ``blob``: its samples up
    to and including the first at or after ``seconds`` (two at least).

    Made from the blob's own quantised values (same steps, no second rounding), so it
    decodes to exactly the first samples ``blob`` decodes to: a client may walk the head
    while the whole path is on its way, then go on along the whole path without a jump.
    None when the head would be the whole path.

    Raises
    ------
    CodecError
        ``blob`` is not a well-formed compact path (as :func:`decode_path_q`).
    """
    obj = _header(blob, what)
    diffs = _diffs(obj, what)
    steps = np.asarray(obj["steps"], np.float64)
    qt = np.cumsum(diffs[0], dtype=np.int64)
    t = (qt - qt[0]).astype(np.float64) * steps[0]  # as decode_path_q has the times
    k = max(2, int(np.searchsorted(t, seconds, side="left")) + 1)
    if k >= diffs.shape[1]:
        return None
    z = ((diffs[:, :k] << 1) ^ (diffs[:, :k] >> 63)).astype(np.uint64)  # zigzag, column by column
    body = {**obj, "n": k, "d": encode_varints(z.reshape(-1))}
    return PATH_Q_MAGIC + bytes([_VERSION]) + zlib.compress(msgpack.packb(body, use_bin_type=True), 9)


def decode_path_q(blob: bytes, what: str = "compact path") -> RecordedPath:
    """Decode a ``walkstream-path-q/1`` blob from untrusted bytes.

    Raises
    ------
    CodecError
        A one-line message naming what is wrong (header, truncation, bomb, counts,
        or the path's own checks).
    """
    obj = _header(blob, what)
    diffs = _diffs(obj, what)
    q = np.cumsum(diffs, axis=1, dtype=np.int64)
    table = (q.astype(np.float64) * np.asarray(obj["steps"], np.float64)[:, None]).T
    table[:, 0] -= table[0, 0]  # a path starts at t = 0 (the first time rounds to it)
    try:
        return RecordedPath(obj["name"], table[:, 0], table[:, 1:4], table[:, 4], table[:, 5],  # type: ignore[arg-type]
                            obj.get("speed_kmh"))  # type: ignore[arg-type]
    except InputError as exc:
        raise CodecError(f"{what}: {exc}") from exc


def decode_path_any(blob: bytes, what: str = "recorded path") -> RecordedPath:
    """Decode a path body in either encoding: compact (starts with :data:`PATH_Q_MAGIC`)
    or the ``walkstream-path`` msgpack blob."""
    if bytes(blob[:4]) == PATH_Q_MAGIC:
        return decode_path_q(blob, what)
    return RecordedPath.from_msgpack(blob, what)
