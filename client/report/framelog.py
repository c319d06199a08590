"""A replay's per-frame log: the rows the walk appends, the columns the figures read.

The replay appends one row per frame to a :class:`FrameLogBuilder` and turns it into a
:class:`FrameLog` (columns of equal-length, read-only numpy arrays) when the walk ends;
:mod:`walkstream.client.report.metrics` reduces it to the report's figures. The displayed
frame rate (:func:`displayed_fps`) is a column of the log, defined here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.shared.arrays import F64, I64, Bool
from walkstream.shared.errors import InputError

__all__ = ["COLUMNS", "FrameLog", "FrameLogBuilder", "displayed_fps"]


#: ``(name, dtype)`` of every :class:`FrameLog` column, in CSV order.
COLUMNS: tuple[tuple[str, type[np.generic]], ...] = (
    ("t", np.float64),
    ("frame_time", np.float64),
    ("fps", np.float64),
    ("cell", np.int64),
    ("pvs", np.int64),
    ("download_quality", np.float64),
    ("rewrite_quality", np.float64),
    ("bytes_down", np.int64),
    ("budget", np.int64),
    ("triangles", np.int64),
    ("visible", np.int64),
    ("floor_limited", np.bool_),
    ("all_lod2", np.bool_),
)


def displayed_fps(frame_time: ArrayLike, fps_cap: float) -> F64:
    """Displayed frame rate of frames that took ``frame_time`` seconds of work.

    Parameters
    ----------
    frame_time : (n,) float
        Work time of each frame, seconds.  Negative values count as 0; an infinite
        time (a frame that never finished) gives rate 0, a NaN time (no measurement)
        rate NaN, which the summary's statistics turn into ``None``.
    fps_cap : float
        The replay's tick rate (``--fps``), frames per second, > 0 and finite.

    Returns
    -------
    (n,) float64
        ``1 / max(frame_time, 1 / fps_cap)``.

    Raises
    ------
    InputError
        ``fps_cap`` is not a positive finite number.
    """
    cap = float(fps_cap)
    if not (math.isfinite(cap) and cap > 0.0):
        raise InputError(f"fps_cap must be a positive finite frame rate, got {fps_cap!r}")
    ft = np.asarray(frame_time, dtype=np.float64)
    out: F64 = 1.0 / np.maximum(ft, 1.0 / cap)
    return out


def _column(name: str, values: ArrayLike, dtype: type[np.generic]) -> NDArray[Any]:
    a = np.array(values, dtype=dtype)  # always a copy, so the log owns its data
    if a.ndim != 1:
        raise InputError(f"FrameLog column {name!r} must be 1-D, got shape {a.shape}")
    a.flags.writeable = False
    return a


@dataclass(frozen=True, slots=True, eq=False)
class FrameLog:
    """One row per drawn frame, as columns of equal length (read-only arrays).

    Attributes
    ----------
    t : (n,) float64
        Frame start, seconds (virtual or real clock).
    frame_time : (n,) float64
        Work time of the frame, seconds.
    fps : (n,) float64
        Displayed frame rate (:func:`displayed_fps`).
    cell : (n,) int64
        Current view cell id; -1 while none is known yet.
    pvs : (n,) int64
        Size of the current cell's PVS.
    download_quality, rewrite_quality : (n,) float64
        0..1: share of the current cell's PVS whose parameters have arrived / whose
        geometry is built.
    bytes_down : (n,) int64
        Cumulative bytes received by the start of the frame.
    budget, triangles, visible : (n,) int64
        Triangle budget, triangles drawn, objects left after culling.
    floor_limited : (n,) bool
        The LOD0s of the visible objects alone exceeded the budget.
    all_lod2 : (n,) bool
        Everything visible was drawn at LOD2 (vacuously true with nothing visible).
    """

    t: F64
    frame_time: F64
    fps: F64
    cell: I64
    pvs: I64
    download_quality: F64
    rewrite_quality: F64
    bytes_down: I64
    budget: I64
    triangles: I64
    visible: I64
    floor_limited: Bool
    all_lod2: Bool

    def __post_init__(self) -> None:
        n = None
        for name, dtype in COLUMNS:
            a = _column(name, getattr(self, name), dtype)
            object.__setattr__(self, name, a)
            if n is None:
                n = len(a)
            elif len(a) != n:
                raise InputError(
                    f"FrameLog column {name!r} has {len(a)} rows, expected {n} like 't'"
                )

    def __len__(self) -> int:
        return len(self.t)

    @classmethod
    def empty(cls) -> FrameLog:
        """A log with no frames."""
        return cls(**{name: np.empty(0, dtype) for name, dtype in COLUMNS})

    @classmethod
    def from_columns(
        cls,
        *,
        fps_cap: float,
        t: ArrayLike,
        frame_time: ArrayLike,
        download_quality: ArrayLike,
        rewrite_quality: ArrayLike,
        bytes_down: ArrayLike | None = None,
        cell: ArrayLike | None = None,
        pvs: ArrayLike | None = None,
        budget: ArrayLike | None = None,
        triangles: ArrayLike | None = None,
        visible: ArrayLike | None = None,
        floor_limited: ArrayLike | None = None,
        all_lod2: ArrayLike | None = None,
    ) -> FrameLog:
        """Build a log from columns, computing ``fps`` from ``frame_time`` and the tick.

        Columns left out get the defaults of :meth:`FrameLogBuilder.append` (``cell``
        -1, counts 0, flags False); scalars are broadcast to the length of ``t``.
        """
        tt = np.asarray(t, dtype=np.float64)
        n = tt.shape[0] if tt.ndim == 1 else -1

        def col(v: ArrayLike | None, default: Any) -> Any:
            if v is None:
                return np.full(max(n, 0), default)
            a = np.asarray(v)
            return np.broadcast_to(a, (max(n, 0),)) if a.ndim == 0 else a

        return cls(
            t=tt,
            frame_time=np.asarray(frame_time, dtype=np.float64),
            fps=displayed_fps(frame_time, fps_cap),
            cell=col(cell, -1),
            pvs=col(pvs, 0),
            download_quality=np.asarray(download_quality, dtype=np.float64),
            rewrite_quality=np.asarray(rewrite_quality, dtype=np.float64),
            bytes_down=col(bytes_down, 0),
            budget=col(budget, 0),
            triangles=col(triangles, 0),
            visible=col(visible, 0),
            floor_limited=col(floor_limited, False),
            all_lod2=col(all_lod2, False),
        )

    def columns(self) -> dict[str, NDArray[Any]]:
        """The columns by name, in :data:`COLUMNS` order (the arrays themselves, read-only)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


class FrameLogBuilder:
    """Growable per-frame log: one cheap :meth:`append` per frame, one :meth:`build` at the end.

    Rows are kept in Python lists (an append is a handful of list appends, a few
    microseconds) and turned into arrays once.

    Parameters
    ----------
    fps_cap : float, optional
        The replay's tick rate (``--fps``), used to compute the displayed frame rate;
        may instead be given to :meth:`build`.
    """

    __slots__ = (
        "fps_cap",
        "_t",
        "_frame_time",
        "_cell",
        "_pvs",
        "_dq",
        "_rq",
        "_bytes",
        "_budget",
        "_tri",
        "_vis",
        "_floor",
        "_lod2",
    )

    def __init__(self, fps_cap: float | None = None) -> None:
        if fps_cap is not None:
            displayed_fps(np.empty(0), fps_cap)  # validates the cap now, not at build time
        self.fps_cap = None if fps_cap is None else float(fps_cap)
        self._t: list[float] = []
        self._frame_time: list[float] = []
        self._cell: list[int] = []
        self._pvs: list[int] = []
        self._dq: list[float] = []
        self._rq: list[float] = []
        self._bytes: list[int] = []
        self._budget: list[int] = []
        self._tri: list[int] = []
        self._vis: list[int] = []
        self._floor: list[bool] = []
        self._lod2: list[bool] = []

    def __len__(self) -> int:
        return len(self._t)

    def append(
        self,
        *,
        t: float,
        frame_time: float,
        download_quality: float,
        rewrite_quality: float,
        bytes_down: int = 0,
        cell: int = -1,
        pvs: int = 0,
        budget: int = 0,
        triangles: int = 0,
        visible: int = 0,
        floor_limited: bool = False,
        all_lod2: bool = False,
    ) -> None:
        """Add one frame (keyword arguments named like the :class:`FrameLog` columns, but no ``fps``)."""
        self._t.append(t)
        self._frame_time.append(frame_time)
        self._dq.append(download_quality)
        self._rq.append(rewrite_quality)
        self._bytes.append(bytes_down)
        self._cell.append(cell)
        self._pvs.append(pvs)
        self._budget.append(budget)
        self._tri.append(triangles)
        self._vis.append(visible)
        self._floor.append(floor_limited)
        self._lod2.append(all_lod2)

    def build(self, fps_cap: float | None = None) -> FrameLog:
        """The frames appended so far as a :class:`FrameLog` (the builder stays usable).

        ``fps_cap`` overrides the tick rate given to the constructor; one of the two is
        required (:class:`~walkstream.shared.errors.InputError` otherwise).
        """
        cap = self.fps_cap if fps_cap is None else fps_cap
        if cap is None:
            raise InputError("FrameLogBuilder.build needs fps_cap (the replay's tick rate)")
        return FrameLog.from_columns(
            fps_cap=cap,
            t=np.array(self._t, dtype=np.float64),
            frame_time=np.array(self._frame_time, dtype=np.float64),
            download_quality=np.array(self._dq, dtype=np.float64),
            rewrite_quality=np.array(self._rq, dtype=np.float64),
            bytes_down=np.array(self._bytes, dtype=np.int64),
            cell=np.array(self._cell, dtype=np.int64),
            pvs=np.array(self._pvs, dtype=np.int64),
            budget=np.array(self._budget, dtype=np.int64),
            triangles=np.array(self._tri, dtype=np.int64),
            visible=np.array(self._vis, dtype=np.int64),
            floor_limited=np.array(self._floor, dtype=np.bool_),
            all_lod2=np.array(self._lod2, dtype=np.bool_),
        )
