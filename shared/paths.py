"""Recorded paths: a walk or drive through a scene as timed key points.

A recorded path says where the viewer is and where it looks at every moment of a
walkthrough.  The bake records a few (``SE``, ``SM``, ``drive``), ``walkstream path``
adds more, and the client replays them.  A client downloads the path before it
starts walking, possibly over a 56 kbit/s link, so the format stores only key
points (corners, the start and end of turns), not samples at a fixed rate.

Format ``walkstream-path``, version 1
-------------------------------------
One msgpack map (the same structure as a JSON object is accepted too)::

    {"format": "walkstream-path", "version": 1, "name": str,
     "speed_kmh": float or nil,
     "columns": ["t", "x", "y", "z", "yaw", "pitch"],
     "samples": [[t, x, y, z, yaw, pitch], ...]}

``t``
    Seconds from the start of the path: the first sample has ``t = 0`` and ``t``
    strictly increases.
``x, y``
    Scene-local metres (the scene's CRS minus its origin, as everywhere else).
``z``
    Eye height above the ground in metres (1.7 walking, 1.2 driving).
``yaw``
    View direction in radians, counter-clockwise from +x (0 looks east, pi/2 north).
``pitch``
    Radians above the horizon (0 is level, positive looks up).
``speed_kmh``
    The nominal speed the path was timed with, for display; nil when unknown.

Numbers may be msgpack/JSON integers or floats (booleans are refused); the writer
stores sample values as float32 (millimetres over tens of kilometres, far below what the
viewer can notice) unless that would make two times equal, then as float64.  Keys
other than the ones above are ignored, so later versions may add some.  There must
be at least two samples; a path may stand still (equal positions at increasing
times) and go back on itself (a U-turn is just a polyline going back).

Between key points the position and pitch are interpolated linearly and the yaw
along the shorter arc, so a writer splits turns of more than half a circle into
steps (as :meth:`RecordedPath.from_polyline` does).  Before the first and after the
last sample the path stays at its ends.

Decoding is bounded (:func:`~walkstream.shared.codec.unpack_bounded` with tight limits) and
every malformed thing raises :class:`~walkstream.shared.errors.CodecError` naming the field and,
for samples, the sample index.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import Any

import msgpack
import numpy as np
from numpy.typing import ArrayLike

from walkstream.shared.arrays import F64
from walkstream.shared.codec import unpack_bounded
from walkstream.shared.errors import CodecError, InputError
from walkstream.shared.records import readonly

__all__ = [
    "FORMAT",
    "VERSION",
    "COLUMNS",
    "MAX_SAMPLES",
    "WALK_EYE_HEIGHT",
    "DRIVE_EYE_HEIGHT",
    "RecordedPath",
    "direction",
    "wrap_angle",
]

FORMAT = "walkstream-path"
"""The value of the ``format`` key."""
VERSION = 1
"""The one format version this code reads and writes."""
COLUMNS = ("t", "x", "y", "z", "yaw", "pitch")
"""The columns of a sample, in order."""
MAX_SAMPLES = 1 << 16
"""Most key points a path may have (about 30 km of city streets with a corner every 10 m)."""
WALK_EYE_HEIGHT = 1.7
"""Eye height of a walker, metres."""
DRIVE_EYE_HEIGHT = 1.2
"""Eye height of a car driver, metres."""


_MAX_NAME = 200  # as the scene store allows
# a sample is at most 1 + 6 * 9 bytes of msgpack; plus the header
_MAX_BLOB = MAX_SAMPLES * 56 + 4096
_MAX_JSON = 64 * _MAX_BLOB
_TWO_PI = 2.0 * math.pi
# a turn sharper than this is made standing still (the walker stops and turns),
# gentler ones while walking on (the view turns across the corner)
_SHARP_TURN = math.radians(100.0)
# bends below this are not worth key points of their own before and after
_SMALL_TURN = math.radians(8.0)
# consecutive vertices closer than this (metres) are merged: keeps time steps well
# above float64 resolution even for long paths
_MIN_STEP = 1e-3


def wrap_angle(a: ArrayLike) -> F64:
    """Angles wrapped into ``[-pi, pi)`` radians (same shape as ``a``)."""
    x = np.asarray(a, dtype=np.float64)
    return np.asarray((x + math.pi) % _TWO_PI - math.pi, dtype=np.float64)


def direction(yaw: ArrayLike, pitch: ArrayLike = 0.0) -> F64:
    """Unit view vectors for yaw and pitch angles.

    Parameters
    ----------
    yaw:
        Radians counter-clockwise from +x, any shape.
    pitch:
        Radians above the horizon, broadcastable with ``yaw``.

    Returns
    -------
    numpy.ndarray
        ``(..., 3) float64`` unit vectors ``(cos p cos y, cos p sin y, sin p)``.
    """
    y, p = np.broadcast_arrays(np.asarray(yaw, np.float64), np.asarray(pitch, np.float64))
    cp = np.cos(p)
    return np.stack([cp * np.cos(y), cp * np.sin(y), np.sin(p)], axis=-1)


def _check_name(name: object, what: str, err: type[InputError]) -> str:
    if not isinstance(name, str) or not 0 < len(name) <= _MAX_NAME:
        raise err(f"{what}: name: expected 1 to {_MAX_NAME} characters, got {name!r:.60}")
    if not name.isprintable():
        raise err(f"{what}: name {name!r:.60}: control characters are not allowed")
    return name


def _check_speed(speed: object, what: str, err: type[InputError]) -> float | None:
    if speed is None:
        return None
    if isinstance(speed, bool) or not isinstance(speed, int | float | np.floating | np.integer):
        raise err(f"{what}: speed_kmh: expected a number or nil, got {type(speed).__name__}")
    v = float(speed)
    if not (math.isfinite(v) and v > 0):
        raise err(f"{what}: speed_kmh: expected a positive number of km/h, got {v}")
    return v


def _validate_table(table: F64, what: str, err: type[InputError]) -> None:
    """Check an ``(n, 6)`` sample table: finite, ``t`` from 0 strictly increasing."""
    n = len(table)
    if n < 2:
        raise err(f"{what}: samples: expected at least 2 samples, got {n}")
    if n > MAX_SAMPLES:
        raise err(f"{what}: samples: {n} samples, more than the limit of {MAX_SAMPLES}")
    bad = np.argwhere(~np.isfinite(table))
    if len(bad):
        i, j = (int(v) for v in bad[0])
        raise err(f"{what}: samples[{i}]: {COLUMNS[j]} is not finite ({table[i, j]})")
    t = table[:, 0]
    if t[0] != 0.0:
        raise err(f"{what}: samples[0]: t must be 0 (seconds from the start), got {t[0]}")
    steps = np.flatnonzero(np.diff(t) <= 0)
    if len(steps):
        i = int(steps[0]) + 1
        raise err(f"{what}: samples[{i}]: t must increase strictly, got {t[i]} after {t[i - 1]}")


@dataclass(frozen=True, eq=False)
class RecordedPath:
    """A recorded path: timed key points of position and view direction.

    Attributes
    ----------
    name:
        The path's name (1 to 200 printable characters).
    t:
        ``(n,) float64`` seconds from the start, ``t[0] = 0``, strictly increasing.
    xyz:
        ``(n, 3) float64`` positions: scene-local metres, ``z`` the eye height.
    yaw:
        ``(n,) float64`` radians counter-clockwise from +x.
    pitch:
        ``(n,) float64`` radians above the horizon.
    speed_kmh:
        Nominal speed the path was timed with, or None.

    All arrays are read-only.  Construction validates everything and raises
    :class:`~walkstream.shared.errors.InputError` naming the first problem.
    """

    name: str
    t: F64
    xyz: F64
    yaw: F64
    pitch: F64
    speed_kmh: float | None = None

    def __post_init__(self) -> None:
        err = InputError
        what = f"path {self.name!r:.60}" if isinstance(self.name, str) else "path"
        _check_name(self.name, what, err)
        try:
            t = np.asarray(self.t, dtype=np.float64).reshape(-1)
            xyz = np.asarray(self.xyz, dtype=np.float64)
            yaw = np.asarray(self.yaw, dtype=np.float64).reshape(-1)
            pitch = np.asarray(self.pitch, dtype=np.float64).reshape(-1)
        except (TypeError, ValueError) as exc:
            raise err(f"{what}: samples are not numbers ({exc})") from exc
        n = len(t)
        if xyz.shape != (n, 3):
            raise err(f"{what}: xyz: expected shape ({n}, 3), got {xyz.shape}")
        for label, a in (("yaw", yaw), ("pitch", pitch)):
            if a.shape != (n,):
                raise err(f"{what}: {label}: expected {n} values, got {a.shape[0]}")
        table = np.column_stack([t, xyz, yaw, pitch])
        _validate_table(table, what, err)
        object.__setattr__(self, "t", readonly(t))
        object.__setattr__(self, "xyz", readonly(xyz))
        object.__setattr__(self, "yaw", readonly(yaw))
        object.__setattr__(self, "pitch", readonly(pitch))
        object.__setattr__(self, "speed_kmh", _check_speed(self.speed_kmh, what, err))

    # -- basics --------------------------------------------------------------

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, RecordedPath):
            return NotImplemented
        return (
            self.name == other.name
            and self.speed_kmh == other.speed_kmh
            and np.array_equal(self.t, other.t)
            and np.array_equal(self.xyz, other.xyz)
            and np.array_equal(self.yaw, other.yaw)
            and np.array_equal(self.pitch, other.pitch)
        )

    __hash__ = None  # type: ignore[assignment]

    def __len__(self) -> int:
        """Number of key points."""
        return len(self.t)

    @property
    def duration(self) -> float:
        """Seconds from the first to the last key point."""
        return float(self.t[-1])

    def length_m(self) -> float:
        """Distance travelled in metres (3D, along the straight legs between key points)."""
        return float(np.linalg.norm(np.diff(self.xyz, axis=0), axis=1).sum())

    def table(self) -> F64:
        """The samples as an ``(n, 6)`` array in :data:`COLUMNS` order (a fresh copy)."""
        return np.column_stack([self.t, self.xyz, self.yaw, self.pitch])

    # -- sampling ------------------------------------------------------------

    def sample(self, ts: ArrayLike) -> tuple[F64, F64, F64]:
        """Positions and view angles at many times (vectorised).

        Parameters
        ----------
        ts:
            Times in seconds, any shape; clamped into ``[0, duration]``.

        Returns
        -------
        tuple
            ``xyz`` ``(m, 3)``, ``yaw`` ``(m,)`` in ``[-pi, pi)`` and ``pitch``
            ``(m,)``, with ``m`` the number of times (``ts`` flattened).
        """
        q = np.clip(np.asarray(ts, dtype=np.float64).reshape(-1), 0.0, self.duration)
        t = self.t
        i = np.clip(np.searchsorted(t, q, side="right") - 1, 0, len(t) - 2)
        f = (q - t[i]) / (t[i + 1] - t[i])
        xyz = self.xyz[i] + f[:, None] * (self.xyz[i + 1] - self.xyz[i])
        dyaw = wrap_angle(self.yaw[i + 1] - self.yaw[i])
        yaw = wrap_angle(self.yaw[i] + f * dyaw)
        pitch = self.pitch[i] + f * (self.pitch[i + 1] - self.pitch[i])
        return xyz, yaw, pitch

    def at(self, t: float) -> tuple[F64, float, float]:
        """Position ``(3,)``, yaw and pitch at time ``t`` (clamped into the path)."""
        xyz, yaw, pitch = self.sample([float(t)])
        return xyz[0], float(yaw[0]), float(pitch[0])

    # -- encoding ------------------------------------------------------------

    def to_dict(self) -> dict[str, Any]:
        """The format's map with plain Python numbers (as written to msgpack/JSON)."""
        return {
            "format": FORMAT,
            "version": VERSION,
            "name": self.name,
            "speed_kmh": self.speed_kmh,
            "columns": list(COLUMNS),
            "samples": [[_plain(v) for v in row] for row in self.table().tolist()],
        }

    def to_msgpack(self) -> bytes:
        """The path as a compact msgpack blob (see the module docstring).

        Sample values are stored as float32 unless that would make two consecutive
        times equal; reading the blob back gives this path up to float32 rounding
        (``speed_kmh`` is kept exactly).
        """
        obj = self.to_dict()
        t32 = np.asarray(self.t, dtype=np.float32)
        single = bool(np.all(np.diff(t32) > 0))
        # the header (speed included) in full precision, the samples in float32
        pk = msgpack.Packer(use_single_float=False)
        pk_samples = msgpack.Packer(use_single_float=single)
        parts = [pk.pack_map_header(len(obj))]
        for key, value in obj.items():
            parts.append(pk.pack(key))
            parts.append((pk_samples if key == "samples" else pk).pack(value))
        return b"".join(parts)

    @classmethod
    def from_msgpack(cls, blob: bytes, what: str = "recorded path") -> RecordedPath:
        """Decode a path blob from untrusted bytes.

        Parameters
        ----------
        blob:
            The msgpack bytes.
        what:
            How error messages name the blob (``"path 'SE'"``).

        Raises
        ------
        CodecError
            Not msgpack, too large, or any field missing or malformed (the message
            names the field and, for samples, the sample index).
        """
        obj = unpack_bounded(
            blob,
            what,
            max_bytes=_MAX_BLOB,
            max_array_len=MAX_SAMPLES,
            max_map_len=32,
            max_str_len=4 * _MAX_NAME,
            max_bin_len=0,
        )
        return cls.from_dict(obj, what, CodecError)

    def to_json(self, *, indent: bool = True) -> str:
        """The path as JSON text: the same map, one sample per line when ``indent``.

        Numbers are rounded to 6 decimals (micrometres, microseconds) when that keeps
        the times strictly increasing.
        """
        d = self.to_dict()
        rows = d.pop("samples")
        rounded = [[_plain(round(v, 6)) for v in row] for row in rows]
        if all(b[0] > a[0] for a, b in zip(rounded, rounded[1:], strict=False)):
            rows = rounded
        head = json.dumps(d, allow_nan=False)[:-1]  # open the object to append samples
        if not indent:
            return head + ', "samples": ' + json.dumps(rows, allow_nan=False) + "}"
        body = ",\n  ".join(json.dumps(r, allow_nan=False) for r in rows)
        return head + ',\n "samples": [\n  ' + body + "\n ]\n}\n"

    @classmethod
    def from_json(cls, text: str | bytes, what: str = "recorded path") -> RecordedPath:
        """Read the JSON form (see :meth:`to_json`).

        Raises
        ------
        CodecError
            Not JSON, too large, or any field malformed.
        """
        if not isinstance(text, str | bytes | bytearray):
            raise CodecError(f"{what}: expected JSON text, got {type(text).__name__}")
        if len(text) > _MAX_JSON:
            raise CodecError(
                f"{what}: {len(text)} bytes of JSON, more than the limit of {_MAX_JSON}"
            )
        try:
            obj = json.loads(text)
        except (ValueError, RecursionError) as exc:
            raise CodecError(f"{what}: not JSON ({exc})") from exc
        return cls.from_dict(obj, what, CodecError)

    @classmethod
    def from_dict(
        cls, obj: object, what: str = "recorded path", err: type[InputError] = CodecError
    ) -> RecordedPath:
        """Validate and convert the format's map (as unpacked from msgpack or JSON).

        Raises
        ------
        CodecError
            (or ``err``) naming the first malformed field or sample.
        """
        if not isinstance(obj, dict):
            raise err(f"{what}: expected a map, got {type(obj).__name__}")
        fmt = obj.get("format")
        if fmt != FORMAT:
            raise err(f"{what}: format: expected {FORMAT!r}, got {fmt!r:.60}")
        version = obj.get("version")
        if type(version) is not int:
            raise err(f"{what}: version: expected an integer, got {version!r:.40}")
        if version != VERSION:
            raise err(f"{what}: version: {version} is not supported (this reader knows {VERSION})")
        if "name" not in obj:
            raise err(f"{what}: name: missing")
        name = _check_name(obj["name"], what, err)
        speed = _check_speed(obj.get("speed_kmh"), what, err)
        columns = obj.get("columns")
        if columns != list(COLUMNS):
            raise err(f"{what}: columns: expected {list(COLUMNS)}, got {columns!r:.120}")
        samples = obj.get("samples")
        if not isinstance(samples, list):
            raise err(f"{what}: samples: expected a list, got {type(samples).__name__}")
        if len(samples) > MAX_SAMPLES:
            raise err(f"{what}: samples: {len(samples)} samples, more than {MAX_SAMPLES}")
        for i, row in enumerate(samples):
            if not isinstance(row, list) or len(row) != len(COLUMNS):
                got = f"{len(row)} values" if isinstance(row, list) else type(row).__name__
                raise err(f"{what}: samples[{i}]: expected {len(COLUMNS)} numbers, got {got}")
            for j, v in enumerate(row):
                if type(v) is not float and type(v) is not int:
                    raise err(
                        f"{what}: samples[{i}]: {COLUMNS[j]}: expected a number, "
                        f"got {type(v).__name__}"
                    )
        try:
            table = np.array(samples, dtype=np.float64).reshape(-1, len(COLUMNS))
        except OverflowError as exc:  # an integer beyond float64
            raise err(f"{what}: samples: a number is out of range") from exc
        _validate_table(table, what, err)
        # everything the constructor checks has been checked with ``err`` above
        return cls(name, table[:, 0], table[:, 1:4], table[:, 4], table[:, 5], speed)

    # -- making paths ----------------------------------------------------------

    @classmethod
    def from_polyline(
        cls,
        name: str,
        xy: ArrayLike,
        speed_kmh: float,
        eye_height: float = WALK_EYE_HEIGHT,
        turn_seconds: float = 1.0,
    ) -> RecordedPath:
        """Walk along a polyline at constant speed, facing along the motion.

        Key points are the polyline's vertices plus a few around each corner so the
        view turns smoothly instead of snapping:

        - a bend of less than 8 degrees gets no extra key point (the view drifts
          through it along the neighbouring legs);
        - a corner up to 100 degrees is taken walking: the view turns from the
          incoming to the outgoing direction over ``turn_seconds`` per 90 degrees,
          centred on the corner (key points before, at and after it, at most 45 %
          of the neighbouring legs away);
        - a sharper corner, such as a U-turn (the polyline going back on itself), is
          taken standing: the walker stops at the vertex and turns on the spot,
          ``turn_seconds`` per 90 degrees, in steps of at most 90 degrees so that
          the shorter-arc interpolation turns the intended way.

        Parameters
        ----------
        name:
            The path's name.
        xy:
            ``(n, 2)`` vertices in scene-local metres, ``n >= 2``; repeated vertices
            and vertices on a straight line through their neighbours are dropped.
        speed_kmh:
            Walking (or driving) speed, km/h, > 0.
        eye_height:
            ``z`` of every key point, metres.
        turn_seconds:
            Seconds per 90 degrees of turning, > 0.

        Raises
        ------
        InputError
            Fewer than two distinct vertices, non-finite vertices, or a parameter out
            of range.
        """
        what = f"path {name!r:.60}"
        _check_name(name, what, InputError)
        speed = _check_speed(speed_kmh, what, InputError)
        if speed is None:
            raise InputError(f"{what}: speed_kmh: a speed is needed to time the path")
        try:
            pts = np.asarray(xy, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise InputError(f"{what}: polyline: not numbers ({exc})") from exc
        if pts.ndim != 2 or pts.shape[1] != 2:
            raise InputError(f"{what}: polyline: expected (n, 2) points, got shape {pts.shape}")
        bad = np.argwhere(~np.isfinite(pts))
        if len(bad):
            raise InputError(f"{what}: polyline point {int(bad[0][0])} is not finite")
        z = float(eye_height)
        if not math.isfinite(z):
            raise InputError(f"{what}: eye_height: expected a finite number, got {eye_height}")
        turn = float(turn_seconds)
        if not (math.isfinite(turn) and turn > 0):
            raise InputError(
                f"{what}: turn_seconds: expected a positive number, got {turn_seconds}"
            )
        pts = _clean_polyline(pts)
        if len(pts) < 2:
            raise InputError(f"{what}: polyline: expected at least 2 distinct points")

        v = speed / 3.6
        seg = np.diff(pts, axis=0)
        lengths = np.hypot(seg[:, 0], seg[:, 1])
        unit = seg / lengths[:, None]
        heading = np.arctan2(seg[:, 1], seg[:, 0])

        # (time, x, y, yaw); yaw kept unwrapped so consecutive steps are the short way
        keys: list[tuple[float, float, float, float]] = []
        t = 0.0
        pos = pts[0]
        yaw = float(heading[0])
        keys.append((0.0, float(pos[0]), float(pos[1]), yaw))

        def walk_to(p: F64, new_yaw: float) -> None:
            nonlocal t, pos
            t += float(np.hypot(*(p - pos))) / v
            pos = p
            keys.append((t, float(p[0]), float(p[1]), new_yaw))

        for j in range(1, len(pts) - 1):
            delta = float(wrap_angle(heading[j] - heading[j - 1]))
            if delta <= -math.pi + 1e-9:
                delta = math.pi  # an exact U-turn: turn left, deterministically
            vertex = pts[j]
            if abs(delta) < _SMALL_TURN:
                walk_to(vertex, yaw + 0.5 * delta)
                yaw += delta
            elif abs(delta) <= _SHARP_TURN:
                half = 0.5 * turn * abs(delta) / (0.5 * math.pi) * v
                d = min(half, 0.45 * float(lengths[j - 1]), 0.45 * float(lengths[j]))
                if d > 1e-3:
                    walk_to(vertex - unit[j - 1] * d, yaw)
                walk_to(vertex, yaw + 0.5 * delta)
                yaw += delta
                if d > 1e-3:
                    walk_to(vertex + unit[j] * d, yaw)
            else:
                walk_to(vertex, yaw)
                steps = max(1, math.ceil(abs(delta) / (0.5 * math.pi) - 1e-9))
                dwell = turn * abs(delta) / (0.5 * math.pi)
                for k in range(1, steps + 1):
                    t += dwell / steps
                    keys.append((t, float(vertex[0]), float(vertex[1]), yaw + delta * k / steps))
                yaw += delta
        walk_to(pts[-1], yaw)

        arr = np.array(keys, dtype=np.float64)
        xyz = np.column_stack([arr[:, 1], arr[:, 2], np.full(len(arr), z)])
        return cls(name, arr[:, 0], xyz, wrap_angle(arr[:, 3]), np.zeros(len(arr)), speed)


def _plain(v: float) -> float | int:
    """An integral value as int (1 msgpack byte for small ones), else the float."""
    if v == 0.0:
        return 0  # also turns -0.0 into 0
    if float(v).is_integer() and abs(v) < 2**31:
        return int(v)
    return float(v)


def _clean_polyline(pts: F64) -> F64:
    """Drop repeated vertices and vertices on the straight line through their neighbours.

    A vertex where the line goes back on itself is kept: that is a U-turn.
    """
    keep = [pts[0]]
    for p in pts[1:]:
        if float(np.hypot(*(p - keep[-1]))) > _MIN_STEP:
            keep.append(p)
    if len(keep) < 3:
        return np.array(keep, dtype=np.float64).reshape(-1, 2)
    out = [keep[0]]
    for j in range(1, len(keep) - 1):
        a, b, c = out[-1], keep[j], keep[j + 1]
        u, w = b - a, c - b
        cross = float(u[0] * w[1] - u[1] * w[0])
        dot = float(u[0] * w[0] + u[1] * w[1])
        if abs(cross) <= 1e-9 * float(np.hypot(*u)) * float(np.hypot(*w)) and dot > 0:
            continue  # straight on: b adds nothing
        out.append(b)
    out.append(keep[-1])
    return np.array(out, dtype=np.float64)
